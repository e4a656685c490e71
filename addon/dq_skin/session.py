# SPDX-License-Identifier: GPL-3.0-or-later
"""The session: the one owner of everything the add-on keeps between Blender's calls.

- `states`: each DQ Skin modifier's state (`model.state`);
- `tracker`: the DQ Skin objects and what they depend on (`engine.tracker`);
- `meshes`: what was read of each mesh (`blender.meshdata`);
- `influences`: the influences bindings share (`engine.binding.SharedInfluences`);
- `interned`: the bone names, rest matrices and group names characters share (`model.interned`);
- `readers`: the readers of Blender's memory (`blender.memory`);
- `scan`: what simulates on what (`blender.consumers`);
- `routes`: how positions reach Blender, with the feed (`routes`);
- `centers`: the Optimized Centers computed and computing (`engine.centers`);
- `exports`, `signals`, `errors`: exporters running, batch commands' signals, the last
  internal error (`model.runtime`).

`reset()` forgets everything tied to the file's data-blocks (a file is loaded, an undo step
replaced them); `close()` also releases what the session made (the add-on is disabled).
Nothing else in the add-on keeps mutable state at module level.
"""

from __future__ import annotations

from .blender.consumers import Scan
from .blender.memory import Readers
from .blender.meshdata import MeshCache
from .engine.binding import SharedInfluences
from .engine.centers import Centers
from .engine.context import mod_key
from .engine.fed import skin_members
from .engine.tracker import Tracker
from .model.interned import Interned
from .model.runtime import Errors, Exports, Signals
from .model.state import States
from .routes.feed import Feeds
from .routes.table import Routes


class Session:
    def __init__(self):
        self.errors = Errors()
        self.signals = Signals()
        self.commands: list = []  # Blender's handles of the registered command-line commands
        self.exports = Exports()
        self.states = States()
        self.interned = Interned()
        self.meshes = MeshCache(self.interned)
        self.influences = SharedInfluences()
        self.readers = Readers()
        self.scan = Scan()
        self.centers = Centers(interrupted=self.signals.requested)
        # Whether the main thread is inside a Python operator (set by the scheduling layer,
        # which reads the interpreter's stack; see `scheduling.inside_python_operator`).
        self.operator_running = lambda: False
        self.routes = Routes(Feeds(busy=lambda: self.operator_running()))
        self.routes.feeds.skin = skin_members(self)
        self.tracker = Tracker(self)

    def reset(self) -> None:
        """Forgets everything tied to the file's data-blocks (the point-cache files go)."""
        self.tracker.reset()
        for _key, st in self.states.items():
            if st.output.pointcache is not None:
                st.output.pointcache.close()
        self.states.clear()
        self.routes.feeds.close()
        self.meshes.forget()
        self.influences.forget()
        self.interned.forget()
        self.scan.version = -1

    def close(self) -> None:
        """Releases what the session made, then forgets everything (the add-on is disabled)."""
        for _key, st in self.states.items():
            self.routes.release_state(st)
        self.centers.close()
        self.reset()

    # -- the panel's and the operators' view of a modifier ----------------------------------
    def state_of(self, obj, mod):
        return self.states.get(mod_key(obj, mod))

    def status_of(self, obj, mod):
        """The panel's view of a modifier (`state.Status`)."""
        return self.state_of(obj, mod).status

    def find_status(self, obj, mod):
        """`status_of` without creating a state (drawing a panel must not)."""
        st = self.states.find(mod_key(obj, mod))
        return st.status if st is not None else None


SESSION = Session()

# SPDX-License-Identifier: GPL-3.0-or-later
"""The interface every way of getting DQ Skin's positions into Blender implements.

A *target* is one DQ Skin modifier on one object, with its state. A route:
- `prepare(target)`: makes what it needs (a result object, a carrier modifier, a feed) and
  returns it; cheap when it is already there;
- `write(target, positions, ...)`: publishes positions computed outside Blender's evaluation
  (a full evaluation in a handler or an operator), so that Blender shows them;
- `pass_through(target)`: DQ Skin does not deform now; the mesh passes through its modifier
  (and the companion deforms it, see `blender.companion`);
- `release(target)`: everything of the route for that modifier goes (the modifier was removed,
  another route takes over, the file is saved).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ..model.keys import ModKey
from ..model.state import ModifierState, ResultMode


@dataclass
class Target:
    """One DQ Skin modifier on one object, its key and its state."""

    obj: object
    mod: object
    st: ModifierState
    key: ModKey


class Route(Protocol):
    def prepare(self, target: Target) -> object: ...

    def write(self, target: Target, positions: np.ndarray, kind: ResultMode, mesh=None) -> None: ...

    def pass_through(self, target: Target) -> None: ...

    def release(self, target: Target) -> None: ...

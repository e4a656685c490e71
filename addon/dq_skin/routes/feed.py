# SPDX-License-Identifier: GPL-3.0-or-later
"""Skinning inside Blender's first evaluation, for results whose frames read the pose from
Blender's memory (envelopes and B-Bones: a Rigify character).

Elsewhere DQ Skin writes its result in the frame handler, and Blender evaluates the scene a
second time to show it; in a scene with a production rig that second evaluation costs more
than the Armature modifier's whole deformation (Blender walks the rig's whole graph again,
whatever changed; see the README's figures). A *fed* result instead carries a Mesh Cache
modifier reading a point-cache file the add-on owns, and a Python driver on that modifier's
Factor whose variables name the bound bones, so that Blender runs it after every bone (and
every B-Bone's segments) and before the result's geometry: it reads this frame's pose from
memory, skins, and writes the file, all inside the evaluation that posed the bones. The frame
handler then finds the result already this frame's and writes nothing.

The handler stays the authority: the driver only takes a frame where nothing but the pose
changed since the last full evaluation (its key says so), and the handler's full evaluation
compares everything as before; whatever the driver could not know (settings, the mesh, the
spaces) it computes and writes again, to the file and the mesh, which then agree.

The file always holds what the result shows: the handler writes it with the result's mesh,
the driver alone only when it skinned (renders too: their graph runs the driver for their own
frame). The result objects are runtime data (never saved), so the modifier, the driver and the
file never reach a user's file. The file lives in memory-backed storage where there is one
(`/dev/shm`), else in the temporary folder, and is made again if something deletes it.
"""

from __future__ import annotations

import os
import struct
import tempfile
import threading
from dataclasses import dataclass

import numpy as np

import bpy

from .. import dqskin
from ..blender import pose
from ..model.state import Mode, ResultMode

FUNCTION = "dq_skin_feed"
MODIFIER = "DQ Skin feed"
_HEADER = b"POINTCACHE2\0"


@dataclass
class Feed:
    result: object
    st: object  # the ModifierState whose result this is
    armature: object
    names: tuple  # the bone names the driver's variables follow
    path: str
    file: object  # the open point-cache file
    points: int  # the point count its header says
    runs: int = 0  # frames the driver skinned (tests and the benchmark read it)
    skinned: tuple = (0, 0)  # (frame change, depsgraph address) of the driver's last skinning


def _folder() -> str:
    return "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else tempfile.gettempdir()


class Feeds:
    """Every fed result of the session (owned by the session). `busy()`: whether the main
    thread is inside a Python operator (a rig rebuild, say: Blender evaluates the scene after
    each of its steps, and the handler skins once it is done); `readers`: the memory readers."""

    def __init__(self, busy, readers):
        self._busy = busy
        self._readers = readers
        self._feeds: dict[int, Feed] = {}  # result session uid -> its feed
        self._frame_change = 0  # counts frame changes (`new_frame`): whether the driver skinned in this one
        # A render's graph may run a driver on its own thread while the viewport's runs one: one
        # skins and writes at a time (the kernel releases the GIL).
        self._lock = threading.Lock()

    def fed(self, result) -> Feed | None:
        try:
            return self._feeds.get(result.session_uid) if result is not None else None
        except ReferenceError:
            return None

    def ensure(self, result, st, armature, binding, positions: np.ndarray) -> None:
        """Makes `result` fed for `st`'s binding on `armature` (built once, rebuilt when the
        bound bones change), its file holding `positions`."""
        feed = self.fed(result)
        names = tuple(binding.bone_names)
        if (
            feed is not None
            and feed.st is st
            and feed.armature == armature
            and feed.names == names
            and result.modifiers.get(MODIFIER) is not None
        ):
            self.write(result, positions)
            return
        self.remove(result)
        path = os.path.join(_folder(), f"dqskin-{os.getpid()}-{result.session_uid}.pc2")
        file = open(path, "w+b", buffering=0)  # kept open; closed in `_close`
        self._feeds[result.session_uid] = Feed(result, st, armature, names, path, file, -1)
        self.write(result, positions)
        m = result.modifiers.new(MODIFIER, "MESH_CACHE")
        m.cache_format, m.filepath = "PC2", path
        m.time_mode, m.play_mode, m.eval_frame = "FRAME", "CUSTOM", 0.0
        m.deform_mode, m.interpolation = "OVERWRITE", "NONE"
        driver = m.driver_add("factor").driver
        driver.type = "SCRIPTED"
        order_after_bones(driver, armature, names)
        # Set last: Blender compiles the expression now, while the function is known to it (with
        # Auto Run Python Scripts off it refuses names it does not know at compile time).
        bpy.app.driver_namespace[FUNCTION] = self.run
        driver.expression = f"{FUNCTION}({result.session_uid})"

    def write(self, result, positions: np.ndarray) -> None:
        """The file holds `positions` (called wherever the result's mesh is written, so that the
        two always agree)."""
        feed = self.fed(result)
        if feed is None:
            return
        with self._lock:
            _write(feed, positions)

    def remove(self, result) -> None:
        """`result` is no longer fed: its modifier (and driver) and file go."""
        try:
            uid = result.session_uid
        except ReferenceError:
            return
        feed = self._feeds.pop(uid, None)
        if feed is not None:
            _close(feed)
        m = result.modifiers.get(MODIFIER) if result.library is None else None
        if m is not None:
            result.modifiers.remove(m)

    def prune(self) -> None:
        """Forgets the feeds whose result is gone (deleted, or replaced by an undo step)."""
        for uid, feed in list(self._feeds.items()):
            try:
                alive = feed.result.session_uid == uid
            except ReferenceError:
                alive = False
            if not alive:
                _close(self._feeds.pop(uid))

    def close(self) -> None:
        """No result is fed any more (the add-on is unregistered): modifiers and files go."""
        for feed in list(self._feeds.values()):
            try:
                self.remove(feed.result)
            except ReferenceError:
                pass
        for feed in self._feeds.values():
            _close(feed)
        self._feeds.clear()
        # The function stays in the driver namespace (with no feed it does nothing): touching
        # the namespace while Blender 4.2 exits crashes it (`addon/install.py` under bpy 4.2.23).

    def new_frame(self) -> None:
        """A frame change starts (`frame_change_pre`)."""
        self._frame_change += 1

    def skinned_now(self, result, depsgraph) -> bool:
        """Whether the driver skinned `result` in this frame change's evaluation of `depsgraph`
        (the handler then checks what the driver could not know, see `pipeline.fed_frame_stands`)."""
        feed = self.fed(result)
        return feed is not None and feed.skinned == (self._frame_change, depsgraph.as_pointer())

    def runs(self, result) -> int:
        feed = self.fed(result)
        return feed.runs if feed is not None else 0

    def run(self, uid: int) -> float:
        """The driver: this frame's result, if only the pose changed since the last full
        evaluation (in whichever graph runs it: the viewport's, a render's). Always 1 (the file
        holds what the result shows); never raises (Blender would switch a failing Python
        driver off)."""
        try:
            depsgraph = bpy.app.driver_namespace.get("depsgraph")
            feed = self._feeds.get(uid)
            if feed is not None and depsgraph is not None and not self._busy():
                with self._lock:
                    self._skin(feed, depsgraph)
        except Exception:  # the handler's full evaluation follows and reports what is wrong
            pass
        return 1.0

    def _skin(self, feed: Feed, depsgraph) -> None:
        st = feed.st
        out = st.output
        old = out.written
        if (
            st.status.mode is not Mode.LIVE
            or out.kind is not ResultMode.REPLACE
            or old is None
            or out.job is None
            or not st.needs_effective
            or not old.pose.from_memory
        ):
            return
        binding = st.binding.binding
        if binding is None or binding.effective is None:
            return
        arm_eval = feed.armature.evaluated_get(depsgraph)
        reads = pose.PoseReads(self._readers.pose, self._readers.pose_error)
        data = reads.read(arm_eval)
        if data is None or not pose.same_bones(data, binding):
            return
        key = pose.memory_key(data)
        if key == old.pose or key.binding_signature != old.pose.binding_signature:
            return  # the same frame, or other bones: the full evaluation decides
        job = out.job
        job.deform = data.deform
        if dqskin.skin_many([job])[0] is not None:
            return
        _write(feed, out.buffer)
        out.written = old.with_pose(key)
        out.generation += 1
        feed.runs += 1
        feed.skinned = (self._frame_change, depsgraph.as_pointer())


def order_after_bones(driver, armature, names, prefix: str = "b") -> int:
    """Adds the variables that make Blender evaluate `driver` after every bone of `names`: each
    B-Bone's segments (a B-Bone property links to them), and the bones with no bound descendant
    (a bone is done after its parent, so after those every bound bone is). About 1 µs each per
    frame. Returns how many (named `prefix` and a number, after those `driver` has)."""
    above = set()
    bones = armature.data.bones
    for name in names:
        b = bones.get(name)
        p = b.parent if b is not None else None
        while p is not None and p.name not in above:
            above.add(p.name)
            p = p.parent
    targets = []
    for name in names:
        b = bones.get(name)
        if b is None:
            continue
        if b.bbone_segments > 1:
            targets.append((name, "bbone_easein"))
        elif name not in above:
            targets.append((name, "matrix"))
    start = len(driver.variables)
    for i, (name, prop) in enumerate(targets):
        v = driver.variables.new()
        v.name, v.type = f"{prefix}{start + i}", "SINGLE_PROP"
        v.targets[0].id = armature
        v.targets[0].data_path = f"pose.bones[{_quoted(name)}].{prop}"
    return len(targets)


def _quoted(name: str) -> str:
    return '"' + name.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _write(feed: Feed, positions: np.ndarray) -> None:
    n = len(positions)
    if not os.path.exists(feed.path):  # (a cleaner removed it: Mesh Cache reads by name)
        feed.file.close()
        feed.file, feed.points = open(feed.path, "w+b", buffering=0), -1
    f = feed.file
    f.seek(0)
    f.write(_HEADER + struct.pack("<iiffi", 1, n, 0.0, 1.0, 1))
    f.write(memoryview(np.ascontiguousarray(positions, np.float32)).cast("B"))
    if n != feed.points:
        f.truncate()
        feed.points = n


def _close(feed: Feed) -> None:
    try:
        feed.file.close()
        os.unlink(feed.path)
    except OSError:
        pass

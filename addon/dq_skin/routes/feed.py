# SPDX-License-Identifier: GPL-3.0-or-later
"""Skinning inside Blender's first evaluation: the feed.

Each scene's fed DQ Skin modifiers (its *members*) form one *batch*: a runtime Empty (never
saved, in no scene) whose custom property is driven by one Python driver. Its variables name
every member's bound bones (each B-Bone's segments, and the bones with no bound descendant),
its object's and armature's transforms and its shape keys, so Blender runs it after all of
them; it skins every member of the batch in one call and writes each one's positions where its
route's carrier reads them. Each carrier (a Mesh Cache on the character, or the deform-only
modifier on a result object) has a driver Blender evaluates without Python that reads the
batch's property, so it is evaluated after the batch: everything happens in the evaluation
that posed the bones, and Blender never evaluates the scene a second time for it. Its expression
subscripts the function rather than calling it, so Blender runs it only when something it
follows changed, not on every frame: a character standing still is not evaluated at all, as
with the Armature modifier.

Members Blender would not evaluate in the viewport on its own (disabled in viewports, or in
excluded or disabled collections: `blender.visibility`) get no variable in the scene's batch,
because a variable pulls its target into the graph: a hidden character then costs nothing per
frame, as with the Armature modifier. Each hidden character has a batch of its own instead,
which only its own carriers read: a graph that evaluates the character anyway (a render's, or
the viewport's through a collection instance) pulls in that batch with it, and skins the
character inside its first evaluation, while a graph without the character never evaluates it.

The frame handler stays the authority: the driver only skins a member whose last full
evaluation still stands as far as the driver can tell (its pose, transforms and shape keys are
read each time); the handler checks what it could not know and evaluates fully where anything
else changed (`engine.playback.fed_frame_stands`).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import bpy

from ..blender import visibility
from ..model.keys import ModKey
from ..model.state import RouteKind
from .base import Target
from .feed_drivers import PATH, PROPERTY, order_after_inputs

FUNCTION = "dq_skin_feed"


@dataclass
class Member:
    key: ModKey
    target: Target
    kind: RouteKind
    armature: object
    bones: tuple  # the bound bone names the batch's variables follow
    bbones: tuple = ()  # those that are B-Bones (their variables wait for the segments)
    shape_keys: object = None  # the mesh's Key, whose values come each frame
    order: int = 0  # the modifier's index in its stack (a chain's earlier modifier first)
    previous: object = None  # the ModifierState of the DQ Skin before it, whose output reaches it
    alone: bool = True  # no DQ Skin after it reads its output (it keeps no buffer between frames)
    ordered: bool = False  # the batch's variables cover it (until then the handler skins it)
    # Blender would not evaluate its object in the viewport (disabled there, or in no enabled
    # collection): its object's own batch feeds it, which only its carriers pull into a graph
    hidden: bool = False
    skinned: tuple = (0, 0)  # (frame change, depsgraph address) of its last skinning here
    covered: int = 0  # the batch's run (`Batch.calls`) that last skinned it or found it current
    runs: int = 0  # frames skinned here (tests and the benchmark read it)


@dataclass
class Batch:
    uid: int
    scene: int  # the scene's session uid
    carrier: object  # the runtime Empty with the driven property
    owner: int = 0  # the session uid of the hidden object whose members it feeds (0: the scene's)
    members: dict = field(default_factory=dict)  # ModKey -> Member
    dirty: bool = True  # its variables must be built again (`Feeds.commit`)
    layout: tuple = ()  # its scene's `visibility.layout` when its members' visibility was read
    runs: int = 0
    calls: int = 0  # every time Blender ran its driver (a run that skinned nothing too)
    called: tuple = (0, 0)  # the stamp of the last of them


class Feeds:
    """Every batch of the session (owned by the session). `skin(members, depsgraph)` skins
    members inside an evaluation and returns those it skinned and those whose carrier held the
    frame already (the engine's fed frame);
    `busy()` says whether the main thread is inside a Python operator (a rig rebuild, say:
    Blender evaluates the scene after each of its steps, and the handler skins once it is done)."""

    def __init__(self, busy):
        self._busy = busy
        self.skin = None  # set by the session: the engine's fed frame
        # Set by the routes: points a member's carriers at the batch that now feeds it.
        self.retarget = None
        self._batches: dict[tuple[int, int], Batch] = {}  # (scene uid, owner) -> batch
        self._by_uid: dict[int, Batch] = {}  # the number its driver passes -> batch
        self._of: dict[ModKey, Batch] = {}
        self._frame_change = 0
        # What the batches' runs read of Blender's memory in one evaluation (`keep`): the
        # frame handler right after it reads the same pose (`kept`).
        self._kept: tuple = ((), None)
        self._visibility_stale = True  # visibility may have changed: `commit` reads it again
        self._scenes: dict[int, object] = {}  # session uid -> the scene (`_scene`)
        self._next_uid = 1
        # A render's graph may run its driver on its own thread while the viewport's runs one:
        # one batch skins at a time (the kernel releases the GIL).
        self._lock = threading.Lock()

    # -- membership ------------------------------------------------------------------------
    def join(self, member: Member, scene) -> Batch:
        """`member` is fed by a batch of `scene` (made if missing) from its next build on: the
        scene's, or its object's own where it is known to be hidden."""
        old = self._of.get(member.key)
        known = old.members.get(member.key) if old is not None and old.scene == scene.session_uid else None
        if known is not None:
            member.hidden = known.hidden
        batch = self._batch(scene, member.key.object_uid if member.hidden else 0)
        if old is not None and old is not batch:
            self.leave(member.key)
            known = None
        if known is not None and (known.armature, known.bones, known.bbones, known.shape_keys) == (
            member.armature,
            member.bones,
            member.bbones,
            member.shape_keys,
        ):
            known.target, known.kind, known.order, known.previous = member.target, member.kind, member.order, member.previous
            return batch
        self._put(member, batch)
        return batch

    def _put(self, member: Member, batch: Batch) -> None:
        """`member` into `batch` (its variables are built again at the next commit)."""
        batch.members[member.key] = member
        batch.dirty = True
        self._of[member.key] = batch

    def _batch(self, scene, owner: int) -> Batch:
        """`scene`'s batch (`owner` 0) or the batch of its hidden object `owner`, made if missing."""
        batch = self._batches.get((scene.session_uid, owner))
        if batch is None or not _alive(batch.carrier):
            batch = self._new_batch(scene, owner)
        return batch

    def _new_batch(self, scene, owner: int) -> Batch:
        name = f".DQ Skin feed {scene.name}" + (f" {owner}" if owner else "")
        carrier = bpy.data.objects.new(name, None)
        carrier.is_runtime_data = True
        # Drivers do not count as users: without one, Purge Unused would delete it under the
        # carriers that read it.
        carrier.use_fake_user = True
        carrier[PROPERTY] = 1.0
        uid = self._next_uid
        self._next_uid += 1
        batch = self._batches[(scene.session_uid, owner)] = self._by_uid[uid] = Batch(uid, scene.session_uid, carrier, owner)
        driver = carrier.driver_add(PATH).driver
        driver.type = "SCRIPTED"
        # Set last: Blender compiles the expression now, while the function is known to it (with
        # Auto Run Python Scripts off it refuses names it does not know at compile time).
        bpy.app.driver_namespace[FUNCTION] = _Driver(self)
        # A subscript, not a call: Blender runs a Python expression with a call in it on every
        # frame ("may depend on time"); this one runs only when its variables' targets change,
        # so a character standing still costs no evaluation at all (`stands_with`).
        driver.expression = f"{FUNCTION}[{uid}]"
        return batch

    def leave(self, key: ModKey) -> None:
        batch = self._of.pop(key, None)
        if batch is not None and batch.members.pop(key, None) is not None:
            batch.dirty = True

    def member(self, key: ModKey) -> Member | None:
        batch = self._of.get(key)
        return batch.members.get(key) if batch is not None else None

    def carrier_of(self, key: ModKey):
        """The runtime object whose property a member's carrier driver reads."""
        batch = self._of.get(key)
        return batch.carrier if batch is not None else None

    def visibility_changed(self) -> None:
        """Objects or collections may have been hidden or shown (the next `commit` reads it)."""
        self._visibility_stale = True

    def commit(self) -> None:
        """Reads which members are hidden where anything may have changed it, moves those that
        changed to the batch that now feeds them (their carriers follow), and builds the
        variables of every batch whose members changed (once per handler call, not once per
        member: a crowd joins at once)."""
        stale, self._visibility_stale = self._visibility_stale, False
        moved = []
        # (Called on every frame: where nothing changed, a scene's layout is read once and no
        # carrier is looked up.)
        by_scene: dict[int, list] = {}
        for b in self._batches.values():
            by_scene.setdefault(b.scene, []).append(b)
        for scene_uid, batches in by_scene.items():
            scene = self._scene(scene_uid)
            layout = visibility.layout(scene) if scene is not None else ()
            if stale or _changed(batches, layout):
                batches = [b for b in batches if _alive(b.carrier)]  # (`prune` forgets the others)
                if stale or _changed(batches, layout):
                    for b in batches:
                        b.layout = layout
                    moved += self._read_visibility(batches, scene)
        for key, batch in list(self._batches.items()):
            if not batch.dirty:
                continue  # (whatever adds or removes a member marks its batch dirty)
            if _alive(batch.carrier):
                driver = batch.carrier.animation_data.drivers[0].driver
                while driver.variables:
                    driver.variables.remove(driver.variables[0])
                order_after_inputs(driver, list(batch.members.values()))
                for m in batch.members.values():
                    m.ordered = True
                batch.dirty = False
            if not batch.members:
                self._drop(key)
        if self.retarget is not None:
            for m in moved:
                self.retarget(m)

    def _scene(self, uid: int):
        """The scene of session uid `uid` (None where it is gone), kept between calls."""
        scene = self._scenes.get(uid)
        try:
            if scene is not None and scene.session_uid == uid:
                return scene
        except ReferenceError:
            pass
        scene = self._scenes[uid] = next((sc for sc in bpy.data.scenes if sc.session_uid == uid), None)
        return scene

    def _read_visibility(self, batches: list, scene) -> list:
        """Marks the members of `scene`'s `batches` hidden or not and moves those that changed
        to the batch that now feeds them; returns them."""
        if scene is None:
            return []  # (the scene is gone: its members are forgotten with their objects)
        enabled = visibility.enabled_in_viewport(scene)
        moved = []
        for batch in batches:
            for key, m in list(batch.members.items()):
                try:
                    hidden = not visibility.evaluated_on_its_own(m.target.obj, enabled)
                except ReferenceError:
                    continue  # (gone: `prune` forgets it)
                if hidden == m.hidden and batch.owner == (key.object_uid if hidden else 0):
                    continue
                m.hidden = hidden
                m.ordered = False
                batch.members.pop(key)
                batch.dirty = True
                self._put(m, self._batch(scene, key.object_uid if hidden else 0))
                moved.append(m)
        return moved

    def _drop(self, key: tuple) -> None:
        batch = self._batches.pop(key)
        self._by_uid.pop(batch.uid, None)
        if _alive(batch.carrier):
            bpy.data.objects.remove(batch.carrier)

    def prune(self) -> None:
        """Forgets members whose object is gone and batches whose carrier is (an undo step
        replaced the data-blocks)."""
        for batch_key, batch in list(self._batches.items()):
            if not _alive(batch.carrier):
                self._batches.pop(batch_key)
                self._by_uid.pop(batch.uid, None)
                for key in batch.members:
                    self._of.pop(key, None)
                continue
            for key, m in list(batch.members.items()):
                if not _alive(m.target.obj):
                    self.leave(key)

    def close(self) -> None:
        """Every batch goes (the add-on is disabled). The function stays in the driver namespace
        (with no batch it does nothing): touching the namespace while Blender 4.2 exits crashes
        it (`addon/install.py` under bpy 4.2.23)."""
        for key in list(self._batches):
            self._drop(key)
        self._of.clear()
        self._scenes.clear()

    # -- frames ----------------------------------------------------------------------------
    def new_frame(self) -> None:
        """A frame change starts (`frame_change_pre`)."""
        self._frame_change += 1

    def stamp(self, depsgraph) -> tuple:
        """What a member skinned in this frame change's evaluation of `depsgraph` carries."""
        return (self._frame_change, depsgraph.as_pointer())

    def keep(self, depsgraph, reads) -> None:
        """`reads` (a run's `pose.PoseReads`, called under the runs' lock) were made in this
        frame change's evaluation of `depsgraph`: the frame handler after it adopts them
        (`kept`) instead of reading the same pose from memory again. Only the newest read of
        each armature is kept (the driver runs again on every edit until the next frame
        change), and another evaluation's are dropped."""
        stamp = self.stamp(depsgraph)
        kept = self._kept
        if kept[0] == stamp and kept[1] is not reads:
            kept[1].update(reads)
        else:
            self._kept = (stamp, reads)

    def kept(self, stamp: tuple):
        """The poses the batches' runs read in the evaluation `stamp` names (`keep`), or None."""
        kept = self._kept
        return kept[1] if kept[0] == stamp else None

    def stands_with(self, key: ModKey, stamp: tuple) -> bool:
        """Whether what the member's carrier holds is this pose's skinning as far as the batch can
        tell, in the evaluation `stamp` names (see `stamp`): the batch skinned it (or found it
        current) in this evaluation, or Blender did not run the batch's driver in it and its
        last run in this graph covered the member: then none of the bones, transforms and shape
        keys its variables follow changed since (a character standing still, which Blender does
        not evaluate again either)."""
        batch = self._of.get(key)
        m = batch.members.get(key) if batch is not None else None
        if m is None:
            return False
        if m.skinned == stamp:
            return True
        return (
            m.ordered
            and not batch.dirty
            and batch.called != stamp
            and batch.called[1] == stamp[1]
            and m.covered == batch.calls
            # (Shape keys added since it joined: no variable of the batch follows them yet.)
            and m.shape_keys == _shape_keys(m.target.obj)
        )

    def runs(self, key: ModKey) -> int:
        m = self.member(key)
        return m.runs if m is not None else 0

    def run(self, uid: int) -> float:
        """The driver: skins the batch's members in whichever graph runs it (the viewport's, a
        render's). Always 1; never raises (Blender would switch a failing Python driver off)."""
        try:
            depsgraph = bpy.app.driver_namespace.get("depsgraph")
            batch = self._by_uid.get(uid)
            if batch is None or depsgraph is None:
                return 1.0
            with self._lock:
                # Counted first: a run that skins nothing (a Python operator is busy, a failure)
                # leaves its members to the frame handler until a later run covers them.
                batch.calls += 1
                batch.called = stamp = self.stamp(depsgraph)
                if self.skin is not None and not self._busy():
                    members = [m for m in batch.members.values() if m.ordered]
                    skinned, current = self.skin(members, depsgraph)
                    for m in skinned:
                        m.runs += 1
                    for m in (*skinned, *current):
                        m.skinned = stamp
                        m.covered = batch.calls
                    batch.runs += 1
        except Exception:  # the handler's full evaluation follows and reports what is wrong
            pass
        return 1.0


class _Driver:
    """What the batches' driver expression subscripts (`dq_skin_feed[uid]`): runs that batch
    (`Feeds.run`, looked up at each run)."""

    __slots__ = ("feeds",)

    def __init__(self, feeds: Feeds):
        self.feeds = feeds

    def __getitem__(self, uid: int) -> float:
        return self.feeds.run(uid)


def _changed(batches, layout: tuple) -> bool:
    """Whether any of `batches` has members to order again or saw another layout of its scene."""
    return any(b.dirty or b.layout != layout for b in batches)


def _shape_keys(obj):
    try:
        return obj.data.shape_keys
    except (AttributeError, ReferenceError):
        return None


def _alive(datablock) -> bool:
    try:
        return datablock is not None and datablock.name is not None
    except ReferenceError:
        return False

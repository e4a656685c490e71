# SPDX-License-Identifier: GPL-3.0-or-later
"""Which objects have DQ Skin modifiers, which datablocks each depends on, and when to evaluate
them.

The handlers ask it what an update concerns, so that their cost follows what changed, not how
many DQ Skin objects the file has: moving an unrelated object costs a dictionary lookup. It is
rebuilt from `bpy.data` when a file is loaded and after undo (which replaces the datablocks),
and it notices new objects (duplicates, appends, copied modifiers) and removed modifiers
(removed or applied) from the updates Blender reports.

While a Python operator runs (Rigify's Generate, an add-on's rig tools), Blender evaluates the
scene after every `bpy.ops` step it takes: the registry keeps its bookkeeping current then, but
skins once the scene settles (an idle moment of the interface, the next update outside an
operator or the next frame change), not on every intermediate update.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field

import numpy as np

import bpy

from . import companion, compat, feed, meshdata, modifier, nodes, results
from .state import STATES, Mode


@dataclass
class ModInfo:
    """What is needed to clean up after a DQ Skin modifier once it is gone."""

    name: str
    companion: dict
    capture: str


@dataclass
class Record:
    obj: object
    mods: dict[str, ModInfo] = field(default_factory=dict)  # modifier uid -> info
    watched: set = field(default_factory=set)
    steady: object = None  # the ModifierState of its one DQ Skin while playback needs only the pose
    volatile: bool = False  # evaluated by Blender before the frame handler (see `frame_pre`)
    pending: bool = False  # evaluate fully at the next frame (its result was let go)
    modifier_count: int = 0


class Registry:
    def __init__(self):
        self.suspended = 0  # > 0 while an operator rearranges a stack (see `suspend`)
        self.built = False
        self.records: dict[int, Record] = {}
        self.watch: dict[int, set[int]] = {}  # datablock uid -> uids of objects depending on it
        self.structure = 0  # bumped when objects, modifiers or constraints may have changed
        self.deferred: set[int] = set()  # objects to evaluate once the scene settles
        self.counts: dict[int, int] = {}  # modifier + constraint counts of other objects seen updated

    def suspend(self):
        """No evaluation while an operator is halfway through changing a modifier stack."""
        registry = self

        class _Suspended:
            def __enter__(self):
                registry.suspended += 1

            def __exit__(self, *exc):
                registry.suspended -= 1

        return _Suspended()

    # -- building ---------------------------------------------------------------------------
    def reset(self) -> None:
        self.built = False
        self.records.clear()
        self.watch.clear()
        self.deferred.clear()
        self.counts.clear()
        self.structure += 1
        STATES.clear()
        feed.prune()
        meshdata.forget()
        nodes.forget_socket_ids()

    def build(self) -> None:
        self.reset()
        self.built = True
        for obj in bpy.data.objects:
            if obj.type == "MESH" and any(nodes.is_dq_skin(m) for m in obj.modifiers):
                self.add(obj)
        results.remove_unused()

    def ensure(self) -> None:
        if not self.built:
            self.build()

    def add(self, obj) -> Record:
        rec = Record(obj)
        self.records[obj.session_uid] = rec
        self._describe(rec)
        self.structure += 1
        return rec

    def record_of(self, obj) -> Record:
        self.ensure()
        rec = self.records.get(obj.session_uid)
        if rec is None:
            rec = self.add(obj)
        else:
            self._describe(rec)
        return rec

    def _describe(self, rec: Record) -> None:
        """Records the object's DQ Skin modifiers and what they depend on."""
        obj = rec.obj
        for uid in rec.watched:
            self.watch.get(uid, set()).discard(obj.session_uid)
        mods = {}
        watched = {obj.data.session_uid}
        if obj.data.shape_keys is not None:
            watched.add(obj.data.shape_keys.session_uid)
        for mod in modifier.dq_skin_modifiers(obj):
            mods[compat.modifier_uid(mod)] = ModInfo(mod.name, nodes.get_companion(mod), modifier.capture_name(mod))
            if nodes.version_of(mod.node_group) == nodes.VERSION:
                arm = nodes.get(mod, "Armature")
                if arm is not None:
                    watched.add(arm.session_uid)
                    if arm.data is not None:
                        watched.add(arm.data.session_uid)
        rec.mods = mods
        rec.steady = None
        rec.watched = watched
        rec.modifier_count = len(obj.modifiers)
        for uid in watched:
            self.watch.setdefault(uid, set()).add(obj.session_uid)

    # -- changes ----------------------------------------------------------------------------
    def refresh(self, rec: Record) -> None:
        """The object was updated: its DQ Skin modifiers may have been added, removed, applied,
        renamed or changed."""
        obj = rec.obj
        current = {compat.modifier_uid(m) for m in modifier.dq_skin_modifiers(obj)}
        for uid in [u for u in rec.mods if u not in current]:
            self._gone(obj, uid, rec.mods[uid])
        if len(obj.modifiers) != rec.modifier_count:
            self.structure += 1
        modifier.prepare_capture(obj)
        self._describe(rec)
        if not rec.mods:
            self._drop(rec)

    def _gone(self, obj, uid: str, info: ModInfo) -> None:
        """A DQ Skin modifier disappeared: applied (Ctrl+A) or removed (its X button)."""
        self.forget_modifier(obj, uid, info, _was_applied(obj, info, STATES.find(obj.session_uid, uid)))

    def forget_modifier(self, obj, uid: str, info: ModInfo, applied: bool) -> None:
        """Everything of a DQ Skin modifier that is gone: its companion (removed too when the
        modifier was applied, since the mesh keeps the deformation, or when `dq_skin_add` made
        it; else put back as it was before `dq_skin_add`), the parent type `dq_skin_add`
        changed, what the node group stored in the mesh, its results and its state."""
        st = STATES.pop(obj.session_uid, uid)
        c = obj.modifiers.get(info.companion.get("name", "")) if info.companion.get("name") else None
        if c is not None and c.type == "ARMATURE":
            if applied or info.companion.get("created"):
                obj.modifiers.remove(c)
            else:
                companion.restore(c, info.companion.get("original", {}))
        if not applied and info.companion.get("parent_type") and obj.parent is not None:
            obj.parent_type = info.companion["parent_type"]
        attr = obj.data.attributes.get(info.capture)
        if attr is not None:
            obj.data.attributes.remove(attr)
        if st is not None and st.output.result is not None:
            try:
                results.remove(st.output.result)
            except ReferenceError:
                pass
        results.remove_unused()

    def _drop(self, rec: Record) -> None:
        self.records.pop(rec.obj.session_uid, None)
        for uid in rec.watched:
            self.watch.get(uid, set()).discard(rec.obj.session_uid)

    def prune(self) -> None:
        """Forgets deleted objects (and their results)."""
        for key, rec in list(self.records.items()):
            try:
                alive = rec.obj.session_uid == key and rec.obj.name is not None
            except ReferenceError:
                alive = False
            if not alive:
                self.records.pop(key, None)
                for uid in rec.watched:
                    self.watch.get(uid, set()).discard(key)
                for st in STATES.drop_object(key):
                    try:
                        results.remove(st.output.result)
                    except ReferenceError:
                        pass
                self.structure += 1
        results.remove_unused()

    def _armature_changed(self, arm_data_uid: int) -> None:
        """Bones may have changed (deform flags, segments, rest pose): every object bound to
        them takes the full path, which compares the bones, at its next evaluation (forced, so
        that no steady-playback shortcut skips it). Objects whose every modifier reads its
        bones from memory (envelopes, B-Bones) take the full path anyway, and its keys hold the
        bones and the pose: they are not forced, since Rigify's armature data is updated on
        every frame and a forced evaluation would write again what a feed made (see `feed`)."""
        for obj_uid in self.watch.get(arm_data_uid, ()):
            rec = self.records.get(obj_uid)
            if rec is not None:
                rec.steady = None
                states = [STATES.find(obj_uid, m) for m in rec.mods]
                if not states or not all(st is not None and st.needs_effective for st in states):
                    rec.pending = True

    def _other_object_changed(self, obj) -> None:
        """Another object's geometry was updated: if its modifiers or constraints changed, what
        simulates on the DQ Skin objects may have too (see `consumers`)."""
        count = len(obj.modifiers) + len(obj.constraints) if hasattr(obj, "modifiers") else 0
        uid = obj.session_uid
        if self.counts.get(uid) != count:
            self.counts[uid] = count
            self.structure += 1

    # -- evaluation -------------------------------------------------------------------------
    def context(self, depsgraph, batch=None) -> modifier.Context:
        return modifier.Context(depsgraph, structure=self.structure, batch=batch)

    def evaluate(self, rec: Record, depsgraph, force: bool = False, ctx=None) -> None:
        try:
            obj = rec.obj
            obj.name
        except ReferenceError:
            self.prune()
            return
        modifier.evaluate_object(obj, ctx or self.context(depsgraph), force)
        rec.steady = None
        if len(rec.mods) == 1:
            st = STATES.find(obj.session_uid, next(iter(rec.mods)))
            if st is not None and st.status.mode is Mode.LIVE and st.status.source == "mesh" and not st.needs_effective:
                rec.steady = st

    def evaluate_all(self, depsgraph, force: bool = True) -> None:
        """Every DQ Skin object of `depsgraph` (exports starting or ending, a save)."""
        self.ensure()
        ctx = self.context(depsgraph)
        for rec in list(self.records.values()):
            if _in(rec.obj, depsgraph):
                self.evaluate(rec, depsgraph, force, ctx)

    def updates(self, depsgraph) -> None:
        """After an interactive change: re-evaluate only what it concerns (once the scene
        settles, while a Python operator runs)."""
        if self.suspended:
            return
        self.ensure()
        dirty: set[int] = set()
        structure = False
        for update in depsgraph.updates:
            ident = update.id
            orig = getattr(ident, "original", ident)
            if orig is None:
                continue
            uid = orig.session_uid
            if isinstance(orig, bpy.types.Object):
                rec = self.records.get(uid)
                if rec is not None:
                    self.refresh(rec)
                    dirty.add(uid)
                elif orig.type == "MESH" and any(nodes.is_dq_skin(m) for m in orig.modifiers):
                    self.add(orig)
                    dirty.add(uid)
                elif update.is_updated_geometry:
                    self._other_object_changed(orig)
                if uid in self.watch:
                    dirty |= self.watch[uid]
            elif isinstance(orig, (bpy.types.Collection, bpy.types.Scene)):
                structure = True
            elif uid in self.watch:
                if isinstance(orig, bpy.types.Mesh) and update.is_updated_geometry:
                    meshdata.mark_stale(uid)
                elif isinstance(orig, bpy.types.Key):
                    user = getattr(orig, "user", None)
                    if user is not None:
                        meshdata.mark_stale(user.session_uid)
                elif isinstance(orig, bpy.types.Armature):
                    self._armature_changed(uid)
                dirty |= self.watch[uid]
        if structure:
            self.structure += 1
            self.prune()
        if inside_python_operator():
            self.defer(dirty)
            return
        dirty |= self.deferred
        self.deferred.clear()
        ctx = self.context(depsgraph)
        for uid in dirty:
            rec = self.records.get(uid)
            if rec is not None and _in(rec.obj, depsgraph):
                self.evaluate(rec, depsgraph, ctx=ctx)

    def defer(self, uids: set) -> None:
        """Evaluates these objects once the scene settles."""
        if not uids:
            return
        first = not self.deferred
        self.deferred |= uids
        if first and not bpy.app.background:
            bpy.app.timers.register(_settle, first_interval=0.0)

    def settle(self) -> None:
        """The scene settled: evaluate what the operators changed."""
        if not self.deferred or self.suspended:
            return
        depsgraph = bpy.context.evaluated_depsgraph_get()
        uids, self.deferred = self.deferred, set()
        ctx = self.context(depsgraph)
        for uid in uids:
            rec = self.records.get(uid)
            if rec is not None and _in(rec.obj, depsgraph):
                self.evaluate(rec, depsgraph, ctx=ctx)

    def frame_pre(self) -> None:
        """Before a frame change: objects Blender will evaluate anyway before the frame handler
        (their shape keys, transforms or earlier modifiers are animated) output nothing in that
        evaluation, so that the modifiers after DQ Skin run once per frame, not twice."""
        feed.new_frame()
        for rec in self.records.values():
            if not rec.volatile:
                continue
            for _uid, st in STATES.of_object(rec.obj.session_uid):
                # (A modifier reading what reaches it needs that evaluated in the first pass; a
                # fed result is this frame's there, see `feed`.)
                if (
                    st.status.mode is Mode.LIVE
                    and st.output.result is not None
                    and st.output.kind == nodes.RESULT_REPLACE
                    and not st.capture_on
                    and feed.fed(st.output.result) is None
                ):
                    try:
                        results.set_mode(st.output.result, nodes.RESULT_PENDING)
                        rec.pending = True
                    except ReferenceError:
                        pass

    def frame(self, depsgraph) -> None:
        """After a frame change: every DQ Skin object of this depsgraph."""
        if self.suspended:
            return
        self.ensure()
        updated, moved = set(), set()
        for update in depsgraph.updates:
            orig = getattr(update.id, "original", update.id)
            if orig is None:
                continue
            if isinstance(orig, bpy.types.Object):
                uid = orig.session_uid
                if update.is_updated_geometry:
                    updated.add(uid)
                if update.is_updated_transform:
                    moved.add(uid)
                rec = self.records.get(uid)
                if rec is None:
                    # New since the last update (a script duplicated or linked it).
                    if orig.type == "MESH" and any(nodes.is_dq_skin(m) for m in orig.modifiers):
                        self.add(orig)
                        moved.add(uid)
                    elif update.is_updated_geometry and uid not in self.watch:
                        self._other_object_changed(orig)  # (not the armatures, posed every frame)
                elif len(orig.modifiers) != rec.modifier_count:
                    self.refresh(rec)
                    moved.add(uid)
            elif orig.session_uid in self.watch:
                if isinstance(orig, bpy.types.Mesh) and update.is_updated_geometry:
                    # A script edited the mesh before changing frames (animated shape keys also
                    # flag it; then comparing costs a read, but nothing is recomputed).
                    key = orig.shape_keys
                    if key is None or key.animation_data is None:
                        meshdata.mark_stale(orig.session_uid)
                elif isinstance(orig, bpy.types.Armature):
                    # A script edited bones (deform flags, B-Bone segments) before changing frames.
                    self._armature_changed(orig.session_uid)
        ctx = self.context(depsgraph, batch=[])
        # Objects Blender did not update in this evaluation keep their settings; those that did
        # not move keep their spaces. Those changed while an operator ran are evaluated fully.
        deferred, self.deferred = self.deferred, set()
        ctx.unchanged = {uid for uid in self.records if uid not in updated and uid not in deferred}
        ctx.unmoved = _unmoved(self, moved | deferred)
        for uid, rec in list(self.records.items()):
            if uid not in self.records or not _in(rec.obj, depsgraph):
                continue
            if uid in updated and not rec.pending:
                rec.volatile = True
            force, rec.pending = rec.pending, False
            st = rec.steady
            if st is not None and not force and uid in ctx.unchanged:
                plan = modifier._quick(rec.obj, None, st, ctx)
                if plan is None:
                    continue
                if plan is not False:
                    ctx.batch.append(plan)
                    continue
            if not force and modifier.fed_frame_stands(rec.obj, ctx):
                continue  # the feed made this frame inside Blender's evaluation
            self.evaluate(rec, depsgraph, force, ctx)
        modifier.run_batch(ctx.batch)

    # -- saving -----------------------------------------------------------------------------
    def deactivate_all(self, detach: bool) -> None:
        """Puts every DQ Skin in the state files are saved in."""
        self.ensure()
        for obj, mod in self._local_modifiers():
            modifier.deactivate(obj, mod, detach)

    def reactivate_all(self) -> None:
        """Back from `deactivate_all` (after a save)."""
        for obj, mod in self._local_modifiers():
            modifier.reactivate(obj, mod)
        for rec in self.records.values():
            rec.pending = True

    def _local_modifiers(self):
        for rec in list(self.records.values()):
            try:
                obj = rec.obj
                obj.name
            except ReferenceError:
                continue
            if obj.library is not None:
                continue
            for mod in modifier.dq_skin_modifiers(obj):
                if nodes.version_of(mod.node_group) == nodes.VERSION:
                    yield obj, mod


def inside_python_operator(frame=None) -> bool:
    """Whether a Python operator is running (its `execute`, `invoke` or `modal` is on the
    stack, the caller's or from `frame` up): Blender evaluates the scene after each `bpy.ops`
    step it takes. (A script calling operators itself is not deferred: it may read the result
    right after.)"""
    f = frame if frame is not None else sys._getframe(1)
    while f is not None:
        code = f.f_code
        if code.co_name in ("execute", "invoke", "modal") and code.co_varnames[:1] == ("self",):
            if isinstance(f.f_locals.get("self"), bpy.types.Operator):
                return True
        f = f.f_back
    return False


def _settle():
    REGISTRY.settle()
    return None


def _unmoved(reg: Registry, moved: set) -> set:
    """Objects (DQ Skin objects and the armatures they watch) whose transform did not change."""
    ids = set(reg.records) | set(reg.watch)
    return ids - moved


def _in(obj, depsgraph) -> bool:
    try:
        return obj.evaluated_get(depsgraph).is_evaluated
    except ReferenceError:
        return False


def _was_applied(obj, info: ModInfo, st) -> bool:
    """Whether a vanished modifier was applied (Ctrl+A) rather than removed."""
    op = compat.last_operator()
    if op is not None and op.bl_idname == "OBJECT_OT_modifier_apply":
        try:
            if op.properties.modifier == info.name:
                return True
        except (AttributeError, ReferenceError):
            pass
    if st is None or st.output.buffer is None or len(st.output.buffer) != len(obj.data.vertices) or not st.status.live:
        return False
    # The mesh now holds what the modifier output (and that differs from what reached it).
    current = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.attributes["position"].data.foreach_get("vector", current)
    current = current.reshape(-1, 3)
    data = meshdata.peek_any(obj)
    moved = data is None or not np.array_equal(data.positions, st.output.buffer)
    return moved and np.allclose(current, st.output.buffer, atol=1e-6, rtol=0)


REGISTRY = Registry()

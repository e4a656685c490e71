# SPDX-License-Identifier: GPL-3.0-or-later
"""Which objects have DQ Skin modifiers, and which datablocks each depends on.

The handlers ask it what an update concerns, so that their cost follows what changed, not how
many DQ Skin objects the file has: moving an unrelated object costs a dictionary lookup. It is
rebuilt from `bpy.data` when a file is loaded and after undo (which replaces the datablocks),
and it notices new objects (duplicates, appends, copied modifiers) and removed modifiers
(removed or applied) from the updates Blender reports.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field

import bpy
import numpy as np

from . import companion, compat, meshdata, modifier, nodes, results


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
    steady: object = None  # the State of its one DQ Skin while playback needs only the pose
    volatile: bool = False  # evaluated by Blender before the frame handler (see `frame_pre`)
    pending: bool = False
    modifier_count: int = 0


class Registry:
    def __init__(self):
        self.suspended = 0  # > 0 while an operator rearranges a stack (see `suspend`)
        self.built = False
        self.records: dict[int, Record] = {}
        self.watch: dict[int, set[int]] = {}  # datablock uid -> uids of objects depending on it
        self.claimed: dict[int, tuple] = {}  # result object uid -> (object uid, modifier uid)

    @contextlib.contextmanager
    def suspend(self):
        """No evaluation while an operator is halfway through changing a modifier stack."""
        self.suspended += 1
        try:
            yield
        finally:
            self.suspended -= 1

    # -- building ---------------------------------------------------------------------------
    def reset(self) -> None:
        self.built = False
        self.records.clear()
        self.watch.clear()
        self.claimed.clear()
        modifier.forget()
        nodes.forget_socket_ids()

    def build(self) -> None:
        self.reset()
        self.built = True
        for obj in bpy.data.objects:
            if obj.type == "MESH" and any(nodes.is_dq_skin(m) for m in obj.modifiers):
                self._add(obj)
        # Results whose owner tag matches keep their owner; the others are claimed in stack
        # order at the first evaluation (duplicates then get their own).
        for rec in self.records.values():
            for mod in modifier.dq_skin_modifiers(rec.obj):
                r = nodes.get(mod, "Result") if nodes.version_of(mod.node_group) == nodes.VERSION else None
                uid = compat.modifier_uid(mod)
                if r is not None and results.is_result(r) and r.get(results.OWNER) == results.owner_key(rec.obj, uid):
                    self.claimed.setdefault(r.session_uid, (rec.obj.session_uid, uid))
        for r in results.orphans():
            results.remove(r)

    def ensure(self) -> None:
        if not self.built:
            self.build()

    def _add(self, obj) -> Record:
        rec = Record(obj)
        self.records[obj.session_uid] = rec
        self._describe(rec)
        return rec

    def _describe(self, rec: Record) -> None:
        """Records the object's DQ Skin modifiers and what they depend on."""
        obj = rec.obj
        for uid in rec.watched:
            self.watch.get(uid, set()).discard(obj.session_uid)
        rec.watched = set()
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
        self._describe(rec)
        if not rec.mods:
            self._drop(rec)

    def _gone(self, obj, uid: str, info: ModInfo) -> None:
        """A DQ Skin modifier disappeared: applied (its companion goes too, the mesh keeps the
        deformation) or removed (its companion is put back as it was)."""
        st = modifier._states.pop((obj.session_uid, uid), None)
        c = obj.modifiers.get(info.companion.get("name", "")) if info.companion.get("name") else None
        if c is not None and c.type != "ARMATURE":
            c = None
        if _was_applied(obj, info, st):
            if c is not None:
                obj.modifiers.remove(c)
            attr = obj.data.attributes.get(info.capture)
            if attr is not None:
                obj.data.attributes.remove(attr)
        elif c is not None:
            companion.restore(c, info.companion.get("original", {}))
        if st is not None and st.result is not None:
            try:
                self.claimed.pop(st.result.session_uid, None)
                results.remove(st.result)
            except ReferenceError:
                pass
        for r in results.orphans():
            results.remove(r)

    def _drop(self, rec: Record) -> None:
        self.records.pop(rec.obj.session_uid, None)
        for uid in rec.watched:
            self.watch.get(uid, set()).discard(rec.obj.session_uid)

    def prune(self) -> None:
        """Forgets deleted objects (and their results)."""
        for key, rec in list(self.records.items()):
            try:
                rec.obj.name
                alive = rec.obj.session_uid == key
            except ReferenceError:
                alive = False
            if not alive:
                self.records.pop(key, None)
                for uid in rec.watched:
                    self.watch.get(uid, set()).discard(key)
                for k in [k for k in modifier._states if k[0] == key]:
                    st = modifier._states.pop(k)
                    try:
                        results.remove(st.result)
                    except ReferenceError:
                        pass
        for r in results.orphans():
            results.remove(r)

    # -- evaluation -------------------------------------------------------------------------
    def evaluate(self, rec: Record, depsgraph, force: bool = False, ctx=None) -> None:
        try:
            obj = rec.obj
            obj.name
        except ReferenceError:
            self.prune()
            return
        modifier.evaluate_object(obj, depsgraph, self.claimed, force, ctx)
        rec.steady = None
        if len(rec.mods) == 1:
            st = modifier._states.get((obj.session_uid, next(iter(rec.mods))))
            if st is not None and st.mode == "replace" and st.source == "mesh" and not st.needs_effective:
                rec.steady = st

    def updates(self, depsgraph) -> None:
        """After an interactive change: re-evaluate only what it concerns."""
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
                    self._add(orig)
                    dirty.add(uid)
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
            self.prune()
        for uid in dirty:
            rec = self.records.get(uid)
            if rec is not None and _in(rec.obj, depsgraph):
                self.evaluate(rec, depsgraph)

    def _states_of(self, rec: Record):
        for uid in rec.mods:
            st = modifier._states.get((rec.obj.session_uid, uid))
            if st is not None:
                yield st

    def _armature_changed(self, arm_data_uid: int) -> None:
        for obj_uid in self.watch.get(arm_data_uid, ()):
            rec = self.records.get(obj_uid)
            if rec is not None:
                for st in self._states_of(rec):
                    st.check_armature = True

    def frame_pre(self) -> None:
        """Before a frame change: objects Blender will evaluate anyway before the frame handler
        (their shape keys, transforms or earlier modifiers are animated) output nothing in that
        evaluation, so that the modifiers after DQ Skin run once per frame, not twice."""
        for rec in self.records.values():
            if not rec.volatile:
                continue
            for st in self._states_of(rec):
                if st.mode == "replace" and st.result is not None:
                    try:
                        results.set_mode(st.result, nodes.RESULT_PENDING)
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
                        self._add(orig)
                        moved.add(uid)
                elif len(orig.modifiers) != rec.modifier_count:
                    self.refresh(rec)
                    moved.add(uid)
            elif isinstance(orig, bpy.types.Mesh) and update.is_updated_geometry and orig.session_uid in self.watch:
                # A script edited the mesh before changing frames (animated shape keys also
                # flag it; then comparing costs a read, but nothing is recomputed).
                key = orig.shape_keys
                if key is None or not (key.animation_data is not None):
                    meshdata.mark_stale(orig.session_uid)
        ctx = modifier.Context(depsgraph, self.claimed, batch=[])
        # Objects Blender did not update in this evaluation keep their settings; those that did
        # not move keep their spaces.
        ctx.unchanged = {uid for uid in self.records if uid not in updated}
        ctx.unmoved = _unmoved(self, moved)
        for uid, rec in list(self.records.items()):
            if uid not in self.records or not _in(rec.obj, depsgraph):
                continue
            if uid in updated and not rec.pending:
                rec.volatile = True
            force, rec.pending = rec.pending, False
            st = rec.steady
            if st is not None and not force and uid in ctx.unchanged:
                plan = modifier._quick(rec.obj, None, st, ctx, "mesh")
                if plan is None:
                    continue
                if plan is not False:
                    ctx.batch.append(plan)
                    continue
            self.evaluate(rec, depsgraph, force, ctx)
        modifier.run_batch(ctx.batch)

    # -- saving -----------------------------------------------------------------------------
    def deactivate_all(self, detach: bool) -> list:
        """Puts every DQ Skin in the state files are saved in; returns what to put back."""
        self.ensure()
        restore = []
        for rec in self.records.values():
            try:
                obj = rec.obj
                obj.name
            except ReferenceError:
                continue
            if obj.library is not None:
                continue
            for mod in modifier.dq_skin_modifiers(obj):
                if nodes.version_of(mod.node_group) != nodes.VERSION:
                    continue
                result = nodes.get(mod, "Result")
                modifier.deactivate(obj, mod, detach)
                restore.append((obj, mod.name, result))
        return restore


def _unmoved(reg: Registry, moved: set) -> set:
    """Objects (DQ Skin objects and the armatures they watch) whose transform did not change."""
    ids = set(reg.records) | {uid for uid in reg.watch}
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
    if st is None or st.out is None or len(st.out) != len(obj.data.vertices) or not st.live:
        return False
    # The mesh now holds what the modifier output (and that differs from what reached it).
    current = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.attributes["position"].data.foreach_get("vector", current)
    current = current.reshape(-1, 3)
    data = meshdata._cache.get(obj.data.session_uid)
    moved = data is None or not np.array_equal(data.positions, st.out)
    return moved and np.allclose(current, st.out, atol=1e-6, rtol=0)


REGISTRY = Registry()

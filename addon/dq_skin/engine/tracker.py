# SPDX-License-Identifier: GPL-3.0-or-later
"""Which objects have DQ Skin modifiers, which data-blocks each depends on, and when to evaluate
them.

The handlers ask it what an update concerns, so that their cost follows what changed, not how
many DQ Skin objects the file has: moving an unrelated object costs a dictionary lookup. It is
rebuilt from `bpy.data` when a file is loaded and after undo (which replaces the data-blocks),
and it notices new objects (duplicates, appends, copied modifiers) and removed modifiers
(removed or applied) from the updates Blender reports.

While a Python operator runs (Rigify's Generate, an add-on's rig tools), Blender evaluates the
scene after every `bpy.ops` step it takes: the tracker keeps its bookkeeping current then, but
skins once the scene settles (an idle moment of the interface, the next update outside an
operator or the next frame change), not on every intermediate update.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import bpy
from bpy.types import Armature, Collection, Key, Mesh, Object, Scene  # (each `bpy.types.X` is a lookup by name)

from ..blender import compat, nodes
from ..model.keys import ModKey
from ..routes import cache_route
from . import pipeline, playback, removal
from .context import Context, dq_skin_modifiers
from .removal import ModInfo


@dataclass
class Record:
    obj: object
    mods: dict[str, ModInfo] = field(default_factory=dict)  # modifier uid -> info
    watched: set = field(default_factory=set)
    pending: bool = False  # evaluate fully at the next frame
    bones_changed: bool = False  # its armature's data was updated: the bones' binding is compared
    modifier_count: int = 0
    fed_check: object = None  # what the last check of its fed frame that stood saw (`playback.FedCheck`)
    aside_check: object = None  # what the last check that it still steps aside saw (`playback.AsideCheck`)


class Tracker:
    """The records of the session's DQ Skin objects (owned by the session, which it is given)."""

    def __init__(self, session):
        self.session = session
        self.suspended = 0  # > 0 while an operator rearranges a stack (see `suspend`)
        self.built = False
        self.records: dict[int, Record] = {}
        self.watch: dict[int, set[int]] = {}  # data-block uid -> uids of objects depending on it
        self.structure = 0  # bumped when objects, modifiers or constraints may have changed
        self.deferred: set[int] = set()  # objects to evaluate once the scene settles
        self.counts: dict[int, int] = {}  # modifier + constraint counts of other objects seen updated

    def suspend(self):
        """No evaluation while an operator is halfway through changing a modifier stack."""
        tracker = self

        class _Suspended:
            def __enter__(self):
                tracker.suspended += 1

            def __exit__(self, *exc):
                tracker.suspended -= 1

        return _Suspended()

    # -- building ---------------------------------------------------------------------------
    def reset(self) -> None:
        self.built = False
        self.records.clear()
        self.watch.clear()
        self.deferred.clear()
        self.counts.clear()
        self.structure += 1

    def build(self) -> None:
        self.session.reset()
        self.built = True
        for obj in bpy.data.objects:
            if obj.type == "MESH" and any(nodes.is_dq_skin(m) for m in obj.modifiers):
                self.add(obj)
        self.session.routes.remove_unused()

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
        for mod in dq_skin_modifiers(obj):
            mods[compat.modifier_uid(mod)] = removal.info_of(mod)
            if nodes.version_of(mod.node_group) == nodes.VERSION:
                arm = nodes.get(mod, "Armature")
                if arm is not None:
                    watched.add(arm.session_uid)
                    if arm.data is not None:
                        watched.add(arm.data.session_uid)
        rec.mods = mods
        rec.watched = watched
        rec.modifier_count = len(obj.modifiers)
        for uid in watched:
            self.watch.setdefault(uid, set()).add(obj.session_uid)

    # -- changes ----------------------------------------------------------------------------
    def refresh(self, rec: Record) -> None:
        """The object was updated: its DQ Skin modifiers may have been added, removed, applied,
        renamed or changed."""
        obj = rec.obj
        current = {compat.modifier_uid(m) for m in dq_skin_modifiers(obj)}
        for uid in [u for u in rec.mods if u not in current]:
            info = rec.mods[uid]
            st = self.session.states.find(ModKey(obj.session_uid, uid))
            removal.forget_modifier(self.session, obj, uid, info, removal.was_applied(self.session, obj, info, st))
        if len(obj.modifiers) != rec.modifier_count:
            self.structure += 1
        pipeline.prepare_capture(self.session, obj)
        self._describe(rec)
        if not rec.mods:
            self._drop(rec)

    def _drop(self, rec: Record) -> None:
        self.records.pop(rec.obj.session_uid, None)
        for uid in rec.watched:
            self.watch.get(uid, set()).discard(rec.obj.session_uid)

    def prune(self) -> None:
        """Forgets deleted objects (and their results)."""
        routes = self.session.routes
        for key, rec in list(self.records.items()):
            try:
                alive = rec.obj.session_uid == key and rec.obj.name is not None
            except ReferenceError:
                alive = False
            if not alive:
                self.records.pop(key, None)
                for uid in rec.watched:
                    self.watch.get(uid, set()).discard(key)
                for st in self.session.states.drop_object(key):
                    routes.release_state(st)
                self.structure += 1
        routes.feeds.prune()
        routes.remove_unused()

    def _armature_changed(self, arm_data_uid: int) -> None:
        """Bones may have changed (deform flags, segments, rest pose): every object bound to them
        compares its bones' binding at its next evaluation (a fed frame too: Rigify's armature
        data is updated on every frame, and a forced full evaluation would publish again what
        the feed made)."""
        for obj_uid in self.watch.get(arm_data_uid, ()):
            rec = self.records.get(obj_uid)
            if rec is not None:
                rec.bones_changed = True

    def _other_object_changed(self, obj) -> None:
        """Another object's geometry was updated: if its modifiers or constraints changed, what
        simulates on the DQ Skin objects may have too (see `consumers`)."""
        count = len(obj.modifiers) + len(obj.constraints) if hasattr(obj, "modifiers") else 0
        uid = obj.session_uid
        if self.counts.get(uid) != count:
            self.counts[uid] = count
            self.structure += 1

    # -- evaluation -------------------------------------------------------------------------
    def context(self, depsgraph, batch=None) -> Context:
        return Context(self.session, depsgraph, structure=self.structure, batch=batch)

    def evaluate(self, rec: Record, depsgraph, force: bool = False, ctx=None) -> None:
        try:
            obj = rec.obj
            obj.name
        except ReferenceError:
            self.prune()
            return
        pipeline.evaluate_object(obj, ctx or self.context(depsgraph), force)

    def evaluate_all(self, depsgraph, force: bool = True) -> None:
        """Every DQ Skin object of `depsgraph` (exports starting or ending, a save)."""
        self.ensure()
        ctx = self.context(depsgraph)
        for rec in list(self.records.values()):
            if _in(rec.obj, depsgraph):
                self.evaluate(rec, depsgraph, force, ctx)
        self.session.routes.feeds.commit()

    def updates(self, depsgraph, in_operator: bool) -> bool:
        """After an interactive change: re-evaluate only what it concerns (once the scene
        settles, while a Python operator runs: `in_operator`). Returns whether the caller must
        call `settle` once the scene settles."""
        if self.suspended:
            return False
        self.ensure()
        dirty: set[int] = set()
        structure = False
        meshes = self.session.meshes
        for update in depsgraph.updates:
            ident = update.id
            orig = getattr(ident, "original", ident)
            if orig is None:
                continue
            uid = orig.session_uid
            if isinstance(orig, Object):
                rec = self.records.get(uid)
                if rec is not None:
                    self.refresh(rec)
                    dirty.add(uid)
                elif orig.type == "MESH" and any(nodes.is_dq_skin(m) for m in orig.modifiers):
                    self.add(orig)
                    dirty.add(uid)
                elif update.is_updated_geometry:
                    self._other_object_changed(orig)
                    cache_route.remove_orphans(orig)
                if uid in self.watch:
                    dirty |= self.watch[uid]
            elif isinstance(orig, (Collection, Scene)):
                structure = True
            elif uid in self.watch:
                if isinstance(orig, Mesh) and update.is_updated_geometry:
                    meshes.mark_stale(uid)
                elif isinstance(orig, Key):
                    user = getattr(orig, "user", None)
                    if user is not None:
                        meshes.mark_stale(user.session_uid)
                elif isinstance(orig, Armature):
                    self._armature_changed(uid)
                dirty |= self.watch[uid]
        if structure:
            self.structure += 1
            self.session.routes.feeds.visibility_changed()
            self.prune()
        if in_operator:
            first = not self.deferred and bool(dirty)
            self.deferred |= dirty
            return first
        dirty |= self.deferred
        self.deferred.clear()
        ctx = self.context(depsgraph)
        for uid in dirty:
            rec = self.records.get(uid)
            if rec is not None and _in(rec.obj, depsgraph):
                self.evaluate(rec, depsgraph, ctx=ctx)
        self.session.routes.feeds.commit()
        return False

    def settle(self, depsgraph) -> None:
        """The scene settled: evaluate what the operators changed."""
        if not self.deferred or self.suspended:
            return
        uids, self.deferred = self.deferred, set()
        ctx = self.context(depsgraph)
        for uid in uids:
            rec = self.records.get(uid)
            if rec is not None and _in(rec.obj, depsgraph):
                self.evaluate(rec, depsgraph, ctx=ctx)
        self.session.routes.feeds.commit()

    def frame_pre(self) -> None:
        """Before a frame change: the feed counts it (whether it skinned in this one)."""
        self.session.routes.feeds.new_frame()

    def frame(self, depsgraph) -> None:
        """After a frame change: every DQ Skin object of this depsgraph."""
        if self.suspended:
            return
        self.ensure()
        meshes = self.session.meshes
        feeds = self.session.routes.feeds
        updated, moved = set(), set()
        for update in depsgraph.updates:
            id_ = update.id
            orig = getattr(id_, "original", id_)
            if orig is None:
                continue
            if isinstance(orig, Object):
                uid = orig.session_uid
                if update.is_updated_geometry:
                    updated.add(uid)
                if update.is_updated_transform:
                    moved.add(uid)
                rec = self.records.get(uid)
                if rec is None:
                    if uid in self.watch:
                        continue  # an armature a character follows (posed on every frame)
                    # New since the last update (a script duplicated or linked it).
                    if orig.type == "MESH" and any(nodes.is_dq_skin(m) for m in orig.modifiers):
                        self.add(orig)
                        moved.add(uid)
                    elif update.is_updated_geometry:
                        self._other_object_changed(orig)
                        cache_route.remove_orphans(orig)
                elif len(orig.modifiers) != rec.modifier_count:
                    self.refresh(rec)
                    moved.add(uid)
            elif orig.session_uid in self.watch:
                if isinstance(orig, Mesh) and update.is_updated_geometry:
                    # A script edited the mesh before changing frames (animated shape keys also
                    # flag it on every frame: then only shape keys added or removed count).
                    key = orig.shape_keys
                    if key is None or key.animation_data is None or not meshes.knows_shape_keys_of(orig):
                        meshes.mark_stale(orig.session_uid)
                elif isinstance(orig, Armature):
                    # A script edited bones (deform flags, B-Bone segments) before changing frames.
                    self._armature_changed(orig.session_uid)
            elif isinstance(orig, Collection):
                # A script hid or showed objects or collections before changing frames.
                feeds.visibility_changed()
        ctx = self.context(depsgraph, batch=[])
        fed_reads = feeds.kept(ctx.fed_stamp)
        if fed_reads is not None:  # (the poses the feed read in this evaluation)
            ctx.reads.adopt(fed_reads)
        # Objects Blender did not update in this evaluation keep their settings; those that did
        # not move keep their spaces. Those changed while an operator ran are evaluated fully.
        deferred, self.deferred = self.deferred, set()
        ctx.unchanged = {uid for uid in self.records if uid not in updated and uid not in deferred}
        ctx.unmoved = (set(self.records) | set(self.watch)) - (moved | deferred)
        for uid, rec in list(self.records.items()):
            if uid not in self.records:
                continue
            if not rec.pending and not rec.bones_changed and playback.fed_frame_stands_as_checked(rec, ctx):
                # The feed made this frame and nothing its last check saw changed (the feed
                # skinned it in this graph: no need to ask whether the object is in it).
                continue
            if not _in(rec.obj, depsgraph):
                continue
            forced, rec.pending = rec.pending, False
            bones, rec.bones_changed = rec.bones_changed, False
            if not forced and not bones and playback.steps_aside_as_checked(rec, ctx):
                continue  # Blender's Armature modifier deforms it, as it did (nothing was fed)
            if not forced and playback.fed_frame_stands(rec, ctx, bones):
                continue  # the feed made this frame inside Blender's evaluation
            if not forced and not bones and playback.stepped_aside_stands(rec, ctx):
                continue  # Blender's Armature modifier deforms it, as it did
            self.evaluate(rec, depsgraph, forced, ctx)
        pipeline.run_batch(self.session, ctx.batch)
        feeds.commit()

    def local_modifiers(self):
        """Every current DQ Skin modifier of the local objects tracked, with its object."""
        for rec in list(self.records.values()):
            try:
                obj = rec.obj
                obj.name
            except ReferenceError:
                continue
            if obj.library is not None:
                continue
            for mod in dq_skin_modifiers(obj):
                if nodes.version_of(mod.node_group) == nodes.VERSION:
                    yield obj, mod


def _in(obj, depsgraph) -> bool:
    try:
        return obj.evaluated_get(depsgraph).is_evaluated
    except ReferenceError:
        return False

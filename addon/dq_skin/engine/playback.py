# SPDX-License-Identifier: GPL-3.0-or-later
"""The way past the full evaluation during playback: the feed skinned the frame inside Blender's
evaluation (see `routes.feed` and `fed`); what it could not know is checked here, cheaply."""

from __future__ import annotations

from dataclasses import dataclass

from ..blender import pose, settings
from ..model.state import Mode
from ..routes.feed import Feeds
from . import companions, pipeline
from .context import Context, dq_skin_modifiers, mod_key


@dataclass(frozen=True)
class FedCheck:
    """What the last check of an object's fed frame that stood saw (`fed_frame_stands`): the
    digest of its state in Blender's memory (`dqskin.memory.ObjectStateMemory`: its modes,
    modifier stack, inputs, companion and vertex-group names) and, for each DQ Skin, what the
    check compared on the add-on's side."""

    digest: bytes
    mods: tuple  # (key, state, written settings, mesh version, companion (shown, deforms)) each


def fed_frame_stands(rec, ctx: Context, bones_changed: bool = False) -> bool:
    """Whether the frame the feed skinned for every DQ Skin of `rec.obj` in this evaluation is
    what the full path would publish, checked cheaply (a Rigify character's full path reads the
    whole pose again). The driver read the pose, the transforms and the shape keys, and skinned
    only where the bones' binding signature and the mesh were the last full evaluation's;
    checked here is what it could not know: the settings, the mesh and its vertex groups, the
    scene's structure, exports, the toggles and the companion; with `bones_changed` (the
    armature's data was updated), also the bones' binding signature.

    Where none of what Blender holds of it changed since the last time this check stood (one
    read of its state from memory, `FedCheck`), only the add-on's side is compared again, in
    place of dozens of calls through Blender's Python API for every character and frame."""
    obj = rec.obj
    if ctx.render or ctx.session.exports.active():
        rec.fed_check = None
        return False
    if bones_changed and _bones_as_checked(rec, ctx):
        # (A Rigify rig's armature data is updated on every frame, its bones unchanged.)
        bones_changed = False
    if not bones_changed and _stands_as_checked(rec, ctx):
        return True
    rec.fed_check = None
    checked = _fed_frame_stands(obj, ctx, bones_changed)
    if checked is None:
        return False
    digest = _state_digest(ctx, obj)
    if digest is not None:
        mods = tuple(
            (key, st, st.output.written.settings, st.output.written.mesh_version, (st.companion.shown, st.companion.deforms))
            for key, st in checked
        )
        rec.fed_check = FedCheck(digest, mods)
    return True


def fed_frame_stands_as_checked(rec, ctx: Context) -> bool:
    """Whether the fed frame stands for what the last check that stood saw (`rec.fed_check`),
    without the rest of `fed_frame_stands`: False where there is no such check, or anything it
    saw changed (the whole check decides then, without that check: it is dropped here, as
    `fed_frame_stands` drops it). An object gone since is not there (False)."""
    if rec.fed_check is None or ctx.render or ctx.session.exports.active():
        return False
    try:
        if _stands_as_checked(rec, ctx):
            return True
    except ReferenceError:
        pass
    rec.fed_check = None
    return False


def _stands_as_checked(rec, ctx: Context) -> bool:
    """Whether the fed frame stands for what `rec.fed_check` saw: Blender's side unchanged (one
    read of the object's state), the add-on's side compared as `_fed_frame_stands` does."""
    check: FedCheck | None = rec.fed_check
    if check is None:
        return False
    obj, session = rec.obj, ctx.session
    data = session.meshes.peek(obj)  # (None where Blender said the mesh may have changed)
    if data is None:
        return False
    feeds, states = session.routes.feeds, session.states
    for key, st, settings_key, mesh_version, companion in check.mods:
        written = st.output.written
        if (
            not feeds.stands_with(key, ctx.fed_stamp)
            or states.find(key) is not st
            or written is None
            or written.settings != settings_key
            or written.mesh_version != mesh_version
            or data.version != mesh_version[0]
            or (written.result and session.meshes.revision(obj.data) != mesh_version[1])
            or st.decided_structure != ctx.structure
            or (st.companion.shown, st.companion.deforms) != companion
        ):
            return False
    return _state_unchanged(ctx, obj, check.digest)


def _bones_as_checked(rec, ctx: Context) -> bool:
    """Whether every DQ Skin `rec.fed_check` saw is still bound to its armature's bones as they
    are (the bones' binding signature, from the pose the feed read in this evaluation): then an
    update of the armature's data changed nothing the binding depends on."""
    check: FedCheck | None = rec.fed_check
    if check is None:
        return False
    for _key, st, *_rest in check.mods:
        s, bound = st.settings.value, st.binding.key
        arm = s.armature if s is not None else None
        if arm is None or bound is None:
            return False
        try:
            if arm.mode == "EDIT" or pose.armature_signature(arm.evaluated_get(ctx.depsgraph), ctx.reads) != bound.bones:
                return False
        except ReferenceError:  # (the armature was deleted: the full path says so)
            return False
    return True


def _state_digest(ctx: Context, obj) -> bytes | None:
    """The digest of `obj`'s state in Blender's memory (`dqskin.memory.ObjectStateMemory`); None
    where the reader is refused for the session."""
    reader = ctx.session.readers.object_state
    return reader.digest(obj) if reader is not None else None


def _state_unchanged(ctx: Context, obj, digest: bytes) -> bool:
    """Whether `obj`'s state in Blender's memory still has `digest`."""
    reader = ctx.session.readers.object_state
    return reader is not None and reader.unchanged(obj, digest)


def _fed_frame_stands(obj, ctx: Context, bones_changed: bool) -> list | None:
    """`fed_frame_stands` through Blender's Python API: the (key, state) of each DQ Skin it
    checked where the fed frame stands, else None."""
    if obj.mode == "EDIT":
        return None
    mods = dq_skin_modifiers(obj)
    if not mods:
        return None
    session = ctx.session
    feeds: Feeds = session.routes.feeds
    checked = []
    for mod in mods:
        key = mod_key(obj, mod)
        if not mod.show_viewport or not feeds.stands_with(key, ctx.fed_stamp):
            return None
        st = session.states.find(key)
        checked.append((key, st))
        s = settings.cached(mod, st.settings)
        try:
            arm = s.armature
            if s.key() != st.output.written.settings or st.decided_structure != ctx.structure or arm is None or arm.mode == "EDIT":
                return None
            if bones_changed and pose.armature_signature(arm.evaluated_get(ctx.depsgraph), ctx.reads) != st.binding.key.bones:
                return None
        except (ReferenceError, AttributeError):  # (the armature was deleted: the full path says so)
            return None
    data = session.meshes.get(obj, session.readers.mesh)  # (compares the vertex group names)
    for mod, (_key, st) in zip(mods, checked):
        written = st.output.written
        if written is None or data.version != written.mesh_version[0]:
            return None
        if written.result and session.meshes.revision(obj.data) != written.mesh_version[1]:
            return None
        companions.follow_the_user(obj, mod, st, False)
    # (Following the user may have switched one off.)
    return checked if all(mod.show_viewport for mod in mods) else None


@dataclass(frozen=True)
class AsideCheck:
    """What the last check that an object's DQ Skins still step aside saw (`stepped_aside_stands`):
    the digest of its state in Blender's memory (as `FedCheck`'s) and, for each DQ Skin, its key,
    its state and the decision that state kept (`ModifierState.stepped_aside`)."""

    digest: bytes
    mods: tuple  # (key, state, decision) each


def stepped_aside_stands(rec, ctx: Context) -> bool:
    """Whether every DQ Skin of `rec.obj` leaves the deforming to its companion (switched off or
    handed over) as at its last full evaluation (`pipeline.still_steps_aside`): the companion
    deforms each frame by itself, and a full evaluation of each frame would only decide the same
    again (a crowd whose characters have a Corrective Smooth after DQ Skin, or DQ Skin switched
    off to compare, paid it for every character on every frame). Where it stands, what it saw is
    kept (`AsideCheck`) for `steps_aside_as_checked` on the frames after."""
    obj = rec.obj
    rec.aside_check = None
    if obj.library is not None:
        return False
    mods = dq_skin_modifiers(obj)
    if not mods:
        return False
    states = ctx.session.states
    checked = []
    try:
        for mod in mods:
            key = mod_key(obj, mod)
            st = states.find(key)
            if st is None or st.status.mode not in STEPPED_ASIDE or not pipeline.still_steps_aside(obj, mod, st, ctx):
                return False
            checked.append((key, st, st.stepped_aside))
    except (ReferenceError, AttributeError):  # (the armature was deleted: the full path says so)
        return False
    digest = _state_digest(ctx, obj)
    if digest is not None:
        rec.aside_check = AsideCheck(digest, tuple(checked))
    return True


def steps_aside_as_checked(rec, ctx: Context) -> bool:
    """Whether `rec.obj` still steps aside as `rec.aside_check` saw: Blender's side unchanged (one
    read of the object's state: its modes, modifier stack with every switch, DQ Skin's inputs,
    the companion's settings), the add-on's side the same decisions, the scene's structure the
    same, no export and no render (as `pipeline.still_steps_aside` requires), in place of reading
    the decision's inputs again through Blender's Python API for every character and frame."""
    check: AsideCheck | None = rec.aside_check
    if check is None:
        return False
    session = ctx.session
    if ctx.render or session.exports.active():
        return False
    states = session.states
    for key, st, decision in check.mods:
        if (
            states.find(key) is not st
            or st.stepped_aside is not decision
            or st.status.mode not in STEPPED_ASIDE
            or st.decided_structure != ctx.structure
        ):
            rec.aside_check = None
            return False
    return _state_unchanged(ctx, rec.obj, check.digest)


STEPPED_ASIDE = (Mode.OFF, Mode.HANDED_OVER)

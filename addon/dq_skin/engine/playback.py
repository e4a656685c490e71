# SPDX-License-Identifier: GPL-3.0-or-later
"""The way past the full evaluation during playback: the feed skinned the frame inside Blender's
evaluation (see `routes.feed` and `fed`); what it could not know is checked here, cheaply."""

from __future__ import annotations

from ..blender import pose, settings
from ..model.state import Mode
from ..routes.feed import Feeds
from . import companions, pipeline
from .context import Context, dq_skin_modifiers, mod_key


def fed_frame_stands(obj, ctx: Context, bones_changed: bool = False) -> bool:
    """Whether the frame the feed skinned for every DQ Skin of `obj` in this evaluation is what
    the full path would publish, checked cheaply (a Rigify character's full path reads the whole
    pose again). The driver read the pose, the transforms and the shape keys, and skinned
    only where the bones' binding signature and the mesh were the last full evaluation's;
    checked here is what it could not know: the settings, the mesh and its vertex groups, the
    scene's structure, exports, the toggles and the companion; with `bones_changed` (the
    armature's data was updated), also the bones' binding signature."""
    if ctx.render or obj.mode == "EDIT":
        return False
    mods = dq_skin_modifiers(obj)
    if not mods:
        return False
    session = ctx.session
    feeds: Feeds = session.routes.feeds
    if session.exports.active():
        return False
    states = []
    for mod in mods:
        key = mod_key(obj, mod)
        if not mod.show_viewport or not feeds.skinned_with(key, ctx.fed_stamp):
            return False
        st = session.states.find(key)
        states.append(st)
        s = settings.cached(mod, st.settings)
        try:
            arm = s.armature
            if s.key() != st.output.written.settings or st.decided_structure != ctx.structure or arm is None or arm.mode == "EDIT":
                return False
            if bones_changed and pose.armature_signature(arm.evaluated_get(ctx.depsgraph), ctx.reads) != st.binding.key.bones:
                return False
        except (ReferenceError, AttributeError):  # (the armature was deleted: the full path says so)
            return False
    data = session.meshes.get(obj, session.readers.mesh)  # (compares the vertex group names)
    for mod, st in zip(mods, states):
        written = st.output.written
        if written is None or data.version != written.mesh_version[0]:
            return False
        if written.result and session.meshes.revision(obj.data) != written.mesh_version[1]:
            return False
        companions.follow_the_user(obj, mod, st, False)
    return all(mod.show_viewport for mod in mods)  # (following the user may have switched one off)


def stepped_aside_stands(obj, ctx: Context) -> bool:
    """Whether every DQ Skin of `obj` leaves the deforming to its companion (switched off or
    handed over) as at its last full evaluation (`pipeline.still_steps_aside`): the companion
    deforms each frame by itself, and a full evaluation of each frame would only decide the same
    again (a crowd whose characters have a Corrective Smooth after DQ Skin, or DQ Skin switched
    off to compare, paid it for every character on every frame)."""
    if obj.library is not None:
        return False
    mods = dq_skin_modifiers(obj)
    if not mods:
        return False
    states = ctx.session.states
    try:
        for mod in mods:
            st = states.find(mod_key(obj, mod))
            if st is None or st.status.mode not in STEPPED_ASIDE or not pipeline.still_steps_aside(obj, mod, st, ctx):
                return False
    except (ReferenceError, AttributeError):  # (the armature was deleted: the full path says so)
        return False
    return True


STEPPED_ASIDE = (Mode.OFF, Mode.HANDED_OVER)

# SPDX-License-Identifier: GPL-3.0-or-later
"""The two ways past the full evaluation during playback:

- steady (`quick_plan`): a live DQ Skin on the mesh's own coordinates, with plain vertex groups,
  where nothing about the object, its armature or the scene's structure changed but the pose:
  the last job with this frame's bones;
- fed (`fed_frame_stands`): the feed skinned the frame inside Blender's evaluation (see
  `routes.feed`); what it could not know is checked here, cheaply.
"""

from __future__ import annotations

import time

from .. import dqskin
from ..blender import rig, settings
from ..model.keys import PoseKey, Source
from ..model.state import Mode, ModifierState, ResultMode
from . import companions
from .context import Context, Plan, dq_skin_modifiers


def live_and_in_place(obj, st: ModifierState, arm, ctx: Context) -> bool:
    """What both ways past the full path need: a live DQ Skin on the mesh's own coordinates
    with a result written, the scene's structure as last decided, no export running, neither
    the object nor its armature moved, the armature not in Edit Mode."""
    out = st.output
    return (
        st.status.mode is Mode.LIVE
        and st.status.source is Source.MESH
        and out.result is not None
        and out.written is not None
        and st.decided_structure == ctx.structure
        and obj.session_uid in ctx.unmoved
        and not ctx.session.exports.active()
        and arm is not None
        and arm.session_uid in ctx.unmoved
        and arm.mode != "EDIT"
    )


def quick_plan(obj, mod, st: ModifierState, ctx: Context):
    """The steady state of playback, cheaply. Returns a plan, None (nothing to do), or False
    (take the full path)."""
    s = st.settings.value
    out = st.output
    if s is None or st.needs_effective or st.binding.binding is None or out.spaces is None or obj.session_uid not in ctx.unchanged:
        return False
    arm = s.armature
    meshes = ctx.session.meshes
    try:
        if not live_and_in_place(obj, st, arm, ctx):
            return False
        uid = arm.session_uid
        data = meshes.peek(obj)
        if data is None or data.keys is not None:
            return False
        if out.kind is ResultMode.REPLACE and (data.version != out.copied_version or meshes.revision(obj.data) != out.copied_revision):
            return False
        deform = ctx.poses.get(uid)
        if deform is None:
            deform = ctx.poses[uid] = rig.pose_matrices(arm.evaluated_get(ctx.depsgraph))
    except ReferenceError:
        return False
    bound = st.binding.binding
    if len(bound.bone_indices) != len(deform):
        deform = deform[bound.bone_indices]
    pose_key = PoseKey(matrices=deform.tobytes())
    old = out.written
    if pose_key == old.pose:
        return None  # the pose did not change: the result is already this
    if s.method == dqskin.Method.CENTERS_OF_ROTATION and st.binding.centers is None:
        return False
    job = out.job  # the last full evaluation's: only the pose changed
    try:
        job.deform = deform
    except (AttributeError, TypeError, ValueError):
        return False  # the full path says what is wrong
    deforms = st.companion.deforms or (True, True)
    return Plan(
        obj, mod, st, s, out.result, out.kind, old.with_pose(pose_key), job, deforms, time.perf_counter(), quick=True, render=ctx.render
    )


def fed_frame_stands(obj, ctx: Context) -> bool:
    """Whether the frame the feed skinned for `obj`'s one DQ Skin in this evaluation is what the
    full path would write, checked cheaply (a Rigify character's full path reads the whole pose
    again: 0.4 ms). The driver knew the pose and that the bones' binding signature is the last
    full evaluation's (it skins only then); checked here is what it could not know: the
    settings, the mesh and its vertex groups, the stack before DQ Skin, the object's and the
    armature's transforms, the scene's structure (what hands over), the toggles and the
    companion. The feed's result is always re-evaluated, so the object always looks updated
    to the frame handler: these checks replace the steady path's "not updated"."""
    if ctx.render or obj.mode == "EDIT":
        return False
    mods = dq_skin_modifiers(obj)
    if len(mods) != 1:
        return False
    mod = mods[0]
    for m in obj.modifiers:
        if m == mod:
            break
        if m.show_viewport:
            return False  # something reaches DQ Skin before it: the full path decides
    session = ctx.session
    st = ctx.state(obj, mod)
    out = st.output
    feeds = session.route.feeds
    if (
        out.kind is not ResultMode.REPLACE
        or not mod.show_viewport
        or out.result is None
        or not feeds.skinned_now(out.result, ctx.depsgraph)
    ):
        return False
    s = settings.cached(mod, st.settings)
    try:
        if not live_and_in_place(obj, st, s.armature, ctx) or s.key() != out.written.settings:
            return False
    except ReferenceError:  # (the armature was deleted: the full path says so)
        return False
    data = session.meshes.get(obj, session.readers.mesh)  # (compares the vertex group names)
    if data.keys is not None or (data.version, session.meshes.revision(obj.data)) != out.written.mesh_version:
        return False
    companions.follow_the_user(obj, mod, st, bool(session.exports.active()))
    return mod.show_viewport

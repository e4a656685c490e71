# SPDX-License-Identifier: GPL-3.0-or-later
"""Evaluating the DQ Skin modifiers of one object, in stack order: what reaches each (`inputs`),
whether DQ Skin deforms (or Blender's own deformation does, for a reason: `decisions`), the
binding and the kernel's job (`binding`), skinning, and publishing the result through a route
(`routes`). This module is the only writer of results and of the panel's status.

Where DQ Skin does not deform (switched off, handed over, an error), the node group passes the
mesh through and the companion deforms it (see `companions`). Everything that does not change
between frames is kept (see `model.state`); nothing is computed or written when nothing
changed, which also keeps Blender's update loop from cycling.
"""

from __future__ import annotations

import time

import numpy as np

from .. import dqskin
from ..blender import companion, consumers, nodes, pose, rig, settings
from ..model import decisions
from ..model.keys import FrameKey, PoseKey, Source
from ..model.methods import Settings
from ..model.state import Mode, ModifierState, RouteKind
from ..routes import pointcache
from ..routes.base import Target
from ..routes.feed import Member
from ..routes.result_route import MeshSource
from . import binding, companions, inputs
from .context import Context, Plan, SkinError, dq_skin_modifiers, mod_key

CENTERS_UPDATING = "Optimized Centers: updating for the new weights (the last centers show meanwhile)"


def evaluate_object(obj, ctx: Context, force: bool = False) -> bool:
    """Evaluates every DQ Skin modifier of `obj`, in stack order. With `ctx.batch`, the skinning
    of an object with one DQ Skin is queued there instead of run (see `run_batch`). Returns
    whether a result was written or queued."""
    obj_eval = obj.evaluated_get(ctx.depsgraph)
    wrote = False
    reaching: Source | None = None
    previous: ModifierState | None = None
    batchable = ctx.batch is not None and len(dq_skin_modifiers(obj)) == 1
    for mod in obj.modifiers:
        enabled = mod.show_render if ctx.render else mod.show_viewport
        if not nodes.is_dq_skin(mod):
            if not _ours(obj, mod):
                reaching = decisions.next_source(reaching, False, enabled, False)
            continue
        st = ctx.state(obj, mod)
        if nodes.version_of(mod.node_group) != nodes.VERSION:
            report(st, Mode.FALLBACK, "Made with an older DQ Skin: remove it and add it again")
            reaching = decisions.next_source(reaching, True, enabled, False)
            continue
        wrote |= _evaluate(obj, obj_eval, mod, st, ctx, decisions.source_for(reaching), previous, force, batchable)
        reaching = decisions.next_source(reaching, True, enabled, st.status.live)
        previous = st
    return wrote


def _ours(obj, mod) -> bool:
    """Whether `mod` carries DQ Skin's positions (a carrier, or a Soft Body right before a DQ Skin,
    which simulates them), not something reaching DQ Skin."""
    if mod.type == "MESH_CACHE":
        return pointcache.is_ours(mod.filepath)
    if mod.type != "SOFT_BODY":
        return False
    mods = list(obj.modifiers)
    following = next((m for m in mods[mods.index(mod) + 1 :] if m.type != "SOFT_BODY"), None)
    return following is not None and nodes.is_dq_skin(following)


def report(st: ModifierState, mode: Mode, message: str = "") -> None:
    st.status.mode, st.status.message = mode, message
    st.output.invalidate()


def _evaluate(obj, obj_eval, mod, st: ModifierState, ctx: Context, source: Source, previous, force: bool, batchable: bool) -> bool:
    start = time.perf_counter()
    st.status.source = source
    if obj.library is not None:
        lib = obj.library.filepath or obj.library.name
        report(st, Mode.LINKED, f"Linked from {lib}: Blender's Armature modifier deforms it (make a Library Override to use DQ Skin)")
        return False
    s = None
    target = Target(obj, mod, st, mod_key(obj, mod))
    st.stepped_aside = None
    try:
        s = st.settings.value if st.settings.value is not None and obj.session_uid in ctx.unchanged else settings.cached(mod, st.settings)
        exporting = ctx.session.exports.active()
        companions.follow_the_user(obj, mod, st, bool(exporting))
        deforms, reason = _where_it_deforms(obj, mod, s, ctx, exporting)
        st.decided_structure = ctx.structure
        if not (mod.show_render if ctx.render else mod.show_viewport):
            where = "renders" if ctx.render else "the viewport"
            message = f"Off in {where}: Blender's Armature modifier deforms the mesh there"
            return _step_aside(ctx, target, s, deforms, Mode.OFF, message, reason)
        if reason:
            return _step_aside(ctx, target, s, deforms, Mode.HANDED_OVER, reason, reason)
        if obj.mode == "EDIT" or obj.data.is_editmode:
            return _in_edit_mode(ctx, target, s, deforms)
        plan = _prepare(obj, obj_eval, target, s, ctx, source, previous, force, deforms, start)
        if plan is None:
            if st.companion.deforms != deforms:  # e.g. only the render toggle changed
                companions.settle(obj, mod, st, s, deforms, render=ctx.render)
            return False
        if batchable and not st.needs_effective:
            ctx.batch.append(plan)
            return True
        error = dqskin.skin_many([plan.job])[0]
        if error is not None:
            raise SkinError(error)
        finish(ctx.session, plan)
        return True
    except SkinError as e:
        return fallback(ctx.session, obj, mod, st, s, str(e), ctx.render)
    except Exception as e:  # never a traceback in the user's face; say what happened
        return fallback(ctx.session, obj, mod, st, s, f"{type(e).__name__}: {e}", ctx.render)


def step_aside_key(obj, mod, st: ModifierState, s: Settings, deforms, reason: str) -> tuple:
    """What a decision to leave the deforming to the companion (switched off, handed over) read
    and left: the settings, the toggles, where DQ Skin would deform and why not, and the
    companion as it set it up. While it is the same (`still_steps_aside`), evaluating again
    would change nothing: the companion deforms."""
    c = companions.companion_of(obj, mod, st)
    return (s.key(), mod.show_viewport, mod.show_render, deforms, reason, tuple(companion.snapshot(c).values()) if c is not None else None)


def still_steps_aside(obj, mod, st: ModifierState, ctx: Context) -> bool:
    """Whether the modifier's last full evaluation left the deforming to the companion and this
    one would decide the same (its decision read again, `_where_it_deforms`, without what it
    writes): then nothing of DQ Skin's needs doing for it."""
    if st.stepped_aside is None or ctx.render or st.decided_structure != ctx.structure:
        return False
    exporting = ctx.session.exports.active()
    if exporting:
        return False
    s = settings.cached(mod, st.settings)
    deforms, reason = _where_it_deforms(obj, mod, s, ctx, exporting)
    return step_aside_key(obj, mod, st, s, deforms, reason) == st.stepped_aside


def _where_it_deforms(obj, mod, s: Settings, ctx: Context, exporting: str) -> tuple[tuple[bool, bool], str]:
    """Where DQ Skin would deform ((viewport, render), as far as this evaluation can tell), and
    why it hands over in this evaluation ("" if it does not)."""
    arm = s.armature
    in_edit = arm is not None and arm.type == "ARMATURE" and arm.mode == "EDIT"
    blender_method = s.blender_method
    simulation = consumers.simulation_reason(ctx.session.scan.ensure(ctx.structure), obj, mod) if blender_method else ""
    mode = consumers.mode_reason(obj) if blender_method else ""
    magnifier = (consumers.magnifier_reason(obj, mod, False), consumers.magnifier_reason(obj, mod, True)) if blender_method else ("", "")
    reasons = decisions.hand_over(exporting, in_edit, simulation, mode, blender_method, magnifier)
    return decisions.deforms_where(mod.show_viewport, mod.show_render, reasons), reasons.for_render(ctx.render)


def _in_edit_mode(ctx: Context, target: Target, s: Settings, deforms) -> bool:
    """The mesh is in Edit Mode with one of DQ Skin's own methods: what Object Mode showed last
    stays, through the deform-only carrier (as a baked cache would show it; edits show when
    leaving Edit Mode)."""
    st = target.st
    out = st.output
    n = len(target.obj.data.vertices)
    if st.status.live and out.route is RouteKind.NODE:
        # The feed wrote the last frames into the result's evaluated mesh (it keeps no buffer).
        fed = ctx.session.routes.result.fed_out(target, ctx.depsgraph)
        if fed is not None and len(fed) == n:
            out.buffer = fed.copy()
    if not st.status.live or out.buffer is None or len(out.buffer) != n:
        raise SkinError("The mesh is in Edit Mode (DQ Skin deforms it again in Object Mode)")
    if out.route is not RouteKind.CACHE:
        ctx.session.routes.publish(
            target, RouteKind.CACHE, out.buffer, out.kind, None, deforms, _member(target, s, RouteKind.CACHE, None), _scene(target.obj, ctx)
        )
        out.written = None  # computed again in Object Mode
    else:
        ctx.session.routes.cache.show_like_modifier(target)
    if target.mod.show_in_editmode:
        note = "Edit Mode: the pose of Object Mode shows; edits take effect in Object Mode"
    else:
        note = "Edit Mode: the rest mesh shows (the modifier's Edit Mode display is off)"
    st.status.notes = (note,)
    return False


def _step_aside(ctx: Context, target: Target, s, deforms, mode: Mode, message: str, reason: str) -> bool:
    """DQ Skin does not deform in this evaluation: the mesh passes through, the companion
    deforms (where the user has not switched it off). What decided it is kept for the frames
    after (`still_steps_aside`); `reason`: why DQ Skin would hand over ("" if it would not)."""
    obj, mod, st = target.obj, target.mod, target.st
    if obj.library is None:
        ctx.session.routes.pass_through(target)
        companions.settle(obj, mod, st, s, deforms, render=ctx.render)
    report(st, mode, message)
    if mode is Mode.OFF and not companions.companion_of(obj, mod, st):
        st.status.message = "Off: no Armature modifier after it, the mesh is not deformed"
    if not ctx.render and obj.library is None:
        st.stepped_aside = step_aside_key(obj, mod, st, s, deforms, reason)
    return False


def fallback(session, obj, mod, st: ModifierState, s, message: str, render: bool = False) -> bool:
    """DQ Skin cannot deform: the input passes through and the companion deforms as Blender
    does; the panel shows why."""
    try:
        session.routes.pass_through(Target(obj, mod, st, mod_key(obj, mod)))
        if s is None:
            try:
                s = settings.read(mod)
            except Exception:  # a damaged modifier: the companion as it is
                s = None
        companions.settle(obj, mod, st, s, (False, False), render=render)
    except Exception as e:  # nothing of this may reach Blender's console
        message += f" (and the companion could not be set up: {type(e).__name__}: {e})"
    report(st, Mode.FALLBACK, message)
    c = companions.companion_of(obj, mod, st) if obj.library is None else None
    st.status.instead = (
        f"Blender's Armature modifier '{c.name}' deforms the mesh instead"
        if c is not None
        else "No Armature modifier after it: the mesh is not deformed"
    )
    return False


def _prepare(obj, obj_eval, target: Target, s: Settings, ctx: Context, source, previous, force, deforms, start) -> Plan | None:
    """Everything before the kernel: checks, what reaches the modifier, influences, this frame's
    matrices, the route; None when what Blender shows already is this."""
    session, mod, st = ctx.session, target.mod, target.st
    arm = s.armature
    if arm is None:
        raise SkinError("No armature object set")
    if arm.type != "ARMATURE":
        raise SkinError(f"'{arm.name}' is not an armature")
    data = session.meshes.get(obj, session.readers.mesh)
    if data.vertex_count == 0:
        raise SkinError("The mesh has no vertices")
    arm_eval = arm.evaluated_get(ctx.depsgraph)
    if arm_eval.pose is None:
        raise SkinError(f"The armature '{arm.name}' has no pose")

    # What reaches the modifier.
    if source is Source.MESH:
        try:
            positions, input_key = inputs.mesh_input(obj, obj_eval, st, data, ctx.depsgraph)
        except inputs.CaptureNeeded:
            source = st.status.source = Source.CAPTURE
    if source is Source.CAPTURE:
        positions, input_key = inputs.captured_input(obj, obj_eval, mod, st, data)
    elif source is Source.CHAIN:
        positions, input_key = inputs.chain_input(previous, data.vertex_count)
    if source is not Source.CAPTURE and st.capture_on is not False:
        inputs.set_capture(mod, False)
        st.capture_on = False

    bound = binding.binding(obj, arm, arm_eval, st, s, data, ctx)
    if len(positions) != bound.vertex_count:
        raise SkinError(
            f"An earlier modifier changed the vertex count ({bound.vertex_count} → {len(positions)}); "
            "put DQ Skin before modifiers that add or remove vertices"
        )
    if st.needs_effective:
        bones = pose.frame(arm_eval, bound, st.binding.segments, ctx.reads)  # with every B-Bone's joints
        pose_key = bones.key
    else:
        deform = pose_matrices(ctx, arm, arm_eval, bound)
        pose_key = PoseKey.of_matrices(deform)
    out = st.output
    if out.spaces is None or not (obj.session_uid in ctx.unmoved and arm.session_uid in ctx.unmoved):
        out.spaces = rig.spaces(obj_eval, arm_eval)
        out.spaces_of = (obj_eval.matrix_world.copy(), arm_eval.matrix_world.copy())
    premat, postmat = out.spaces
    scan = session.scan.ensure(ctx.structure)
    by_index = bool(consumers.index_readers(scan, obj))
    kind = decisions.result_kind(source, by_index)
    deform_only = decisions.needs_deform_only(
        consumers.mode_reason(obj), consumers.simulation_reason(scan, obj, mod), by_index or consumers.soft_body_before(obj, mod)
    )
    route = decisions.route_for(source, deform_only, data.vertex_count)
    if route is RouteKind.CACHE:
        # (The carrier reads positions alone: what else of the mesh changed does not matter, and
        # Blender says the mesh changed whenever the carrier is told to read its file again.)
        result_uid, revision = 0, 0
    else:
        result_uid, revision = session.routes.result.prepare(target).session_uid, session.meshes.revision(obj.data)
    key = FrameKey(s.key(), input_key, pose_key, premat.tobytes(), result_uid, (data.version, revision))
    shown, wanted = (out.route, out.kind), decisions.shown_as(route, kind)
    if decisions.already_written(key, out.written, st.status.live, shown, wanted, force):
        return None
    if route is RouteKind.CACHE:
        out.buffer = session.routes.cache.buffer(target, bound.vertex_count)
    elif out.buffer is None or len(out.buffer) != bound.vertex_count or pointcache.is_mapped(out.buffer):
        out.buffer = np.empty((bound.vertex_count, 3), np.float32)
    influences, rest = bound.influences, bound.rest
    if st.needs_effective:
        # Envelopes and B-Bone segments depend on where the vertices are: this frame's
        # influences, over the bones followed by the B-Bones' segment joints.
        cache = st.binding
        positions = inputs.as_array(positions, data)
        influences = pose.influences(
            bones, bound, arm_eval, positions, input_key, premat, s.use_vertex_groups, s.use_envelopes, cache.envelopes, cache.segments
        )
        deform, rest = bones.deform, bones.rest
        if s.method == dqskin.Method.CENTERS_OF_ROTATION:
            binding.centers_of(obj, st, data, influences, ctx)
    out.job = binding.job(st, s, positions, influences, deform, rest, premat, postmat)
    if not st.needs_effective:
        data.release_positions()  # (the kernel reads Blender's; the binding and centers are made)
    return Plan(
        target, s, kind, route, key, out.job, deforms, start, render=ctx.render, data=data, previous=previous, scene=_scene(obj, ctx)
    )


def pose_matrices(ctx: Context, arm, arm_eval, bound: rig.Binding) -> np.ndarray:
    """This evaluation's channel matrices of the bound bones (each armature read once per call)."""
    deform = ctx.poses.get(arm.session_uid)
    if deform is None:
        deform = ctx.poses[arm.session_uid] = rig.pose_matrices(arm_eval, ctx.reads.reader)
    if len(bound.bone_indices) != len(deform):
        deform = deform[bound.bone_indices]
    return deform


def _scene(obj, ctx: Context):
    """The scene whose feed a character joins: its first (a character in two scenes is fed by
    the first's batch in both)."""
    scenes = obj.users_scene
    return scenes[0] if scenes else ctx.depsgraph.scene


def _member(target: Target, s: Settings, route: RouteKind, previous) -> Member:
    bound = target.st.binding.binding
    obj = target.obj
    names = tuple(bound.bone_names)
    bones = s.armature.data.bones
    return Member(
        target.key,
        target,
        route,
        s.armature,
        names,
        tuple(n for n in names if (b := bones.get(n)) is not None and b.bbone_segments > 1),
        obj.data.shape_keys,
        list(obj.modifiers).index(target.mod),
        previous,
        alone=len(dq_skin_modifiers(obj)) == 1,
    )


def finish(session, plan: Plan) -> None:
    """Publishes the result, then switches the companion off where DQ Skin deforms (in this
    order, so that no evaluation sees both or neither)."""
    target, st = plan.target, plan.target.st
    obj, mod = target.obj, target.mod
    out = st.output
    out.generation += 1
    data = plan.data
    source = MeshSource(obj.data, data.version, session.meshes.revision(obj.data), data.counts)
    member = None if plan.route is RouteKind.RESULT else _member(target, plan.s, plan.route, plan.previous)
    session.routes.publish(target, plan.route, out.buffer, plan.kind, source, plan.deforms, member, plan.scene)
    out.written = plan.key
    companions.settle(obj, mod, st, plan.s, plan.deforms, render=plan.render)
    bound = st.binding.binding
    status = st.status
    status.mode, status.message = Mode.LIVE, ""
    status.notes = (CENTERS_UPDATING,) if st.binding.centers_pending else ()
    status.method = plan.s.method.label
    status.bones = len(bound.bone_names)
    status.influences = len(bound.influences)
    status.seconds = time.perf_counter() - plan.start


def run_batch(session, plans: list) -> None:
    """Skins every queued plan in one call (in parallel across objects) and publishes the results."""
    if not plans:
        return
    errors = dqskin.skin_many([p.job for p in plans])  # jobs were checked when built (`binding.job`)
    for plan, error in zip(plans, errors):
        try:
            if error is not None:
                raise SkinError(error)
            finish(session, plan)
        except Exception as e:
            message = str(e) if isinstance(e, SkinError) else f"{type(e).__name__}: {e}"
            t = plan.target
            fallback(session, t.obj, t.mod, t.st, plan.s, message, plan.render)


def prepare_capture(session, obj) -> None:
    """Switches the node group's capture on for the DQ Skin modifiers that other enabled
    modifiers precede, as soon as the stack changes: Blender then stores what reaches them in
    the same evaluation, and the next one skins it (capture found on only while skinning would
    cost an evaluation more)."""
    if obj.library is not None:
        return
    others = False
    for mod in obj.modifiers:
        if nodes.is_dq_skin(mod):
            if others and nodes.version_of(mod.node_group) == nodes.VERSION:
                key = mod_key(obj, mod)
                st = session.states.get(key)
                if st.capture_on is not True:
                    inputs.set_capture(mod, True)
                    session.routes.pass_through(Target(obj, mod, st, key))  # a replacing result would hide what the group stores
                    st.capture_on = True
        elif (mod.show_viewport or mod.show_render) and not _ours(obj, mod):
            others = True

# SPDX-License-Identifier: GPL-3.0-or-later
"""Evaluating the DQ Skin modifiers of one object: what reaches each, whether DQ Skin deforms
(or Blender's own deformation does, for a reason), skinning, writing the result.

What reaches a DQ Skin modifier (its *source*):
- ``mesh``: nothing enabled before it: the mesh's coordinates with its shape keys mixed as
  Blender mixes them (computed here, so the modifier needs no evaluation of its own first);
- ``chain``: only other live DQ Skin modifiers before it: the previous one's output;
- ``capture``: other modifiers before it: the coordinates the node group stored on its way
  through, read from the evaluated mesh (which needs the modifiers after it to keep the vertex
  count, else the companion takes over and the panel says why).

For ``mesh`` and ``chain`` the result is a full copy of the mesh with skinned positions, output
as is by the node group; for ``capture`` it is points whose positions the node group sets.
Where DQ Skin does not deform (switched off, handed over, an error), the node group passes the
mesh through and the companion deforms it (see `companion`). Everything that does not change
between frames is kept (see `state`); nothing is computed or written when nothing changed,
which also keeps Blender's update loop from cycling.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from . import centers, companion, compat, consumers, dqskin, exports, feed, meshdata, nodes, pose, results, rig, settings
from .state import STATES, BindingKey, FrameKey, Mode, ModifierState

# The feed (`feed`) saves Blender's second evaluation, whose cost grows with the scene's graph
# (a Rigify rig: about 1.25 ms), and costs more per vertex than the frame handler's route (its
# Mesh Cache reads the file one vertex at a time: about 18 ns a vertex more). Measured on
# Rigify's 706 bones it wins up to about 60-90 vertices per pose bone (14,824 vertices: 0.5-0.9
# ms a frame faster), and on a 16-bone, 100k-vertex B-Bone grid it loses 2.2 ms: a mesh is fed
# up to this many vertices per pose bone of its armature (see the README's figures).
FEED_VERTICES_PER_BONE = 50


class SkinError(Exception):
    """A problem the user can fix, shown on the panel and in operator reports."""


# Modifiers that never add or remove vertices.
KEEP_VERTEX_COUNT = {
    "ARMATURE",
    "CAST",
    "CLOTH",
    "COLLISION",
    "CORRECTIVE_SMOOTH",
    "CURVE",
    "DATA_TRANSFER",
    "DISPLACE",
    "HOOK",
    "LAPLACIANDEFORM",
    "LAPLACIANSMOOTH",
    "LATTICE",
    "MESH_DEFORM",
    "NORMAL_EDIT",
    "SHRINKWRAP",
    "SIMPLE_DEFORM",
    "SMOOTH",
    "SOFT_BODY",
    "SURFACE_DEFORM",
    "UV_PROJECT",
    "UV_WARP",
    "VERTEX_WEIGHT_EDIT",
    "VERTEX_WEIGHT_MIX",
    "VERTEX_WEIGHT_PROXIMITY",
    "WARP",
    "WAVE",
    "WEIGHTED_NORMAL",
    "MESH_CACHE",
}


def dq_skin_modifiers(obj):
    return [m for m in obj.modifiers if nodes.is_dq_skin(m)] if obj.type == "MESH" else []


def state_of(obj, mod) -> ModifierState:
    return STATES.get(obj.session_uid, compat.modifier_uid(mod))


def status_of(obj, mod):
    """The panel's view of a modifier (`state.Status`)."""
    return state_of(obj, mod).status


def find_status(obj, mod):
    """`status_of` without creating a state (drawing a panel must not)."""
    st = STATES.find(obj.session_uid, compat.modifier_uid(mod))
    return st.status if st is not None else None


@dataclass
class Context:
    """What one handler call shares between objects."""

    depsgraph: object
    structure: int = 0  # the registry's structure version (see `consumers.Scan`)
    batch: list | None = None  # plans to skin together (see `run_batch`)
    unchanged: set = field(default_factory=set)  # objects Blender did not update: cached settings hold
    unmoved: set = field(default_factory=set)  # objects whose transform did not change
    poses: dict = field(default_factory=dict)  # armature uid -> this evaluation's pose matrices
    pose_data: dict = field(default_factory=dict)  # armature uid -> its pose from memory (`pose.read`)

    @property
    def render(self) -> bool:
        return self.depsgraph.mode == "RENDER"


@dataclass
class Plan:
    """One skinning to run: the kernel's job and where its result goes."""

    obj: object
    mod: object
    st: ModifierState
    s: settings.Settings
    result: object
    kind: int
    key: FrameKey
    job: object  # dqskin.SkinJob
    deforms: tuple  # (viewport, render): where DQ Skin deforms (the companion is off there)
    start: float
    quick: bool = False  # steady playback: only the positions change
    render: bool = False  # a render's evaluation (only the render side of the companion changes)
    data: object = None  # the mesh's `meshdata.MeshData` as `_prepare` read it (every full-path plan has it)


def evaluate_object(obj, ctx: Context, force: bool = False) -> bool:
    """Evaluates every DQ Skin modifier of `obj`, in stack order. With `ctx.batch`, the skinning
    of an object with one DQ Skin is queued there instead of run (see `run_batch`). Returns
    whether a result was written or queued."""
    obj_eval = obj.evaluated_get(ctx.depsgraph)
    wrote = False
    reaching = "mesh"  # mesh, dq (a live DQ Skin's output), other
    previous: ModifierState | None = None
    mods = dq_skin_modifiers(obj)
    batchable = ctx.batch is not None and len(mods) == 1
    for mod in obj.modifiers:
        enabled = mod.show_render if ctx.render else mod.show_viewport
        if not nodes.is_dq_skin(mod):
            if enabled:
                reaching = "other"
            continue
        st = state_of(obj, mod)
        if nodes.version_of(mod.node_group) != nodes.VERSION:
            _report(st, Mode.FALLBACK, "Made with an older DQ Skin: remove it and add it again")
            reaching = "other"
            continue
        source = {"mesh": "mesh", "dq": "chain"}.get(reaching, "capture")
        wrote |= _evaluate(obj, obj_eval, mod, st, ctx, source, previous, force, batchable)
        reaching = "dq" if st.status.live else "other"
        previous = st
    return wrote


def _report(st: ModifierState, mode: Mode, message: str = "") -> None:
    st.status.mode, st.status.message = mode, message
    st.output.invalidate()


def _evaluate(obj, obj_eval, mod, st: ModifierState, ctx: Context, source: str, previous, force: bool, batchable: bool) -> bool:
    start = time.perf_counter()
    st.status.source = source
    if obj.library is not None:
        lib = obj.library.filepath or obj.library.name
        _report(st, Mode.LINKED, f"Linked from {lib}: Blender's Armature modifier deforms it (make a Library Override to use DQ Skin)")
        return False
    s = None
    try:
        if batchable and not force:
            plan = _quick(obj, mod, st, ctx)
            if plan is None:
                return False
            if plan is not False:
                ctx.batch.append(plan)
                return True
        s = st.settings.value if st.settings.value is not None and obj.session_uid in ctx.unchanged else settings.cached(mod, st.settings)
        _follow_the_users_companion(obj, mod, st)
        deforms, reason = _where_it_deforms(obj, mod, st, s, ctx)
        if not (mod.show_render if ctx.render else mod.show_viewport):
            where = "renders" if ctx.render else "the viewport"
            return _step_aside(
                obj, mod, st, s, deforms, Mode.OFF, f"Off in {where}: Blender's Armature modifier deforms the mesh there", ctx.render
            )
        if reason:
            return _step_aside(obj, mod, st, s, deforms, Mode.HANDED_OVER, reason + _instead(s), ctx.render)
        plan = _prepare(obj, obj_eval, mod, st, s, ctx, source, previous, force, deforms, start)
        if plan is None:
            if st.companion.deforms != deforms:  # e.g. only the render toggle changed
                settle_companion(obj, mod, st, s, deforms, render=ctx.render)
            return False
        if batchable and not st.needs_effective:
            ctx.batch.append(plan)
            return True
        error = dqskin.skin_many([plan.job])[0]
        if error is not None:
            raise SkinError(error)
        finish(plan)
        return True
    except SkinError as e:
        return _fallback(obj, mod, st, s, str(e), ctx.render)
    except Exception as e:  # never a traceback in the user's face; say what happened
        return _fallback(obj, mod, st, s, f"{type(e).__name__}: {e}", ctx.render)


def _instead(s: settings.Settings) -> str:
    """What shows instead of a method Blender does not have."""
    if s.method in settings.BLENDER_METHODS:
        return ""
    return f" ({s.method.label} shows as Preserve Volume meanwhile)"


def _where_it_deforms(obj, mod, st: ModifierState, s: settings.Settings, ctx: Context) -> tuple[tuple[bool, bool], str]:
    """Where DQ Skin would deform ((viewport, render), as far as this evaluation can tell), and
    why it hands over in this evaluation ("" if it does not)."""
    reasons = consumers.reasons(obj, mod, s.armature, ctx.structure, exports.active())
    st.decided_structure = ctx.structure
    deforms = (mod.show_viewport and not reasons.viewport, mod.show_render and not reasons.render)
    return deforms, reasons.for_render(ctx.render)


def _follow_the_users_companion(obj, mod, st: ModifierState) -> None:
    """The user switched the companion on where DQ Skin deforms: they asked for Blender's
    deformation there, so DQ Skin switches off there (both would deform the mesh twice)."""
    known = st.companion
    if known.shown is None or known.deforms is None or exports.active():
        return
    c = _companion(obj, mod, st)
    if c is None:
        return
    now = companion.shown(c)
    for i, attr in enumerate(("show_viewport", "show_render")):
        if now[i] and not known.shown[i] and known.deforms[i] and getattr(mod, attr):
            setattr(mod, attr, False)


def _companion(obj, mod, st: ModifierState):
    c = obj.modifiers.get(st.companion.name) if st.companion.name else None
    if c is None or c.type != "ARMATURE":
        c = companion.find(obj, mod)
        if c is not None and _claimed_before(obj, mod, c):
            c = None  # a copy of a DQ Skin: the Armature modifier is its original's
        st.companion.name = c.name if c is not None else ""
    return c


def _claimed_before(obj, mod, c) -> bool:
    """Whether a DQ Skin earlier in the stack has `c` as its companion."""
    for other in obj.modifiers:
        if other == mod:
            return False
        if nodes.is_dq_skin(other) and nodes.version_of(other.node_group) == nodes.VERSION and companion.find(obj, other) == c:
            return True
    return False


def settle_companion(obj, mod, st: ModifierState, s, deforms: tuple[bool, bool], render: bool = False) -> None:
    """Switches the companion where DQ Skin's part changed since the last decision: off where
    DQ Skin now deforms, on where it now does not; elsewhere as the user left it. A render
    evaluation only touches the render side."""
    c = _companion(obj, mod, st)
    if c is None:
        return
    known = st.companion
    show = list(companion.shown(c))
    for i in range(2):
        if render and i == 0:
            continue
        if known.deforms is None or known.deforms[i] != deforms[i] or (deforms[i] and show[i]):
            show[i] = not deforms[i]
    if s is None:
        companion.configure_without_settings(c, mod)
        show = list(companion.shown(c))
    else:
        companion.configure(c, mod, s, tuple(show))
    merged = list(deforms)
    if render and known.deforms is not None:
        merged[0] = known.deforms[0]
    known.deforms, known.shown = tuple(merged), tuple(show)


def _step_aside(obj, mod, st: ModifierState, s, deforms, mode: Mode, message: str, render: bool) -> bool:
    """DQ Skin does not deform in this evaluation: the mesh passes through, the companion
    deforms (where the user has not switched it off)."""
    if obj.library is None:
        _pass_through(mod)
        settle_companion(obj, mod, st, s, deforms, render=render)
    _report(st, mode, message)
    if mode is Mode.OFF and not _companion(obj, mod, st):
        st.status.message = "Off: no Armature modifier after it, the mesh is not deformed"
    return False


def _pass_through(mod) -> None:
    result = nodes.get(mod, "Result")
    if results.is_result(result) and result.library is None:
        results.set_mode(result, nodes.RESULT_OFF)


def _fallback(obj, mod, st: ModifierState, s, message: str, render: bool = False) -> bool:
    """DQ Skin cannot deform: the input passes through and the companion deforms as Blender
    does; the panel shows why."""
    try:
        _pass_through(mod)
        if s is None:
            try:
                s = settings.read(mod)
            except Exception:  # a damaged modifier: the companion as it is
                s = None
        settle_companion(obj, mod, st, s, (False, False), render=render)
    except Exception as e:  # nothing of this may reach Blender's console
        message += f" (and the companion could not be set up: {type(e).__name__}: {e})"
    _report(st, Mode.FALLBACK, message)
    c = _companion(obj, mod, st) if obj.library is None else None
    st.status.instead = (
        f"Blender's Armature modifier '{c.name}' deforms the mesh instead"
        if c is not None
        else "No Armature modifier after it: the mesh is not deformed"
    )
    return False


# -- steady playback ----------------------------------------------------------------------------


def _quick(obj, mod, st: ModifierState, ctx: Context):
    """The steady state of playback, cheaply: a live DQ Skin on the mesh's own coordinates
    (no shape keys), plain vertex groups, nothing about the object, its armature or the scene's
    structure changed but the pose. Returns a plan, None (nothing to do), or False (take the
    full path)."""
    s = st.settings.value
    out = st.output
    if s is None or st.needs_effective or st.binding.binding is None or out.spaces is None or obj.session_uid not in ctx.unchanged:
        return False
    arm = s.armature
    try:
        if not _live_and_in_place(obj, st, arm, ctx):
            return False
        uid = arm.session_uid
        data = meshdata.peek(obj)
        if data is None or data.keys is not None:
            return False
        if out.kind == nodes.RESULT_REPLACE and (data.version != out.copied_version or meshdata.revision(obj.data) != out.copied_revision):
            return False
        deform = ctx.poses.get(uid)
        if deform is None:
            deform = ctx.poses[uid] = rig.pose_matrices(arm.evaluated_get(ctx.depsgraph))
    except ReferenceError:
        return False
    binding = st.binding.binding
    if len(binding.bone_indices) != len(deform):
        deform = deform[binding.bone_indices]
    raw = deform.tobytes()
    old = out.written
    if raw == old.pose:
        return None  # the pose did not change: the result is already this
    if s.method == dqskin.Method.CENTERS_OF_ROTATION and st.binding.centers is None:
        return False
    key = FrameKey(old.settings, old.source, raw, old.spaces, old.result, old.mesh_version)
    job = out.job  # the last full evaluation's: only the pose changed
    try:
        job.deform = deform
    except (AttributeError, TypeError, ValueError):
        return False  # the full path says what is wrong
    deforms = st.companion.deforms or (True, True)
    return Plan(obj, mod, st, s, out.result, out.kind, key, job, deforms, time.perf_counter(), quick=True, render=ctx.render)


def _live_and_in_place(obj, st: ModifierState, arm, ctx: Context) -> bool:
    """What both ways past the full path (`_quick`, `fed_frame_stands`) need: a live DQ Skin on
    the mesh's own coordinates with a result written, the scene's structure as last decided, no
    export running, neither the object nor its armature moved, the armature not in Edit Mode."""
    out = st.output
    return (
        st.status.mode is Mode.LIVE
        and st.status.source == "mesh"
        and out.result is not None
        and out.written is not None
        and st.decided_structure == ctx.structure
        and obj.session_uid in ctx.unmoved
        and not exports.active()
        and arm is not None
        and arm.session_uid in ctx.unmoved
        and arm.mode != "EDIT"
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
    st = state_of(obj, mod)
    out = st.output
    if out.kind != nodes.RESULT_REPLACE or not mod.show_viewport or out.result is None or not feed.skinned_now(out.result, ctx.depsgraph):
        return False
    s = settings.cached(mod, st.settings)
    try:
        if not _live_and_in_place(obj, st, s.armature, ctx) or s.key() != out.written.settings:
            return False
    except ReferenceError:  # (the armature was deleted: the full path says so)
        return False
    data = meshdata.get(obj)  # (compares the vertex group names)
    if data.keys is not None or (data.version, meshdata.revision(obj.data)) != out.written.mesh_version:
        return False
    _follow_the_users_companion(obj, mod, st)
    return mod.show_viewport


def run_batch(plans: list) -> None:
    """Skins every queued plan in one call (in parallel across objects) and writes the results."""
    if not plans:
        return
    errors = dqskin.skin_many([p.job for p in plans])  # jobs were checked when built (`_job`)
    for plan, error in zip(plans, errors):
        try:
            if error is not None:
                raise SkinError(error)
            finish(plan)
        except Exception as e:
            message = str(e) if isinstance(e, SkinError) else f"{type(e).__name__}: {e}"
            # Steady playback plans carry no modifier (an object with one DQ Skin).
            mod = plan.mod or next(iter(dq_skin_modifiers(plan.obj)), None)
            if mod is not None:
                _fallback(plan.obj, mod, plan.st, plan.s, message, plan.render)


# -- the full path ------------------------------------------------------------------------------


def _prepare(
    obj, obj_eval, mod, st: ModifierState, s: settings.Settings, ctx: Context, source, previous, force, deforms, start
) -> Plan | None:
    """Everything before the kernel: checks, what reaches the modifier, influences, this frame's
    matrices; None when the result is already this."""
    arm = s.armature
    if arm is None:
        raise SkinError("No armature object set")
    if arm.type != "ARMATURE":
        raise SkinError(f"'{arm.name}' is not an armature")
    if obj.mode == "EDIT" or obj.data.is_editmode:
        raise SkinError("The mesh is in Edit Mode")
    data = meshdata.get(obj)
    if data.vertex_count == 0:
        raise SkinError("The mesh has no vertices")
    arm_eval = arm.evaluated_get(ctx.depsgraph)
    if arm_eval.pose is None:
        raise SkinError(f"The armature '{arm.name}' has no pose")

    # What reaches the modifier.
    if source == "mesh":
        try:
            positions, input_key = _mesh_input(obj, obj_eval, st, data, ctx.depsgraph)
        except _CaptureNeeded:
            source = st.status.source = "capture"
    if source == "capture":
        positions, input_key = _captured(obj, obj_eval, mod, st, data, ctx)
    elif source == "chain":
        out = previous.output if previous is not None else None
        if out is None or out.buffer is None or len(out.buffer) != data.vertex_count:
            raise SkinError("The DQ Skin modifier before this one has no result")
        positions, input_key = out.buffer, ("chain", id(previous), out.generation)
    if source != "capture" and st.capture_on is not False:
        _set_capture(mod, False)
        st.capture_on = False

    binding = _binding(obj, arm, arm_eval, st, s, data, ctx)
    if len(positions) != binding.vertex_count:
        raise SkinError(
            f"An earlier modifier changed the vertex count ({binding.vertex_count} → {len(positions)}); "
            "put DQ Skin before modifiers that add or remove vertices"
        )
    if st.needs_effective:
        bones = pose.frame(arm_eval, binding, st.binding.segments, ctx.pose_data)  # with every B-Bone's joints
        pose_key = bones.key
    else:
        deform = ctx.poses.get(arm.session_uid)
        if deform is None:
            deform = ctx.poses[arm.session_uid] = rig.pose_matrices(arm_eval)
        if len(binding.bone_indices) != len(deform):
            deform = deform[binding.bone_indices]
        pose_key = deform.tobytes()
    out = st.output
    if out.spaces is None or not (obj.session_uid in ctx.unmoved and arm.session_uid in ctx.unmoved):
        out.spaces = rig.spaces(obj_eval, arm_eval)
    premat, postmat = out.spaces
    by_index = consumers.index_readers(obj, ctx.structure)
    kind = nodes.RESULT_POSITIONS if source == "capture" or by_index else nodes.RESULT_REPLACE
    result = _own_result(obj, mod, st)
    key = FrameKey(s.key(), input_key, pose_key, premat.tobytes(), result.session_uid, (data.version, meshdata.revision(obj.data)))
    if not force and key == out.written and st.status.live and results.mode_of(result) == kind:
        return None  # the result is already this
    if out.buffer is None or len(out.buffer) != binding.vertex_count:
        out.buffer = np.empty((binding.vertex_count, 3), np.float32)
    influences, rest = binding.influences, binding.rest
    if st.needs_effective:
        # Envelopes and B-Bone segments depend on where the vertices are: this frame's
        # influences, over the bones followed by the B-Bones' segment joints.
        cache = st.binding
        influences = pose.influences(
            bones, binding, arm_eval, positions, input_key, premat, s.use_vertex_groups, s.use_envelopes, cache.envelopes, cache.segments
        )
        deform, rest = bones.deform, bones.rest
    job = out.job = _job(st, s, positions, influences, deform, rest, premat, postmat)
    return Plan(obj, mod, st, s, result, kind, key, job, deforms, start, render=ctx.render, data=data)


def _binding(obj, arm, arm_eval, st: ModifierState, s: settings.Settings, data, ctx: Context):
    """The influences of this mesh on this armature, kept while what they depend on holds
    (the armature's bones are compared on every full evaluation, whatever changed them: from
    Blender's memory, see `pose.armature_signature`)."""
    cache = st.binding
    key = BindingKey(
        data.uid,
        data.version,
        arm.session_uid,
        pose.armature_signature(arm_eval, ctx.pose_data),
        s.mask_group,
        s.invert_mask,
        s.blend_group,
        s.use_vertex_groups,
    )
    if cache.binding is None or cache.key != key:
        cache.clear()
        binding = rig.bind(obj, arm, s.mask_group, s.invert_mask, s.use_vertex_groups, data=data)
        cache.binding = binding
        cache.envelopes = rig.envelopes(arm, binding)
        cache.blend = data.group_weights(s.blend_group) if s.blend_group else None
        cache.segments = rig.bbone_segments(arm, binding)
        cache.uses_envelopes = bool(cache.envelopes[:, 10].any())
        cache.uses_bbones = bool(cache.segments.max(initial=0) > 1)
        cache.key = key
        st.output.invalidate()
    st.needs_effective = s.use_envelopes or cache.uses_envelopes or cache.uses_bbones
    if s.method == dqskin.Method.CENTERS_OF_ROTATION:
        _centers(obj, st, data, cache.binding, ctx)
    return cache.binding


def _job(st: ModifierState, s: settings.Settings, positions, influences, deform, rest, premat, postmat) -> dqskin.SkinJob:
    """The `dqskin.SkinJob` of one modifier: its settings, kept data and output (checked here:
    a bad input, a bone scaled to NaN say, is this modifier's error, shown on its panel)."""
    method = s.method
    try:
        return dqskin.SkinJob(
            positions,
            influences,
            np.ascontiguousarray(deform),
            rest,
            method=method,
            premat=premat,
            postmat=postmat,
            mask=st.binding.binding.mask,
            blend=st.binding.blend if method == dqskin.Method.BLEND else None,
            blend_factor=s.blend_factor,
            out=st.output.buffer,
            centers=st.binding.centers if method == dqskin.Method.CENTERS_OF_ROTATION else None,
        )
    except (TypeError, ValueError) as e:
        raise SkinError(str(e)) from None


def _centers(obj, st: ModifierState, data, binding, ctx: Context) -> None:
    """Puts the Optimized Centers of Rotation for this binding in `st.binding.centers`: kept,
    found in the cache, computed now (small meshes, command line, renders), or started in the
    background (the SkinError that says so lets Blender's deformation stand in until they are
    ready)."""
    if st.needs_effective:
        raise SkinError("Optimized Centers works with vertex groups only, not with envelopes or B-Bones: choose another method")
    if st.binding.centers is not None:
        return
    triangles = centers.triangles_of(obj.data)
    key = centers.key_of(data.positions, triangles, binding.influences)
    got = centers.lookup(key, data.vertex_count)
    if got is None:
        job = centers.job_of(key)
        if job is not None and job.finished and job.error:
            raise SkinError(f"Optimized Centers: {job.error} (change the method or any setting to try again)")
        if data.vertex_count <= centers.INLINE_VERTICES or centers.in_background() or ctx.render:
            label = f"Optimized Centers for {obj.name} ({data.vertex_count} vertices)" if centers.in_background() else ""
            try:
                got = centers.compute(data.positions, triangles, binding.influences, key, label=label)
            except centers.Cancelled:
                raise SkinError("Optimized Centers: cancelled") from None
        else:
            job = centers.start(data.positions, triangles, binding.influences, key, obj.name)
            raise SkinError(
                f"Optimized Centers: computing for {data.vertex_count} vertices ({job.fraction:.0%}); "
                "Blender's deformation shows until they are ready"
            )
    st.binding.centers = got


def finish(plan: Plan) -> None:
    """Writes the result, then switches the companion off where DQ Skin deforms (in this order,
    so that no evaluation sees both or neither)."""
    obj, mod, st, result, kind = plan.obj, plan.mod, plan.st, plan.result, plan.kind
    out = st.output
    out.generation += 1
    if plan.quick:
        results.write_positions(result, out.buffer)
        out.written = plan.key
        st.status.seconds = time.perf_counter() - plan.start
        return
    data = plan.data
    if kind == nodes.RESULT_REPLACE:
        mesh = result.data
        revision = meshdata.revision(obj.data)
        if (
            out.copied_version != data.version
            or out.copied_revision != revision
            or (len(mesh.vertices), len(mesh.edges), len(mesh.polygons), len(mesh.loops)) != data.counts
        ):
            # Everything but the positions comes from the mesh (materials, UV maps, colors...).
            results.copy_mesh(result, obj.data)
            out.copied_version, out.copied_revision = data.version, revision
    else:
        results.points_mesh(result, len(out.buffer))
        out.copied_version = 0
    results.write_positions(result, out.buffer)
    results.set_mode(result, kind)
    out.result, out.kind, out.written = result, kind, plan.key
    if _feedable(plan, kind, data):
        feed.ensure(result, st, plan.s.armature, st.binding.binding, out.buffer)
    elif feed.fed(result) is not None:
        feed.remove(result)
    settle_companion(obj, mod, st, plan.s, plan.deforms, render=plan.render)
    binding = st.binding.binding
    status = st.status
    status.mode, status.message = Mode.LIVE, ""
    status.notes = tuple(consumers.notes(obj, mod))
    status.method = plan.s.method.label
    status.bones = len(binding.bone_names)
    status.influences = len(binding.influences)
    status.seconds = time.perf_counter() - plan.start


def _feedable(plan: Plan, kind: int, data) -> bool:
    """Whether the result can be skinned inside Blender's first evaluation (see `feed`): a
    whole-mesh result of the mesh itself (no shape keys), its frames' bones read from memory
    (envelopes, B-Bones), in the viewport, and worth it (`feeds_faster`)."""
    st = plan.st
    return (
        kind == nodes.RESULT_REPLACE
        and st.needs_effective
        and st.status.source == "mesh"
        and data.keys is None
        and not plan.render
        and isinstance(plan.key.pose, tuple)
        and plan.key.pose[:1] == ("memory",)
        and feeds_faster(data.vertex_count, plan.s.armature)
    )


def feeds_faster(vertices: int, armature) -> bool:
    """Whether the feed is expected to beat the frame handler's route for a mesh of `vertices`
    on `armature` (see FEED_VERTICES_PER_BONE)."""
    return vertices <= FEED_VERTICES_PER_BONE * len(armature.data.bones)


# -- what reaches the modifier ------------------------------------------------------------------


class _CaptureNeeded(SkinError):
    """Shape keys DQ Skin cannot mix itself: it reads what reaches it from the evaluation."""


def _mesh_input(obj, obj_eval, st: ModifierState, data, depsgraph):
    """The mesh's coordinates with its shape keys mixed, and a key that changes with them."""
    keys = data.keys
    if keys is None:
        return data.positions, ("mesh", data.version)
    if not keys.relative:
        raise _CaptureNeeded("absolute shape keys")
    key_eval = obj.data.shape_keys.evaluated_get(depsgraph)
    blocks = key_eval.key_blocks
    if len(blocks) != len(keys.data):
        raise _CaptureNeeded("shape keys changing")
    values = np.empty(len(blocks), np.float32)
    blocks.foreach_get("value", values)
    mutes = np.empty(len(blocks), bool)
    blocks.foreach_get("mute", mutes)
    shown = obj_eval.active_shape_key_index if obj_eval.show_only_shape_key else None
    input_key = ("keys", data.version, values.tobytes(), mutes.tobytes(), shown)
    out = st.output
    if out.mixed is not None and out.mixed_key == input_key:
        return out.mixed, input_key
    if out.mixed is None or len(out.mixed) != data.vertex_count:
        out.mixed = np.empty((data.vertex_count, 3), np.float32)
    blocks_in = [
        (
            keys.data[i],
            keys.relative_to[i],
            float(values[i]),
            bool(mutes[i]),
            data.group_weights(keys.vertex_groups[i]) if keys.vertex_groups[i] and data.groups is not None else None,
        )
        for i in range(len(keys.data))
    ]
    try:
        dqskin.shape_key_mix(blocks_in, keys.reference, out.mixed, shown)
    except ValueError as e:
        raise _CaptureNeeded(str(e)) from None
    out.mixed_key = input_key
    return out.mixed, input_key


def _set_capture(mod, on: bool) -> None:
    """Stores the incoming positions (or not) in the node group."""
    if bool(nodes.get(mod, "Capture")) != on:
        nodes.put(mod, "Capture", on)
    if on:
        nodes.put(mod, "Capture Name", capture_name(mod))


def prepare_capture(obj) -> None:
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
                st = state_of(obj, mod)
                if st.capture_on is not True:
                    _set_capture(mod, True)
                    _pass_through(mod)  # a replacing result would hide what the group stores
                    st.capture_on = True
        elif mod.show_viewport or mod.show_render:
            others = True


def capture_name(mod) -> str:
    return f"dq_skin_input_{compat.modifier_uid(mod)}"


def _captured(obj, obj_eval, mod, st: ModifierState, data, ctx: Context):
    _set_capture(mod, True)
    st.capture_on = True
    name = capture_name(mod)
    mesh = obj_eval.data
    attribute = mesh.attributes.get(name) if mesh is not None else None
    if attribute is None:
        raise SkinError("Waiting for the modifier to be evaluated (modifiers before DQ Skin)")
    count = len(attribute.data)
    if count != data.vertex_count:
        mods = list(obj.modifiers)
        at = mods.index(mod)
        earlier = [m.name for m in mods[:at] if m.show_viewport and m.type not in KEEP_VERTEX_COUNT]
        if earlier:
            raise SkinError(
                f"An earlier modifier changed the vertex count ({data.vertex_count} → {count}): "
                f"put DQ Skin before {', '.join(earlier)}, which add or remove vertices"
            )
        later = [m.name for m in mods[at + 1 :] if m.show_viewport and m.type not in KEEP_VERTEX_COUNT]
        raise SkinError(
            f"Modifiers before DQ Skin deform the mesh, so it reads the coordinates reaching it from "
            f"the evaluated mesh, but {', '.join(later) or 'a later modifier'} changes the vertex count "
            f"({data.vertex_count} → {count}); move them before DQ Skin's modifiers or apply them"
        )
    positions = np.empty(count * 3, np.float32)
    attribute.data.foreach_get("vector", positions)
    positions = positions.reshape(-1, 3)
    return positions, ("capture", positions.tobytes())


# -- the result object --------------------------------------------------------------------------


def _own_result(obj, mod, st: ModifierState):
    """This modifier's result object: the one it wrote last, or the one its node group points at
    if that is its own (a copied modifier points at another's), else a new one. The node group
    is made to point at it."""
    result = st.output.result
    try:
        if result is not None and not results.owned_by(result, obj, mod):
            result = None
    except ReferenceError:
        result = None
    if result is None:
        pointed = nodes.get(mod, "Result")
        result = pointed if results.owned_by(pointed, obj, mod) else results.create(obj, mod)
        st.output.result = result
    if nodes.get(mod, "Result") != result:
        nodes.put(mod, "Result", result)
    return result


def switch_off(obj, mod) -> None:
    """DQ Skin and its companion both off, as the user would switch off an Armature modifier
    (a cache plays in their place, see `bake`)."""
    mod.show_viewport = mod.show_render = False
    st = state_of(obj, mod)
    c = _companion(obj, mod, st)
    if c is not None:
        companion.configure(c, mod, settings.cached(mod, st.settings), (False, False))
    st.companion.deforms = st.companion.shown = (False, False)


# -- files ----------------------------------------------------------------------------------------


def deactivate(obj, mod, detach: bool) -> None:
    """The state files are saved in: the companion on wherever DQ Skin is on, set up like it, no
    result (detached with `detach`)."""
    if obj.library is not None:
        return
    try:
        s = settings.read(mod)
    except Exception:
        s = None
    c = companion.find(obj, mod)
    if c is not None:
        if s is not None:
            companion.configure(c, mod, s, (mod.show_viewport, mod.show_render))
        else:
            companion.configure_without_settings(c, mod)
    _pass_through(mod)
    if detach and nodes.get(mod, "Result") is not None:
        nodes.put(mod, "Result", None)
    st = STATES.find(obj.session_uid, compat.modifier_uid(mod))
    if st is not None:
        st.output.invalidate()


def reactivate(obj, mod) -> None:
    """After a save: back to how it was before `deactivate` (the next evaluation writes again)."""
    st = STATES.find(obj.session_uid, compat.modifier_uid(mod))
    if st is None or obj.library is not None:
        return
    if st.output.result is not None:
        try:
            nodes.put(mod, "Result", st.output.result)
        except ReferenceError:
            st.output.result = None
    c = _companion(obj, mod, st)
    known = st.companion
    if c is not None and known.shown is not None and st.settings.value is not None:
        companion.configure(c, mod, st.settings.value, known.shown)
    st.output.invalidate()

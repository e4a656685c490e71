# SPDX-License-Identifier: GPL-3.0-or-later
"""Evaluating the DQ Skin modifiers of one object: what reaches each, skinning it, writing the
result, or falling back to Blender's own deformation with the reason on the modifier.

What reaches a DQ Skin modifier (its *source*):
- ``mesh``: nothing enabled before it: the mesh's coordinates with its shape keys mixed as
  Blender mixes them (computed here, so the modifier needs no evaluation of its own first);
- ``chain``: only other live DQ Skin modifiers before it: the previous one's output;
- ``capture``: other modifiers before it: the coordinates the node group stored on its way
  through, read from the evaluated mesh (which needs the modifiers after it to keep the vertex
  count, else the companion takes over and the panel says why).

For ``mesh`` and ``chain`` the result is a full copy of the mesh with skinned positions, output
as is by the node group; for ``capture`` it is points whose positions the node group sets.
Everything that does not change between frames is cached: mesh data per mesh (`meshdata`),
influences per mesh version, armature and settings. Nothing is recomputed or written when
nothing changed, which also keeps Blender's update loop from cycling.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import bpy
import numpy as np

from . import centers, companion, compat, dqskin, meshdata, nodes, pose, results, rig


class SkinError(Exception):
    """A problem the user can fix, shown in the panel and operator reports."""


@dataclass
class Settings:
    armature: object
    method: str
    blend_group: str
    blend_factor: float
    use_vertex_groups: bool
    use_envelopes: bool
    mask_group: str
    invert_mask: bool

    def key(self) -> tuple:
        arm = self.armature.session_uid if self.armature is not None else 0
        return (arm, self.method, self.blend_group, self.blend_factor, self.use_vertex_groups, self.use_envelopes, self.mask_group, self.invert_mask)


def settings(mod) -> Settings:
    return Settings(
        armature=nodes.get(mod, "Armature"),
        method=nodes.METHOD_KEYS[nodes.get_method(mod)],
        blend_group=nodes.get_attribute(mod, "Blend Amount"),
        blend_factor=float(nodes.get(mod, "Blend Factor")),
        use_vertex_groups=bool(nodes.get(mod, "Use Vertex Groups")),
        use_envelopes=bool(nodes.get(mod, "Use Envelopes")),
        mask_group=nodes.get_attribute(mod, "Mask"),
        invert_mask=bool(nodes.get(mod, "Invert Mask")),
    )


def _settings(mod, st: "State") -> Settings:
    """`settings(mod)`, rebuilt only when the modifier's raw values changed (they can be keyed,
    so they are read on every evaluation)."""
    raw = nodes.raw_settings(mod)
    if st.settings is None or raw != st.raw_settings:
        st.settings = settings(mod)
        st.raw_settings = raw
    return st.settings


LIVE = ("replace", "positions")

# Modifiers that never add or remove vertices.
KEEP_VERTEX_COUNT = {
    "ARMATURE", "CAST", "CLOTH", "COLLISION", "CORRECTIVE_SMOOTH", "CURVE", "DATA_TRANSFER", "DISPLACE",
    "HOOK", "LAPLACIANDEFORM", "LAPLACIANSMOOTH", "LATTICE", "MESH_DEFORM", "NORMAL_EDIT", "SHRINKWRAP",
    "SIMPLE_DEFORM", "SMOOTH", "SOFT_BODY", "SURFACE_DEFORM", "UV_PROJECT", "UV_WARP", "VERTEX_WEIGHT_EDIT",
    "VERTEX_WEIGHT_MIX", "VERTEX_WEIGHT_PROXIMITY", "WARP", "WAVE", "WEIGHTED_NORMAL", "MESH_CACHE",
}


@dataclass
class State:
    """What the add-on knows about one DQ Skin modifier between evaluations."""

    mode: str = ""  # replace, positions, fallback, linked, off, or "" before the first evaluation
    source: str = ""
    status: str = ""
    error: str = ""
    seconds: float = 0.0
    binding: rig.Binding | None = None
    binding_key: tuple = ()
    blend: np.ndarray | None = field(default=None, repr=False)
    envelopes: np.ndarray | None = field(default=None, repr=False)
    out: np.ndarray | None = field(default=None, repr=False)
    mixed: np.ndarray | None = field(default=None, repr=False)
    signature: tuple | None = field(default=None, repr=False)
    generation: int = 0  # counts the outputs computed (a following DQ Skin's input signature)
    result_version: int = 0  # mesh version the replace-mode result was copied from
    armature_signature: tuple | None = field(default=None, repr=False)
    check_armature: bool = True
    result: object = field(default=None, repr=False)  # the result object last written
    settings: Settings | None = field(default=None, repr=False)
    raw_settings: tuple = ()
    companion: str = ""  # name of the companion Armature modifier, once found
    needs_effective: bool = False  # envelopes or B-Bones: influences change with the pose
    segments: np.ndarray | None = field(default=None, repr=False)
    uses_envelopes: bool = False
    uses_bbones: bool = False
    spaces: tuple | None = field(default=None, repr=False)  # (premat, postmat) last computed
    capture_on: bool | None = None
    parked: bool = False  # the companion was parked by the last write
    method: str = ""
    centers: np.ndarray | None = field(default=None, repr=False)  # Optimized Centers, for binding_key
    centers_key: tuple = ()

    def describe(self) -> str:
        """The panel's status line."""
        if self.status or not self.live or self.binding is None:
            return self.status
        method = {v: k for k, v in nodes.METHOD_KEYS.items()}.get(self.method, self.method)
        line = f"{method}: {len(self.binding.bone_names)} bones, {len(self.binding.influences)} influences, {self.seconds * 1e3:.1f} ms"
        if not self.companion:
            line += " · no Armature modifier after it for Blender without DQ Skin"
        return line

    @property
    def live(self) -> bool:
        return self.mode in LIVE


_states: dict[tuple, State] = {}


def state(obj, mod) -> State:
    return _states.setdefault((obj.session_uid, compat.modifier_uid(mod)), State())


def drop_state(key: tuple) -> None:
    _states.pop(key, None)


def forget(obj_names=None) -> None:
    """Drops cached bindings (all, or those of the named objects), e.g. after a load."""
    if obj_names is None:
        _states.clear()
        meshdata.forget()
        return
    uids = {o.session_uid for o in bpy.data.objects if o.name_full in obj_names}
    for key in [k for k in _states if k[0] in uids]:
        del _states[key]


def dq_skin_modifiers(obj):
    return [m for m in obj.modifiers if nodes.is_dq_skin(m)] if obj.type == "MESH" else []


# -- one object ---------------------------------------------------------------------------------

@dataclass
class Plan:
    """One skinning to run: the kernel's inputs and where its result goes."""

    obj: object
    mod: object
    st: "State"
    s: Settings
    result: object
    mode: int
    signature: tuple
    job: tuple  # the arguments of `dqskin.skin_many`
    start: float
    quick: bool = False  # steady playback: only the positions change


@dataclass
class Context:
    """What one handler call shares between objects."""

    depsgraph: object
    claimed: dict
    batch: list | None = None  # plans to run together (see `Registry.frame`)
    unchanged: set = field(default_factory=set)  # objects Blender did not update: cached settings hold
    unmoved: set = field(default_factory=set)  # objects whose transform did not change
    poses: dict = field(default_factory=dict)  # armature uid -> this evaluation's pose matrices


def evaluate_object(obj, depsgraph, claimed: dict, force: bool = False, ctx: Context | None = None) -> bool:
    """Evaluates every DQ Skin modifier of `obj` for `depsgraph`, in stack order. `claimed`:
    result object uid -> owner key, shared by all objects (see `results`). With `ctx.batch`, the
    skinning of an object with one DQ Skin is queued there instead of run (see `run_batch`).
    Returns whether a result was written or queued (the object will be evaluated again)."""
    ctx = ctx or Context(depsgraph, claimed)
    render = depsgraph.mode == "RENDER"
    obj_eval = obj.evaluated_get(depsgraph)
    wrote = False
    what_reaches = "mesh"  # mesh, dq (a live DQ Skin's output), other
    previous: State | None = None
    mods = [m for m in obj.modifiers if nodes.is_dq_skin(m)]
    batchable = ctx.batch is not None and len(mods) == 1
    for mod in obj.modifiers:
        enabled = mod.show_render if render else mod.show_viewport
        if not nodes.is_dq_skin(mod):
            if enabled:
                what_reaches = "other"
            continue
        st = state(obj, mod)
        if not enabled:
            _off(obj, mod, st, render)
            continue
        source = {"mesh": "mesh", "dq": "chain"}.get(what_reaches, "capture")
        if nodes.version_of(mod.node_group) != nodes.VERSION:
            _note(st, "fallback", "Made with an older DQ Skin: remove it and add it again")
            what_reaches = "other"
            continue
        wrote |= _evaluate(obj, obj_eval, mod, st, ctx, source, previous, force, batchable)
        what_reaches = "dq" if st.live else "other"
        previous = st
    return wrote


def _note(st: State, mode: str, message: str = "", status: str = "") -> None:
    st.mode, st.error, st.status, st.signature, st.parked = mode, message, status, None, False


def _off(obj, mod, st: State, render: bool) -> None:
    """DQ Skin switched off (for this kind of evaluation): nothing to compute; the companion
    stays out of the way, as an Armature modifier switched off would not deform either."""
    other = mod.show_viewport if render else mod.show_render
    where = "renders" if render else "the viewport"
    status = f"Off in {where}" + (" (on in the other: skinned there)" if other else "")
    _note(st, "off", status=status)
    if obj.library is None:
        c = companion.find(obj, mod)
        if c is not None:
            companion.park(c)


def _evaluate(obj, obj_eval, mod, st: State, ctx: Context, source: str, previous: State | None, force: bool, batchable: bool) -> bool:
    start = time.perf_counter()
    st.source = source
    if obj.library is not None:
        lib = obj.library.filepath or obj.library.name
        _note(st, "linked", status=f"Linked from {lib}: Blender's Armature modifier deforms it (make a Library Override to use DQ Skin)")
        return False
    s = None
    try:
        plan = _quick(obj, mod, st, ctx, source) if batchable and not force else False
        if plan is None:
            return False
        if plan is not False:
            ctx.batch.append(plan)
            return True
        if st.settings is not None and obj.session_uid in ctx.unchanged:
            s = st.settings
        else:
            s = _settings(mod, st)
        plan = _prepare(obj, obj_eval, mod, st, s, ctx, source, previous, force, start)
        if plan is None:
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
        return _fallback(obj, mod, st, s, str(e))
    except Exception as e:  # never a traceback in the user's face; say what happened
        return _fallback(obj, mod, st, s, f"{type(e).__name__}: {e}")


def _quick(obj, mod, st: State, ctx: Context, source: str):
    """The steady state of playback, cheaply: a live DQ Skin on the mesh's own coordinates
    (no shape keys), plain vertex groups, nothing about the object or its armature changed but
    the pose. Returns a plan, None (nothing to do), or False (take the full path)."""
    s = st.settings
    if (
        s is None
        or st.mode != "replace"
        or source != "mesh"
        or st.needs_effective
        or st.binding is None
        or st.result is None
        or st.spaces is None
        or st.signature is None
        or obj.session_uid not in ctx.unchanged
        or obj.session_uid not in ctx.unmoved
    ):
        return False
    arm = s.armature
    try:
        uid = arm.session_uid
        if uid not in ctx.unmoved or arm.mode == "EDIT":
            return False
        data = meshdata.peek(obj)
        if data is None or data.keys is not None or data.version != st.result_version:
            return False
        deform = ctx.poses.get(uid)
        if deform is None:
            deform = ctx.poses[uid] = rig.pose_matrices(arm.evaluated_get(ctx.depsgraph))
    except ReferenceError:
        return False
    binding = st.binding
    if len(binding.bone_indices) != len(deform):
        deform = deform[binding.bone_indices]
    raw = deform.tobytes()
    old = st.signature
    if raw == old[2]:
        return None  # the pose did not change: the result is already this
    premat, postmat = st.spaces
    signature = (old[0], old[1], raw) + old[3:]
    if s.method == "centers_of_rotation" and (st.centers is None or st.centers_key != st.binding_key):
        return False
    job = _job(st, s, data.positions, binding.influences, deform, binding.rest, premat, postmat)
    return Plan(obj, mod, st, s, st.result, nodes.RESULT_REPLACE, signature, job, time.perf_counter(), quick=True)


def run_batch(plans: list) -> None:
    """Skins every queued plan in one call (in parallel across objects) and writes the results."""
    if not plans:
        return
    errors = dqskin.skin_many([p.job for p in plans])
    for plan, error in zip(plans, errors):
        try:
            if error is not None:
                raise SkinError(error)
            finish(plan)
        except SkinError as e:
            _fallback(plan.obj, plan.mod, plan.st, plan.s, str(e))
        except Exception as e:
            _fallback(plan.obj, plan.mod, plan.st, plan.s, f"{type(e).__name__}: {e}")


def _prepare(obj, obj_eval, mod, st: State, s: Settings, ctx: Context, source, previous, force, start) -> Plan | None:
    """Everything before the kernel: checks, what reaches the modifier, influences, this frame's
    matrices; None when the result is already this."""
    arm = s.armature
    if arm is None or arm.type != "ARMATURE":
        raise SkinError("No armature object set")
    if arm.mode == "EDIT" or arm.data.is_editmode:
        raise SkinError(f"Armature {arm.name} is in Edit Mode")
    if obj.mode == "EDIT":
        raise SkinError(f"{obj.name} is in Edit Mode: DQ Skin resumes in Object Mode")
    depsgraph = ctx.depsgraph
    data = meshdata.get(obj)
    if data.vertex_count == 0:
        raise SkinError(f"{obj.name}'s mesh has no vertices: nothing to skin")
    arm_eval = arm.evaluated_get(depsgraph)

    # What reaches the modifier.
    if source == "mesh":
        try:
            positions, input_key = _mesh_input(obj, obj_eval, mod, st, data, depsgraph)
        except _CaptureNeeded:
            source = st.source = "capture"  # keys DQ Skin cannot mix: read Blender's
    if source == "capture":
        positions, input_key = _captured(obj, obj_eval, mod, data)
    elif source == "chain":
        if previous is None or previous.out is None or len(previous.out) != data.vertex_count:
            raise SkinError("The DQ Skin modifier before this one has no result")
        positions, input_key = previous.out, ("chain", id(previous), previous.generation)
    if source != "capture" and st.capture_on is not False:
        _set_capture(mod, False)
        st.capture_on = False

    # What does not change between frames.
    if st.check_armature or st.armature_signature is None:
        st.armature_signature = pose.armature_signature(arm_eval)
        st.check_armature = False
    key = (data.uid, data.version, arm.session_uid, st.armature_signature, s.mask_group, s.invert_mask, s.blend_group, s.use_vertex_groups)
    if st.binding is None or st.binding_key != key:
        st.binding = rig.bind(obj, arm, s.mask_group, s.invert_mask, s.use_vertex_groups, data=data)
        st.envelopes = rig.envelopes(arm, st.binding)
        st.blend = data.group_weights(s.blend_group) if s.blend_group else None
        st.binding_key = key
        st.signature = None
        st.centers = None
        st.segments = rig.bbone_segments(arm, st.binding)
        st.uses_envelopes = bool(st.envelopes[:, 10].any())
        st.uses_bbones = bool(st.segments.max(initial=0) > 1)
    st.needs_effective = s.use_envelopes or st.uses_envelopes or st.uses_bbones
    binding = st.binding
    if s.method == "centers_of_rotation":
        _centers(obj, st, data, binding, ctx)  # kept in st.centers
    if len(positions) != binding.vertex_count:
        raise SkinError(
            f"An earlier modifier changed the vertex count ({binding.vertex_count} → {len(positions)}); "
            "put DQ Skin before modifiers that add or remove vertices"
        )
    if st.needs_effective:
        bones = pose.frame(arm_eval, binding, st.segments)  # with every B-Bone's joints
        pose_key = bones.key
    else:
        deform = ctx.poses.get(arm.session_uid)
        if deform is None:
            deform = ctx.poses[arm.session_uid] = rig.pose_matrices(arm_eval)
        if len(binding.bone_indices) != len(deform):
            deform = deform[binding.bone_indices]
        pose_key = deform.tobytes()
    if st.spaces is None or not (obj.session_uid in ctx.unmoved and arm.session_uid in ctx.unmoved):
        st.spaces = rig.spaces(obj_eval, arm_eval)
    premat, postmat = st.spaces
    mode = nodes.RESULT_POSITIONS if source == "capture" else nodes.RESULT_REPLACE
    result = st.result if st.result is not None and _still(st.result, mod, ctx.claimed) else _own_result(obj, mod, ctx.claimed)
    signature = (s.key(), input_key, pose_key, premat.tobytes(), result.session_uid, data.version)
    current = results.mode_of(result)
    if not force and signature == st.signature and st.live and current == mode:
        return None  # the result is already this
    if st.out is None or len(st.out) != binding.vertex_count:
        st.out = np.empty((binding.vertex_count, 3), np.float32)
    influences, rest = binding.influences, binding.rest
    if st.needs_effective:
        # Envelopes and B-Bone segments depend on where the vertices are: this frame's
        # influences, over the bones followed by the B-Bones' segment joints.
        influences = pose.influences(
            bones, binding, arm_eval, positions, input_key, premat, s.use_vertex_groups, s.use_envelopes, st.envelopes, st.segments
        )
        deform, rest = bones.deform, bones.rest
    job = _job(st, s, positions, influences, deform, rest, premat, postmat)
    return Plan(obj, mod, st, s, result, mode, signature, job, start)


def _job(st: State, s: Settings, positions, influences, deform, rest, premat, postmat) -> tuple:
    """The arguments of `dqskin.skin_many` for one modifier: its settings, kept data and output."""
    return (
        positions,
        influences,
        np.ascontiguousarray(deform),
        rest,
        s.method,
        premat,
        postmat,
        st.binding.mask,
        st.blend if s.method == "blend" else None,
        s.blend_factor,
        st.out,
        st.centers if s.method == "centers_of_rotation" else None,
    )


def _centers(obj, st: State, data, binding, ctx: Context) -> None:
    """Puts the Optimized Centers of Rotation for this binding in `st.centers`: kept, found in the
    cache, computed now (small meshes, command line, renders), or started in the background (the
    SkinError that says so lets Blender's deformation stand in until they are ready)."""
    if st.needs_effective:
        raise SkinError("Optimized Centers works with vertex groups only, not with envelopes or B-Bones: choose another method")
    if st.centers is not None and st.centers_key == st.binding_key:
        return
    triangles = centers.triangles_of(obj.data)
    key = centers.key_of(data.positions, triangles, binding.influences)
    got = centers.lookup(key, data.vertex_count)
    if got is None:
        job = centers.job_of(key)
        if job is not None and job.finished and job.error:
            raise SkinError(f"Optimized Centers: {job.error} (change the method or any setting to try again)")
        if data.vertex_count <= centers.INLINE_VERTICES or centers.in_background() or ctx.depsgraph.mode == "RENDER":
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
    st.centers, st.centers_key = got, st.binding_key


def finish(plan: Plan) -> None:
    """Writes the result, then takes the companion out of the way (in this order, so that no
    evaluation sees both or neither)."""
    obj, mod, st, result, mode = plan.obj, plan.mod, plan.st, plan.result, plan.mode
    st.generation += 1
    if plan.quick:
        results.write_positions(result, st.out)
        st.signature = plan.signature
        st.seconds = time.perf_counter() - plan.start
        return
    data = meshdata.get(obj)
    if mode == nodes.RESULT_REPLACE:
        mesh = result.data
        if st.result_version != data.version or (len(mesh.vertices), len(mesh.edges), len(mesh.polygons), len(mesh.loops)) != data.counts:
            results.replace_mesh(result, obj.data)
            st.result_version = data.version
    else:
        results.points_mesh(result, len(st.out))
        st.result_version = 0
    results.write_positions(result, st.out)
    results.set_mode(result, mode)
    st.result = result
    # The companion stays parked while DQ Skin deforms (re-parked if someone switched it on:
    # both deforming would deform the mesh twice).
    c = obj.modifiers.get(st.companion) if st.companion else None
    if c is None or c.type != "ARMATURE":
        c = companion.find(obj, mod)
        st.companion = c.name if c is not None else ""
    if c is not None and not companion.is_parked(c):
        companion.park(c)
    st.parked = True
    st.signature = plan.signature
    st.mode = "replace" if mode == nodes.RESULT_REPLACE else "positions"
    st.error = ""
    st.seconds = time.perf_counter() - plan.start
    st.method = plan.s.method
    st.status = ""


def _mesh_input(obj, obj_eval, mod, st: State, data, depsgraph):
    """The mesh's coordinates with its shape keys mixed, and a key that changes with them."""
    keys = data.keys
    if keys is None:
        return data.positions, ("mesh", data.version)
    if not keys.relative:
        raise _needs_capture(mod, "absolute shape keys")
    key_eval = obj.data.shape_keys.evaluated_get(depsgraph)
    blocks = key_eval.key_blocks
    if len(blocks) != len(keys.data):
        raise _needs_capture(mod, "shape keys changing")
    values = np.empty(len(blocks), np.float32)
    blocks.foreach_get("value", values)
    mutes = np.empty(len(blocks), bool)
    blocks.foreach_get("mute", mutes)
    shown = obj_eval.active_shape_key_index if obj_eval.show_only_shape_key else None
    signature = ("keys", data.version, values.tobytes(), mutes.tobytes(), shown)
    if st.mixed is not None and st.signature is not None and st.signature[1] == signature:
        return st.mixed, signature
    if st.mixed is None or len(st.mixed) != data.vertex_count:
        st.mixed = np.empty((data.vertex_count, 3), np.float32)
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
        dqskin.shape_key_mix(blocks_in, keys.reference, st.mixed, shown)
    except ValueError as e:
        raise _needs_capture(mod, str(e)) from None
    return st.mixed, signature


class _CaptureNeeded(SkinError):
    """Shape keys DQ Skin cannot mix itself: it reads what reaches it from the evaluation."""


def _needs_capture(mod, why: str) -> SkinError:
    return _CaptureNeeded(why)


def _set_capture(mod, on: bool) -> None:
    """Stores the incoming positions (or not) in the node group."""
    if bool(nodes.get(mod, "Capture")) != on:
        nodes.put(mod, "Capture", on)
    if on:
        nodes.put(mod, "Capture Name", capture_name(mod))


def capture_name(mod) -> str:
    return f"dq_skin_input_{compat.modifier_uid(mod)}"


def _captured(obj, obj_eval, mod, data):
    _set_capture(mod, True)
    state(obj, mod).capture_on = True
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
        later = [m.name for m in mods[at + 1:] if m.show_viewport and m.type not in KEEP_VERTEX_COUNT]
        raise SkinError(
            f"Modifiers before DQ Skin deform the mesh, so it reads the coordinates reaching it from "
            f"the evaluated mesh, but {', '.join(later) or 'a later modifier'} changes the vertex count "
            f"({data.vertex_count} → {count}); move them before DQ Skin's modifiers or apply them"
        )
    positions = np.empty(count * 3, np.float32)
    attribute.data.foreach_get("vector", positions)
    positions = positions.reshape(-1, 3)
    return positions, ("capture", positions.tobytes())


def _still(result, mod, claimed: dict) -> bool:
    """Whether the result written last time is still this modifier's (the usual case)."""
    try:
        return nodes.get(mod, "Result") == result and claimed.get(result.session_uid) is not None
    except ReferenceError:
        return False


def _own_result(obj, mod, claimed: dict):
    """This modifier's result object: the one it points at if that is ours and not another
    modifier's, else a new one."""
    uid = compat.modifier_uid(mod)
    owner = results.owner_key(obj, uid)
    me = (obj.session_uid, uid)
    result = nodes.get(mod, "Result")
    if result is not None and results.is_result(result) and result.library is None and claimed.get(result.session_uid, me) == me:
        claimed[result.session_uid] = me
        if result.get(results.OWNER) != owner:
            result[results.OWNER] = owner
        return result
    result = results.create(obj, mod, owner)
    claimed[result.session_uid] = me
    nodes.put(mod, "Result", result)
    return result


def _fallback(obj, mod, st: State, s: Settings | None, message: str) -> bool:
    """DQ Skin cannot deform: pass the input through and let the companion deform as Blender
    does; the panel shows why."""
    st.mode, st.error, st.signature, st.parked = "fallback", message, None, False
    result = nodes.get(mod, "Result")
    if result is not None and results.is_result(result) and result.library is None:
        results.set_mode(result, nodes.RESULT_OFF)
    c = companion.find(obj, mod)
    if c is None:
        st.status = "No Armature modifier after it: the mesh is not deformed"
    else:
        if s is not None:
            companion.activate(c, mod, s)
        else:
            c.show_viewport, c.show_render = mod.show_viewport, mod.show_render
        st.status = f"Blender's Armature modifier '{c.name}' deforms the mesh instead"
    return False


def deactivate(obj, mod, detach: bool) -> None:
    """The state files are saved in: companion active, no result (detached with `detach`)."""
    if obj.library is not None:
        return
    try:
        s = settings(mod)
    except Exception:
        s = None
    c = companion.find(obj, mod)
    if c is not None:
        if s is not None:
            companion.activate(c, mod, s)
        else:
            c.show_viewport, c.show_render = mod.show_viewport, mod.show_render
    result = nodes.get(mod, "Result")
    if result is not None and results.is_result(result) and result.library is None:
        results.set_mode(result, nodes.RESULT_OFF)
    if detach and result is not None:
        nodes.put(mod, "Result", None)
    st = _states.get((obj.session_uid, compat.modifier_uid(mod)))
    if st is not None:
        st.signature = None
        st.parked = False
        if st.live:
            st.mode = ""

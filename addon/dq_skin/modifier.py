# SPDX-License-Identifier: GPL-3.0-or-later
"""Evaluating DQ Skin modifiers: read their settings and input, skin, write the result.

Everything that does not change between frames (influences, mask, blend amounts) is cached per
modifier until the mesh or its weights change. Errors are kept per modifier for the panel and
never raised into Blender's handlers.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import bpy
import numpy as np

from . import nodes, rig


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
    result: object


@dataclass
class State:
    """What the add-on knows about one DQ Skin modifier between evaluations."""

    binding: rig.Binding | None = None
    binding_key: tuple = ()
    blend: np.ndarray | None = None
    envelopes: np.ndarray | None = field(default=None, repr=False)
    status: str = ""
    error: str = ""
    seconds: float = 0.0
    out: np.ndarray | None = field(default=None, repr=False)
    # What the last result was computed from, to skip work (and update loops) when nothing changed.
    last_input: np.ndarray | None = field(default=None, repr=False)
    last_frame: rig.Frame | None = field(default=None, repr=False)
    last_settings: tuple = ()


_states: dict[tuple[str, str], State] = {}

RESULT_TAG = "dq_skin_result"


def state(obj, mod) -> State:
    return _states.setdefault((obj.name_full, mod.name), State())


def forget(obj_names=None) -> None:
    """Drops cached bindings (all, or those of the named objects), e.g. after weights change."""
    if obj_names is None:
        _states.clear()
        return
    for key in [k for k in _states if k[0] in obj_names]:
        _states[key].binding = None
        _states[key].last_input = None


def settings(mod) -> Settings:
    group = mod.node_group
    ids = nodes.socket_ids(group)
    value = lambda name: mod[ids[name]]  # noqa: E731
    attribute = lambda name: mod.get(ids[name] + "_attribute_name", "") if mod.get(ids[name] + "_use_attribute") else ""  # noqa: E731
    menu = nodes.menu_values(group).get(value("Method"), "Dual Quaternion")
    return Settings(
        armature=value("Armature"),
        method=nodes.METHOD_KEYS[menu],
        blend_group=attribute("Blend Amount"),
        blend_factor=float(value("Blend Factor")),
        use_vertex_groups=bool(value("Use Vertex Groups")),
        use_envelopes=bool(value("Use Envelopes")),
        mask_group=attribute("Mask"),
        invert_mask=bool(value("Invert Mask")),
        result=value("Result"),
    )


def dq_skin_modifiers(obj):
    return [m for m in obj.modifiers if nodes.is_dq_skin(m)] if obj.type == "MESH" else []


def ensure_result(obj, mod):
    """The vertex-only mesh object the modifier samples, created if missing. It is linked to no
    scene; the modifier's reference keeps it alive and it goes with the modifier."""
    ids = nodes.socket_ids(mod.node_group)
    result = mod[ids["Result"]]
    if result is None or result.type != "MESH":
        mesh = bpy.data.meshes.new(f"DQ Skin result of {obj.name}")
        result = bpy.data.objects.new(mesh.name, mesh)
        result[RESULT_TAG] = True
        mod[ids["Result"]] = result
    return result


def _binding_key(obj, s: Settings) -> tuple:
    mesh = obj.data
    return (
        mesh.as_pointer(),
        len(mesh.vertices),
        tuple(g.name for g in obj.vertex_groups),
        s.armature.as_pointer() if s.armature else 0,
        tuple(
            (b.name, b.use_deform, b.use_envelope_multiply, b.head_radius, b.tail_radius, b.envelope_distance, b.envelope_weight)
            for b in s.armature.data.bones
        )
        if s.armature
        else (),
        s.mask_group,
        s.invert_mask,
        s.blend_group,
        s.use_vertex_groups,
    )


def _group_weights(obj, name: str) -> np.ndarray:
    """A vertex group's weights per vertex (0 outside it)."""
    weights = np.zeros(len(obj.data.vertices), np.float32)
    index = obj.vertex_groups.find(name)
    if index < 0:
        return weights
    for v in obj.data.vertices:
        for g in v.groups:
            if g.group == index:
                weights[v.index] = g.weight
    return weights


def evaluate(obj, mod, depsgraph) -> None:
    """Skins one DQ Skin modifier for the depsgraph's current state and writes its result.
    Problems end up in the modifier's state (panel) and leave the input unchanged."""
    st = state(obj, mod)
    start = time.perf_counter()
    try:
        s = settings(mod)
        arm = s.armature
        if arm is None or arm.type != "ARMATURE":
            raise SkinError("No armature object set")
        if arm.mode == "EDIT" or arm.data.is_editmode:
            raise SkinError(f"Armature {arm.name} is in Edit Mode")
        key = _binding_key(obj, s)
        if st.binding is None or st.binding_key != key:
            st.binding = rig.bind(obj, arm, s.mask_group, s.invert_mask, s.use_vertex_groups)
            st.envelopes = rig.envelopes(arm, st.binding)
            st.blend = _group_weights(obj, s.blend_group) if s.blend_group else None
            st.binding_key = key
        evaluated = obj.evaluated_get(depsgraph)
        attribute = evaluated.data.attributes.get(nodes.INPUT_ATTRIBUTE)
        if attribute is None:
            raise SkinError("Waiting for the modifier to be evaluated")
        count = len(attribute.data)
        if count != st.binding.vertex_count:
            raise SkinError(
                f"An earlier modifier changed the vertex count ({st.binding.vertex_count} → {count}); "
                "put DQ Skin before modifiers that add or remove vertices"
            )
        positions = np.empty(count * 3, np.float32)
        attribute.data.foreach_get("vector", positions)
        positions = positions.reshape(-1, 3)
        arm_eval = arm.evaluated_get(depsgraph)
        matrices = rig.frame(st.binding, evaluated, arm_eval)
        signature = (s.method, s.blend_factor, s.use_envelopes)
        result = ensure_result(obj, mod)
        if (
            signature == st.last_settings
            and matrices.same_as(st.last_frame)
            and st.last_input is not None
            and np.array_equal(positions, st.last_input)
            and len(result.data.vertices) == count
        ):
            return  # the result is already this
        if st.out is None or len(st.out) != count:
            st.out = np.empty((count, 3), np.float32)
        binding = st.binding
        segments = rig.bbone_segments(arm_eval, binding)
        if s.use_envelopes or st.envelopes[:, 10].any() or segments.max(initial=0) > 1:
            # Envelopes and B-Bone segments depend on where the vertices are: this frame's
            # influences, over the bones followed by the B-Bones' segment joints.
            effective = binding.influences.effective(
                positions,
                matrices.premat,
                envelopes=st.envelopes,
                use_vertex_groups=s.use_vertex_groups,
                use_envelopes=s.use_envelopes,
                bbone_segments=segments,
                rest=matrices.rest,
                lengths=rig.bone_lengths(arm_eval, binding),
                bbone_mapping=rig.curved_bbone_mapping(arm_eval, binding, positions, matrices.premat, s.use_envelopes),
            )
            binding = rig.Binding(effective, binding.bone_names, binding.bone_indices, binding.mask, binding.vertex_count)
            matrices = rig.with_bbone_joints(matrices, arm_eval, st.binding, segments)
        rig.skin(
            binding,
            evaluated,
            arm_eval,
            positions,
            s.method,
            blend=st.blend,
            blend_factor=s.blend_factor,
            out=st.out,
            matrices=matrices,
        )
        mesh = result.data
        if len(mesh.vertices) != count:
            mesh.clear_geometry()
            mesh.vertices.add(count)
        mesh.attributes["position"].data.foreach_set("vector", st.out.ravel())
        mesh.update()
        st.last_input, st.last_frame, st.last_settings = positions, matrices, signature
        st.error = ""
        st.seconds = time.perf_counter() - start
        st.status = (
            f"{len(st.binding.bone_names)} bones, {len(st.binding.influences)} influences, "
            f"{st.seconds * 1e3:.1f} ms"
        )
    except SkinError as e:
        _fail(obj, mod, st, str(e))
    except Exception as e:  # never a traceback in the user's face; say what happened
        _fail(obj, mod, st, f"{type(e).__name__}: {e}")


def _fail(obj, mod, st: State, message: str) -> None:
    """Records the error and makes the modifier pass its input through (an empty result)."""
    st.error = message
    st.last_input = None
    st.status = ""
    result = nodes.socket_ids(mod.node_group) and mod.get(nodes.socket_ids(mod.node_group)["Result"])
    if result is not None and result.type == "MESH" and len(result.data.vertices):
        result.data.clear_geometry()
        result.data.update()

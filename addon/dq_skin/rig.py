# SPDX-License-Identifier: GPL-3.0-or-later
"""Reads what Blender's Armature modifier uses from Blender data, as arrays for `dqskin`.

Mirrors `armature_deform.cc`: vertex groups are mapped to pose bones by name, and groups with no
bone or whose bone does not deform are dropped; a vertex's remaining groups keep their stored
order (dual quaternion skinning chooses signs in that order); bone matrices are
`PoseBone.matrix_channel` (posed times inverse rest, armature space) and `Bone.matrix_local`;
`postmat = inverse(object world) · armature world` and `premat = inverse(postmat)`, computed the
way Blender does (a double inverse).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import dqskin


@dataclass
class Binding:
    """What does not change from frame to frame: the influences and the bones they refer to."""

    influences: dqskin.Influences
    bone_names: list[str]
    """Deforming pose bones, in the order their indices in `influences` refer to."""
    bone_indices: np.ndarray
    """Index of each of those bones in `armature.pose.bones`."""
    mask: np.ndarray | None
    """Per-vertex strength from the modifier's vertex group (inverted if asked), or None."""
    vertex_count: int


def deforming_bones(armature) -> list:
    """Pose bones whose bone has Deform on, in `pose.bones` order."""
    return [pb for pb in armature.pose.bones if pb.bone.use_deform]


def bind(
    mesh_object, armature, mask_group: str = "", invert_mask: bool = False, use_vertex_groups: bool = True
) -> Binding:
    """Influences of `mesh_object`'s vertex groups on `armature`'s deforming bones. The bone
    indices run over every deforming pose bone in Blender's order (what envelopes need too);
    zero weights are kept, since a vertex with any group mapped to a bone never uses envelopes."""
    mesh = mesh_object.data
    pose_bones = armature.pose.bones
    bone_names: list[str] = []
    bone_indices: list[int] = []
    for i, pb in enumerate(pose_bones):
        if pb.bone.use_deform:
            bone_names.append(pb.name)
            bone_indices.append(i)
    ours = {name: k for k, name in enumerate(bone_names)}
    # Vertex group index -> our bone index, for groups naming a deforming bone.
    group_to_bone: dict[int, int] = {}
    if use_vertex_groups:
        for group in mesh_object.vertex_groups:
            if group.name in ours:
                group_to_bone[group.index] = ours[group.name]

    vertex_count = len(mesh.vertices)
    offsets = np.zeros(vertex_count + 1, np.int64)
    bones: list[int] = []
    weights: list[float] = []
    mask_index = mesh_object.vertex_groups.find(mask_group) if mask_group else -1
    # Outside the mask group a vertex's weight in it is 0. Blender applies the mask only to
    # meshes that have vertex weights at all.
    mask = np.zeros(vertex_count, np.float32) if mask_index >= 0 else None
    any_weights = False
    for v in mesh.vertices:
        for g in v.groups:
            any_weights = True
            b = group_to_bone.get(g.group)
            if b is not None:
                bones.append(b)
                weights.append(g.weight)
            if g.group == mask_index:
                mask[v.index] = g.weight
        offsets[v.index + 1] = len(bones)
    if mask is not None:
        if not any_weights:
            mask = None
        elif invert_mask:
            mask = (1.0 - mask).astype(np.float32)
    influences = dqskin.Influences(
        offsets,
        np.asarray(bones, np.int64),
        np.asarray(weights, np.float32),
        len(bone_names),
    )
    return Binding(influences, bone_names, np.asarray(bone_indices, np.int64), mask, vertex_count)


def _pose_matrices(collection, prop: str) -> np.ndarray:
    """`(N, 4, 4)` row-major float32 from a collection's 4×4 matrix property (stored by columns)."""
    flat = np.empty(len(collection) * 16, np.float32)
    collection.foreach_get(prop, flat)
    return np.ascontiguousarray(flat.reshape(-1, 4, 4).transpose(0, 2, 1))


def bone_matrices(armature, binding: Binding) -> tuple[np.ndarray, np.ndarray]:
    """`(deform, rest)` matrices of the bound bones for the current pose."""
    deform = _pose_matrices(armature.pose.bones, "matrix_channel")[binding.bone_indices]
    rest = _pose_matrices(armature.data.bones, "matrix_local")
    # data.bones and pose.bones share their order.
    rest = rest[binding.bone_indices]
    return np.ascontiguousarray(deform), np.ascontiguousarray(rest)


def spaces(mesh_object, armature) -> tuple[np.ndarray, np.ndarray]:
    """`(premat, postmat)`: mesh space to armature space and back, as Blender computes them."""
    obmat = np.linalg.inv(np.array(mesh_object.matrix_world, np.float32))
    postmat = (obmat @ np.array(armature.matrix_world, np.float32)).astype(np.float32)
    premat = np.linalg.inv(postmat).astype(np.float32)
    return premat, postmat


def envelopes(armature, binding: Binding) -> np.ndarray:
    """`(B, 11)` float32 envelope rows of the bound bones (see `dqskin.Influences.with_envelopes`)."""
    rows = np.empty((len(binding.bone_names), 11), np.float32)
    for k, name in enumerate(binding.bone_names):
        b = armature.data.bones[name]
        rows[k, 0:3] = b.head_local
        rows[k, 3:6] = b.tail_local
        rows[k, 6:10] = (b.head_radius, b.tail_radius, b.envelope_distance, b.envelope_weight)
        rows[k, 10] = 1.0 if b.use_envelope_multiply else 0.0
    return rows


def bbone_segments(armature, binding: Binding) -> np.ndarray:
    """Segment count of each bound bone (1 for ordinary bones)."""
    bones = armature.data.bones
    return np.array([bones[n].bbone_segments for n in binding.bone_names], np.int64)


def bone_lengths(armature, binding: Binding) -> np.ndarray:
    bones = armature.data.bones
    return np.array([bones[n].length for n in binding.bone_names], np.float32)


@dataclass
class Frame:
    """The per-frame inputs besides positions: bone matrices and spaces."""

    deform: np.ndarray
    rest: np.ndarray
    premat: np.ndarray
    postmat: np.ndarray

    def same_as(self, other: "Frame | None") -> bool:
        return other is not None and all(
            np.array_equal(a, b)
            for a, b in ((self.deform, other.deform), (self.premat, other.premat), (self.postmat, other.postmat))
        )


def frame(binding: Binding, mesh_object, armature) -> Frame:
    """The current pose's matrices for `binding` (use evaluated objects inside handlers)."""
    deform, rest = bone_matrices(armature, binding)
    premat, postmat = spaces(mesh_object, armature)
    return Frame(deform, rest, premat, postmat)


def curved_bbone_mapping(armature, binding: Binding, positions: np.ndarray, premat: np.ndarray, use_envelopes: bool):
    """For B-Bones with the Curved vertex mapping, `{bone index: (segment index, blend)}` per
    vertex from Blender's own `PoseBone.bbone_segment_index` (its runtime data is not exposed),
    for the vertices the bone can influence; -1 elsewhere. None when no bone needs it."""
    bones = armature.data.bones
    curved = [
        k for k, name in enumerate(binding.bone_names)
        if bones[name].bbone_segments > 1 and bones[name].bbone_mapping_mode == "CURVED"
    ]
    if not curved:
        return None
    from mathutils import Vector

    counts = np.diff(binding.influences.offsets)
    owner = np.repeat(np.arange(len(counts)), counts)
    influence_bones = binding.influences.bones
    co = dqskin.transform_points(premat, positions)
    mapping = {}
    for k in curved:
        vertices = set(owner[influence_bones == k].tolist())
        if use_envelopes:
            vertices.update(np.flatnonzero(counts == 0).tolist())
        index = np.full(len(counts), -1, np.int32)
        blend = np.zeros(len(counts), np.float32)
        pb = armature.pose.bones[binding.bone_names[k]]
        for v in sorted(vertices):
            index[v], blend[v] = pb.bbone_segment_index(Vector(co[v]))
        mapping[k] = (index, blend)
    return mapping


def with_bbone_joints(f: Frame, armature, binding: Binding, segments: np.ndarray) -> Frame:
    """`f` with every B-Bone's segment joints appended after the bones (in bone order), read
    from the armature's current B-Bone shape (use the evaluated armature)."""
    deform, rest = [f.deform], [f.rest]
    for k in np.flatnonzero(segments > 1):
        pb = armature.pose.bones[binding.bone_names[k]]
        n = int(segments[k])
        pose = np.array([np.array(pb.bbone_segment_matrix(a), np.float32) for a in range(n + 1)], np.float32)
        rest_joints = np.array([np.array(pb.bbone_segment_matrix(a, rest=True), np.float32) for a in range(n + 1)], np.float32)
        d, r = dqskin.bbone_segment_matrices(f.deform[k], f.rest[k], pose, rest_joints)
        deform.append(d)
        rest.append(r)
    return Frame(
        np.ascontiguousarray(np.concatenate(deform), np.float32),
        np.ascontiguousarray(np.concatenate(rest), np.float32),
        f.premat,
        f.postmat,
    )


def skin(
    binding: Binding,
    mesh_object,
    armature,
    positions: np.ndarray,
    method: str,
    *,
    blend: np.ndarray | None = None,
    blend_factor: float = 1.0,
    out: np.ndarray | None = None,
    matrices: Frame | None = None,
) -> np.ndarray:
    """Skins `positions` (the coordinates that reach the modifier, `(V, 3)` float32) for the
    armature's current pose (or the given `matrices`); returns `out`."""
    f = matrices or frame(binding, mesh_object, armature)
    return dqskin.skin(
        positions,
        binding.influences,
        f.deform,
        f.rest,
        method=method,
        blend=blend if method == "blend" else None,
        blend_factor=blend_factor,
        premat=f.premat,
        postmat=f.postmat,
        mask=binding.mask,
        out=out,
    )


def mesh_positions(mesh) -> np.ndarray:
    """A mesh's vertex positions as `(V, 3)` float32 (the fast attribute path)."""
    flat = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.attributes["position"].data.foreach_get("vector", flat)
    return flat.reshape(-1, 3)

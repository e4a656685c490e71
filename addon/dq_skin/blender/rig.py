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

from .. import dqskin
from .meshdata import MeshData, digest_of


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
    rest: np.ndarray | None = None
    """`(B, 4, 4)` rest matrices of the bound bones (`Bone.matrix_local`)."""
    effective: tuple | None = None
    """`(key, influences)`: the last effective influences from Blender's memory (see `pose`)."""
    pose_signature: int | None = None
    """The binding signature of the last pose from memory whose bones matched these."""


def bind(
    data: MeshData, armature, mask_group: str = "", invert_mask: bool = False, use_vertex_groups: bool = True, shared=None, interned=None
) -> Binding:
    """Influences of a mesh's vertex groups (`data`) on `armature`'s deforming bones. The bone
    indices run over every deforming pose bone in Blender's order (what envelopes need too);
    zero weights are kept, since a vertex with any group mapped to a bone never uses envelopes.
    `data`: the mesh's `meshdata.MeshData`. `shared(key, make)`: the influences of that key if
    another binding made them (the same weights on bones mapped the same way), else `make()`'s;
    `interned(value)`: the bone names and rest matrices of the same content another binding
    keeps (`model.interned.Interned`), else these."""
    deform = np.empty(len(armature.data.bones), bool)
    armature.data.bones.foreach_get("use_deform", deform)
    # data.bones and pose.bones share their order.
    bone_indices = np.flatnonzero(deform)
    bone_names = (
        [armature.pose.bones[int(i)].name for i in bone_indices]
        if len(bone_indices) < len(deform)
        else [pb.name for pb in armature.pose.bones]
    )
    ours = {name: k for k, name in enumerate(bone_names)}
    # Vertex group index -> our bone index, for groups naming a deforming bone.
    group_to_bone = np.full(max(len(data.group_names), 1), -1, np.int32)
    if use_vertex_groups:
        for g, name in enumerate(data.group_names):
            group_to_bone[g] = ours.get(name, -1)
    n = data.vertex_count
    groups = data.groups

    def make():
        if groups is None:
            return dqskin.Influences(np.zeros(n + 1, np.int64), np.zeros(0, np.int64), np.zeros(0, np.float32), len(bone_names))
        return dqskin.influences_from_deform_groups(groups.offsets, groups.groups, groups.weights, group_to_bone, len(bone_names))

    if shared is None:
        influences = make()
    else:
        # (Weights read again that differ from those first read have their own digest.)
        digest = digest_of(groups) if data.changed_under else data.groups_digest
        influences = shared((digest, n, group_to_bone.tobytes(), len(bone_names)), make)
    # Outside the mask group a vertex's weight in it is 0. Blender applies the mask only to
    # meshes that have vertex weights at all.
    mask = None
    if mask_group and groups is not None:
        mask = data.group_weights(mask_group)
        if mask is not None and invert_mask:
            mask = (1.0 - mask).astype(np.float32)
    rest = np.ascontiguousarray(_pose_matrices(armature.data.bones, "matrix_local")[bone_indices])
    if interned is not None:
        bone_names, rest = interned(bone_names), interned(rest)
    return Binding(influences, bone_names, bone_indices.astype(np.int64), mask, n, rest)


def _pose_matrices(collection, prop: str) -> np.ndarray:
    """`(N, 4, 4)` row-major float32 from a collection's 4×4 matrix property (stored by columns)."""
    flat = np.empty(len(collection) * 16, np.float32)
    collection.foreach_get(prop, flat)
    return np.ascontiguousarray(flat.reshape(-1, 4, 4).transpose(0, 2, 1))


def pose_matrices(armature, memory=None) -> np.ndarray:
    """`(B, 4, 4)` deform matrices of all pose bones (`PoseBone.matrix_channel`), row-major:
    read from Blender's memory with `memory` (`blender.memory.CheckedPose`), else through the
    Python API (no reader, or it refused the armature)."""
    if memory is not None:
        try:
            return memory.channel_matrices(armature)
        except (TypeError, ValueError):
            pass
    return _pose_matrices(armature.pose.bones, "matrix_channel")


def bone_matrices(armature, binding: Binding) -> tuple[np.ndarray, np.ndarray]:
    """`(deform, rest)` matrices of the bound bones for the current pose."""
    deform = _pose_matrices(armature.pose.bones, "matrix_channel")
    if len(binding.bone_indices) != len(deform):
        deform = deform[binding.bone_indices]
    rest = binding.rest
    if rest is None:
        # data.bones and pose.bones share their order.
        rest = _pose_matrices(armature.data.bones, "matrix_local")[binding.bone_indices]
    return np.ascontiguousarray(deform), np.ascontiguousarray(rest)


def world(obj) -> np.ndarray:
    """An object's world matrix as row-major `(4, 4)` float32."""
    return np.array(obj.matrix_world, np.float32)


def spaces(mesh_object, armature) -> tuple[np.ndarray, np.ndarray]:
    """`(premat, postmat)`: mesh space to armature space and back, as Blender computes them."""
    return dqskin.armature_spaces(world(mesh_object), world(armature))


def armature_signature(arm) -> tuple:
    """What of the armature's bones a binding depends on (names, deform flags, rest pose,
    envelopes, B-Bone segments), whatever route changed them, through the Python API
    (`pose.armature_signature` reads it from memory)."""
    bones = arm.data.bones
    n = len(bones)
    deform = np.empty(n, bool)
    bones.foreach_get("use_deform", deform)
    rest = np.empty(n * 16, np.float32)
    bones.foreach_get("matrix_local", rest)
    envelope = np.empty(n * 4, np.float32)
    for i, attr in enumerate(("head_radius", "tail_radius", "envelope_distance", "envelope_weight")):
        col = np.empty(n, np.float32)
        bones.foreach_get(attr, col)
        envelope[i::4] = col
    multiply = np.empty(n, bool)
    bones.foreach_get("use_envelope_multiply", multiply)
    segments = np.empty(n, np.int32)
    bones.foreach_get("bbone_segments", segments)
    return (tuple(b.name for b in bones), deform.tobytes(), rest.tobytes(), envelope.tobytes(), multiply.tobytes(), segments.tobytes())


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
        k for k, name in enumerate(binding.bone_names) if bones[name].bbone_segments > 1 and bones[name].bbone_mapping_mode == "CURVED"
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

# SPDX-License-Identifier: GPL-3.0-or-later
"""The memory readers checked against Blender's own data (its Python API) on their first read
in a session: a reader whose layout does not match this Blender (a release that changed a
struct the SDNA describes differently than the reader assumes) is caught before anything it read
is used, and the session takes the Python paths. Each check returns "" when the reader agrees,
else what differs."""

from __future__ import annotations

import numpy as np

from .. import dqskin

SAMPLE_VERTICES = 256  # vertices compared on a mesh's first read (evenly spread)
SAMPLE_BBONES = 4  # B-Bones whose joints are compared on an armature's first read
JOINT_TOLERANCE = 2e-5  # Blender's B-Bone cache against its Python API (float32 rounding)


def _row_major(matrix) -> np.ndarray:
    return np.array(matrix, np.float32)


def channels_differ(matrices, arm_eval) -> str:
    """What the channel matrices read from memory get wrong about `arm_eval`."""
    want = [_row_major(pb.matrix_channel) for pb in arm_eval.pose.bones]
    if len(matrices) != len(want) or not np.array_equal(matrices, np.array(want, np.float32).reshape(-1, 4, 4)):
        return "the bones' channel matrices"
    return ""


def pose_differs(data, arm_eval) -> str:
    """What the pose read from memory (`dqskin.PoseData`) gets wrong about `arm_eval`."""
    bones = list(arm_eval.pose.bones)
    deforming = [(i, pb) for i, pb in enumerate(bones) if pb.bone.use_deform]
    if list(data.names) != [pb.name for _, pb in deforming]:
        return "the deforming bones' names"
    if list(data.bone_indices) != [i for i, _ in deforming]:
        return "the deforming bones' order"
    b = len(deforming)
    deform = np.asarray(data.deform)
    rest = np.asarray(data.rest)
    if not np.array_equal(deform[:b], [_row_major(pb.matrix_channel) for _, pb in deforming]):
        return "the bones' pose matrices"
    if not np.array_equal(rest[:b], [_row_major(pb.bone.matrix_local) for _, pb in deforming]):
        return "the bones' rest matrices"
    if list(data.segments) != [pb.bone.bbone_segments for _, pb in deforming]:
        return "the B-Bones' segment counts"
    first, checked = b, 0
    for k, (_, pb) in enumerate(deforming):
        n = int(data.segments[k])
        if n < 2:
            continue
        if checked < SAMPLE_BBONES:
            joints = np.array([_row_major(pb.bbone_segment_matrix(a)) for a in range(n + 1)], np.float32)
            rest_joints = np.array([_row_major(pb.bbone_segment_matrix(a, rest=True)) for a in range(n + 1)], np.float32)
            want, want_rest = dqskin.bbone_segment_matrices(deform[k], rest[k], joints, rest_joints)
            scale = max(1.0, float(np.abs(want).max()))
            if not (
                np.allclose(deform[first : first + n + 1], want, atol=JOINT_TOLERANCE * scale)
                and np.allclose(rest[first : first + n + 1], want_rest, atol=JOINT_TOLERANCE * scale)
            ):
                return f"the joints of B-Bone {pb.name}"
            checked += 1
        first += n + 1
    if first != len(deform):
        return "the number of B-Bone joints"
    return ""


def groups_differ(groups, mesh) -> str:
    """What the vertex-group weights read from memory (`meshdata.Groups`, or None for no weights)
    get wrong about `mesh`, on a sample of its vertices."""
    n = len(mesh.vertices)
    if groups is None:
        return "" if not any(len(mesh.vertices[i].groups) for i in _sample(n)) else "a mesh with weights read as none"
    if len(groups.offsets) != n + 1:
        return "the vertex count"
    for i in _sample(n):
        want = [(g.group, g.weight) for g in mesh.vertices[i].groups]
        a, b = int(groups.offsets[i]), int(groups.offsets[i + 1])
        got = list(zip(groups.groups[a:b].tolist(), groups.weights[a:b].tolist()))
        if [(g, np.float32(w)) for g, w in got] != [(g, np.float32(w)) for g, w in want]:
            return f"the weights of vertex {i}"
    return ""


def positions_differ(positions, mesh) -> str:
    """What the positions read from memory get wrong about `mesh`, on a sample of its vertices
    (read one by one: reading the whole array through the Python API would make a mesh that
    shares it with its copies take its own)."""
    n = len(mesh.vertices)
    if positions.shape != (n, 3):
        return "the vertex count"
    for i in _sample(n):
        if tuple(np.float32(c) for c in mesh.vertices[i].co) != tuple(positions[i]):
            return f"the position of vertex {i}"
    return ""


def _sample(n: int) -> list[int]:
    if n <= SAMPLE_VERTICES:
        return list(range(n))
    return sorted(set(np.linspace(0, n - 1, SAMPLE_VERTICES).astype(int).tolist()))

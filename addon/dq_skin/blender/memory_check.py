# SPDX-License-Identifier: GPL-3.0-or-later
"""The memory readers checked against Blender's own data (its Python API) on their first read
in a session: a reader whose layout does not match this Blender (a release that changed a
struct the SDNA describes differently than the reader assumes) is caught before anything it read
is used, and the session takes the Python paths. Each check returns "" when the reader agrees,
else what differs."""

from __future__ import annotations

from types import MappingProxyType

import numpy as np

import bpy

from .. import dqskin
from . import compat

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


# `eModifierType` values (stored in files, so they never change) and `eModifierMode_Realtime`.
MODIFIER_TYPES = MappingProxyType({"ARMATURE": 8, "NODES": 57})
SHOWN_IN_VIEWPORT = 1


def object_state_differs(found: dict, obj) -> str:
    """What the object's state read from memory (`ObjectStateMemory.describe`) gets wrong about
    `obj`: its mode, its modifiers (order, names, types, switches, node groups, the inputs'
    names and values, an Armature modifier's object) and its vertex-group names."""
    if (found["mode"] == 0) != (obj.mode == "OBJECT"):
        return "the object's mode"
    if found["vertex_groups"] != list(obj.vertex_groups.keys()):
        return "the vertex-group names"
    mods = list(obj.modifiers)
    if [m["name"] for m in found["modifiers"]] != [m.name for m in mods]:
        return "the modifiers' names and order"
    for got, mod in zip(found["modifiers"], mods):
        want = MODIFIER_TYPES.get(mod.type)
        if (want is not None and got["type"] != want) or (want is None and got["type"] in MODIFIER_TYPES.values()):
            return f"the type of modifier {mod.name}"
        if bool(got["mode"] & SHOWN_IN_VIEWPORT) != mod.show_viewport:
            return f"whether modifier {mod.name} is shown in the viewport"
        if mod.type == "ARMATURE" and got["object"] != _address(mod.object):
            return f"the object of modifier {mod.name}"
        if mod.type == "NODES":
            what = _inputs_differ(got, mod)
            if what:
                return f"{what} of modifier {mod.name}"
    return ""


def _inputs_differ(got: dict, mod) -> str:
    group = mod.node_group
    if got["node_group"] != _address(group):
        return "the node group"
    if group is None:
        return ""
    inputs = got["inputs"]
    if compat.RNA_INPUTS:  # (5.2: the system properties' group "inputs", each input a group with its value)
        inputs = {k: v.get("value") for k, v in inputs.get("inputs", {}).items() if isinstance(v, dict)}
    for item in group.interface.items_tree:
        if item.item_type != "SOCKET" or item.in_out != "INPUT" or item.socket_type == "NodeSocketGeometry":
            continue
        if item.identifier not in inputs:
            return f"input {item.name}"
        want = compat.get_input(mod, item.identifier)
        value = inputs[item.identifier]
        if isinstance(want, bpy.types.ID) or want is None:
            if item.socket_type in (
                "NodeSocketObject",
                "NodeSocketCollection",
                "NodeSocketMaterial",
                "NodeSocketImage",
            ) and value != _address(want):
                return f"input {item.name}"
        elif isinstance(want, (bool, int, float, str)) and item.socket_type != "NodeSocketMenu" and value != want:
            if not (isinstance(want, float) and np.float32(want) == np.float32(value)):
                return f"input {item.name}"
    return ""


def _address(data) -> int:
    return data.as_pointer() if data is not None else 0

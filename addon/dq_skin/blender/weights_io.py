# SPDX-License-Identifier: GPL-3.0-or-later
"""Blender data in and out of the weighting functions of `dqskin`: rest meshes and bones as
arrays in one space, a body's vertex-group weights as `dqskin.Influences`, and weights written
back into vertex groups named after the bones."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import bmesh

from .. import dqskin
from . import meshdata


@dataclass
class RestMesh:
    """A mesh object's own vertices (no modifiers, no shape-key mix) and triangles, in a given
    space."""

    positions: np.ndarray  # (V, 3) float32
    triangles: np.ndarray  # (T, 3) uint32


def to_space(obj, space) -> np.ndarray:
    """`obj`'s world matrix taken into `space` (an object, or None for world space), row-major."""
    m = obj.matrix_world if space is None else space.matrix_world.inverted_safe() @ obj.matrix_world
    return np.array(m, np.float32)


def rest_mesh(obj, space=None) -> RestMesh:
    """`obj`'s mesh as it is stored (what Parent > With Automatic Weights binds), in the space of
    the object `space` (world space for None)."""
    mesh = obj.data
    flat = np.empty(len(mesh.vertices) * 3, np.float32)
    if len(flat):
        mesh.attributes["position"].data.foreach_get("vector", flat)
    positions = dqskin.transform_points(to_space(obj, space), flat.reshape(-1, 3)) if len(flat) else flat.reshape(-1, 3)
    mesh.calc_loop_triangles()
    tris = np.empty(len(mesh.loop_triangles) * 3, np.uint32)
    mesh.loop_triangles.foreach_get("vertices", tris)
    return RestMesh(np.ascontiguousarray(positions, np.float32), tris.reshape(-1, 3))


@dataclass
class Bones:
    names: list[str]
    heads: np.ndarray  # (B, 3) float32, armature space
    tails: np.ndarray


def rest_bones(armature, deforming_only: bool = True) -> Bones:
    """The armature's bones at rest (`Bone.head_local`, `tail_local`: armature space), the
    deforming ones only unless asked otherwise."""
    bones = [b for b in armature.data.bones if b.use_deform or not deforming_only]
    heads = np.array([b.head_local for b in bones], np.float32).reshape(-1, 3)
    tails = np.array([b.tail_local for b in bones], np.float32).reshape(-1, 3)
    return Bones([b.name for b in bones], np.ascontiguousarray(heads), np.ascontiguousarray(tails))


def body_influences(obj, bone_names: list[str], reader) -> dqskin.Influences:
    """`obj`'s vertex-group weights on the groups named `bone_names`, as influences over those
    bones (`reader`: the session's `dqskin.memory.MeshMemory`, or None for the Python API)."""
    mesh = obj.data
    groups = meshdata.read_groups(mesh, reader)
    n = len(mesh.vertices)
    if groups is None:
        return dqskin.Influences(np.zeros(n + 1, np.int64), np.zeros(0, np.int64), np.zeros(0, np.float32), len(bone_names))
    ours = {name: k for k, name in enumerate(bone_names)}
    group_to_bone = np.full(max(len(obj.vertex_groups), 1), -1, np.int32)
    for g in obj.vertex_groups:
        group_to_bone[g.index] = ours.get(g.name, -1)
    return dqskin.influences_from_deform_groups(groups.offsets, groups.groups, groups.weights, group_to_bone, len(bone_names))


def write_groups(obj, bone_names: list[str], influences: dqskin.Influences, reader) -> None:
    """Writes `influences` into the vertex groups named `bone_names` (created where missing).
    Those groups' old weights are replaced; other groups are left as they are. `reader`: as
    for `body_influences`."""
    mesh = obj.data
    index = []
    for name in bone_names:
        group = obj.vertex_groups.get(name) or obj.vertex_groups.new(name=name)
        index.append(group.index)
    # The old weights of these groups go first: one call per group, for the vertices that have it.
    old = meshdata.read_groups(mesh, reader)
    if old is not None and len(old.groups):
        owner = np.repeat(np.arange(len(mesh.vertices)), np.diff(old.offsets.astype(np.int64)))
        for g in set(index) & set(np.unique(old.groups).tolist()):
            obj.vertex_groups[g].remove(owner[old.groups == g].tolist())
    offsets = influences.offsets.tolist()
    bones = np.asarray(index, np.int64)[influences.bones].tolist() if len(influences) else []
    weights = influences.weights.tolist()
    bm = bmesh.new()
    try:
        bm.from_mesh(mesh)
        layer = bm.verts.layers.deform.verify()
        for v, start, end in zip(bm.verts, offsets, offsets[1:]):
            dv = v[layer]
            for i in range(start, end):
                dv[bones[i]] = weights[i]
        bm.to_mesh(mesh)
    finally:
        bm.free()
    mesh.update()

"""Meshes on which Blender's automatic weights (bone heat) fail, and how the weights they get are
judged, for test_weights.py and bench/weights_bench.py.

`figure(scale)`: a figure of intersecting closed parts as artists block characters out (torso,
neck, head, arms, hands and legs as separate closed tubes and spheres pushed into each other),
with loose eyes and a row of teeth (closed shells inside the head) and an unwelded seam down the
left thigh, on a 15-bone armature with an animation that bends, raises and twists. `cloth`: an
open skirt around its hips. Everything is built at `scale` (the mesh and the bones themselves,
not an object scale).
"""

from __future__ import annotations

import math

import numpy as np

import bpy

import bmesh
from mathutils import Matrix, Quaternion, Vector

# name: (head, tail, parent); the figure faces −Y, Z up, arms along ±X.
BONES = {
    "hips": ((0, 0, 0.95), (0, 0, 1.15), None),
    "spine": ((0, 0, 1.15), (0, 0, 1.35), "hips"),
    "chest": ((0, 0, 1.35), (0, 0, 1.5), "spine"),
    "neck": ((0, 0, 1.5), (0, 0, 1.6), "chest"),
    "head": ((0, 0, 1.6), (0, 0, 1.82), "neck"),
    "upper_arm.L": ((0.12, 0, 1.42), (0.43, 0, 1.42), "chest"),
    "forearm.L": ((0.43, 0, 1.42), (0.72, 0, 1.42), "upper_arm.L"),
    "hand.L": ((0.72, 0, 1.42), (0.85, 0, 1.42), "forearm.L"),
    "thigh.L": ((0.1, 0, 0.95), (0.1, 0, 0.52), "hips"),
    "shin.L": ((0.1, 0, 0.52), (0.1, 0, 0.08), "thigh.L"),
}
for _name in [n for n in BONES if n.endswith(".L")]:
    (_h, _t, _p) = BONES[_name]
    BONES[_name[:-2] + ".R"] = ((-_h[0], _h[1], _h[2]), (-_t[0], _t[1], _t[2]), _p if not _p.endswith(".L") else _p[:-2] + ".R")

# (bone, axis, angle at full): keyed at frames 1 (rest), 15 (full) and 30 (half).
MOTION = [
    ("spine", (0, 0, 1), 0.5),
    ("chest", (1, 0, 0), 0.3),
    ("head", (0, 0, 1), 0.7),
    ("upper_arm.L", (0, 1, 0), 0.9),
    ("forearm.L", (0, 0, 1), 1.4),
    ("hand.L", (1, 0, 0), 0.8),
    ("upper_arm.R", (0, 1, 0), -0.7),
    ("forearm.R", (1, 0, 0), 1.2),
    ("thigh.L", (1, 0, 0), -1.0),
    ("shin.L", (1, 0, 0), 1.4),
    ("thigh.R", (0, 1, 0), 0.5),
    ("shin.R", (1, 0, 0), 0.9),
]
FRAMES = (1, 15, 30)


def tube(bm, a, b, radius: float, rings: int, segments: int = 20) -> list:
    """A closed tube from `a` to `b` (capped), its side vertices ring by ring."""
    a, b = Vector(a), Vector(b)
    axis = (b - a).normalized()
    u = axis.orthogonal().normalized()
    v = axis.cross(u)
    rows = []
    for i in range(rings):
        c = a.lerp(b, i / (rings - 1))
        rows.append(
            [bm.verts.new(c + radius * (math.cos(t) * u + math.sin(t) * v)) for t in np.linspace(0, 2 * math.pi, segments, endpoint=False)]
        )
    for r0, r1 in zip(rows, rows[1:]):
        for k in range(segments):
            bm.faces.new((r0[k], r1[k], r1[(k + 1) % segments], r0[(k + 1) % segments]))
    bm.faces.new(list(reversed(rows[0])))
    bm.faces.new(rows[-1])
    return rows


def sphere(bm, center, radius: float, segments: int = 16) -> None:
    bmesh.ops.create_uvsphere(bm, u_segments=segments, v_segments=segments // 2, radius=radius, matrix=Matrix.Translation(center))


def figure_mesh(scale: float = 1.0, name: str = "Figure"):
    """The figure's mesh object (intersecting parts, loose eyes and teeth, an unwelded seam)."""
    bm = bmesh.new()
    tube(bm, (0, 0, 0.88), (0, 0, 1.52), 0.17, 26, 28)  # torso
    tube(bm, (0, 0, 1.45), (0, 0, 1.64), 0.06, 8)  # neck
    sphere(bm, (0, 0, 1.7), 0.12, 24)  # head
    for side in (1, -1):
        tube(bm, (side * 0.08, 0, 1.42), (side * 0.45, 0, 1.42), 0.055, 16)  # upper arm, from inside the torso
        tube(bm, (side * 0.41, 0, 1.42), (side * 0.74, 0, 1.42), 0.045, 16)  # forearm, through the elbow
        sphere(bm, (side * 0.79, 0, 1.42), 0.055)  # hand
        tube(bm, (side * 0.1, 0, 0.98), (side * 0.1, 0, 0.5), 0.08, 20)  # thigh, from inside the hips
        tube(bm, (side * 0.1, 0, 0.55), (side * 0.1, 0, 0.06), 0.06, 20)  # shin, through the knee
        sphere(bm, (side * 0.045, -0.095, 1.72), 0.025, 12)  # eye (loose, half in the head)
    for k in range(6):  # teeth: loose shells inside the head
        bmesh.ops.create_cube(bm, size=0.012, matrix=Matrix.Translation((-0.03 + 0.012 * k, -0.085, 1.64)))
    # The unwelded seam: the left thigh's vertices at its front meridian, split apart.
    seam = [e for e in bm.edges if all(0.52 < v.co.z < 0.96 and v.co.x > 0.05 and v.co.y < -0.079 for v in e.verts)]
    bmesh.ops.split_edges(bm, edges=seam)
    bmesh.ops.scale(bm, vec=(scale, scale, scale), verts=bm.verts)
    mesh = bpy.data.meshes.new(name)
    bm.to_mesh(mesh)
    bm.free()
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def armature(scale: float = 1.0, name: str = "Rig"):
    """The figure's armature with its animation."""
    data = bpy.data.armatures.new(name)
    arm = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(arm)
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="EDIT")
    for bone, (head, tail, parent) in BONES.items():
        eb = data.edit_bones.new(bone)
        eb.head, eb.tail = Vector(head) * scale, Vector(tail) * scale
        if parent:
            eb.parent = data.edit_bones[parent]
    bpy.ops.object.mode_set(mode="OBJECT")
    for k, frame in enumerate(FRAMES):
        amount = (0.0, 1.0, 0.5)[k]
        for bone, axis, angle in MOTION:
            pb = arm.pose.bones[bone]
            pb.rotation_mode = "QUATERNION"
            pb.rotation_quaternion = Quaternion(axis, angle * amount)
            pb.keyframe_insert("rotation_quaternion", frame=frame)
    bpy.context.scene.frame_start, bpy.context.scene.frame_end = FRAMES[0], FRAMES[-1]
    return arm


def skirt(scale: float = 1.0, name: str = "Skirt"):
    """An open skirt around the hips, flaring away from the legs below them."""
    bm = bmesh.new()
    rows = []
    for i in range(14):
        z = 1.0 - 0.04 * i
        r = 0.18 + max(0.0, 0.9 - z) * 0.6 + 0.004
        rows.append(
            [
                bm.verts.new((r * math.cos(t) * scale, r * math.sin(t) * scale, z * scale))
                for t in np.linspace(0, 2 * math.pi, 40, endpoint=False)
            ]
        )
    for r0, r1 in zip(rows, rows[1:]):
        for k in range(40):
            bm.faces.new((r0[k], r0[(k + 1) % 40], r1[(k + 1) % 40], r1[k]))
    mesh = bpy.data.meshes.new(name)
    bm.to_mesh(mesh)
    bm.free()
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


# -- judging weights ------------------------------------------------------------------------------


def dense_weights(obj, bone_names: list[str]) -> np.ndarray:
    """`(V, B)` weights of `obj`'s groups named after `bone_names` (other groups ignored)."""
    index = {g.index: bone_names.index(g.name) for g in obj.vertex_groups if g.name in bone_names}
    w = np.zeros((len(obj.data.vertices), len(bone_names)), np.float64)
    for v in obj.data.vertices:
        for g in v.groups:
            if g.group in index:
                w[v.index, index[g.group]] += g.weight
    return w


def bone_segments(arm, bone_names: list[str], obj) -> tuple[np.ndarray, np.ndarray]:
    """Heads and tails of the bones in `obj`'s space."""
    to_obj = obj.matrix_world.inverted() @ arm.matrix_world
    heads = np.array([to_obj @ arm.data.bones[n].head_local for n in bone_names])
    tails = np.array([to_obj @ arm.data.bones[n].tail_local for n in bone_names])
    return heads, tails


def segment_distances(points: np.ndarray, heads: np.ndarray, tails: np.ndarray) -> np.ndarray:
    """`(V, B)` distances from each point to each bone segment."""
    ab = tails - heads
    t = np.einsum("vbk,bk->vb", points[:, None, :] - heads[None], ab) / np.maximum((ab * ab).sum(1), 1e-30)
    closest = heads[None] + np.clip(t, 0, 1)[..., None] * ab[None]
    return np.linalg.norm(points[:, None, :] - closest, axis=2)


def rest_positions(obj) -> np.ndarray:
    flat = np.empty(len(obj.data.vertices) * 3)
    obj.data.vertices.foreach_get("co", flat)
    return flat.reshape(-1, 3)


def edges_of(obj) -> np.ndarray:
    e = np.empty(len(obj.data.edges) * 2, np.int64)
    obj.data.edges.foreach_get("vertices", e)
    return e.reshape(-1, 2)


def edge_stretch(obj, frames) -> np.ndarray:
    """Per edge and frame, how far its length is from its rest length: `max(l/l0, l0/l) − 1`."""
    rest = rest_positions(obj)
    e = edges_of(obj)
    l0 = np.linalg.norm(rest[e[:, 0]] - rest[e[:, 1]], axis=1)
    keep = l0 > 1e-9 * np.ptp(rest, axis=0).max()
    out = []
    for f in frames:
        bpy.context.scene.frame_set(f)
        dg = bpy.context.evaluated_depsgraph_get()
        ev = obj.evaluated_get(dg)
        flat = np.empty(len(ev.data.vertices) * 3)
        ev.data.vertices.foreach_get("co", flat)
        p = flat.reshape(-1, 3)
        l = np.linalg.norm(p[e[:, 0]] - p[e[:, 1]], axis=1)[keep]
        ratio = l / l0[keep]
        out.append(np.maximum(ratio, 1.0 / np.maximum(ratio, 1e-12)) - 1.0)
    return np.concatenate(out)


def parent_with(mesh, arm, kind: str):
    """Blender's own Parent > With ... (`ARMATURE_AUTO`, `ARMATURE_ENVELOPE`, `ARMATURE_NAME`)."""
    bpy.context.view_layer.update()  # objects linked since the last update join the view layer
    for o in bpy.context.view_layer.objects:
        o.select_set(o in (mesh, arm))
    bpy.context.view_layer.objects.active = arm
    return bpy.ops.object.parent_set(type=kind)


def copy_of(obj, name: str):
    c = obj.copy()
    c.data = obj.data.copy()
    c.name = name
    c.vertex_groups.clear()
    c.modifiers.clear()
    c.parent = None
    bpy.context.scene.collection.objects.link(c)
    return c

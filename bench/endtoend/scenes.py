"""The benchmark's scenes: grids with their rigs, the B-Bone grid, CesiumMan (alone, subdivided,
a crowd) and the Rigify character of the tests."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

import bpy

ROOT = Path(__file__).resolve().parents[2]
ASSETS = ROOT.parent / "shared" / "assets"
sys.path.insert(0, str(ROOT / "tests" / "blender"))
import characters  # noqa: E402  (the Rigify character the tests use too)


def empty_scene() -> None:
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)


def grid_rig(vertices: int, bones_per_side: int = 8, influences: int = 4, seed: int = 1):
    """A square grid of about `vertices` vertices with a grid of bones above it, each vertex
    weighted to its 4 nearest bones (weights quantized to 16 levels so that vertex groups can be
    filled with few calls); every bone keyed to bend and twist over frames 1-40."""
    side = max(2, int(round(math.sqrt(vertices))))
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=side - 1, y_subdivisions=side - 1, size=8.0)
    grid = bpy.context.active_object
    grid.name = "Grid"
    arm_data = bpy.data.armatures.new("Rig")
    arm = bpy.data.objects.new("Rig", arm_data)
    bpy.context.scene.collection.objects.link(arm)
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="EDIT")
    heads = []
    for i in range(bones_per_side):
        for j in range(bones_per_side):
            b = arm_data.edit_bones.new(f"B{i}_{j}")
            x = -4.0 + 8.0 * (i + 0.5) / bones_per_side
            y = -4.0 + 8.0 * (j + 0.5) / bones_per_side
            b.head = (x, y, 0.0)
            b.tail = (x, y + 0.5, 0.0)
            heads.append((x, y))
    bpy.ops.object.mode_set(mode="OBJECT")
    heads = np.array(heads, np.float32)
    co = np.empty(len(grid.data.vertices) * 3, np.float32)
    grid.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)[:, :2]
    d2 = ((co[:, None, :] - heads[None, :, :]) ** 2).sum(-1)
    nearest = np.argsort(d2, axis=1)[:, :influences]
    w = 1.0 / (np.take_along_axis(d2, nearest, 1) + 0.05)
    w /= w.sum(1, keepdims=True)
    levels = np.clip(np.round(w * 15), 1, 15).astype(np.int64)
    groups = [grid.vertex_groups.new(name=f"B{i}_{j}") for i in range(bones_per_side) for j in range(bones_per_side)]
    for k in range(influences):
        for b in range(len(groups)):
            sel = nearest[:, k] == b
            for level in np.unique(levels[sel, k]):
                idx = np.flatnonzero(sel & (levels[:, k] == level))
                groups[b].add(idx.tolist(), float(level) / 15.0, "REPLACE")
    rng = np.random.default_rng(seed)
    for pb in arm.pose.bones:
        pb.rotation_mode = "QUATERNION"
        axis = rng.normal(size=3)
        for frame, angle in ((1, 0.0), (20, 1.2), (40, 2.4)):
            pb.rotation_quaternion = (math.cos(angle / 2), *(math.sin(angle / 2) * axis / np.linalg.norm(axis)))
            pb.keyframe_insert("rotation_quaternion", frame=frame)
    m = grid.modifiers.new("Armature", "ARMATURE")
    m.object = arm
    return grid, arm


def bbone_grid(vertices: int, mapping: str = "STRAIGHT"):
    """`grid_rig` with 16 bones (4×4), all B-Bones of 8 segments with a curved rest shape and
    their curves and eases keyed along with the rotations (frames 1-40)."""
    grid, arm = grid_rig(vertices, bones_per_side=4)
    for b in arm.data.bones:
        b.bbone_segments = 8
        b.bbone_mapping_mode = mapping
        b.bbone_curveinx, b.bbone_curveoutz = 0.15, -0.1
    for i, pb in enumerate(arm.pose.bones):
        for frame, amount in ((1, 0.0), (20, 1.0), (40, 0.5)):
            pb.bbone_curveinx = 0.4 * amount * math.cos(i)
            pb.bbone_curveoutx = -0.3 * amount * math.sin(i)
            pb.bbone_easein = 1.0 + 0.8 * amount
            for prop in ("bbone_curveinx", "bbone_curveoutx", "bbone_easein"):
                pb.keyframe_insert(prop, frame=frame)
    return grid, arm


def cesium_man():
    """CesiumMan imported (3,273 vertices, 19 bones, a walk): its mesh and armature."""
    bpy.ops.import_scene.gltf(filepath=str(ASSETS / "CesiumMan.glb"))
    body = next(o for o in bpy.data.objects if o.type == "MESH" and any(m.type == "ARMATURE" for m in o.modifiers))
    return body, next(m for m in body.modifiers if m.type == "ARMATURE").object


def subdivided_cesium_man(levels: int):
    """CesiumMan with a Subdivision Surface applied at rest (weights interpolated by Blender)."""
    body, arm = cesium_man()
    sub = body.modifiers.new("Subdivision", "SUBSURF")
    sub.levels = sub.render_levels = levels
    while body.modifiers[0] != sub:
        body.modifiers.move(body.modifiers.find(sub.name), 0)
    bpy.context.view_layer.objects.active = body
    arm.data.pose_position = "REST"
    bpy.context.view_layer.update()
    with bpy.context.temp_override(object=body, active_object=body):
        bpy.ops.object.modifier_apply(modifier=sub.name)
    arm.data.pose_position = "POSE"
    return body, arm


def crowd(count: int):
    """`count` CesiumMen side by side, each with its own armature playing the walk: [(mesh, armature)]."""
    src, arm0 = cesium_man()
    scene = bpy.context.scene
    pairs = [(src, arm0)]
    for i in range(count - 1):
        a = arm0.copy()
        scene.collection.objects.link(a)
        a.location.x += 1.0 + i
        m = src.copy()
        m.data = src.data.copy()
        scene.collection.objects.link(m)
        m.parent = a
        next(x for x in m.modifiers if x.type == "ARMATURE").object = a
        pairs.append((m, a))
    return pairs


def rigify():
    """The tests' Rigify character (`characters.rigify_character`): (body, rig)."""
    return characters.rigify_character()


def later_modifier(obj, later: str) -> None:
    """The modifier of the stack after the skinning one: Smooth (5 iterations), Corrective
    Smooth (5 iterations) or Subdivision Surface (level 2)."""
    if later == "smooth5":
        obj.modifiers.new("Smooth", "SMOOTH").iterations = 5
    elif later == "corrective5":
        obj.modifiers.new("CorrectiveSmooth", "CORRECTIVE_SMOOTH").iterations = 5
    elif later == "subsurf2":
        obj.modifiers.new("Subdivision", "SUBSURF").levels = 2
    elif later:
        raise ValueError(later)


def copy_of(obj, name: str):
    """A copy of `obj` with its own copy of the mesh, in the scene."""
    c = obj.copy()
    c.data = obj.data.copy()
    c.name = name
    bpy.context.scene.collection.objects.link(c)
    return c

"""A character with a generated Rigify rig, as artists make one: Blender's bundled `rigify`
add-on, the human metarig, a body mesh fitted to it, Generate Rig, parented with automatic
weights (160 deforming bones, 52 of them B-Bones on Blender 4.2-5.x), and an animation that
bends, twists and scales. Used by the tests and by `bench/blender_bench.py`.

Generating takes tens of seconds: `rigify_file(folder)` builds it once into a .blend that
callers open (and reuse within a session).
"""

from __future__ import annotations

import math
from pathlib import Path

import bpy

# Bones the body mesh does not cover (the face, hands' palms and the like get weights anyway).
_SKIP = ("face", "eye", "ear", "lip", "brow", "lid", "nose", "cheek", "jaw", "teeth", "tongue", "chin", "forehead", "temple", "breast", "pelvis", "heel", "palm")


def body_mesh(metarig, radius: float = 0.05, subdivisions: int = 2):
    """A body around the metarig's bones: a Skin modifier over a skeleton of its bones, applied,
    then subdivided (about 9,000 vertices with the defaults)."""
    verts, edges, index = [], [], {}

    def vertex(p):
        key = tuple(round(c, 4) for c in p)
        if key not in index:
            index[key] = len(verts)
            verts.append(key)
        return index[key]

    for b in metarig.data.bones:
        if not any(s in b.name for s in _SKIP):
            edges.append((vertex(b.head_local), vertex(b.tail_local)))
    mesh = bpy.data.meshes.new("Body")
    mesh.from_pydata(verts, edges, [])
    body = bpy.data.objects.new("Body", mesh)
    bpy.context.scene.collection.objects.link(body)
    body.modifiers.new("Skin", "SKIN")
    for v in body.data.skin_vertices[0].data:
        v.radius = (radius, radius)
    body.modifiers.new("Subdivision", "SUBSURF").levels = subdivisions
    bpy.context.view_layer.objects.active = body
    for m in list(body.modifiers):
        with bpy.context.temp_override(object=body, active_object=body):
            bpy.ops.object.modifier_apply(modifier=m.name)
    return body


def animate_rig(rig, frames: int = 24) -> None:
    """Keys on the rig's controls over `frames` frames: bends (arms, legs, spine), twists
    (forearms) and scales (the torso), beyond 90 degrees where Linear and Dual Quaternion differ."""
    pose = rig.pose.bones
    moves = [
        ("upper_arm_fk.L", "rotation", (1, 0, 0), 1.6),
        ("upper_arm_fk.R", "rotation", (0, 0, 1), -1.2),
        ("forearm_fk.L", "rotation", (0, 1, 0), 2.2),  # a twist along the bone
        ("thigh_fk.L", "rotation", (1, 0, 0), -1.3),
        ("shin_fk.R", "rotation", (1, 0, 0), 1.5),
        ("chest", "rotation", (0, 0, 1), 0.7),
        ("torso", "scale", (1.0, 1.25, 1.0), 1.0),
    ]
    for name, kind, axis, amount in moves:
        pb = pose.get(name)
        if pb is None:
            continue
        pb.rotation_mode = "QUATERNION"
        for frame, t in ((1, 0.0), (frames // 2, 1.0), (frames, 0.4)):
            if kind == "rotation":
                half = 0.5 * amount * t
                n = math.sqrt(sum(a * a for a in axis))
                pb.rotation_quaternion = (math.cos(half), *(math.sin(half) * a / n for a in axis))
                pb.keyframe_insert("rotation_quaternion", frame=frame)
            else:
                pb.scale = tuple(1.0 + (a - 1.0) * t for a in axis)
                pb.keyframe_insert("scale", frame=frame)


def select_only_object(obj) -> None:
    for o in bpy.context.view_layer.objects:
        o.select_set(o is obj)
    bpy.context.view_layer.objects.active = obj


def build_rigify_character():
    """In the current (empty) scene: metarig, body, generated rig, automatic weights, animation.
    Returns `(body, rig, metarig)`."""
    import addon_utils

    addon_utils.enable("rigify", default_set=True)
    bpy.ops.object.armature_human_metarig_add()
    metarig = bpy.context.active_object
    body = body_mesh(metarig)
    select_only_object(metarig)
    assert bpy.ops.pose.rigify_generate() == {"FINISHED"}  # (an override of the context would pin Rigify's)
    rig = next(o for o in bpy.data.objects if o.type == "ARMATURE" and o is not metarig and o.name.startswith("rig"))
    for o in bpy.context.view_layer.objects:
        o.select_set(o in (body, rig))
    bpy.context.view_layer.objects.active = rig
    with bpy.context.temp_override(active_object=rig, object=rig, selected_objects=[body, rig], selected_editable_objects=[body, rig]):
        assert bpy.ops.object.parent_set(type="ARMATURE_AUTO") == {"FINISHED"}
    animate_rig(rig)
    bpy.context.scene.frame_start, bpy.context.scene.frame_end = 1, 24
    return body, rig, metarig


def rigify_file(folder: Path) -> Path:
    """A .blend in `folder` with the character of `build_rigify_character` (built if missing)."""
    path = Path(folder) / f"rigify-{bpy.app.version_string}.blend"
    if not path.exists():
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        build_rigify_character()
        bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    return path


def open_rigify_character(folder: Path):
    """Opens the Rigify character file (see `rigify_file`); returns `(body, rig, metarig)`."""
    import addon_utils

    addon_utils.enable("rigify", default_set=True)
    bpy.ops.wm.open_mainfile(filepath=str(rigify_file(folder)))
    body = bpy.data.objects["Body"]
    rig = next(m.object for m in body.modifiers if m.type == "ARMATURE")
    metarig = next(o for o in bpy.data.objects if o.type == "ARMATURE" and o is not rig)
    return body, rig, metarig


def bbone_counts(rig) -> tuple[int, int]:
    """(deforming bones, deforming B-Bones)."""
    deforming = [b for b in rig.data.bones if b.use_deform]
    return len(deforming), sum(1 for b in deforming if b.bbone_segments > 1)

"""A character with a generated Rigify rig, as artists make one: Blender's bundled `rigify`
add-on, the human metarig, a body mesh fitted to it, `pose.rigify_generate`, automatic weights
and an animation that bends, twists and scales (FK arms and left leg, an IK right leg, scaled
tweak bones). Used by the tests and by `bench/blender_bench.py`.

The body is a Skin modifier over the metarig's body bones (the face bones left out), applied and
subdivided twice: one closed mesh of about 14,000 vertices. The generated rig has 160 deforming
bones, 52 of them B-Bones with 8 or 10 segments (Rigify's limbs, spine and face, on Blender
4.2-5.x); automatic weights bind the body to the ones near it.

Generating takes tens of seconds: `rigify_file(folder)` builds it once into a .blend that
tests open (and reuse within a session).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

import bpy

import addon_utils  # noqa: E402  (importable once bpy is)

# Controls animated on frames 1-40 (Rigify's names): (bone, rotation axis, angle, scale).
MOTION = [
    ("torso", (0, 0, 1), 0.5, None),
    ("hips", (1, 0, 0), 0.3, None),
    ("chest", (0, 1, 0), 0.4, (1.1, 0.95, 1.1)),
    ("neck", (1, 0, 0), -0.4, None),
    ("head", (0, 0, 1), 0.6, None),
    ("upper_arm_fk.L", (1, 0, 0), 1.2, (1.0, 1.15, 1.0)),
    ("forearm_fk.L", (0, 1, 0), 1.4, None),  # about the bone: a twist
    ("hand_fk.L", (0, 0, 1), 0.7, None),
    ("upper_arm_fk.R", (0, 0, 1), -1.0, None),
    ("forearm_fk.R", (1, 0, 0), 1.6, (0.9, 1.0, 0.9)),
    ("thigh_fk.L", (1, 0, 0), -0.9, None),
    ("shin_fk.L", (1, 0, 0), 1.3, None),
    ("thigh_fk.R", (0, 1, 0), 0.8, None),
    ("shin_fk.R", (1, 0, 0), 0.6, None),
    ("forearm_tweak.L", (0, 1, 0), 0.3, (1.3, 1.0, 1.3)),  # a scaled tweak: the B-Bones' ends scale
    ("shin_tweak.L", (1, 0, 0), 0.2, (0.8, 1.0, 0.8)),
]
# The IK/FK switches of the limbs (1: FK, 0: IK): the arms and the left leg follow the FK controls
# above, the right leg its IK foot (moved by IK_FOOT at full amount).
LIMBS = {"upper_arm_parent.L": 1.0, "upper_arm_parent.R": 1.0, "thigh_parent.L": 1.0, "thigh_parent.R": 0.0}
IK_FOOT = ("foot_ik.R", (0.0, -0.25, 0.3))


def _in_face(bone) -> bool:
    while bone is not None:
        if bone.name == "face":
            return True
        bone = bone.parent
    return False


def _radius(bone) -> float:
    if bone.name.startswith("spine"):
        return 0.05 if bone.name in ("spine.004", "spine.005") else 0.13
    return min(0.14, max(0.008, 0.3 * bone.length))


def body_mesh(metarig):
    """A closed body around the metarig's bones (face bones left out): a Skin modifier over the
    bones (each split in three, unconnected bones joined to the nearest end of their parent),
    applied, then two levels of subdivision."""
    index: dict[tuple, int] = {}
    verts, radii, edges = [], [], []

    def vertex(p, r: float) -> int:
        key = tuple(round(float(x), 4) for x in p)
        if key not in index:
            index[key] = len(verts)
            verts.append(tuple(p))
            radii.append(r)
        else:
            radii[index[key]] = max(radii[index[key]], r)
        return index[key]

    for b in metarig.data.bones:
        if _in_face(b):
            continue
        r = _radius(b)
        head, tail = b.head_local, b.tail_local
        ring = [vertex(head + (tail - head) * (k / 3), r * (1.0 - 0.05 * k)) for k in range(4)]
        edges += list(zip(ring, ring[1:]))
        h = ring[0]
        if b.parent is not None and not b.use_connect and not _in_face(b.parent):
            ph, pt = b.parent.head_local, b.parent.tail_local
            near = vertex(ph if (ph - head).length < (pt - head).length else pt, r)
            if near != h:
                edges.append((near, h))
    mesh = bpy.data.meshes.new("Body")
    mesh.from_pydata(verts, edges, [])
    obj = bpy.data.objects.new("Body", mesh)
    bpy.context.scene.collection.objects.link(obj)
    obj.modifiers.new("Skin", "SKIN")
    for i, sv in enumerate(mesh.skin_vertices[0].data):
        sv.radius = (radii[i], radii[i])
    mesh.skin_vertices[0].data[0].use_root = True
    sub = obj.modifiers.new("Subdivision", "SUBSURF")
    sub.levels = 2
    with bpy.context.temp_override(object=obj, active_object=obj):
        for name in ("Skin", "Subdivision"):
            bpy.ops.object.modifier_apply(modifier=name)
    return obj


def animate(rig, frames=(1, 20, 40), scaling_only: bool = False) -> None:
    """Keys the controls of `MOTION` at `frames`: rest, full, then half way back. With
    `scaling_only`, only the scales move (the rotations and the IK foot stay at rest): what the
    animation asks of the body's volume, which no skinning method changes without rotations."""
    for name, fk in LIMBS.items():
        rig.pose.bones[name]["IK_FK"] = fk
    for k, frame in enumerate(frames):
        amount = (0.0, 1.0, 0.5)[k % 3]
        moves = 0.0 if scaling_only else amount
        foot, offset = IK_FOOT
        rig.pose.bones[foot].location = tuple(moves * x for x in offset)
        rig.pose.bones[foot].keyframe_insert("location", frame=frame)
        for name, axis, angle, scale in MOTION:
            pb = rig.pose.bones[name]
            pb.rotation_mode = "QUATERNION"
            a = np.array(axis, float) / np.linalg.norm(axis)
            half = 0.5 * angle * moves
            pb.rotation_quaternion = (math.cos(half), *(math.sin(half) * a))
            pb.keyframe_insert("rotation_quaternion", frame=frame)
            if scale is not None:
                pb.scale = tuple(1.0 + (s - 1.0) * amount for s in scale)
                pb.keyframe_insert("scale", frame=frame)
    bpy.context.scene.frame_start, bpy.context.scene.frame_end = frames[0], frames[-1]


def select_only_object(obj) -> None:
    for o in bpy.context.view_layer.objects:
        o.select_set(o is obj)
    bpy.context.view_layer.objects.active = obj


def build_rigify_character():
    """In the current (empty) scene: metarig, body, generated rig, automatic weights, animation.
    Returns `(body, rig, metarig)`."""
    was_enabled = addon_utils.check("rigify")[1]
    addon_utils.enable("rigify", default_set=True)  # Rigify reads its preferences
    try:
        bpy.ops.object.armature_human_metarig_add()
        metarig = bpy.context.active_object
        body = body_mesh(metarig)
        select_only_object(metarig)
        assert bpy.ops.pose.rigify_generate() == {"FINISHED"}  # (an override of the context would pin Rigify's)
    finally:
        if not was_enabled:  # later tests and benchmark cases see the add-on state they had
            addon_utils.disable("rigify", default_set=True)
    rig = next(o for o in bpy.data.objects if o.type == "ARMATURE" and o is not metarig and o.name.startswith("rig"))
    bpy.ops.object.mode_set(mode="OBJECT")
    for o in bpy.context.view_layer.objects:
        o.select_set(o in (body, rig))
    bpy.context.view_layer.objects.active = rig
    with bpy.context.temp_override(active_object=rig, object=rig, selected_objects=[body, rig], selected_editable_objects=[body, rig]):
        assert bpy.ops.object.parent_set(type="ARMATURE_AUTO") == {"FINISHED"}
    animate(rig)
    return body, rig, metarig


def rigify_character():
    """The character of `build_rigify_character` without its metarig: `(body, rig)`."""
    body, rig, metarig = build_rigify_character()
    bpy.data.objects.remove(metarig)
    return body, rig


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

"""A generated Rigify character, as production rigs are: Rigify's human metarig, a body mesh
fitted to it, `pose.rigify_generate`, automatic weights and an animation that bends, twists and
scales. Used by the tests and by `bench/blender_bench.py`.

The body is a Skin modifier over the metarig's body bones (the face bones left out), applied and
subdivided twice: one closed mesh of about 14,000 vertices. The generated rig has 160 deforming
bones, 52 of them B-Bones with 8 or 10 segments (Rigify's limbs, spine and face); automatic
weights bind the body to the ones near it.
"""

from __future__ import annotations

import math

import bpy
import addon_utils  # noqa: E402  (importable once bpy is)
import numpy as np

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
]
# The IK/FK switches of the four limbs, set to FK so that the FK controls above drive them.
LIMBS = ("upper_arm_parent.L", "upper_arm_parent.R", "thigh_parent.L", "thigh_parent.R")


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


def animate(rig, frames=(1, 20, 40)) -> None:
    """Keys the controls of `MOTION` at `frames`: rest, full, then half way back."""
    for name in LIMBS:
        rig.pose.bones[name]["IK_FK"] = 1.0
    for k, frame in enumerate(frames):
        amount = (0.0, 1.0, 0.5)[k % 3]
        for name, axis, angle, scale in MOTION:
            pb = rig.pose.bones[name]
            pb.rotation_mode = "QUATERNION"
            a = np.array(axis, float) / np.linalg.norm(axis)
            half = 0.5 * angle * amount
            pb.rotation_quaternion = (math.cos(half), *(math.sin(half) * a))
            pb.keyframe_insert("rotation_quaternion", frame=frame)
            if scale is not None:
                pb.scale = tuple(1.0 + (s - 1.0) * amount for s in scale)
                pb.keyframe_insert("scale", frame=frame)
    bpy.context.scene.frame_start, bpy.context.scene.frame_end = frames[0], frames[-1]


def rigify_character():
    """A generated Rigify character in the current (empty) scene: `(body, rig)`; the body has an
    Armature modifier with automatic weights on the rig, and the rig is animated (`animate`).
    The metarig is removed, and Rigify is left enabled only if it was (the generated rig needs
    nothing of it). Takes 15-40 s (Rigify generation)."""
    was_enabled = addon_utils.check("rigify")[1]
    addon_utils.enable("rigify", default_set=True)  # Rigify reads its preferences
    try:
        bpy.ops.object.armature_human_metarig_add()
        metarig = bpy.context.active_object
        body = body_mesh(metarig)
        for o in bpy.context.view_layer.objects:
            o.select_set(False)
        bpy.context.view_layer.objects.active = metarig
        metarig.select_set(True)
        assert bpy.ops.pose.rigify_generate() == {"FINISHED"}
        rig = bpy.context.active_object
    finally:
        if not was_enabled:
            addon_utils.disable("rigify", default_set=True)
    bpy.ops.object.mode_set(mode="OBJECT")
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    body.select_set(True)
    rig.select_set(True)
    bpy.context.view_layer.objects.active = rig
    assert bpy.ops.object.parent_set(type="ARMATURE_AUTO") == {"FINISHED"}
    bpy.data.objects.remove(metarig)
    animate(rig)
    return body, rig

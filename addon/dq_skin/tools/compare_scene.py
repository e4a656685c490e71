# SPDX-License-Identifier: GPL-3.0-or-later
"""The comparison scene: a rigged mesh (or built-in test rigs) deformed side by side by the
Armature modifier (Linear, Preserve Volume) and by DQ Skin (Linear, Dual Quaternion, Blend,
Optimized Centers), labelled, sharing one animation, with a camera and a light."""

from __future__ import annotations

import math

import numpy as np

import bpy

from mathutils import Quaternion, Vector

from ..blender import compat
from ..ops import modifiers as operators

VARIANTS = (
    ("Armature Linear", "armature", False),
    ("Armature Preserve Volume", "armature", True),
    ("DQ Skin Linear", "LINEAR", None),
    ("DQ Skin Dual Quaternion", "DUAL_QUATERNION", None),
    ("DQ Skin Blend", "BLEND", None),
    ("DQ Skin Optimized Centers", "CENTERS_OF_ROTATION", None),
)
FRAMES = (1, 48)


def _tube_rig(scene, name, bones, length=4.0, radius=0.4, rings=32, segments=24):
    """A closed tube along +Z with a chain of bones and blended weights (like a limb)."""
    arm = bpy.data.objects.new(f"{name} Rig", bpy.data.armatures.new(f"{name} Rig"))
    scene.collection.objects.link(arm)
    bpy.context.view_layer.objects.active = arm
    with bpy.context.temp_override(active_object=arm, object=arm, edit_object=arm):
        bpy.ops.object.mode_set(mode="EDIT")
        prev = None
        for i in range(bones):
            b = arm.data.edit_bones.new(f"Bone{i}")
            b.head, b.tail = (0, 0, length * i / bones), (0, 0, length * (i + 1) / bones)
            if prev:
                b.parent, b.use_connect = prev, True
            prev = b
        bpy.ops.object.mode_set(mode="OBJECT")
    verts = [
        (radius * math.cos(2 * math.pi * s / segments), radius * math.sin(2 * math.pi * s / segments), length * r / (rings - 1))
        for r in range(rings)
        for s in range(segments)
    ]
    verts += [(0, 0, 0), (0, 0, length)]
    faces = [
        (r * segments + s, r * segments + (s + 1) % segments, (r + 1) * segments + (s + 1) % segments, (r + 1) * segments + s)
        for r in range(rings - 1)
        for s in range(segments)
    ]
    bottom, top, last = len(verts) - 2, len(verts) - 1, (rings - 1) * segments
    faces += [(bottom, (s + 1) % segments, s) for s in range(segments)]
    faces += [(top, last + s, last + (s + 1) % segments) for s in range(segments)]
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    obj = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(obj)
    groups = [obj.vertex_groups.new(name=f"Bone{i}") for i in range(bones)]
    for v in mesh.vertices:
        u = min(bones - 1e-6, max(0.0, v.co.z / length * bones))
        i, f = int(u), u - int(u)
        blend_next = max(0.0, (f - 0.75) / 0.5) if i + 1 < bones else 0.0
        blend_prev = max(0.0, (0.25 - f) / 0.5) if i > 0 else 0.0
        groups[i].add([v.index], 1 - blend_next - blend_prev, "REPLACE")
        if blend_next:
            groups[i + 1].add([v.index], blend_next, "REPLACE")
        if blend_prev:
            groups[i - 1].add([v.index], blend_prev, "REPLACE")
    mod = obj.modifiers.new("Armature", "ARMATURE")
    mod.object = arm
    for pb in arm.pose.bones:
        pb.rotation_mode = "QUATERNION"
    return obj, arm


def builtin_rigs(scene):
    """The three test rigs, animated over FRAMES: a candy-wrapper twist, an elbow bend and a
    shoulder raise."""
    rigs = []
    obj, arm = _tube_rig(scene, "Candy Wrapper Twist", 2)
    rigs.append((obj, arm, "Bone1", (0, 1, 0), math.radians(180)))  # about the bone's own axis
    obj, arm = _tube_rig(scene, "Elbow Bend", 2)
    rigs.append((obj, arm, "Bone1", (0, 0, -1), math.radians(130)))  # bends across the view
    obj, arm = _tube_rig(scene, "Shoulder Raise", 3, length=5.0)
    rigs.append((obj, arm, "Bone1", (0, 0, 1), math.radians(150)))
    out = []
    for obj, arm, bone, axis, angle in rigs:
        pb = arm.pose.bones[bone]
        for frame, a in ((FRAMES[0], 0.0), (FRAMES[1], angle)):
            pb.rotation_quaternion = Quaternion(axis, a)
            pb.keyframe_insert("rotation_quaternion", frame=frame)
        out.append(obj)
    return out


def build(context, sources, spacing: float | None = None):
    """A "DQ Skin Comparison" collection in the current scene with one row per source mesh and
    one column per variant, each labelled. Returns `(collection, rows)`, `rows[i][name]` the
    variant objects."""
    scene = context.scene
    collection = bpy.data.collections.new("DQ Skin Comparison")
    scene.collection.children.link(collection)
    # One column pitch for every row, so that columns line up and labels have one size: as
    # wide as the widest source gets over its animation (sampled), so that bent or striding
    # meshes do not overlap and characters stay large in the picture.
    extents = _animated_extents(context, sources)
    step = spacing or max(max(w, 0.35 * h) * 1.25 + 0.06 * h for w, h in extents)
    label_size = min(step / 9, max(h for _, h in extents) / 12)
    label_material = flat_material("DQ Skin Label", (0.9, 0.9, 0.9))
    rows = []
    y = 0.0
    for src, (_, height) in zip(sources, extents):
        arm_src = next(m for m in src.modifiers if m.type == "ARMATURE").object
        row = {}
        # Labels at one height per row: above the source as it stands now.
        context.view_layer.update()
        corners = [src.matrix_world @ Vector(c) for c in src.bound_box]
        top = max(c.z for c in corners) - y
        middle = (min(c.x for c in corners) + max(c.x for c in corners)) / 2
        for col, (label, kind, preserve) in enumerate(VARIANTS):
            offset = Vector((col * step, 0.0, -y))  # rows stack downwards, facing the camera
            arm = arm_src.copy()
            arm.matrix_world = arm_src.matrix_world.copy()
            arm.location += offset
            obj = src.copy()
            obj.data = src.data
            if src.parent == arm_src:
                obj.parent = arm  # moves with its armature copy
            else:
                obj.location += offset
            collection.objects.link(arm)
            collection.objects.link(obj)
            arm_mod = next(m for m in obj.modifiers if m.type == "ARMATURE")
            arm_mod.object = arm
            for m in [m for m in obj.modifiers if m.type == "NODES"]:
                obj.modifiers.remove(m)
            if kind == "armature":
                arm_mod.use_deform_preserve_volume = preserve
                arm_mod.show_viewport = arm_mod.show_render = True
            else:
                context.view_layer.objects.active = obj
                with context.temp_override(object=obj, active_object=obj):
                    bpy.ops.object.dq_skin_add(method=kind)
                if kind == "BLEND":
                    mod = next(m for m in obj.modifiers if m.type == "NODES")
                    operators.set_input(mod, "Blend Factor", 0.5)
            head, _, tail = label.partition(" Skin " if label.startswith("DQ") else " ")
            body = f"{head} Skin\n{tail}" if label.startswith("DQ") else f"{head}\n{tail}"
            caption = text(collection, f"{label} label", body, label_size, label_material)
            caption.location = (middle + offset.x, 0.0, top + label_size * 2.2)
            row[label] = obj
        rows.append(row)
        y += height * 1.2 + label_size * 4.5
    for src in sources:  # the originals stay, hidden, so the comparison shows once
        src.hide_viewport = src.hide_render = True
        arm_src = next(m for m in src.modifiers if m.type == "ARMATURE").object
        arm_src.hide_viewport = arm_src.hide_render = True
    _camera_and_light(scene, collection)
    return collection, rows


def _animated_extents(context, sources, samples: int = 9) -> list[tuple[float, float]]:
    """The largest X (across the picture) and Z (up) extents of each source's deformed mesh
    over the scene's frame range (sampled), in world space. The current frame is restored."""
    scene = context.scene
    current = scene.frame_current
    extents = [(0.0, 0.0)] * len(sources)
    start, end = scene.frame_start, max(scene.frame_end, scene.frame_start)
    for i in range(samples):
        scene.frame_set(round(start + (end - start) * i / max(samples - 1, 1)))
        depsgraph = context.evaluated_depsgraph_get()
        for k, src in enumerate(sources):
            ev = src.evaluated_get(depsgraph)
            corners = [src.matrix_world @ Vector(c) for c in ev.bound_box]
            w = max(c.x for c in corners) - min(c.x for c in corners)
            h = max(c.z for c in corners) - min(c.z for c in corners)
            extents[k] = (max(extents[k][0], w), max(extents[k][1], h))
    scene.frame_set(current)
    return extents


def text(collection, name, body, size, material, align="CENTER"):
    text = bpy.data.objects.new(name, bpy.data.curves.new(name, "FONT"))
    text.data.body = body
    text.data.size = size
    text.data.align_x = align
    text.data.materials.append(material)
    text.rotation_euler = (math.pi / 2, 0, 0)  # faces the camera, which looks along +Y
    collection.objects.link(text)
    return text


def flat_material(name, color):
    """A material that shows `color` whatever the light (labels, the legend)."""
    mat = compat.node_material(name)
    nodes = mat.node_tree.nodes
    nodes.clear()
    emission = nodes.new("ShaderNodeEmission")
    emission.inputs["Color"].default_value = (*color, 1.0)
    out = nodes.new("ShaderNodeOutputMaterial")
    mat.node_tree.links.new(emission.outputs["Emission"], out.inputs["Surface"])
    return mat


def _camera_and_light(scene, collection):
    cam = bpy.data.objects.new("Comparison Camera", bpy.data.cameras.new("Comparison Camera"))
    cam.data.type = "ORTHO"
    cam.rotation_euler = (math.pi / 2, 0, 0)
    collection.objects.link(cam)
    scene.camera = cam
    sun = bpy.data.objects.new("Comparison Sun", bpy.data.lights.new("Comparison Sun", "SUN"))
    sun.data.energy = 3.0
    sun.rotation_euler = (math.radians(50), math.radians(10), math.radians(-30))
    collection.objects.link(sun)
    world = bpy.data.worlds.new("Comparison World")
    world.color = (0.05, 0.05, 0.06)
    scene.world = world
    fit_camera(bpy.context, scene, collection)


def visible_bounds(context, collection):
    """World-space bounds of what the comparison shows at the current frame: the deformed meshes
    (evaluated) and the labels."""
    depsgraph = context.evaluated_depsgraph_get()
    points = []
    for obj in collection.all_objects:
        if obj.hide_render or obj.type not in ("MESH", "FONT"):
            continue
        ev = obj.evaluated_get(depsgraph)
        if obj.type == "MESH" and len(ev.data.vertices):
            co = np.empty(len(ev.data.vertices) * 3, np.float32)
            ev.data.vertices.foreach_get("co", co)
            m = np.array(obj.matrix_world)
            points.append(co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3])
        else:
            points.append(np.array([obj.matrix_world @ Vector(c) for c in ev.bound_box]))
    if not points:
        return np.zeros(3), np.ones(3)
    allp = np.concatenate(points)
    return allp.min(0), allp.max(0)


def fit_camera(context, scene, collection=None) -> float:
    """Frames the comparison as it is at the current frame (deformed), with a small margin.
    Returns the content's width / height, for a picture without empty bands."""
    collection = collection or bpy.data.collections["DQ Skin Comparison"]
    cam = scene.camera
    lo, hi = visible_bounds(context, collection)
    margin = 0.04 * max(hi[0] - lo[0], hi[2] - lo[2])
    width, height = hi[0] - lo[0] + 2 * margin, hi[2] - lo[2] + 2 * margin
    aspect = scene.render.resolution_x * scene.render.pixel_aspect_x / max(1, scene.render.resolution_y * scene.render.pixel_aspect_y)
    cam.data.ortho_scale = float(max(width, height * aspect))
    center = (lo + hi) / 2
    cam.location = (float(center[0]), float(lo[1] - 20.0), float(center[2]))
    cam.data.clip_end = float(hi[1] - lo[1] + 40.0)
    return float(width / max(height, 1e-9))

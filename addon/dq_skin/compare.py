# SPDX-License-Identifier: GPL-3.0-or-later
"""Comparison scenes: a rigged mesh (or built-in test rigs) deformed side by side by the
Armature modifier (Linear, Preserve Volume) and by DQ Skin (Linear, Dual Quaternion, Blend),
labelled, sharing one animation, with a camera and a light; and the numbers to choose by."""

from __future__ import annotations

import math
import time

import bpy
import numpy as np
from mathutils import Quaternion, Vector

from . import dqskin, operators

VARIANTS = (
    ("Armature Linear", "armature", False),
    ("Armature Preserve Volume", "armature", True),
    ("DQ Skin Linear", "LINEAR", None),
    ("DQ Skin Dual Quaternion", "DUAL_QUATERNION", None),
    ("DQ Skin Blend", "BLEND", None),
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
    verts = [(radius * math.cos(2 * math.pi * s / segments), radius * math.sin(2 * math.pi * s / segments), length * r / (rings - 1))
             for r in range(rings) for s in range(segments)]
    verts += [(0, 0, 0), (0, 0, length)]
    faces = [(r * segments + s, r * segments + (s + 1) % segments, (r + 1) * segments + (s + 1) % segments, (r + 1) * segments + s)
             for r in range(rings - 1) for s in range(segments)]
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
    one column per variant. Returns `(collection, rows)`, `rows[i][name]` the variant objects."""
    scene = context.scene
    collection = bpy.data.collections.new("DQ Skin Comparison")
    scene.collection.children.link(collection)
    rows = []
    y = 0.0
    for src in sources:
        arm_src = next(m for m in src.modifiers if m.type == "ARMATURE").object
        size = Vector(src.dimensions)
        step = spacing or max(size.x, size.z * 0.6) * 1.6 + 0.5
        row = {}
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
            text = bpy.data.objects.new(f"{label} label", bpy.data.curves.new(f"{label} label", "FONT"))
            head, _, tail = label.partition(" Skin " if label.startswith("DQ") else " ")
            text.data.body = f"{head} Skin\n{tail}" if label.startswith("DQ") else f"{head}\n{tail}"
            text.data.size = 0.25 * max(size.z, 1.0) / 4
            text.data.align_x = "CENTER"
            context.view_layer.update()
            text.location = obj.matrix_world.translation + Vector((0, 0, size.z * 1.1 + 0.3))
            text.rotation_euler = (math.pi / 2, 0, 0)
            collection.objects.link(text)
            row[label] = obj
        rows.append(row)
        y += size.z * 1.8 + 1.5
    for src in sources:  # the originals stay, hidden, so the comparison shows once
        src.hide_viewport = src.hide_render = True
        arm_src = next(m for m in src.modifiers if m.type == "ARMATURE").object
        arm_src.hide_viewport = arm_src.hide_render = True
    _camera_and_light(scene, collection, [o for r in rows for o in r.values()])
    return collection, rows


def _camera_and_light(scene, collection, objects):
    points = np.array([o.matrix_world @ Vector(c) for o in objects for c in o.bound_box])
    lo, hi = points.min(0), points.max(0)
    center = (lo + hi) / 2
    cam = bpy.data.objects.new("Comparison Camera", bpy.data.cameras.new("Comparison Camera"))
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = float(max(hi[0] - lo[0], (hi[2] - lo[2]) * 16 / 9) * 1.15 + 1.0)
    cam.location = (float(center[0]), float(lo[1] - 20.0), float(center[2] + 0.6))
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


def _positions(obj, depsgraph):
    ev = obj.evaluated_get(depsgraph)
    flat = np.empty(len(ev.data.vertices) * 3, np.float32)
    ev.data.attributes["position"].data.foreach_get("vector", flat)
    return flat.reshape(-1, 3)


def _triangles(mesh):
    mesh.calc_loop_triangles()
    tris = np.empty(len(mesh.loop_triangles) * 3, np.int64)
    mesh.loop_triangles.foreach_get("vertices", tris)
    return tris.reshape(-1, 3)


def _closed(mesh) -> bool:
    counts = {}
    for p in mesh.polygons:
        for e in p.edge_keys:
            counts[e] = counts.get(e, 0) + 1
    return bool(counts) and all(c == 2 for c in counts.values())


def report(context, scene, rows, frames, check=None):
    """Per row and variant: max and mean deviation from both built-in methods, volume relative
    to rest (closed meshes), and the per-frame evaluation time. `check` is called every frame and
    may raise to stop (the command line's Ctrl-C and SIGTERM)."""
    check = check or (lambda: None)
    result = []
    for row in rows:
        names = list(row)
        first = row[names[0]]
        mesh = first.data
        tris = _triangles(mesh) if _closed(mesh) else None
        rest_co = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", rest_co)
        rest_volume = dqskin.mesh_volume(rest_co.reshape(-1, 3), tris) if tris is not None else None
        per = {n: {"positions": [], "seconds": 0.0} for n in names}
        for f in frames:
            check()
            scene.frame_set(f)
            depsgraph = context.evaluated_depsgraph_get()
            for n in names:
                # The copies stand side by side with their own armatures; in each copy's own
                # space the deformations are directly comparable.
                per[n]["positions"].append(_positions(row[n], depsgraph))
        for n in names:
            others = [o for o in names if o != n]
            for o in others:
                row[o].hide_viewport = True
            start = time.perf_counter()
            for f in frames:
                check()
                scene.frame_set(f)
                _positions(row[n], context.evaluated_depsgraph_get())
            per[n]["seconds"] = time.perf_counter() - start
            for o in others:
                row[o].hide_viewport = False
        entry = {"mesh": first.name.split(".")[0], "vertices": len(mesh.vertices), "frames": [frames[0], frames[-1]], "methods": {}}
        for n in names:
            ours = np.stack(per[n]["positions"])
            stats = {"ms_per_frame": per[n]["seconds"] / len(frames) * 1e3}
            for ref in ("Armature Linear", "Armature Preserve Volume"):
                d = np.linalg.norm(ours - np.stack(per[ref]["positions"]), axis=2)
                stats[f"max_deviation_from_{ref.lower().replace(' ', '_')}"] = float(d.max())
                stats[f"mean_deviation_from_{ref.lower().replace(' ', '_')}"] = float(d.mean())
            if tris is not None and rest_volume:
                last = per[n]["positions"][-1]
                stats["volume_relative_to_rest"] = dqskin.mesh_volume(np.ascontiguousarray(last, np.float32), tris) / rest_volume
            entry["methods"][n] = stats
        result.append(entry)
    return result


def write_report(result, out_dir, source: str, frames, picture: str | None = None) -> None:
    """`report.json` and `report.md` in `out_dir` (each written to a temporary file first)."""
    import json
    import os
    import tempfile
    from pathlib import Path

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    start, end = frames[0], frames[-1]
    lines = [f"# DQ Skin vs the Armature modifier: {source}, frames {start}-{end}", ""]
    lines.append("| mesh | method | max dev. from Linear | max dev. from Preserve Volume | volume / rest | ms/frame |")
    lines.append("|---|---|---|---|---|---|")
    for row in result:
        for method, r in row["methods"].items():
            volume = r.get("volume_relative_to_rest")
            lines.append(
                f"| {row['mesh']} | {method} | {r['max_deviation_from_armature_linear']:.3e} | "
                f"{r['max_deviation_from_armature_preserve_volume']:.3e} | "
                f"{'' if volume is None else f'{volume:.3f}'} | {r['ms_per_frame']:.2f} |"
            )
    if picture:
        lines += ["", f"![comparison at frame {end}]({picture})"]
    texts = {
        "report.json": json.dumps({"source": source, "frames": [start, end], "rows": result}, indent=2),
        "report.md": "\n".join(lines) + "\n",
    }
    for name, text in texts.items():
        tmp = out / f".{name}.dqskin-{os.getpid()}.tmp"
        with open(tmp, "w") as f:
            f.write(text)
        os.replace(tmp, out / name)


def render(scene, path, width=960, height=540, samples=8) -> None:
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(path)
    with bpy.context.temp_override(scene=scene):
        bpy.ops.render.render(write_still=True, scene=scene.name)


class OBJECT_OT_dq_skin_comparison_scene(bpy.types.Operator):
    """Build a scene comparing the Armature modifier (Linear, Preserve Volume) with DQ Skin
    (Linear, Dual Quaternion, Blend) side by side, for the active rigged mesh or, with nothing
    selected, for built-in test rigs"""

    bl_idname = "object.dq_skin_comparison_scene"
    bl_label = "Build Comparison Scene"
    bl_options = {"REGISTER", "UNDO"}

    report_dir: bpy.props.StringProperty(
        name="Report Folder", description="Where to write report.md and report.json (empty: no report)", subtype="DIR_PATH", default=""
    )

    def execute(self, context):
        obj = context.active_object
        if obj is not None and obj.type == "MESH" and any(m.type == "ARMATURE" for m in obj.modifiers):
            sources = [obj]
        elif obj is None or not context.selected_objects:
            sources = builtin_rigs(context.scene)
            context.scene.frame_start, context.scene.frame_end = FRAMES
        else:
            self.report({"ERROR"}, f"{obj.name} has no Armature modifier to compare")
            return {"CANCELLED"}
        collection, rows = build(context, sources)
        if self.report_dir:
            frames = list(range(context.scene.frame_start, context.scene.frame_end + 1))
            result = report(context, context.scene, rows, frames)
            write_report(result, bpy.path.abspath(self.report_dir), sources[0].name if obj in sources else "built-in test rigs", frames)
        self.report({"INFO"}, f"Built {collection.name!r}: {len(rows)} row(s) of {len(VARIANTS)} variants")
        return {"FINISHED"}


CLASSES = (OBJECT_OT_dq_skin_comparison_scene,)

# SPDX-License-Identifier: GPL-3.0-or-later
"""Comparison scenes: a rigged mesh (or built-in test rigs) deformed side by side by the
Armature modifier (Linear, Preserve Volume) and by DQ Skin (Linear, Dual Quaternion, Blend, Optimized Centers),
labelled, sharing one animation, with a camera and a light; and the numbers to choose by."""

from __future__ import annotations

import math
import time

import numpy as np

import bpy

from mathutils import Quaternion, Vector

from . import compat, dqskin, operators
from .progress import Progress

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
    label_material = _flat_material("DQ Skin Label", (0.9, 0.9, 0.9))
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
            text = _text(collection, f"{label} label", body, label_size, label_material)
            text.location = (middle + offset.x, 0.0, top + label_size * 2.2)
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


def _text(collection, name, body, size, material, align="CENTER"):
    text = bpy.data.objects.new(name, bpy.data.curves.new(name, "FONT"))
    text.data.body = body
    text.data.size = size
    text.data.align_x = align
    text.data.materials.append(material)
    text.rotation_euler = (math.pi / 2, 0, 0)  # faces the camera, which looks along +Y
    collection.objects.link(text)
    return text


def _flat_material(name, color):
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


def _visible_bounds(context, collection):
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
    lo, hi = _visible_bounds(context, collection)
    margin = 0.04 * max(hi[0] - lo[0], hi[2] - lo[2])
    width, height = hi[0] - lo[0] + 2 * margin, hi[2] - lo[2] + 2 * margin
    aspect = scene.render.resolution_x * scene.render.pixel_aspect_x / max(1, scene.render.resolution_y * scene.render.pixel_aspect_y)
    cam.data.ortho_scale = float(max(width, height * aspect))
    center = (lo + hi) / 2
    cam.location = (float(center[0]), float(lo[1] - 20.0), float(center[2]))
    cam.data.clip_end = float(hi[1] - lo[1] + 40.0)
    return float(width / max(height, 1e-9))


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
    # Every row's frames once for the positions, then once per variant alone for the timing.
    steps = sum(len(frames) * (1 + len(row)) for row in rows)
    with Progress(context, steps, f"Comparing {len(rows)} row(s) over {len(frames)} frame(s)") as progress:
        for row in rows:
            result.append(_report_row(context, scene, row, frames, check, progress))
    return result


def _report_row(context, scene, row, frames, check, progress):
    names = list(row)
    first = row[names[0]]
    mesh = first.data
    tris = _triangles(mesh) if _closed(mesh) else None
    rest_co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", rest_co)
    rest_volume = dqskin.mesh_volume(rest_co.reshape(-1, 3), tris) if tris is not None else None
    edges = np.empty(len(mesh.edges) * 2, np.int64)
    mesh.edges.foreach_get("vertices", edges)
    edges = edges.reshape(-1, 2)
    rest_lengths = np.linalg.norm(rest_co.reshape(-1, 3)[edges[:, 0]] - rest_co.reshape(-1, 3)[edges[:, 1]], axis=1)
    usable = rest_lengths > 1e-9
    per = {n: {"positions": [], "seconds": 0.0} for n in names}
    for f in frames:
        check()
        scene.frame_set(f)
        depsgraph = context.evaluated_depsgraph_get()
        for n in names:
            # The copies stand side by side with their own armatures; in each copy's own
            # space the deformations are directly comparable.
            per[n]["positions"].append(_positions(row[n], depsgraph))
        progress.step()
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
        progress.step(len(frames))
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
        if usable.any():
            # How much the surface collapses (candy wrapper, elbow pinch) and bulges: edges
            # shorter or longer than at rest, by how much on average over the mesh's edges, at
            # the worst frame (the same mesh for every variant: directly comparable).
            lengths = np.linalg.norm(ours[:, edges[usable, 0]] - ours[:, edges[usable, 1]], axis=2)
            ratio = lengths / rest_lengths[usable]
            stats["edge_shrink_mean"] = float(np.maximum(0.0, 1.0 - ratio).mean(axis=1).max())
            stats["edge_stretch_mean"] = float(np.maximum(0.0, ratio - 1.0).mean(axis=1).max())
        if tris is not None and rest_volume:
            last = per[n]["positions"][-1]
            stats["volume_relative_to_rest"] = dqskin.mesh_volume(np.ascontiguousarray(last, np.float32), tris) / rest_volume
        entry["methods"][n] = stats
    return entry


def write_report(result, out_dir, source: str, frames, pictures: dict[str, str] | None = None) -> None:
    """`report.json` and `report.md` in `out_dir` (each written to a temporary file first)."""
    import json
    import os
    from pathlib import Path

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    start, end = frames[0], frames[-1]
    lines = [f"# DQ Skin vs the Armature modifier: {source}, frames {start}-{end}", ""]
    lines.append(
        "| mesh | method | max dev. from Linear | max dev. from Preserve Volume | volume / rest | edge shrink (collapse) | edge stretch (bulge) | ms/frame |"
    )
    lines.append("|---|---|---|---|---|---|---|---|")
    for row in result:
        for method, r in row["methods"].items():
            volume = r.get("volume_relative_to_rest")
            lines.append(
                f"| {row['mesh']} | {method} | {r['max_deviation_from_armature_linear']:.3e} | "
                f"{r['max_deviation_from_armature_preserve_volume']:.3e} | "
                f"{'' if volume is None else f'{volume:.3f}'} | {_percent(r.get('edge_shrink_mean'))} | "
                f"{_percent(r.get('edge_stretch_mean'))} | {r['ms_per_frame']:.2f} |"
            )
    for caption, picture in (pictures or {}).items():
        lines += ["", f"![{caption}]({picture})"]
    texts = {
        "report.json": json.dumps({"source": source, "frames": [start, end], "rows": result}, indent=2),
        "report.md": "\n".join(lines) + "\n",
    }
    for name, text in texts.items():
        tmp = out / f".{name}.dqskin-{os.getpid()}.tmp"
        with open(tmp, "w") as f:
            f.write(text)
        os.replace(tmp, out / name)


def _percent(value) -> str:
    return "" if value is None else f"{100 * value:.2f} %"


def render(scene, path, width=1600, height=None, samples=8) -> None:
    """Renders the comparison at the current frame (Cycles, CPU) to a PNG, the camera fitted to
    it; `height=None` takes the height from the content's shape."""
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.render.resolution_percentage = 100
    scene.render.resolution_x, scene.render.resolution_y = width, height or width
    shape = fit_camera(bpy.context, scene)
    if height is None:
        scene.render.resolution_y = max(64, min(2 * width, round(width / shape)))
        fit_camera(bpy.context, scene)
    scene.view_settings.view_transform = "Standard"  # colours as the legend's, unfiltered
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(path)
    with bpy.context.temp_override(scene=scene):
        bpy.ops.render.render(write_still=True, scene=scene.name)


# A perceptually uniform scale (viridis), low to high.
DEVIATION_COLORS = (
    (0.0, (0.267, 0.005, 0.329)),
    (0.25, (0.229, 0.322, 0.546)),
    (0.5, (0.128, 0.567, 0.551)),
    (0.75, (0.369, 0.789, 0.383)),
    (1.0, (0.993, 0.906, 0.144)),
)
DEVIATION_ATTRIBUTE = "dq_skin_deviation"


def _deviation_material(scale: float):
    """Colours a surface by its `dq_skin_deviation` attribute over `[0, scale]`."""
    mat = compat.node_material("DQ Skin Deviation")
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    attr = nodes.new("ShaderNodeAttribute")
    attr.attribute_name = DEVIATION_ATTRIBUTE
    to_unit = nodes.new("ShaderNodeMapRange")
    to_unit.inputs["From Max"].default_value = scale
    to_unit.clamp = True
    ramp = nodes.new("ShaderNodeValToRGB")
    elements = ramp.color_ramp.elements
    elements[0].position, elements[0].color = DEVIATION_COLORS[0][0], (*DEVIATION_COLORS[0][1], 1)
    elements[1].position, elements[1].color = DEVIATION_COLORS[-1][0], (*DEVIATION_COLORS[-1][1], 1)
    for position, color in DEVIATION_COLORS[1:-1]:
        elements.new(position).color = (*color, 1)
    emission = nodes.new("ShaderNodeEmission")
    out = nodes.new("ShaderNodeOutputMaterial")
    links.new(attr.outputs["Fac"], to_unit.inputs["Value"])
    links.new(to_unit.outputs["Result"], ramp.inputs["Fac"])
    links.new(ramp.outputs["Color"], emission.inputs["Color"])
    links.new(emission.outputs["Emission"], out.inputs["Surface"])
    return mat


def deviations(context, rows) -> list[dict[str, np.ndarray]]:
    """Per row and variant, every vertex's distance from where Armature Linear puts it, at the
    current frame (each in its own object space, as in the report)."""
    depsgraph = context.evaluated_depsgraph_get()
    out = []
    for row in rows:
        ref = _positions(row["Armature Linear"], depsgraph)
        out.append({n: np.linalg.norm(_positions(o, depsgraph) - ref, axis=1) for n, o in row.items()})
    return out


def render_deviation(context, scene, rows, path, width=1600, height=None, samples=4) -> float:
    """The deviation view: every variant coloured by its distance from Armature Linear at the
    current frame, one scale for the picture, with a legend; rendered like `render`. The
    variants are shown as still copies of their deformed meshes (whatever made them), which are
    removed after: the scene is left as it was. Returns the scale's top (the largest distance)."""
    values = deviations(context, rows)
    scale = max([float(d.max()) for per in values for d in per.values()] + [1e-6])
    collection = bpy.data.collections["DQ Skin Comparison"]
    material = _deviation_material(scale)
    depsgraph = context.evaluated_depsgraph_get()
    added, hidden = [], []
    try:
        for row, per in zip(rows, values):
            for name, obj in row.items():
                mesh = bpy.data.meshes.new_from_object(obj.evaluated_get(depsgraph))
                mesh.materials.clear()
                mesh.materials.append(material)
                attr = mesh.attributes.new(DEVIATION_ATTRIBUTE, "FLOAT", "POINT")
                attr.data.foreach_set("value", per[name].astype(np.float32))
                still = bpy.data.objects.new(f"{name} deviation", mesh)
                still.matrix_world = obj.matrix_world.copy()
                collection.objects.link(still)
                added.append(still)
                hidden.append((obj, obj.hide_render))
                obj.hide_render = True
        added += _legend(context, collection, scale, material)
        render(scene, path, width=width, height=height, samples=samples)
    finally:
        for obj in added:
            data = obj.data
            bpy.data.objects.remove(obj)
            (bpy.data.meshes if isinstance(data, bpy.types.Mesh) else bpy.data.curves).remove(data)
        for obj, was in hidden:
            obj.hide_render = was
    return scale


def _legend(context, collection, scale, material):
    """A colour bar under the comparison, from 0 to `scale`, with its numbers and its title."""
    lo, hi = _visible_bounds(context, collection)
    width = (hi[0] - lo[0]) * 0.5
    size = width / 24
    left, z = (lo[0] + hi[0]) / 2 - width / 2, lo[2] - size * 3
    steps = 64
    verts = [(left + width * i / steps, 0.0, z + dz) for i in range(steps + 1) for dz in (0.0, size)]
    faces = [(2 * i, 2 * i + 2, 2 * i + 3, 2 * i + 1) for i in range(steps)]
    mesh = bpy.data.meshes.new("DQ Skin Legend")
    mesh.from_pydata(verts, [], faces)
    values = np.repeat(np.linspace(0.0, scale, steps + 1, dtype=np.float32), 2)
    mesh.attributes.new(DEVIATION_ATTRIBUTE, "FLOAT", "POINT").data.foreach_set("value", values)
    mesh.materials.append(material)
    bar = bpy.data.objects.new("DQ Skin Legend", mesh)
    collection.objects.link(bar)
    white = _flat_material("DQ Skin Label", (0.9, 0.9, 0.9))
    low = _text(collection, "DQ Skin Legend 0", "0", size, white, align="RIGHT")
    low.location = (left - size * 0.5, 0.0, z + size * 0.15)
    high = _text(collection, "DQ Skin Legend max", f"{scale:.3g}", size, white, align="LEFT")
    high.location = (left + width + size * 0.5, 0.0, z + size * 0.15)
    title = _text(collection, "DQ Skin Legend title", "distance from Armature Linear (scene units)", size, white)
    title.location = (left + width / 2, 0.0, z - size * 1.3)
    return [bar, low, high, title]


class OBJECT_OT_dq_skin_comparison_scene(bpy.types.Operator):
    """Build a scene comparing the Armature modifier (Linear, Preserve Volume) with DQ Skin
    (Linear, Dual Quaternion, Blend, Optimized Centers) side by side, for the active rigged mesh or, with nothing
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

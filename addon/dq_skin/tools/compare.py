# SPDX-License-Identifier: GPL-3.0-or-later
"""Comparing the variants of a comparison scene (`compare_scene`): the numbers to choose by
(deviations from both built-in methods, volume, edge shrink and stretch, time per frame), the
pictures (the variants, and each coloured by its distance from Armature Linear), and the
operator that builds the scene."""

from __future__ import annotations

import time

import numpy as np

import bpy

from .. import dqskin
from ..blender import compat
from ..progress import Progress
from . import compare_scene
from .compare_scene import FRAMES, VARIANTS, build, builtin_rigs, fit_camera, flat_material, visible_bounds  # noqa: F401  (the batch commands use them here)


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
    lo, hi = visible_bounds(context, collection)
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
    white = flat_material("DQ Skin Label", (0.9, 0.9, 0.9))
    low = compare_scene.text(collection, "DQ Skin Legend 0", "0", size, white, align="RIGHT")
    low.location = (left - size * 0.5, 0.0, z + size * 0.15)
    high = compare_scene.text(collection, "DQ Skin Legend max", f"{scale:.3g}", size, white, align="LEFT")
    high.location = (left + width + size * 0.5, 0.0, z + size * 0.15)
    title = compare_scene.text(collection, "DQ Skin Legend title", "distance from Armature Linear (scene units)", size, white)
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

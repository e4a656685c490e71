# SPDX-License-Identifier: GPL-3.0-or-later
"""The A/B switch of the DQ Skin panel: Blender's own deformation in the viewport and back.

*Show Blender's Deformation* switches DQ Skin off in the viewport, so its companion (the
Armature modifier with DQ Skin's settings: Preserve Volume off for Linear, on for every other
method) deforms there; switching back parks the companion again (see `companion`). Renders are
never touched, so a file saved either way renders DQ Skin. After each switch the panel shows how
far the two deformations are apart: the largest distance, where (vertex and its strongest
vertex group), relative to the mesh's size.
"""

from __future__ import annotations

import numpy as np

from ..session import SESSION
from . import modifiers


def _world_positions(obj, depsgraph) -> np.ndarray:
    ev = obj.evaluated_get(depsgraph)
    mesh = ev.to_mesh()
    try:
        co = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", co)
    finally:
        ev.to_mesh_clear()
    m = np.array(obj.matrix_world, np.float64)
    return co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]


def _strongest_group(obj, index: int) -> str:
    if index >= len(obj.data.vertices):
        return ""
    groups = sorted(obj.data.vertices[index].groups, key=lambda g: -g.weight)
    for g in groups:
        if g.group < len(obj.vertex_groups):
            return obj.vertex_groups[g.group].name
    return ""


def describe_difference(obj, a: np.ndarray, b: np.ndarray) -> str:
    if a.shape != b.shape or not len(a):
        return "The two deformations have different vertex counts"
    d = np.linalg.norm(a - b, axis=1)
    i = int(d.argmax())
    size = float(np.linalg.norm(b.max(0) - b.min(0))) or 1.0
    group = _strongest_group(obj, i)
    where = f"vertex {i}" + (f" ({group})" if group else "")
    return f"Largest difference: {d[i]:.4g} ({100 * d[i] / size:.2f} % of the size) at {where}"


class OBJECT_OT_dq_skin_show_blender(modifiers.ModifierOperator):
    """Switch the viewport between DQ Skin's deformation and Blender's own Armature modifier
    with the same settings (Preserve Volume off for Linear, on otherwise), to compare them;
    renders keep DQ Skin. The panel then shows how far the two are apart"""

    bl_idname = "object.dq_skin_show_blender"
    bl_label = "Show Blender's Deformation"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        obj, mod = self.target(context)
        if mod is None:
            return {"CANCELLED"}
        before = _world_positions(obj, context.evaluated_depsgraph_get())
        mod.show_viewport = not mod.show_viewport
        depsgraph = context.evaluated_depsgraph_get()
        tracker = SESSION.tracker
        tracker.evaluate(tracker.record_of(obj), depsgraph, force=True)
        after = _world_positions(obj, context.evaluated_depsgraph_get())
        status = SESSION.status_of(obj, mod)
        status.compared = describe_difference(obj, before, after)
        shown = "DQ Skin" if mod.show_viewport else "Blender's Armature modifier"
        self.report({"INFO"}, f"{shown} shows; {status.compared}")
        return {"FINISHED"}


CLASSES = (OBJECT_OT_dq_skin_show_blender,)

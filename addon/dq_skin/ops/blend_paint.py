# SPDX-License-Identifier: GPL-3.0-or-later
"""Painting where the Blend method mixes Linear and Dual Quaternion: the vertex group that
drives the Blend Amount, created if missing (filled with the Blend Factor, which then becomes 1
so that nothing changes until it is painted), made the active group, and Weight Paint mode."""

from __future__ import annotations

import numpy as np

import bpy

from .. import dqskin
from ..blender import nodes, settings
from ..session import SESSION
from . import modifiers

GROUP_NAME = "DQ Skin Blend"


def blend_group(obj, mod):
    """The vertex group driving `mod`'s Blend Amount, or None."""
    name = nodes.get_attribute(mod, "Blend Amount")
    return obj.vertex_groups.get(name) if name else None


def describe(obj, mod) -> str:
    """What drives the blend, for the panel."""
    factor = float(nodes.get(mod, "Blend Factor"))
    group = blend_group(obj, mod)
    if group is None:
        name = nodes.get_attribute(mod, "Blend Amount")
        if name:
            return f"Blend: vertex group '{name}' is missing (every vertex blends by the factor, {factor:.2f})"
        amount = float(nodes.get(mod, "Blend Amount"))
        return f"Blend: {amount * factor:.2f} Dual Quaternion everywhere (no vertex group)"
    weights = SESSION.meshes.get(obj, SESSION.readers.mesh).group_weights(group.name)
    lo, hi = (float(weights.min()), float(weights.max())) if weights is not None and len(weights) else (0.0, 0.0)
    return f"Blend: vertex group '{group.name}', {lo:.2f} to {hi:.2f} Dual Quaternion, times {factor:.2f}"


class OBJECT_OT_dq_skin_paint_blend(modifiers.ModifierOperator):
    """Paint where the Blend method uses Dual Quaternion (white) or Linear (black): selects the
    vertex group that drives the blend (creating one from the Blend Factor if there is none) and
    enters Weight Paint"""

    bl_idname = "object.dq_skin_paint_blend"
    bl_label = "Paint Blend"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        obj, mod = self.target(context)
        if mod is None:
            return {"CANCELLED"}
        if settings.read(mod).method != dqskin.Method.BLEND:
            self.report({"ERROR"}, f"{mod.name} uses {nodes.get_method(mod)}: choose the Blend method to paint a blend")
            return {"CANCELLED"}
        group = blend_group(obj, mod)
        if group is None:
            factor = float(nodes.get(mod, "Blend Factor"))
            amount = float(nodes.get(mod, "Blend Amount")) if not nodes.get_attribute(mod, "Blend Amount") else 1.0
            group = obj.vertex_groups.new(name=GROUP_NAME)
            group.add(np.arange(len(obj.data.vertices)).tolist(), amount * factor, "REPLACE")
            nodes.put_attribute(mod, "Blend Amount", group.name)
            nodes.put(mod, "Blend Factor", 1.0)
        obj.vertex_groups.active_index = group.index
        if obj.mode != "WEIGHT_PAINT":
            bpy.ops.object.mode_set(mode="WEIGHT_PAINT")
        self.report({"INFO"}, f"Paint '{group.name}': white is Dual Quaternion, black is Linear")
        return {"FINISHED"}


CLASSES = (OBJECT_OT_dq_skin_paint_blend,)

# SPDX-License-Identifier: GPL-3.0-or-later
"""What a DQ Skin modifier renders as where the extension is not installed (render farm nodes,
a colleague's Blender): read from the modifier, its Blend Amount's weights and the bake that may
play in its place (`decisions.renders_elsewhere` decides)."""

from __future__ import annotations

import os

import numpy as np

import bpy

from ..model import decisions
from . import settings

BAKE_NAME = "DQ Skin Cache"  # the Mesh Cache modifier DQ Skin's bake adds (`ops.bake`)


def blend_range(obj, mod, s, group_weights) -> tuple[float, float]:
    """The lowest and highest amount of Dual Quaternion the Blend method mixes in over the mesh
    (`group_weights(name)`: the group's weights per vertex, or None where it is missing)."""
    if not s.blend_group:
        a = s.blend_factor * s.blend_amount
        return (a, a)
    weights = group_weights(s.blend_group)
    if weights is None or not len(weights):
        return (s.blend_factor, s.blend_factor)  # Blender's rule: a missing group counts as 1
    w = np.asarray(weights, np.float64) * s.blend_factor
    return (float(w.min()), float(w.max()))


def bake_state(obj, mod) -> str:
    """ "" where DQ Skin renders itself; "ok" where its bake plays in its place (DQ Skin off for
    renders, the bake's Mesh Cache on, its file there); else what is wrong with the bake."""
    if mod.show_render:
        return ""
    cache = obj.modifiers.get(BAKE_NAME)
    if cache is None or cache.type != "MESH_CACHE" or not cache.show_render:
        return "ok"  # neither renders: Blender's Armature modifier does, as the user chose
    path = bpy.path.abspath(cache.filepath, library=obj.library)
    if not os.path.isfile(path):
        return f"its cache file {cache.filepath} is missing"
    return "ok"


def reason(obj, mod, group_weights) -> str:
    """Why `mod` renders differently without the extension, or ""."""
    try:
        s = settings.read(mod)
    except Exception as e:  # a damaged modifier: it cannot render as itself anywhere
        return f"its settings cannot be read ({type(e).__name__})"
    if not mod.show_render and not obj.modifiers.get(BAKE_NAME):
        return ""
    return decisions.renders_elsewhere(s.method, blend_range(obj, mod, s, group_weights), bake_state(obj, mod))


def group_weights_of(obj):
    """A `group_weights` reading the mesh directly (no caches: the command line)."""

    def read(name: str):
        group = obj.vertex_groups.get(name)
        if group is None:
            return None
        w = np.zeros(len(obj.data.vertices), np.float32)
        for v in obj.data.vertices:
            for e in v.groups:
                if e.group == group.index:
                    w[v.index] = e.weight
        return w

    return read

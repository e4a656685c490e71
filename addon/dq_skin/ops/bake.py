# SPDX-License-Identifier: GPL-3.0-or-later
"""Baking a DQ Skin modifier's result to a PC2 point cache, played back by Blender's own Mesh
Cache modifier, so the animation plays and renders where this add-on is not installed."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import bpy

from ..blender import settings
from ..dqskin import pc2
from ..engine import companions
from ..engine.context import dq_skin_modifiers
from ..model.state import Mode
from ..progress import Progress
from ..session import SESSION
from . import modifiers

CACHE_NAME = "DQ Skin Cache"


def _positions(obj, depsgraph) -> np.ndarray:
    ev = obj.evaluated_get(depsgraph)
    flat = np.empty(len(ev.data.vertices) * 3, np.float32)
    ev.data.attributes["position"].data.foreach_get("vector", flat)
    return flat.reshape(-1, 3)


def bake(context, obj, mod, path, frame_start: int, frame_end: int, check=None) -> pc2.Header:
    """Writes the modifier's output for every frame of `[frame_start, frame_end]` to `path` (PC2,
    object space). Modifiers after it, and simulations before it, are muted while baking, so the
    cache holds exactly what DQ Skin makes of the mesh. Nothing is written under `path` if
    anything fails. `check` is called before every frame and may raise to stop (the command
    line's Ctrl-C and SIGTERM)."""
    if frame_end < frame_start:
        raise ValueError(f"the frame range {frame_start}–{frame_end} is empty")
    scene = context.scene
    mods = list(obj.modifiers)
    at = mods.index(mod)
    muted = [m for m in mods[at + 1 :] + _simulations_before(obj, mod) if m.show_viewport]
    current = scene.frame_current
    progress = Progress(context, frame_end - frame_start + 1, f"Baking {obj.name}")
    try:
        for m in muted:
            m.show_viewport = False
        with pc2.Writer(path, len(obj.data.vertices), frame_start, 1.0) as writer:
            for frame in range(frame_start, frame_end + 1):
                if check is not None:
                    check()
                scene.frame_set(frame)
                if check is not None:
                    check()
                depsgraph = context.evaluated_depsgraph_get()
                status = SESSION.status_of(obj, mod)
                if status.mode is not Mode.LIVE:
                    raise RuntimeError(f"frame {frame}: DQ Skin is not deforming: {status.message}")
                writer.add(_positions(obj, depsgraph))
                progress.step()
    finally:
        for m in muted:
            m.show_viewport = True
        scene.frame_set(current)
        progress.end()
    return pc2.read_header(path)


def _simulations_before(obj, mod) -> list:
    """Soft Bodies before DQ Skin (Blender keeps them before non-deform modifiers)."""
    mods = list(obj.modifiers)
    return [m for m in mods[: mods.index(mod)] if m.type == "SOFT_BODY"]


def add_cache_modifier(obj, mod, path, frame_start: int):
    """A Mesh Cache modifier playing `path` in DQ Skin's place (right after it), or before a
    Soft Body that precedes DQ Skin, which then simulates on the skinned mesh (the Mesh Cache
    modifier is deform-only, so it may come first)."""
    cache = obj.modifiers.get(CACHE_NAME) or obj.modifiers.new(CACHE_NAME, "MESH_CACHE")
    cache.cache_format = "PC2"
    cache.filepath = str(path)
    cache.frame_start = float(frame_start)
    cache.frame_scale = 1.0
    cache.play_mode = "SCENE"
    cache.time_mode = "FRAME"
    cache.deform_mode = "OVERWRITE"
    cache.forward_axis, cache.up_axis = "POS_Y", "POS_Z"
    # Shown in Edit Mode (and on the cage) where DQ Skin was: the baked character edits as the live one.
    cache.show_in_editmode, cache.show_on_cage = mod.show_in_editmode, mod.show_on_cage
    first_simulation = next(iter(_simulations_before(obj, mod)), None)
    index = list(obj.modifiers).index(first_simulation if first_simulation else mod) + (0 if first_simulation else 1)
    with bpy.context.temp_override(object=obj, active_object=obj):
        bpy.ops.object.modifier_move_to_index(modifier=cache.name, index=min(index, len(obj.modifiers) - 1))
    return cache


def switch_off(obj, mod) -> None:
    """DQ Skin and its companion both off, as the user would switch off an Armature modifier
    (the cache plays in their place)."""
    st = SESSION.state_of(obj, mod)
    companions.switch_off(obj, mod, st, settings.cached(mod, st.settings))


class OBJECT_OT_dq_skin_bake(modifiers.ActiveMeshOperator):
    """Bake the DQ Skin result over a frame range to a PC2 point cache and play it with a Mesh
    Cache modifier (so it works without this add-on)"""

    bl_idname = "object.dq_skin_bake"
    bl_label = "Bake DQ Skin to Cache"
    bl_options = {"REGISTER", "UNDO"}

    filepath: bpy.props.StringProperty(name="File", description="PC2 file to write", subtype="FILE_PATH", default="//dq_skin.pc2")
    frame_start: bpy.props.IntProperty(name="Start", description="First frame (default: the scene's)", default=-1)
    frame_end: bpy.props.IntProperty(name="End", description="Last frame (default: the scene's)", default=-1)
    disable_dq_skin: bpy.props.BoolProperty(name="Disable DQ Skin", description="Turn the DQ Skin modifier off once baked", default=True)

    def execute(self, context):
        obj = context.active_object
        mods = dq_skin_modifiers(obj)
        if not mods:
            self.report({"ERROR"}, f"{obj.name} has no DQ Skin modifier to bake")
            return {"CANCELLED"}
        mod = mods[0]
        scene = context.scene
        start = self.frame_start if self.frame_start >= 0 else scene.frame_start
        end = self.frame_end if self.frame_end >= 0 else scene.frame_end
        path = Path(bpy.path.abspath(self.filepath))
        try:
            header = bake(context, obj, mod, path, start, end)
        except (RuntimeError, ValueError, OSError) as e:
            self.report({"ERROR"}, f"Bake failed, nothing written: {e}")
            return {"CANCELLED"}
        add_cache_modifier(obj, mod, path, start)
        if self.disable_dq_skin:
            switch_off(obj, mod)
        self.report({"INFO"}, f"Baked {header.samples} frames of {header.points} points to {path}")
        return {"FINISHED"}


CLASSES = (OBJECT_OT_dq_skin_bake,)

# SPDX-License-Identifier: GPL-3.0-or-later
"""Baking an object's DQ Skin result to a PC2 point cache, played back by Blender's own Mesh
Cache modifier, so the animation plays and renders where this add-on is not installed.

The cache holds the object's full DQ Skin result: the mesh as it comes out of its last DQ Skin
modifier, every DQ Skin before it included (two armatures, two DQ Skins). The Mesh Cache
modifier plays it right after that last DQ Skin, and every DQ Skin is switched off.

From the panel, *Bake to Cache* opens a file browser on a file of the object's own
(`default_path`: never another object's bake, never a file the user did not name), then bakes
frame by frame in a modal run with progress, Esc cancelling. A bake (`Baking`) writes to a
temporary file beside the target, renamed into place when complete: cancelled or failed,
nothing is written and the object is as it was."""

from __future__ import annotations

import os
import time
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
EXTENSION = ".pc2"
STEP_SECONDS = 0.1  # the modal run bakes frames for this long per timer event, then redraws


class Cancelled(Exception):
    """The user pressed Esc."""


def _positions(obj, depsgraph) -> np.ndarray:
    ev = obj.evaluated_get(depsgraph)
    flat = np.empty(len(ev.data.vertices) * 3, np.float32)
    ev.data.attributes["position"].data.foreach_get("vector", flat)
    return flat.reshape(-1, 3)


def _simulations_before(obj, mod) -> list:
    """Soft Bodies before DQ Skin (Blender keeps them before non-deform modifiers)."""
    mods = list(obj.modifiers)
    return [m for m in mods[: mods.index(mod)] if m.type == "SOFT_BODY"]


class Baking:
    """One bake of `obj`'s DQ Skin result over `[frame_start, frame_end]` to `path`, a frame at
    a time: `start()`, then `step()` until it returns False, then `finish()` (the file appears
    under `path`); or `abort()` at any point (nothing written). Modifiers after the last DQ Skin,
    and simulations before the first, are muted while baking, so the cache holds exactly what
    DQ Skin makes of the mesh; they and the scene's frame are restored by `finish` and `abort`.
    `check` is called around every frame and may raise to stop (the command line's Ctrl-C).
    `played`: the path as the Mesh Cache modifier is to play it (`//` relative to the blend
    file), `path` by default."""

    def __init__(self, context, obj, path, frame_start: int, frame_end: int, check=None, played: str = ""):
        if frame_end < frame_start:
            raise ValueError(f"the frame range {frame_start}–{frame_end} is empty")
        self.mods = dq_skin_modifiers(obj)
        if not self.mods:
            raise ValueError(f"{obj.name} has no DQ Skin modifier to bake")
        self.context, self.obj, self.path = context, obj, Path(path)
        self.played = played or str(path)
        self.frame_start, self.frame_end, self.check = frame_start, frame_end, check
        self.frame = frame_start
        stack = list(obj.modifiers)
        after = stack[stack.index(self.mods[-1]) + 1 :]
        self.muted = [m for m in after + _simulations_before(obj, self.mods[0]) if m.show_viewport]
        self.current = context.scene.frame_current
        self.writer = None
        self.progress = None

    @property
    def total(self) -> int:
        return self.frame_end - self.frame_start + 1

    def start(self) -> None:
        self.progress = Progress(self.context, self.total, f"Baking {self.obj.name}")
        try:
            for m in self.muted:
                m.show_viewport = False
            writer = pc2.Writer(self.path, len(self.obj.data.vertices), self.frame_start, 1.0)
            self.writer = writer.__enter__()
        except BaseException:
            self._restore()
            raise

    def step(self) -> bool:
        """Bakes the next frame; False once every frame is baked."""
        if self.frame > self.frame_end:
            return False
        frame, scene = self.frame, self.context.scene
        if self.check is not None:
            self.check()
        scene.frame_set(frame)
        if self.check is not None:
            self.check()
        depsgraph = self.context.evaluated_depsgraph_get()
        for mod in self.mods:
            status = SESSION.status_of(self.obj, mod)
            if status.mode is not Mode.LIVE:
                raise RuntimeError(f"frame {frame}: {mod.name} is not deforming: {status.message}")
        self.writer.add(_positions(self.obj, depsgraph))
        self.progress.step()
        self.frame += 1
        return self.frame <= self.frame_end

    def advance(self, seconds: float) -> bool:
        """Bakes frames for about `seconds`; False once every frame is baked."""
        until = time.perf_counter() + seconds
        while self.step():
            if time.perf_counter() >= until:
                return True
        return False

    def finish(self) -> pc2.Header:
        """Puts the file in place (every frame must be baked)."""
        if self.frame <= self.frame_end:
            raise RuntimeError(f"frames {self.frame}–{self.frame_end} are not baked yet")
        try:
            self.writer.__exit__(None, None, None)
        finally:
            self.writer = None
            self._restore()
        return pc2.read_header(self.path)

    def abort(self) -> None:
        """Removes the temporary file and restores what baking changed (nothing is written)."""
        if self.writer is not None:
            writer, self.writer = self.writer, None
            writer.__exit__(Cancelled, Cancelled(), None)
        self._restore()

    def _restore(self) -> None:
        for m in self.muted:
            m.show_viewport = True
        self.muted = []
        if self.context.scene.frame_current != self.current:
            self.context.scene.frame_set(self.current)
        if self.progress is not None:
            self.progress.end()
            self.progress = None


def bake(context, obj, path, frame_start: int, frame_end: int, check=None) -> pc2.Header:
    """Bakes `obj`'s DQ Skin result to `path` in one go (see `Baking`); nothing is written under
    `path` if anything fails."""
    baking = Baking(context, obj, path, frame_start, frame_end, check)
    baking.start()
    try:
        while baking.step():
            pass
    except BaseException:
        baking.abort()
        raise
    return baking.finish()


def add_cache_modifier(obj, path, frame_start: int):
    """A Mesh Cache modifier playing `path` in DQ Skin's place (right after the last DQ Skin),
    or before a Soft Body that precedes the first DQ Skin, which then simulates on the skinned
    mesh (the Mesh Cache modifier is deform-only, so it may come first)."""
    mods = dq_skin_modifiers(obj)
    first, last = mods[0], mods[-1]
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
    cache.show_in_editmode, cache.show_on_cage = last.show_in_editmode, last.show_on_cage
    first_simulation = next(iter(_simulations_before(obj, first)), None)
    stack = [m for m in obj.modifiers if m != cache]
    index = stack.index(first_simulation) if first_simulation else stack.index(last) + 1
    with bpy.context.temp_override(object=obj, active_object=obj):
        bpy.ops.object.modifier_move_to_index(modifier=cache.name, index=min(index, len(obj.modifiers) - 1))
    return cache


def switch_off(obj) -> None:
    """Every DQ Skin and its companion off, as the user would switch off an Armature modifier
    (the cache plays in their place)."""
    for mod in dq_skin_modifiers(obj):
        st = SESSION.state_of(obj, mod)
        companions.switch_off(obj, mod, st, settings.cached(mod, st.settings))


def _same_file(a: str, b: str) -> bool:
    return os.path.normcase(os.path.abspath(a)) == os.path.normcase(os.path.abspath(b))


def current_bake(obj) -> str:
    """The absolute path of the file `obj`'s bake plays, or ""."""
    cache = obj.modifiers.get(CACHE_NAME)
    if cache is None or cache.type != "MESH_CACHE" or not cache.filepath:
        return ""
    return bpy.path.abspath(cache.filepath, library=obj.library)


def default_path(obj) -> str:
    """Where `obj` bakes unless the user names a file: `//<blend name>_<object name>.pc2` beside
    the blend file (in the home folder while the file is unsaved), letters and digits kept.
    Never a file another object plays (a duplicate of a baked object plays its original's file),
    nor any existing file but `obj`'s own current bake: then `..._2.pc2`, `..._3.pc2` and so on."""
    saved = bool(bpy.data.filepath)
    blend = Path(bpy.data.filepath).stem if saved else "untitled"
    base = bpy.path.clean_name(f"{blend}_{obj.name}")
    folder = "//" if saved else os.path.expanduser("~") + os.sep
    own = current_bake(obj)
    played = [p for o in bpy.data.objects if o != obj for p in _cache_files(o)]
    n = 1
    while True:
        candidate = f"{folder}{base}{'' if n == 1 else f'_{n}'}{EXTENSION}"
        absolute = bpy.path.abspath(candidate)
        if not any(_same_file(absolute, p) for p in played):
            if (own and _same_file(absolute, own)) or not os.path.exists(absolute):
                return candidate
        n += 1


def _cache_files(obj) -> list[str]:
    """The files the object's Mesh Cache modifiers play."""
    mods = getattr(obj, "modifiers", ())
    return [bpy.path.abspath(m.filepath, library=obj.library) for m in mods if m.type == "MESH_CACHE" and m.filepath]


class OBJECT_OT_dq_skin_bake(modifiers.DQSkinOperator):
    """Bake the object's DQ Skin result (every DQ Skin modifier) over a frame range to a PC2
    point cache and play it with a Mesh Cache modifier, so it plays and renders without this
    add-on. Esc cancels, leaving nothing written"""

    bl_idname = "object.dq_skin_bake"
    bl_label = "Bake DQ Skin to Cache"
    bl_options = {"REGISTER", "UNDO"}

    filepath: bpy.props.StringProperty(
        name="File",
        description="PC2 file to write (empty: <blend name>_<object name>.pc2 beside the blend file, "
        "a new name if that file exists and is not this object's bake)",
        subtype="FILE_PATH",
        default="",
    )
    filter_glob: bpy.props.StringProperty(
        name="Filter", description="Files the file browser lists", default="*" + EXTENSION, options={"HIDDEN"}
    )
    check_existing: bpy.props.BoolProperty(
        name="Check Existing", description="Warn in the file browser before overwriting a file", default=True, options={"HIDDEN"}
    )
    frame_start: bpy.props.IntProperty(name="Start", description="First frame (default: the scene's)", default=-1)
    frame_end: bpy.props.IntProperty(name="End", description="Last frame (default: the scene's)", default=-1)
    disable_dq_skin: bpy.props.BoolProperty(
        name="Disable DQ Skin", description="Turn the DQ Skin modifiers off once baked (the cache plays in their place)", default=True
    )
    use_modal: bpy.props.BoolProperty(
        name="In the Background",
        description="Bake a few frames at a time with progress, Esc cancelling (set when run from the panel)",
        default=False,
        options={"HIDDEN", "SKIP_SAVE"},
    )

    def invoke(self, context, event):
        obj = context.active_object
        if not dq_skin_modifiers(obj):
            self.report({"ERROR"}, f"{obj.name} has no DQ Skin modifier to bake")
            return {"CANCELLED"}
        if not self.properties.is_property_set("filepath") or not self.filepath:
            self.filepath = default_path(obj)
        self.use_modal = context.window is not None and not bpy.app.background
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def check(self, context):
        """The file browser's name always ends in .pc2."""
        fixed = bpy.path.ensure_ext(self.filepath, EXTENSION) if self.filepath else self.filepath
        changed = fixed != self.filepath
        self.filepath = fixed
        return changed

    def execute(self, context):
        obj = context.active_object
        if not dq_skin_modifiers(obj):
            self.report({"ERROR"}, f"{obj.name} has no DQ Skin modifier to bake")
            return {"CANCELLED"}
        scene = context.scene
        start = self.frame_start if self.frame_start >= 0 else scene.frame_start
        end = self.frame_end if self.frame_end >= 0 else scene.frame_end
        played = self.filepath or default_path(obj)
        path = Path(bpy.path.abspath(played))
        try:
            baking = Baking(context, obj, path, start, end, played=played)
            baking.start()
        except (RuntimeError, ValueError, OSError) as e:
            self.report({"ERROR"}, f"Bake failed, nothing written: {e}")
            return {"CANCELLED"}
        self._baking = baking
        if self.use_modal and context.window is not None:
            wm = context.window_manager
            self._timer = wm.event_timer_add(0.01, window=context.window)
            wm.modal_handler_add(self)
            context.workspace.status_text_set(f"Baking {obj.name} to {path.name}: Esc to cancel")
            return {"RUNNING_MODAL"}
        try:
            while baking.step():
                pass
        except BaseException as e:
            baking.abort()
            if not isinstance(e, (RuntimeError, ValueError, OSError)):
                raise
            self.report({"ERROR"}, f"Bake failed, nothing written: {e}")
            return {"CANCELLED"}
        return self._done(context, baking)

    def modal(self, context, event):
        baking = self._baking
        if event.type == "ESC" and event.value == "PRESS":
            self.cancel(context)
            self.report({"WARNING"}, f"Bake of {baking.obj.name} cancelled, nothing written")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"RUNNING_MODAL"}  # nothing else changes the scene while it bakes
        try:
            if baking.advance(STEP_SECONDS):
                return {"RUNNING_MODAL"}
        except Exception as e:  # whatever stops it, nothing is left half written
            self.cancel(context)
            self.report({"ERROR"}, f"Bake failed, nothing written: {e}")
            return {"CANCELLED"}
        self._end_modal(context)
        return self._done(context, baking)

    def cancel(self, context):
        """Esc, or Blender ending the operator (the file closes): nothing written, nothing changed."""
        self._end_modal(context)
        baking = getattr(self, "_baking", None)
        if baking is not None:
            baking.abort()

    def _end_modal(self, context) -> None:
        timer = getattr(self, "_timer", None)
        if timer is not None:
            context.window_manager.event_timer_remove(timer)
            self._timer = None
            if context.workspace is not None:
                context.workspace.status_text_set(None)

    def _done(self, context, baking):
        try:
            header = baking.finish()
        except (RuntimeError, ValueError, OSError) as e:
            self.report({"ERROR"}, f"Bake failed, nothing written: {e}")
            return {"CANCELLED"}
        obj, path = baking.obj, baking.path
        add_cache_modifier(obj, baking.played, baking.frame_start)
        if self.disable_dq_skin:
            switch_off(obj)
        self.report({"INFO"}, f"Baked {header.samples} frames of {header.points} points to {path}")
        return {"FINISHED"}


CLASSES = (OBJECT_OT_dq_skin_bake,)

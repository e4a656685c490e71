# SPDX-License-Identifier: GPL-3.0-or-later
"""Keeps every DQ Skin modifier's result current, and files free of results.

- `frame_change_pre` / `frame_change_post` (playback, `scene.frame_set()`, renders, motion blur
  steps, exporters): Blender evaluates the scene, runs the post handlers, then evaluates what
  they changed a second time. DQ Skin writes its results in the post handler, so the second
  evaluation shows the new frame with no lag. Objects Blender would evaluate in the first pass
  anyway output nothing there (see `Registry.frame_pre`), so the modifiers after DQ Skin run
  once per frame.
- `depsgraph_update_post` (posing, editing settings, painting weights): only what the update
  concerns is evaluated again (see `registry`).
- `save_pre` / `save_post`: files are written with every companion Armature modifier active and
  no results (see `companion`), then put back.
- `load_post`, `undo_post`, `redo_post`: the registry is rebuilt.
"""

from __future__ import annotations

import bpy
from bpy.app.handlers import persistent

from . import nodes
from .registry import REGISTRY

_busy = False
_saved: list = []


def _guarded(fn):
    def run(*args):
        global _busy
        if _busy:
            return
        _busy = True
        try:
            fn(*args)
        finally:
            _busy = False

    return run


@persistent
def on_frame_change_pre(scene, depsgraph=None):
    _guarded(lambda: REGISTRY.frame_pre())()


@persistent
def on_frame_change_post(scene, depsgraph=None):
    dg = depsgraph or bpy.context.evaluated_depsgraph_get()
    _guarded(lambda: REGISTRY.frame(dg))()


@persistent
def on_depsgraph_update_post(scene, depsgraph):
    _guarded(lambda: REGISTRY.updates(depsgraph))()


@persistent
def on_load_post(*_args):
    # Files saved by an earlier DQ Skin: their node group's Method menu gets the newer methods.
    for group in bpy.data.node_groups:
        try:
            if group.bl_idname == "GeometryNodeTree" and nodes.version_of(group) == nodes.VERSION:
                nodes.add_missing_methods(group)
        except (AttributeError, RuntimeError, TypeError) as e:  # never stop a file from loading
            print(f"DQ Skin: could not update node group {group.name!r}: {e}")
    REGISTRY.reset()


@persistent
def on_undo(*_args):
    REGISTRY.reset()


@persistent
def on_save_pre(*_args):
    global _saved
    _saved = REGISTRY.deactivate_all(detach=True)


@persistent
def on_save_post(*_args):
    global _saved
    from . import nodes

    for obj, mod_name, result in _saved:
        try:
            mod = obj.modifiers.get(mod_name)
            if mod is not None and result is not None:
                nodes.put(mod, "Result", result)
        except ReferenceError:
            pass
    _saved = []
    # The next update evaluates everything again (results, companions parked).
    for rec in REGISTRY.records.values():
        rec.pending = True


HANDLERS = (
    (bpy.app.handlers.frame_change_pre, on_frame_change_pre),
    (bpy.app.handlers.frame_change_post, on_frame_change_post),
    (bpy.app.handlers.depsgraph_update_post, on_depsgraph_update_post),
    (bpy.app.handlers.load_post, on_load_post),
    (bpy.app.handlers.undo_post, on_undo),
    (bpy.app.handlers.redo_post, on_undo),
    (bpy.app.handlers.save_pre, on_save_pre),
    (bpy.app.handlers.save_post, on_save_post),
)


def register():
    for handlers, fn in HANDLERS:
        if fn not in handlers:
            # First, so that other add-ons' frame handlers run after DQ Skin wrote its results.
            handlers.insert(0, fn)


def unregister():
    for handlers, fn in HANDLERS:
        while fn in handlers:
            handlers.remove(fn)
    # Without the add-on, Blender's own deformation takes over (as in a saved file), and the
    # results are let go (never saved).
    try:
        REGISTRY.deactivate_all(detach=True)
    except Exception:
        pass
    REGISTRY.reset()

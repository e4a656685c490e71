# SPDX-License-Identifier: GPL-3.0-or-later
"""Keeps every DQ Skin modifier's result current, and files free of results.

- `frame_change_pre` / `frame_change_post` (playback, `scene.frame_set()`, renders, motion blur
  steps, exporters): Blender evaluates the scene, runs the post handlers, then evaluates what
  they changed a second time. DQ Skin writes its results in the post handler, so the second
  evaluation shows the new frame with no lag. Objects Blender would evaluate in the first pass
  anyway output nothing there (see `Registry.frame_pre`), so the modifiers after DQ Skin run
  once per frame.
- `depsgraph_update_post` (posing, editing settings, painting weights, mode changes): only what
  the update concerns is evaluated again, once the scene settles (see `registry`).
- `save_pre` / `save_post`: files are written with every companion Armature modifier on where
  DQ Skin is and no results (see `companion`), then put back.
- `load_post`, `undo_post`, `redo_post`: the registry is rebuilt.
- An exporter starting or ending (see `exports`): every DQ Skin object is evaluated again.

Nothing raised here reaches Blender's console as a traceback: a failure is shown once, in one
line (`DQSKIN_DEBUG=1` prints the traceback), and on the panel.
"""

from __future__ import annotations

import os
import traceback

import bpy
from bpy.app.handlers import persistent

from . import exports, feed, nodes
from .registry import REGISTRY

_busy = False
last_error = ""  # the last unexpected failure of a handler (the panel shows it)


def _guarded(fn, *args) -> None:
    global _busy, last_error
    if _busy:
        return
    _busy = True
    try:
        fn(*args)
    except Exception as e:  # a bug of the add-on: say it once, never stop Blender's work
        message = f"{type(e).__name__}: {e}"
        if message != last_error:
            print(f"DQ Skin: internal error in {getattr(fn, '__name__', 'a handler')}: {message}")
            if os.environ.get("DQSKIN_DEBUG"):
                traceback.print_exc()
        last_error = message
    finally:
        _busy = False


@persistent
def on_frame_change_pre(scene, depsgraph=None):
    _guarded(REGISTRY.frame_pre)


@persistent
def on_frame_change_post(scene, depsgraph=None):
    _guarded(REGISTRY.frame, depsgraph or bpy.context.evaluated_depsgraph_get())


@persistent
def on_depsgraph_update_post(scene, depsgraph):
    _guarded(REGISTRY.updates, depsgraph)


def _upgrade_node_groups() -> None:
    for group in bpy.data.node_groups:
        try:
            if group.bl_idname == "GeometryNodeTree" and nodes.version_of(group) == nodes.VERSION:
                nodes.upgrade(group)
        except (AttributeError, RuntimeError, TypeError) as e:  # never stop a file from loading
            print(f"DQ Skin: could not update node group {group.name!r}: {e}")


@persistent
def on_load_post(*_args):
    _upgrade_node_groups()
    REGISTRY.reset()
    exports.wrap_operators()  # exporters enabled by the file's preferences


@persistent
def on_undo(*_args):
    REGISTRY.reset()


@persistent
def on_save_pre(*_args):
    _guarded(REGISTRY.deactivate_all, True)


@persistent
def on_save_post(*_args):
    _guarded(REGISTRY.reactivate_all)


def _export_changed() -> None:
    """An exporter starts or ends: hand every DQ Skin over, or take it back."""
    depsgraph = bpy.context.view_layer.depsgraph
    _guarded(REGISTRY.evaluate_all, depsgraph)


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
    if _export_changed not in exports._on_change:
        exports._on_change.append(_export_changed)
    exports.wrap_operators()


def unregister():
    exports.unwrap_operators()
    while _export_changed in exports._on_change:
        exports._on_change.remove(_export_changed)
    for handlers, fn in HANDLERS:
        while fn in handlers:
            handlers.remove(fn)
    # Without the add-on, Blender's own deformation takes over (as in a saved file), and the
    # results are let go (never saved).
    _guarded(REGISTRY.deactivate_all, True)
    REGISTRY.reset()
    feed.forget_all()

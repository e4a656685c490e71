# SPDX-License-Identifier: GPL-3.0-or-later
"""When the add-on runs: Blender's handlers, timers and the check for a running Python operator
(nothing but the add-on's registration imports this module).

- `frame_change_pre` / `frame_change_post` (playback, `scene.frame_set()`, renders, motion blur
  steps, exporters): Blender evaluates the scene, runs the post handlers, then evaluates what
  they changed a second time. DQ Skin writes its results in the post handler, so the second
  evaluation shows the new frame with no lag. Objects Blender would evaluate in the first pass
  anyway output nothing there (see `Tracker.frame_pre`), so the modifiers after DQ Skin run
  once per frame.
- `depsgraph_update_post` (posing, editing settings, painting weights, mode changes): only what
  the update concerns is evaluated again, once the scene settles (see `engine.tracker`).
- `save_pre` / `save_post`: files are written with every companion Armature modifier on where
  DQ Skin is and no results (see `engine.saving`), then put back.
- `load_post`, `undo_post`, `redo_post`: the session is reset.
- An exporter starting or ending (see `exports`): every DQ Skin object is evaluated again.

Nothing raised here reaches Blender's console as a traceback: a failure is shown once, in one
line (`DQSKIN_DEBUG=1` prints the traceback), and on the panel.
"""

from __future__ import annotations

import os
import sys
import threading
import traceback

import bpy
from bpy.app.handlers import persistent

from . import exports
from .blender import node_group, nodes
from .engine import saving
from .model.runtime import ISSUES_URL
from .session import SESSION


def _guarded(fn, *args) -> None:
    errors = SESSION.errors
    if errors.busy:
        return
    errors.busy = True
    try:
        fn(*args)
    except Exception as e:  # a bug of the add-on: say it once, never stop Blender's work
        message = f"{type(e).__name__}: {e}"
        if message != errors.last:
            print(f"DQ Skin: internal error in {getattr(fn, '__name__', 'a handler')}: {message} (please report it at {ISSUES_URL})")
            if os.environ.get("DQSKIN_DEBUG"):
                traceback.print_exc()
        errors.last = message
    finally:
        errors.busy = False


def inside_python_operator(frame=None) -> bool:
    """Whether a Python operator is running (its `execute`, `invoke` or `modal` is on the stack,
    the caller's or from `frame` up): Blender evaluates the scene after each `bpy.ops` step it
    takes. (A script calling operators itself is not deferred: it may read the result right
    after.)"""
    f = frame if frame is not None else sys._getframe(1)
    while f is not None:
        code = f.f_code
        if code.co_name in ("execute", "invoke", "modal") and code.co_varnames[:1] == ("self",):
            if isinstance(f.f_locals.get("self"), bpy.types.Operator):
                return True
        f = f.f_back
    return False


def main_thread_in_operator() -> bool:
    """Whether the main thread is inside a Python operator. A driver may run on one of the
    graph's worker threads, whose own stack ends at the driver: the main thread's is the one
    that shows the operator."""
    main = sys._current_frames().get(threading.main_thread().ident)
    return main is not None and inside_python_operator(main)


def _settle():
    SESSION.tracker.settle(bpy.context.evaluated_depsgraph_get())
    return None


def _updates(depsgraph) -> None:
    if SESSION.tracker.updates(depsgraph, inside_python_operator()) and not bpy.app.background:
        bpy.app.timers.register(_settle, first_interval=0.0)


@persistent
def on_frame_change_pre(scene, depsgraph=None):
    _guarded(SESSION.tracker.frame_pre)


@persistent
def on_frame_change_post(scene, depsgraph=None):
    _guarded(SESSION.tracker.frame, depsgraph or bpy.context.evaluated_depsgraph_get())


@persistent
def on_depsgraph_update_post(scene, depsgraph):
    _guarded(_updates, depsgraph)


def _upgrade_node_groups() -> None:
    for group in bpy.data.node_groups:
        try:
            if group.bl_idname == "GeometryNodeTree" and nodes.version_of(group) in nodes.UPGRADABLE:
                node_group.upgrade(group)
        except (AttributeError, RuntimeError, TypeError) as e:  # never stop a file from loading
            print(f"DQ Skin: could not update node group {group.name!r}: {e}")


@persistent
def on_load_post(*_args):
    _upgrade_node_groups()
    SESSION.reset()
    exports.wrap_operators()  # exporters enabled by the file's preferences


@persistent
def on_undo(*_args):
    SESSION.reset()


@persistent
def on_save_pre(*_args):
    _guarded(saving.deactivate_all, SESSION)


@persistent
def on_save_post(*_args):
    _guarded(saving.reactivate_all, SESSION)


def _export_changed() -> None:
    """An exporter starts or ends: hand every DQ Skin over, or take it back."""
    depsgraph = bpy.context.view_layer.depsgraph
    _guarded(SESSION.tracker.evaluate_all, depsgraph)


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
    SESSION.operator_running = main_thread_in_operator
    for handlers, fn in HANDLERS:
        if fn not in handlers:
            # First, so that other add-ons' frame handlers run after DQ Skin wrote its results.
            handlers.insert(0, fn)
    if _export_changed not in SESSION.exports.listeners:
        SESSION.exports.listeners.append(_export_changed)
    exports.wrap_operators()


def unregister():
    exports.unwrap_operators()
    while _export_changed in SESSION.exports.listeners:
        SESSION.exports.listeners.remove(_export_changed)
    for handlers, fn in HANDLERS:
        while fn in handlers:
            handlers.remove(fn)
    # Without the add-on, Blender's own deformation takes over (as in a saved file), and the
    # results are let go (never saved).
    _guarded(saving.deactivate_all, SESSION)
    SESSION.close()

# SPDX-License-Identifier: GPL-3.0-or-later
"""Keeps every DQ Skin modifier's result current.

- `frame_change_post` (playback, `scene.frame_set()`, renders): Blender re-evaluates the scene
  after this handler when it changed data, so the evaluated mesh is the new frame's, not the
  previous one's.
- `depsgraph_update_post` (posing, editing settings): only for updates that are not our own
  writes to result meshes, so that our writes cannot loop.
"""

from __future__ import annotations

import bpy
from bpy.app.handlers import persistent

from . import modifier

_busy = False


def _result_names(scene) -> set[str]:
    names = set()
    for obj in scene.objects:
        for mod in modifier.dq_skin_modifiers(obj):
            s = modifier.nodes.socket_ids(mod.node_group)
            result = mod.get(s["Result"])
            if result is not None:
                names.add(result.name_full)
                names.add(result.data.name_full)
    return names


def update_scene(scene, depsgraph) -> None:
    global _busy
    if _busy:
        return
    _busy = True
    try:
        for obj in scene.objects:
            if obj.type != "MESH":
                continue
            for mod in modifier.dq_skin_modifiers(obj):
                if mod.show_viewport or mod.show_render:
                    modifier.evaluate(obj, mod, depsgraph)
    finally:
        _busy = False


@persistent
def on_frame_change(scene, depsgraph=None):
    update_scene(scene, depsgraph or bpy.context.evaluated_depsgraph_get())


def _tidy(scene) -> None:
    """After a DQ Skin modifier was removed without our operator (the X button), put back what
    `dq_skin_add` changed and drop the orphaned result data."""
    from .operators import REPLACED, restore_armature_modifiers

    for obj in scene.objects:
        if REPLACED in obj and not modifier.dq_skin_modifiers(obj):
            restore_armature_modifiers(obj)
    for result in [o for o in bpy.data.objects if o.get(modifier.RESULT_TAG) and o.users == 0]:
        mesh = result.data
        bpy.data.objects.remove(result)
        if mesh is not None and mesh.users == 0:
            bpy.data.meshes.remove(mesh)


@persistent
def on_depsgraph_update(scene, depsgraph):
    if _busy:
        return
    _tidy(scene)
    ours = _result_names(scene)
    relevant = False
    for update in depsgraph.updates:
        id_ = update.id
        name = getattr(id_, "original", id_).name_full if hasattr(id_, "name_full") else ""
        if name in ours:
            continue
        if update.is_updated_geometry and isinstance(id_, bpy.types.Mesh):
            # Weights or topology of this mesh may have changed: its objects bind again.
            mesh = getattr(id_, "original", id_)
            modifier.forget({o.name_full for o in scene.objects if o.data == mesh})
        relevant = True
    if relevant:
        update_scene(scene, depsgraph)


@persistent
def on_load(*_args):
    modifier.forget()


HANDLERS = (
    (bpy.app.handlers.frame_change_post, on_frame_change),
    (bpy.app.handlers.depsgraph_update_post, on_depsgraph_update),
    (bpy.app.handlers.load_post, on_load),
)


def register():
    for handlers, fn in HANDLERS:
        if fn not in handlers:
            handlers.append(fn)


def unregister():
    for handlers, fn in HANDLERS:
        while fn in handlers:
            handlers.remove(fn)

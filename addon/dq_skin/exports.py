# SPDX-License-Identifier: GPL-3.0-or-later
"""Exporters that skin from the Armature modifier see a DQ Skin character as Blender's own.

FBX and glTF export a skinned character as its rest mesh plus the armature and the vertex-group
weights: they take the skin from the object's Armature modifier and switch that modifier off
(FBX puts the armature in its rest position; glTF turns the modifier off) while they evaluate
the mesh with the other modifiers applied. A DQ Skin modifier is not an Armature modifier, so
while one of them exports, every DQ Skin hands over to its companion (see `consumers`): the
exporter then finds an Armature modifier set up like DQ Skin and exports exactly what it
exports for the same character under Blender's Armature modifier.

- glTF: through its own extension point, the `glTF2_pre_export_callback` and
  `glTF2_post_export_callback` functions of the add-on's module (glTF calls them around its
  export on Blender 4.2 to 5.x).
- FBX has none: its export operator's `execute` runs inside `exporting()` (wrapped while the
  add-on is enabled, unwrapped when it is disabled).

Such a file carries the skin, not the skinning method: other programs deform it with their own
Linear or Dual Quaternion skinning. Characters with one of DQ Skin's own methods (Blend,
Optimized Centers) export the same skin, and the export warns that the method stays behind
(Alembic, USD or a bake carry it).

Exporters that export the evaluated mesh (OBJ, PLY, STL, Alembic, USD, FBX and glTF without
skins) need nothing: they see DQ Skin's result, as they see the Armature modifier's.
"""

from __future__ import annotations

import contextlib
import sys

import bpy

from .blender import nodes
from .engine.context import dq_skin_modifiers
from .model.methods import BLENDER_METHODS
from .session import SESSION

BLENDER_LABELS = tuple(m.label for m in BLENDER_METHODS)


def methods_left_behind(objects) -> list[str]:
    """The objects among `objects` whose DQ Skin uses one of its own methods ("Body (Optimized
    Centers)"): a skin export carries their weights, not the method."""
    found = []
    for obj in objects:
        if obj.type != "MESH":
            continue
        for mod in dq_skin_modifiers(obj):
            method = nodes.get_method(mod)
            if (mod.show_viewport or mod.show_render) and method not in BLENDER_LABELS:
                found.append(f"{obj.name} ({method})")
    return found


def left_behind_warning(label: str, found: list[str]) -> str:
    return (
        f"{label} carries the skin of {', '.join(found)}: other programs deform it with their own Linear or "
        "Dual Quaternion skinning, not DQ Skin's method (export Alembic or USD, or bake, to carry the method)"
    )


@contextlib.contextmanager
def exporting(name: str):
    state = SESSION.exports
    state.running.append(name)
    state.changed()
    try:
        yield
    finally:
        state.running.remove(name)
        state.changed()


def glTF2_pre_export_callback(export_settings):
    """Found by the glTF exporter in every enabled add-on's module (see `__init__`)."""
    if not export_settings.get("gltf_skins", True):
        return
    scope = exporting("glTF")
    scope.__enter__()
    SESSION.exports.scopes.append(scope)
    found = methods_left_behind(_gltf_objects(export_settings))
    if found:
        _gltf_warn(export_settings, left_behind_warning("glTF", found))


def _gltf_objects(export_settings):
    context = bpy.context
    if export_settings.get("gltf_selected"):
        return list(context.selected_objects)
    return list(context.scene.objects) if context.scene is not None else []


def _gltf_warn(export_settings, message: str) -> None:
    """Through glTF's log (shown in its report), else on the console."""
    log = export_settings.get("log")
    if log is not None and hasattr(log, "warning"):
        log.warning(message)
    else:
        print(f"Warning: {message}")


def glTF2_post_export_callback(export_settings):
    if SESSION.exports.scopes:
        SESSION.exports.scopes.pop().__exit__(None, None, None)


# -- operators without extension points --------------------------------------------------------

_WRAPPED = "_dq_skin_original_execute"
# (module, operator class, label)
OPERATORS = (("io_scene_fbx", "ExportFBX", "FBX"),)


def wrap_operators() -> None:
    """Runs the exporters above inside `exporting()` (those whose add-on is loaded now)."""
    for module_name, class_name, label in OPERATORS:
        cls = getattr(sys.modules.get(module_name), class_name, None)
        if cls is None or hasattr(cls, _WRAPPED):
            continue
        setattr(cls, _WRAPPED, cls.execute)
        cls.execute = _wrapped(cls.execute, label)


def _wrapped(original, label: str):
    # Exactly (self, context): Blender checks the arguments of an operator's methods.
    def execute(self, context):
        objects = context.selected_objects if getattr(self, "use_selection", False) else context.scene.objects
        found = methods_left_behind(objects)
        with exporting(label):
            result = original(self, context)
        if found and "FINISHED" in result:
            self.report({"WARNING"}, left_behind_warning(label, found))
        return result

    return execute


def unwrap_operators() -> None:
    for module_name, class_name, _label in OPERATORS:
        cls = getattr(sys.modules.get(module_name), class_name, None)
        if cls is not None and hasattr(cls, _WRAPPED):
            cls.execute = getattr(cls, _WRAPPED)
            delattr(cls, _WRAPPED)

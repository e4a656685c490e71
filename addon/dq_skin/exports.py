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

Exporters that export the evaluated mesh (OBJ, PLY, STL, Alembic, USD, FBX and glTF without
skins) need nothing: they see DQ Skin's result, as they see the Armature modifier's.
"""

from __future__ import annotations

import contextlib
import sys

from .session import SESSION


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
        with exporting(label):
            return original(self, context)

    return execute


def unwrap_operators() -> None:
    for module_name, class_name, _label in OPERATORS:
        cls = getattr(sys.modules.get(module_name), class_name, None)
        if cls is not None and hasattr(cls, _WRAPPED):
            cls.execute = getattr(cls, _WRAPPED)
            delattr(cls, _WRAPPED)

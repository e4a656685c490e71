# SPDX-License-Identifier: GPL-3.0-or-later
"""DQ Skin: dual quaternion skinning for Blender, exact against the Armature modifier.

Blender glue only: Blender data is read into arrays for the bundled `dqskin` module (the Rust
core), which does all the math. The modifier is a Geometry Nodes modifier (`blender.nodes`)
whose positions reach Blender through a route (`routes`), evaluated by the `engine` whenever
the `scheduling` layer says so; everything mutable belongs to the `session`.

Layers, each importing only from those before it: `dqskin` and `model` (plain data, pure
decisions) < `blender` < `routes` < `engine` < `session` < `scheduling` and `exports` < `ops`,
`ui`, `tools`, `cli` < this module (tests/python/test_addon_structure.py checks it).
"""

import bpy

from . import scheduling
from .cli import batch, command  # noqa: F401  (`batch.main` is the launcher's entry point)

# Found by the glTF exporter in every enabled add-on's module (see `exports`).
from .exports import glTF2_post_export_callback, glTF2_pre_export_callback  # noqa: F401
from .ops import automatic_weights, bake, blend_paint, modifiers, switch, transfer_weights
from .session import SESSION  # noqa: F401  (scripts and tests reach the session here)
from .tools import animation, compare
from .ui import panel, preferences

CLASSES = (
    *modifiers.CLASSES,
    *switch.CLASSES,
    *blend_paint.CLASSES,
    *bake.CLASSES,
    *automatic_weights.CLASSES,
    *transfer_weights.CLASSES,
    *compare.CLASSES,
    *animation.CLASSES,
    *panel.CLASSES,
    *preferences.CLASSES,
)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    preferences.apply_saved()
    panel.register_menus()
    scheduling.register()
    command.register()


def unregister():
    command.unregister()
    scheduling.unregister()
    panel.unregister_menus()
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)

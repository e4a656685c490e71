# SPDX-License-Identifier: GPL-3.0-or-later
"""DQ Skin: dual quaternion skinning for Blender, exact against the Armature modifier.

Blender glue only: Blender data is read into arrays for the bundled `dqskin` module (the Rust
core), which does all the math. The modifier is a Geometry Nodes modifier (see `nodes`) whose
result the handlers (see `handlers`) keep current.
"""

import bpy

from . import animation, bake, blend_paint, cli, compare, handlers, operators, switch, ui

# Found by the glTF exporter in every enabled add-on's module (see `exports`).
from .exports import glTF2_post_export_callback, glTF2_pre_export_callback  # noqa: F401

CLASSES = (
    *operators.CLASSES,
    *switch.CLASSES,
    *blend_paint.CLASSES,
    *bake.CLASSES,
    *compare.CLASSES,
    *animation.CLASSES,
    *ui.CLASSES,
)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    ui.register_menus()
    handlers.register()
    cli.register()


def unregister():
    cli.unregister()
    handlers.unregister()
    ui.unregister_menus()
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)

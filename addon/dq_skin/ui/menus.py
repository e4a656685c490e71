# SPDX-License-Identifier: GPL-3.0-or-later
"""Object > DQ Skin in the 3D Viewport: every DQ Skin operator that acts on the active object,
so that the menu search (F3) finds each one, greyed out where it cannot run (their polls). The
animation tools have their own menu (Object and Pose > Animation > DQ Skin, `panel`), the
weighting operators also sit in Object > Parent (`weights_menu`)."""

from __future__ import annotations

import bpy


class VIEW3D_MT_object_dq_skin(bpy.types.Menu):
    """DQ Skin's tools for the active mesh: add and remove it, compare it with Blender's own
    deformation, paint the blend, store or bake its result, weight meshes, compare the methods"""

    bl_label = "DQ Skin"
    bl_idname = "VIEW3D_MT_object_dq_skin"

    def draw(self, context):
        layout = self.layout
        layout.operator("object.dq_skin_add", icon="MOD_ARMATURE")
        layout.operator("object.dq_skin_show_blender", icon="ARMATURE_DATA")
        layout.operator("object.dq_skin_paint_blend", icon="BRUSH_DATA")
        layout.operator("object.dq_skin_apply_as_shape_key", icon="SHAPEKEY_DATA")
        layout.operator("object.dq_skin_bake", text="Bake DQ Skin to Cache...", icon="FILE_CACHE")
        layout.operator("object.dq_skin_cancel_centers", icon="CANCEL")
        layout.operator("object.dq_skin_remove", icon="X")
        layout.separator()
        layout.operator("object.dq_skin_automatic_weights", icon="MOD_ARMATURE")
        layout.operator("object.dq_skin_transfer_weights", icon="MOD_CLOTH")
        layout.separator()
        layout.operator("object.dq_skin_comparison_scene", icon="MOD_ARMATURE")


def draw_object_entry(self, context):
    """Object > DQ Skin, at the end of the Object menu."""
    self.layout.separator()
    self.layout.menu(VIEW3D_MT_object_dq_skin.bl_idname)


CLASSES = (VIEW3D_MT_object_dq_skin,)

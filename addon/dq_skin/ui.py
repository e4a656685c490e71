# SPDX-License-Identifier: GPL-3.0-or-later
"""The DQ Skin panel in the Modifier properties: method, settings and a one-line status."""

from __future__ import annotations

import bpy

from . import centers, modifier, nodes


class OBJECT_PT_dq_skin(bpy.types.Panel):
    bl_label = "DQ Skin"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "modifier"

    @classmethod
    def poll(cls, context):
        obj = context.object
        return obj is not None and obj.type == "MESH"

    def draw(self, context):
        layout = self.layout
        obj = context.object
        mods = modifier.dq_skin_modifiers(obj)
        if not mods:
            row = layout.row()
            row.operator("object.dq_skin_add", icon="MOD_ARMATURE")
            return
        for mod in mods:
            box = layout.box()
            st = modifier.state(obj, mod)
            try:
                method = nodes.get_method(mod)
                box.label(text=f"{mod.name}: {method}", icon="MOD_ARMATURE")
            except Exception:  # a damaged modifier should not break the panel
                box.label(text=mod.name, icon="MOD_ARMATURE")
            job = next((j for j in centers.running() if obj.name in j.owners), None)
            if job is not None:
                row = box.row()
                row.progress(factor=job.fraction, type="BAR", text=f"Optimized Centers: {job.fraction:.0%} of {job.vertices} vertices")
                row.operator("object.dq_skin_cancel_centers", text="", icon="CANCEL")
            elif st.error:
                box.label(text=st.error, icon="ERROR")
            status = st.describe()
            if status:
                box.label(text=status, icon="INFO" if st.live or st.mode in ("off", "linked") else "ERROR")
            elif not st.error:
                box.label(text=_waiting(obj, mod), icon="TIME")
            if obj.library is None:
                op = box.operator("object.dq_skin_remove", icon="X")
                op.modifier = mod.name


def _waiting(obj, mod) -> str:
    if obj.library is not None:
        return "Linked data: Blender's Armature modifier deforms it (make a Library Override to use DQ Skin)"
    return "Not evaluated yet (the next frame change or update skins it)"


class VIEW3D_MT_dq_skin_animation(bpy.types.Menu):
    """The animation tools, in the Object and Pose menus' Animation submenu"""

    bl_label = "DQ Skin"
    bl_idname = "VIEW3D_MT_dq_skin_animation"

    def draw(self, context):
        layout = self.layout
        layout.operator("anim.dq_blend_transforms")
        layout.operator("anim.dq_screw_inbetweens")
        layout.operator("anim.dq_rotation_bake")
        layout.operator("anim.dq_quaternion_cleanup")
        layout.operator("anim.dq_spring_smoothing")
        layout.separator()
        layout.operator("anim.dq_rotation_speed_plot")


def draw_menu_entry(self, context):
    self.layout.menu(VIEW3D_MT_dq_skin_animation.bl_idname)


MENUS = ("VIEW3D_MT_object_animation", "VIEW3D_MT_pose_motion")


def register_menus():
    for name in MENUS:
        menu = getattr(bpy.types, name, None)
        if menu is not None:
            menu.append(draw_menu_entry)


def unregister_menus():
    for name in MENUS:
        menu = getattr(bpy.types, name, None)
        if menu is not None:
            menu.remove(draw_menu_entry)


CLASSES = (OBJECT_PT_dq_skin, VIEW3D_MT_dq_skin_animation)

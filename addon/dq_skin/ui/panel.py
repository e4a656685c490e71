# SPDX-License-Identifier: GPL-3.0-or-later
"""The DQ Skin panel in the Modifier properties: method, settings and a one-line status."""

from __future__ import annotations

from types import MappingProxyType

import bpy

from .. import dqskin
from ..blender import elsewhere, nodes, settings
from ..engine.context import dq_skin_modifiers
from ..model.runtime import ISSUES_URL
from ..model.state import Mode
from ..ops import blend_paint
from ..session import SESSION
from . import menus, weights_menu


class OBJECT_PT_dq_skin(bpy.types.Panel):
    """The object's DQ Skin modifiers: what deforms the mesh and why, the A/B switch against
    Blender's own deformation, and the tools that act on each"""

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
        mods = dq_skin_modifiers(obj)
        weights_menu.draw_panel_row(layout)
        if not mods:
            row = layout.row()
            row.operator("object.dq_skin_add", icon="MOD_ARMATURE")
            return
        for mod in mods:
            box = layout.box()
            try:
                method = nodes.get_method(mod)
                box.label(text=f"{mod.name}: {method}", icon="MOD_ARMATURE")
            except Exception:  # a damaged modifier should not break the panel
                box.label(text=mod.name, icon="MOD_ARMATURE")
            job = next((j for j in SESSION.centers.running() if obj.name in j.owners), None)
            if job is not None:
                row = box.row()
                row.progress(factor=job.fraction, type="BAR", text=f"Optimized Centers: {job.fraction:.0%} of {job.vertices} vertices")
                row.operator("object.dq_skin_cancel_centers", text="", icon="CANCEL")
            for line, icon in status_lines(obj, mod):
                box.label(text=line, icon=icon)
            if obj.library is None:
                _tools(box, obj, mod)
        if obj.library is None:
            # The object's whole DQ Skin result (every DQ Skin modifier) in one cache.
            layout.operator("object.dq_skin_bake", text="Bake to Cache", icon="FILE_CACHE")
        if SESSION.errors.last:
            layout.label(text=f"Internal error (please report it at {ISSUES_URL}): {SESSION.errors.last}", icon="ERROR")
            layout.operator("wm.url_open", text="Report It", icon="URL").url = ISSUES_URL


def _tools(box, obj, mod) -> None:
    """The A/B switch, painting the blend, and what else acts on one DQ Skin."""
    row = box.row()
    showing_blender = not mod.show_viewport
    op = row.operator(
        "object.dq_skin_show_blender",
        text="Show DQ Skin" if showing_blender else "Show Blender's Deformation",
        icon="MOD_ARMATURE" if showing_blender else "ARMATURE_DATA",
        depress=showing_blender,
    )
    op.modifier = mod.name
    status = SESSION.find_status(obj, mod)
    if status is not None and status.compared:
        box.label(text=status.compared, icon="DRIVER_DISTANCE")
    try:
        is_blend = settings.read(mod).method == dqskin.Method.BLEND
    except Exception:  # a damaged modifier should not break the panel
        is_blend = False
    if is_blend:
        box.label(text=blend_paint.describe(obj, mod), icon="GROUP_VERTEX")
        box.operator("object.dq_skin_paint_blend", icon="BRUSH_DATA").modifier = mod.name
    why = elsewhere.reason(obj, mod, lambda name: SESSION.meshes.get(obj, SESSION.readers.mesh).group_weights(name))
    if why:
        box.label(text=f"Without the DQ Skin extension (render farms) it {why}", icon="ERROR")
    row = box.row()
    row.operator("object.dq_skin_apply_as_shape_key", text="Apply as Shape Key", icon="SHAPEKEY_DATA").modifier = mod.name
    row.operator("object.dq_skin_remove", icon="X").modifier = mod.name


def draw_deform_entry(self, context):
    """Add Modifier > Deform > DQ Skin, beside Blender's Armature modifier."""
    if context.object is not None and context.object.type == "MESH":
        self.layout.operator("object.dq_skin_add", text="DQ Skin", icon="MOD_ARMATURE")


ICONS = MappingProxyType(
    {Mode.LIVE: "INFO", Mode.HANDED_OVER: "INFO", Mode.OFF: "INFO", Mode.LINKED: "INFO", Mode.FALLBACK: "ERROR", Mode.NEW: "TIME"}
)


def status_lines(obj, mod) -> list[tuple[str, str]]:
    """What the panel says about a modifier (reading the state creates none)."""
    status = SESSION.find_status(obj, mod)
    if status is None or status.mode is Mode.NEW:
        if obj.library is not None:
            return [("Linked data: Blender's Armature modifier deforms it (make a Library Override to use DQ Skin)", "INFO")]
        return [("Not evaluated yet (the next frame change or update skins it)", "TIME")]
    icon = ICONS[status.mode]
    if status.mode is Mode.LIVE:
        line = f"{status.method}: {status.bones} bones, {status.influences} influences, {status.seconds * 1e3:.1f} ms"
        return [(line, icon), *((note, "ERROR") for note in status.notes)]
    if status.mode is Mode.FALLBACK:
        return [(status.message, icon), (status.instead, "INFO")]
    return [(status.message, icon)]


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


# (menu, draw function): the animation tools in the Object and Pose menus; DQ Skin in the Add
# Modifier menu's Deform column (the Properties editor's and the 3D Viewport's Object > Modifiers);
# the weighting operators in Object > Parent; every other operator in Object > DQ Skin.
MENUS = (
    ("VIEW3D_MT_object", menus.draw_object_entry),
    ("VIEW3D_MT_object_animation", draw_menu_entry),
    ("VIEW3D_MT_pose_motion", draw_menu_entry),
    ("OBJECT_MT_modifier_add_deform", draw_deform_entry),
    ("VIEW3D_MT_object_parent", weights_menu.draw_parent_entries),
)


def register_menus():
    for name, fn in MENUS:
        menu = getattr(bpy.types, name, None)
        if menu is not None:
            menu.append(fn)


def unregister_menus():
    for name, fn in MENUS:
        menu = getattr(bpy.types, name, None)
        if menu is not None:
            menu.remove(fn)


CLASSES = (OBJECT_PT_dq_skin, VIEW3D_MT_dq_skin_animation, *menus.CLASSES)

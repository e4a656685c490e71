# SPDX-License-Identifier: GPL-3.0-or-later
"""Operators: add a DQ Skin modifier in place of an Armature modifier, and remove it again."""

from __future__ import annotations

import bpy

from . import modifier, nodes

# Custom properties on the DQ Skin modifier's object remembering what `dq_skin_add` changed, so
# that removal puts it back: {armature modifier name: [show_viewport, show_render]}.
REPLACED = "dq_skin_replaced"

METHOD_ITEMS = (
    ("AUTO", "From Armature Modifier", "Dual Quaternion if its Preserve Volume is on, else Linear"),
    ("LINEAR", "Linear", "Linear blend skinning (Preserve Volume off)"),
    ("DUAL_QUATERNION", "Dual Quaternion", "Dual quaternion skinning (Preserve Volume on)"),
    ("BLEND", "Blend", "Per-vertex blend of Linear and Dual Quaternion"),
)
MENU_NAME = {"LINEAR": "Linear", "DUAL_QUATERNION": "Dual Quaternion", "BLEND": "Blend"}


def set_input(mod, name: str, value) -> None:
    mod[nodes.socket_ids(mod.node_group)[name]] = value


def set_attribute(mod, name: str, group: str) -> None:
    key = nodes.socket_ids(mod.node_group)[name]
    mod[key + "_use_attribute"] = bool(group)
    mod[key + "_attribute_name"] = group


def menu_value(group, item: str) -> int:
    return next(v for v, name in nodes.menu_values(group).items() if name == item)


class ActiveMeshOperator(bpy.types.Operator):
    """Base of the operators that work on the active mesh object."""

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "MESH"


class OBJECT_OT_dq_skin_add(ActiveMeshOperator):
    """Add a DQ Skin modifier configured from the Armature modifier, in its place, and disable
    the Armature modifier (it is kept, so removing DQ Skin restores it)"""

    bl_idname = "object.dq_skin_add"
    bl_label = "Add DQ Skin"
    bl_options = {"REGISTER", "UNDO"}

    method: bpy.props.EnumProperty(name="Method", items=METHOD_ITEMS, default="AUTO")

    def execute(self, context):
        obj = context.active_object
        armature_mods = [m for m in obj.modifiers if m.type == "ARMATURE"]
        if not armature_mods:
            self.report({"ERROR"}, f"{obj.name} has no Armature modifier to replace")
            return {"CANCELLED"}
        source = next((m for m in armature_mods if m.show_viewport or m.show_render), armature_mods[0])
        if source.object is None:
            self.report({"ERROR"}, f"The Armature modifier {source.name!r} has no armature object")
            return {"CANCELLED"}
        group = nodes.ensure_group()
        index = list(obj.modifiers).index(source)
        mod = obj.modifiers.new("DQ Skin", "NODES")
        mod.node_group = group
        method = self.method
        if method == "AUTO":
            method = "DUAL_QUATERNION" if source.use_deform_preserve_volume else "LINEAR"
        set_input(mod, "Armature", source.object)
        set_input(mod, "Method", menu_value(group, MENU_NAME[method]))
        set_input(mod, "Use Vertex Groups", source.use_vertex_groups)
        set_input(mod, "Use Envelopes", source.use_bone_envelopes)
        set_attribute(mod, "Mask", source.vertex_group)
        set_input(mod, "Invert Mask", source.invert_vertex_group)
        modifier.ensure_result(obj, mod)
        with context.temp_override(object=obj, active_object=obj):
            bpy.ops.object.modifier_move_to_index(modifier=mod.name, index=index)
        replaced = dict(obj.get(REPLACED, {}))
        replaced[source.name] = [source.show_viewport, source.show_render]
        obj[REPLACED] = replaced
        source.show_viewport = False
        source.show_render = False
        modifier.forget({obj.name_full})
        self.report({"INFO"}, f"DQ Skin ({MENU_NAME[method]}) replaces {source.name!r} on {obj.name}")
        return {"FINISHED"}


def restore_armature_modifiers(obj) -> None:
    """Re-enables the Armature modifiers `dq_skin_add` disabled and forgets that it did."""
    replaced = obj.get(REPLACED)
    if replaced is None:
        return
    for name, (viewport, render) in dict(replaced).items():
        arm_mod = obj.modifiers.get(name)
        if arm_mod is not None:
            arm_mod.show_viewport = bool(viewport)
            arm_mod.show_render = bool(render)
    del obj[REPLACED]


def remove_modifier(obj, mod) -> None:
    """Removes a DQ Skin modifier and its result data; restores what `dq_skin_add` changed once
    no DQ Skin modifier is left."""
    result = mod.get(nodes.socket_ids(mod.node_group)["Result"])
    obj.modifiers.remove(mod)
    if result is not None and result.users == 0:
        mesh = result.data
        bpy.data.objects.remove(result)
        if mesh is not None and mesh.users == 0:
            bpy.data.meshes.remove(mesh)
    if not modifier.dq_skin_modifiers(obj):
        restore_armature_modifiers(obj)


class OBJECT_OT_dq_skin_remove(ActiveMeshOperator):
    """Remove the DQ Skin modifier and re-enable the Armature modifier it replaced"""

    bl_idname = "object.dq_skin_remove"
    bl_label = "Remove DQ Skin"
    bl_options = {"REGISTER", "UNDO"}

    modifier: bpy.props.StringProperty(name="Modifier", description="Name of the DQ Skin modifier (default: the first)")

    def execute(self, context):
        obj = context.active_object
        mods = modifier.dq_skin_modifiers(obj)
        if self.modifier:
            mods = [m for m in mods if m.name == self.modifier]
        if not mods:
            self.report({"ERROR"}, f"{obj.name} has no DQ Skin modifier" + (f" named {self.modifier!r}" if self.modifier else ""))
            return {"CANCELLED"}
        remove_modifier(obj, mods[0])
        return {"FINISHED"}


CLASSES = (OBJECT_OT_dq_skin_add, OBJECT_OT_dq_skin_remove)

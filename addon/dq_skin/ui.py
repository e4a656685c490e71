# SPDX-License-Identifier: GPL-3.0-or-later
"""The DQ Skin panel in the Modifier properties: method, settings and a one-line status."""

from __future__ import annotations

import bpy

from . import modifier


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
                s = modifier.settings(mod)
                box.label(text=f"{mod.name}: {s.method.replace('_', ' ').title()}", icon="MOD_ARMATURE")
            except Exception:  # a damaged modifier should not break the panel
                box.label(text=mod.name, icon="MOD_ARMATURE")
            if st.error:
                box.label(text=st.error, icon="ERROR")
            elif st.status:
                box.label(text=st.status, icon="INFO")
            op = box.operator("object.dq_skin_remove", icon="X")
            op.modifier = mod.name


CLASSES = (OBJECT_PT_dq_skin,)

# SPDX-License-Identifier: GPL-3.0-or-later
"""Operators: add a DQ Skin modifier in place of an Armature modifier, and remove it again."""

from __future__ import annotations

import bpy

from ..blender import companion, compat, node_group, nodes, settings
from ..engine import removal
from ..engine.context import dq_skin_modifiers
from ..model.methods import BY_NAME, DESCRIPTIONS, METHODS
from ..session import SESSION

METHOD_ITEMS = (
    ("AUTO", "From Armature Modifier", "Dual Quaternion if the Armature modifier's Preserve Volume is on, else Linear"),
    *((m.name, m.label, DESCRIPTIONS[m]) for m in METHODS),
)


def set_input(mod, name: str, value) -> None:
    """Sets a DQ Skin setting by name ("Method" takes an item name: 'Linear', 'Dual Quaternion',
    'Blend', 'Optimized Centers')."""
    if name == "Method":
        nodes.put_method(mod, value if isinstance(value, str) else nodes.menu_values(mod.node_group)[value])
    else:
        nodes.put(mod, name, value)


def set_attribute(mod, name: str, group: str) -> None:
    nodes.put_attribute(mod, name, group)


def menu_value(group, item: str) -> str:
    """Kept for scripts written for DQ Skin 0.1: the method item itself."""
    return item


class ActiveMeshOperator(bpy.types.Operator):
    """Base of the operators that work on the active mesh object."""

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "MESH"


def add(obj, source, method: str = "AUTO", made: dict | None = None):
    """Adds a DQ Skin modifier configured from the Armature modifier `source`, right before it,
    and keeps `source` as its companion. `made`: what `dq_skin_add` made for it (an Armature
    modifier it created, a parent type it changed), undone when DQ Skin is removed. Returns the
    new modifier."""
    group = node_group.ensure_group()
    index = list(obj.modifiers).index(source)
    mod = obj.modifiers.new("DQ Skin", "NODES")
    mod.node_group = group
    if method == "AUTO":
        method = "DUAL_QUATERNION" if source.use_deform_preserve_volume else "LINEAR"
    nodes.put_companion(mod, {"name": source.name, "original": companion.snapshot(source), **(made or {})})
    nodes.put(mod, "Armature", source.object)
    nodes.put_method(mod, BY_NAME[method].label)
    nodes.put(mod, "Use Vertex Groups", source.use_vertex_groups)
    nodes.put(mod, "Use Envelopes", source.use_bone_envelopes)
    nodes.put_attribute(mod, "Mask", source.vertex_group)
    nodes.put(mod, "Invert Mask", source.invert_vertex_group)
    mod.show_viewport = source.show_viewport
    mod.show_render = source.show_render
    mod.show_in_editmode = source.show_in_editmode
    mod.show_on_cage = source.show_on_cage
    obj.modifiers.move(len(obj.modifiers) - 1, index)
    # Until DQ Skin has its first result, the companion deforms as Blender would.
    companion.configure(source, mod, settings.read(mod), (mod.show_viewport, mod.show_render))
    return mod


def armature_modifier_from_parent(obj):
    """For a mesh parented to an armature without an Armature modifier: one set up as Ctrl+P
    With Automatic Weights sets it up (the parent's armature, vertex groups), at the top of the
    stack, and what was made (to undo on removal). A mesh parented with the legacy Armature
    parent type is deformed by its parent already: it becomes an object parent, so that the
    new modifier deforms it instead (same transform)."""
    made = {"created": True}
    if obj.parent_type == "ARMATURE":
        made["parent_type"] = "ARMATURE"
        obj.parent_type = "OBJECT"
    arm_mod = obj.modifiers.new("Armature", "ARMATURE")
    arm_mod.object = obj.parent
    obj.modifiers.move(len(obj.modifiers) - 1, 0)
    return arm_mod, made


class OBJECT_OT_dq_skin_add(ActiveMeshOperator):
    """Deform the mesh with DQ Skin in place of its Armature modifier (or with the armature it is
    parented to): the same armature, vertex groups and mask, plus Dual Quaternion, a painted
    Blend of both, or Optimized Centers. The Armature modifier stays right after it, switched
    off while DQ Skin deforms, so the file renders the same without DQ Skin"""

    bl_idname = "object.dq_skin_add"
    bl_label = "Add DQ Skin"
    bl_options = {"REGISTER", "UNDO"}

    method: bpy.props.EnumProperty(
        name="Method",
        description="How bones bend the mesh (default: as the Armature modifier's Preserve Volume says)",
        items=METHOD_ITEMS,
        default="AUTO",
    )
    all_selected: bpy.props.BoolProperty(
        name="All Selected",
        description="Add DQ Skin to every selected mesh with an Armature modifier, not only the active one "
        "(one dependency-graph rebuild for all of them)",
        default=False,
    )

    def execute(self, context):
        active = context.active_object
        targets = [active]
        if self.all_selected:
            chosen = [o for o in context.selected_objects if o.type == "MESH" and o is not active]
            targets = [active, *chosen] if active is not None and active.type == "MESH" else chosen
        added, problems = [], []
        tracker = SESSION.tracker
        with tracker.suspend():
            for obj in targets:
                problem = self._add(obj)
                if problem:
                    problems.append(problem)
                else:
                    added.append(obj)
        if not added:
            self.report({"ERROR"}, "; ".join(problems) or "Nothing to add DQ Skin to")
            return {"CANCELLED"}
        # Skin right away, so the first frame is already DQ Skin's (and binding errors show).
        # The view layer's depsgraph as last evaluated (the armatures' poses are there): forcing
        # an evaluation here would rebuild the scene's relations once more for nothing.
        # Records first, then one context: each new record changes the scene's structure, and a
        # context per object would rebuild the scan of what simulates on what once per object
        # (with 200 characters, 1.2 s of a 5.4 s operator).
        depsgraph = context.view_layer.depsgraph
        records = [tracker.record_of(obj) for obj in added]
        ctx = tracker.context(depsgraph)
        for rec in records:
            tracker.evaluate(rec, depsgraph, ctx=ctx)
        if len(added) == 1:
            mod = dq_skin_modifiers(added[0])[-1]
            self.report({"INFO"}, f"DQ Skin ({nodes.get_method(mod)}) replaces {nodes.get_companion(mod)['name']!r} on {added[0].name}")
        else:
            self.report({"INFO"}, f"DQ Skin added to {len(added)} objects" + (f"; skipped: {'; '.join(problems)}" if problems else ""))
        return {"FINISHED"}

    def _add(self, obj) -> str:
        """Adds DQ Skin to `obj`; returns what is wrong instead, if anything."""
        if obj.library is not None:
            return f"{obj.name} is linked from a library: make a Library Override first"
        existing = dq_skin_modifiers(obj)
        taken = {nodes.get_companion(m).get("name") for m in existing}
        armature_mods = [m for m in obj.modifiers if m.type == "ARMATURE" and m.name not in taken]
        made = None
        if not armature_mods:
            if existing:
                # Another one would deform the mesh a second time with the same armature.
                return (
                    f"{obj.name} already has DQ Skin ({', '.join(m.name for m in existing)}) for each of its Armature "
                    "modifiers: change its settings instead, or add an Armature modifier for another armature first"
                )
            if obj.parent is None or obj.parent.type != "ARMATURE":
                return (
                    f"{obj.name} has no Armature modifier and is not parented to an armature: add an "
                    "Armature modifier or parent it to an armature (Ctrl+P) first"
                )
            source, made = armature_modifier_from_parent(obj)
        else:
            source = next((m for m in armature_mods if m.show_viewport or m.show_render), armature_mods[0])
        if source.object is None:
            return f"The Armature modifier {source.name!r} has no armature object"
        add(obj, source, self.method, made)
        return ""


def remove_modifier(obj, mod, applied: bool = False) -> None:
    """Removes a DQ Skin modifier and everything of it (see `Registry.forget_modifier`): its
    companion is put back as it was before `dq_skin_add`, or, with `applied`, removed too."""
    info = removal.info_of(mod)
    uid = compat.modifier_uid(mod)
    obj.modifiers.remove(mod)
    removal.forget_modifier(SESSION, obj, uid, info, applied)
    tracker = SESSION.tracker
    rec = tracker.records.get(obj.session_uid)
    if rec is not None:
        rec.mods.pop(uid, None)
        tracker.refresh(rec)


class DQSkinOperator(ActiveMeshOperator):
    """Base of the operators that need DQ Skin on the active mesh: greyed out without it (the
    tooltip, and a script's error, say why)."""

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        if obj is None or obj.type != "MESH":
            return False
        if not dq_skin_modifiers(obj):
            cls.poll_message_set(f"{obj.name} has no DQ Skin modifier")
            return False
        return True


class ModifierOperator(DQSkinOperator):
    """Base of the operators acting on one DQ Skin modifier of the active object."""

    modifier: bpy.props.StringProperty(name="Modifier", description="Name of the DQ Skin modifier (default: the first)")

    def target(self, context):
        """The active object and the modifier named (or its first DQ Skin); None for the
        modifier after reporting why."""
        obj = context.active_object
        mods = dq_skin_modifiers(obj)
        if self.modifier:
            mods = [m for m in mods if m.name == self.modifier]
        if not mods:
            self.report({"ERROR"}, f"{obj.name} has no DQ Skin modifier" + (f" named {self.modifier!r}" if self.modifier else ""))
            return obj, None
        if obj.library is not None:
            self.report({"ERROR"}, f"{obj.name} is linked from a library and cannot be changed")
            return obj, None
        return obj, mods[0]


class OBJECT_OT_dq_skin_remove(ModifierOperator):
    """Remove the DQ Skin modifier and put back the Armature modifier it replaced"""

    bl_idname = "object.dq_skin_remove"
    bl_label = "Remove DQ Skin"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        obj, mod = self.target(context)
        if mod is None:
            return {"CANCELLED"}
        remove_modifier(obj, mod)
        return {"FINISHED"}


class OBJECT_OT_dq_skin_apply_as_shape_key(ModifierOperator):
    """Store DQ Skin's deformation of the current frame in a new shape key (Blender's own Apply
    as Shape Key only takes deform-only modifiers, which a Geometry Nodes modifier is not)"""

    bl_idname = "object.dq_skin_apply_as_shape_key"
    bl_label = "Apply DQ Skin as Shape Key"
    bl_options = {"REGISTER", "UNDO"}

    keep_modifier: bpy.props.BoolProperty(
        name="Keep Modifier",
        description="Keep DQ Skin in the stack (Save as Shape Key); off: remove it and its Armature modifier, as Apply does",
        default=False,
    )

    def execute(self, context):
        obj, mod = self.target(context)
        if mod is None:
            return {"CANCELLED"}
        tracker = SESSION.tracker
        tracker.evaluate(tracker.record_of(obj), context.evaluated_depsgraph_get(), force=True)
        st = SESSION.state_of(obj, mod)
        out = st.output.buffer
        if not st.status.live or out is None or len(out) != len(obj.data.vertices):
            self.report({"ERROR"}, f"DQ Skin is not deforming {obj.name} now: {st.status.message or 'nothing to store'}")
            return {"CANCELLED"}
        out = out.copy()
        name = mod.name
        if obj.data.shape_keys is None:
            obj.shape_key_add(name="Basis", from_mix=False)
        key = obj.shape_key_add(name=name, from_mix=False)
        key.value = 0.0  # as Blender's Apply as Shape Key leaves it
        points = getattr(key, "points", None)  # the fast path (Blender 4.1+)
        (points if points is not None else key.data).foreach_set("co", out.ravel())
        obj.data.update()
        if not self.keep_modifier:
            remove_modifier(obj, mod, applied=True)
        self.report({"INFO"}, f"DQ Skin's deformation stored in shape key {key.name!r}")
        return {"FINISHED"}


class OBJECT_OT_dq_skin_cancel_centers(bpy.types.Operator):
    """Stop computing the Optimized Centers of the active object (Blender's deformation stays)"""

    bl_idname = "object.dq_skin_cancel_centers"
    bl_label = "Cancel Optimized Centers"

    @classmethod
    def poll(cls, context):
        obj = context.object
        if obj is None or not any(obj.name in j.owners for j in SESSION.centers.running()):
            cls.poll_message_set("No Optimized Centers are being computed for the active object")
            return False
        return True

    def execute(self, context):
        obj = context.object
        jobs = [j for j in SESSION.centers.running() if obj is not None and obj.name in j.owners]
        for job in jobs:
            SESSION.centers.cancel(job.key)
        if not jobs:
            self.report({"INFO"}, "Nothing is being computed for this object")
            return {"CANCELLED"}
        return {"FINISHED"}


CLASSES = (OBJECT_OT_dq_skin_add, OBJECT_OT_dq_skin_remove, OBJECT_OT_dq_skin_apply_as_shape_key, OBJECT_OT_dq_skin_cancel_centers)

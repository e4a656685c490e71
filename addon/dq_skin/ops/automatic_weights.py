# SPDX-License-Identifier: GPL-3.0-or-later
"""Automatic weights that never leave a vertex out: the selected meshes bound to the active
armature by geodesic voxel binding (`dqskin.automatic_weights`), parented and given an Armature
modifier as Parent > With Automatic Weights does (a mesh whose DQ Skin already deforms it with
this armature keeps it)."""

from __future__ import annotations

import bpy

from .. import dqskin
from ..blender import weights_io
from ..session import SESSION
from .background import BackgroundOperator, Plan


def armature_of(context):
    """The armature to bind to: the active object if it is one, else a selected one, else the
    active mesh's (its Armature modifier's or its parent)."""
    active = context.active_object
    if active is not None and active.type == "ARMATURE":
        return active
    chosen = [o for o in context.selected_objects if o.type == "ARMATURE"]
    if chosen:
        return chosen[0]
    if active is not None and active.type == "MESH":
        for m in active.modifiers:
            if m.type == "ARMATURE" and m.object is not None:
                return m.object
        if active.parent is not None and active.parent.type == "ARMATURE":
            return active.parent
    return None


def meshes_of(context) -> list:
    """The selected meshes (and the active one), editable ones only."""
    found = [o for o in context.selected_objects if o.type == "MESH"]
    active = context.active_object
    if active is not None and active.type == "MESH" and active not in found:
        found.append(active)
    return [o for o in found if o.library is None]


def parent_like_blender(armature, meshes) -> None:
    """Parents `meshes` to `armature` and gives each an Armature modifier for it (unless one
    exists: DQ Skin's companion counts) and empty groups for its deforming bones, exactly as
    Blender's Parent > With Empty Groups, which With Automatic Weights shares."""
    objects = [*meshes, armature]
    with bpy.context.temp_override(active_object=armature, object=armature, selected_objects=objects, selected_editable_objects=objects):
        bpy.ops.object.parent_set(type="ARMATURE_NAME")


class OBJECT_OT_dq_skin_automatic_weights(BackgroundOperator):
    """Bind the selected meshes to the active armature with automatic weights from geodesic
    distances through the mesh's volume (voxels): works on open, intersecting and multi-part meshes
    (loose eyes, teeth, unwelded seams) where bone heat fails, and never leaves a vertex
    unweighted. Parents and adds the Armature modifier as Parent > With Automatic Weights does"""

    bl_idname = "object.dq_skin_automatic_weights"
    bl_label = "Automatic Weights (DQ Skin)"
    bl_options = {"REGISTER", "UNDO"}

    resolution: bpy.props.IntProperty(
        name="Resolution",
        description="Voxels along the longest side of each mesh: higher separates fingers and thin parts better, "
        "takes longer and more memory",
        default=128,
        min=16,
        max=512,
    )
    falloff: bpy.props.FloatProperty(
        name="Falloff",
        description="How fast a bone's influence fades with distance (0: slowly, smooth bends; 1: fast, tight joints)",
        default=0.2,
        min=0.0,
        max=1.0,
    )
    max_influences: bpy.props.IntProperty(
        name="Max Influences", description="The most bones that move one vertex", default=4, min=1, max=16
    )
    smoothing: bpy.props.IntProperty(name="Smoothing", description="Smoothing passes over the weights (0: none)", default=0, min=0, max=100)
    deforming_only: bpy.props.BoolProperty(
        name="Deforming Bones Only", description="Weight only bones with Deform on, as Blender does", default=True
    )
    mirror: bpy.props.BoolProperty(
        name="Mirror",
        description="Make the weights symmetric across the armature's X axis, by bone name (hand.L and hand.R)",
        default=False,
    )

    @classmethod
    def poll(cls, context):
        return context.mode == "OBJECT" and armature_of(context) is not None and bool(meshes_of(context))

    def plan(self, context) -> Plan | str:
        armature = armature_of(context)
        meshes = meshes_of(context)
        if armature is None or not meshes:
            return "Select the meshes, then the armature (active), as for Parent > With Automatic Weights"
        bones = weights_io.rest_bones(armature, self.deforming_only)
        if not bones.names:
            return f"{armature.name} has no {'deforming ' if self.deforming_only else ''}bones to weight to"
        rest = [weights_io.rest_mesh(obj, armature) for obj in meshes]
        options = {
            "resolution": self.resolution,
            "falloff": self.falloff,
            "max_influences": self.max_influences,
            "smoothing": self.smoothing,
            "mirror": bones.names if self.mirror else None,
        }

        def starter(r):
            return lambda: dqskin.automatic_weights_job(r.positions, r.triangles, bones.heads, bones.tails, **options)

        steps = [(starter(r), len(r.positions)) for r in rest]

        def finish(context, results) -> str:
            parent_like_blender(armature, meshes)
            reader = SESSION.readers.mesh
            for obj, (influences, _report) in zip(meshes, results):
                weights_io.write_groups(obj, bones.names, influences, reader)
            unreached = sum(r["unreached"] for _i, r in results)
            outside = sorted({bones.names[int(b)] for _i, r in results for b in r["outside_bones"]})
            text = (
                f"Automatic weights: {sum(len(r.positions) for r in rest)} vertices of {len(meshes)} "
                f"mesh{'es' if len(meshes) > 1 else ''} on {len(bones.names)} bones; "
                f"{unreached} vertices no bone reached took their nearest bones"
            )
            if outside:
                text += f"; bones outside the mesh: {', '.join(outside[:8])}{' ...' if len(outside) > 8 else ''}"
            return text

        return Plan(steps, finish, "Automatic weights")


CLASSES = (OBJECT_OT_dq_skin_automatic_weights,)

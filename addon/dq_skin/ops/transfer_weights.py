# SPDX-License-Identifier: GPL-3.0-or-later
"""Weight transfer from a skinned body to clothing (`dqskin.transfer_weights`): the active mesh
is the body, the other selected meshes the clothing. Each garment gets vertex groups named after
the body's bones and, if it has none, an Armature modifier for the body's armature."""

from __future__ import annotations

import math

import bpy

from .. import dqskin
from ..blender import weights_io
from ..session import SESSION
from .background import BackgroundOperator, Plan


def armature_of_body(body):
    """The armature deforming `body` (its first Armature modifier's, else its parent), or None."""
    for m in body.modifiers:
        if m.type == "ARMATURE" and m.object is not None:
            return m.object
    if body.parent is not None and body.parent.type == "ARMATURE":
        return body.parent
    return None


def bone_names_of(body, armature) -> list[str]:
    """The groups to transfer: those of the armature's deforming bones that the body has, else
    (no armature) every group of the body."""
    names = [g.name for g in body.vertex_groups]
    if armature is None:
        return names
    deforming = {b.name for b in armature.data.bones if b.use_deform}
    return [n for n in names if n in deforming]


def ensure_armature_modifier(obj, armature) -> None:
    """An Armature modifier for `armature` at the top of the stack, unless one exists."""
    if armature is None or any(m.type == "ARMATURE" and m.object == armature for m in obj.modifiers):
        return
    mod = obj.modifiers.new("Armature", "ARMATURE")
    mod.object = armature
    obj.modifiers.move(len(obj.modifiers) - 1, 0)


class OBJECT_OT_dq_skin_transfer_weights(BackgroundOperator):
    """Transfer skin weights from the active (skinned) body to the selected clothing: each
    garment vertex near the body and facing the same way takes the body's weights there, the others
    are filled in smoothly from them, and loose parts with no match move with the nearest match"""

    bl_idname = "object.dq_skin_transfer_weights"
    bl_label = "Transfer Weights to Clothing (DQ Skin)"
    bl_options = {"REGISTER", "UNDO"}

    max_distance: bpy.props.FloatProperty(
        name="Max Distance",
        description="How far a garment vertex may be from the body to take its weights there "
        "(0: 5% of the garment's size, as the weight-inpainting paper)",
        default=0.0,
        min=0.0,
        subtype="DISTANCE",
    )
    max_angle: bpy.props.FloatProperty(
        name="Max Angle",
        description="The largest angle between the garment's and the body's normals for a match",
        default=math.radians(30.0),
        min=0.0,
        max=math.pi,
        subtype="ANGLE",
    )
    flipped_normals: bpy.props.BoolProperty(
        name="Flipped Normals", description="Also match where the garment's normals point into the body", default=False
    )
    smoothing: bpy.props.IntProperty(
        name="Smoothing", description="Smoothing passes over the filled-in weights (0: none)", default=0, min=0, max=100
    )
    max_influences: bpy.props.IntProperty(
        name="Max Influences", description="The most bones that move one vertex", default=4, min=1, max=16
    )

    @classmethod
    def poll(cls, context):
        body = context.active_object
        return (
            context.mode == "OBJECT"
            and body is not None
            and body.type == "MESH"
            and any(o.type == "MESH" and o is not body for o in context.selected_objects)
        )

    def plan(self, context) -> Plan | str:
        body = context.active_object
        garments = [o for o in context.selected_objects if o.type == "MESH" and o is not body and o.library is None]
        if body is None or body.type != "MESH" or not garments:
            return "Select the clothing, then the skinned body (active)"
        armature = armature_of_body(body)
        names = bone_names_of(body, armature)
        if not names:
            return f"{body.name} has no vertex groups of deforming bones to transfer"
        reader = SESSION.readers.mesh
        source = weights_io.body_influences(body, names, reader)
        body_mesh = weights_io.rest_mesh(body)
        cloth = [weights_io.rest_mesh(o) for o in garments]
        options = {
            "max_distance": self.max_distance or None,
            "max_angle": math.degrees(self.max_angle),
            "flipped_normals": self.flipped_normals,
            "smoothing": self.smoothing,
            "max_influences": self.max_influences,
        }

        def starter(c):
            return lambda: dqskin.transfer_weights_job(
                body_mesh.positions, body_mesh.triangles, source, c.positions, c.triangles, **options
            )

        steps = [(starter(c), len(c.positions)) for c in cloth]

        def finish(context, results) -> str:
            for obj, (influences, _report) in zip(garments, results):
                weights_io.write_groups(obj, names, influences, reader)
                ensure_armature_modifier(obj, armature)
            matched = sum(r["matched_count"] for _i, r in results)
            inpainted = sum(r["inpainted"] for _i, r in results)
            nearest = sum(r["from_nearest"] for _i, r in results)
            return (
                f"Weights transferred from {body.name} on {len(names)} bones: {matched} vertices matched, "
                f"{inpainted} filled in, {nearest} in loose parts took the nearest match"
            )

        return Plan(steps, finish, "Weight transfer")


CLASSES = (OBJECT_OT_dq_skin_transfer_weights,)

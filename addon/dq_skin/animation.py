# SPDX-License-Identifier: GPL-3.0-or-later
"""Animation tools: blend transforms, screw in-betweens, spherical rotation bake and quaternion
cleanup. Each works on the selected objects, or the selected pose bones in Pose Mode, is
undoable, and reports what it did or why it could not. The math is the bundled core's.
"""

from __future__ import annotations

import bpy
import numpy as np
from mathutils import Matrix

from . import dqskin, keys

F32 = np.float32


def _frames_between(first: float, last: float, step: float, extra) -> np.ndarray:
    """Every `step` from `first` to `last`, plus the `extra` frames (the keys), sorted."""
    grid = np.arange(first, last + step * 1e-3, step, dtype=np.float64)
    return np.unique(np.round(np.concatenate([grid, np.asarray(extra, np.float64)]), 4)).astype(F32)


class ANIM_OT_dq_quaternion_cleanup(bpy.types.Operator):
    """Make quaternion rotation keys sign-continuous (no sudden 360° spins) and normalize them"""

    bl_idname = "anim.dq_quaternion_cleanup"
    bl_label = "Quaternion Cleanup"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        targets = [t for t in keys.selected_targets(context) if keys.rotation_kind(t) == "QUATERNION"]
        if not targets:
            self.report({"ERROR"}, "Nothing selected has keyed quaternion rotation")
            return {"CANCELLED"}
        changed = flipped = 0
        for t in targets:
            frames = keys.key_frames(t, ("rotation_quaternion",))
            q = keys.rotations_at(t, frames)
            if np.any(np.linalg.norm(q, axis=1) == 0):
                self.report({"ERROR"}, f"{t.label} has a zero quaternion key")
                return {"CANCELLED"}
            fixed, n = dqskin.continuous_signs(q)
            flipped += n
            changed += int(np.any(np.abs(fixed - q) > 1e-6, axis=1).sum())
            keys.set_values(t, "rotation_quaternion", frames, fixed)
        self.report({"INFO"}, f"Quaternion Cleanup: {changed} keys changed ({flipped} sign flips) on {len(targets)} item(s)")
        return {"FINISHED"}


class ANIM_OT_dq_rotation_bake(bpy.types.Operator):
    """Resample rotation keys along Slerp (between keys) or Squad (smooth through keys), keeping
    the keys' timing; Euler rotation is converted; writes unit quaternion keys"""

    bl_idname = "anim.dq_rotation_bake"
    bl_label = "Spherical Rotation Bake"
    bl_options = {"REGISTER", "UNDO"}

    method: bpy.props.EnumProperty(
        name="Method",
        items=(("SLERP", "Slerp", "Shortest arc at constant speed between neighbouring keys"),
               ("SQUAD", "Squad", "Smooth through the keys (continuous angular velocity)")),
        default="SQUAD",
    )
    step: bpy.props.FloatProperty(name="Step", description="Frames between baked keys (sub-frames allowed)", default=1.0, min=0.01, soft_max=10.0)

    def execute(self, context):
        targets = [t for t in keys.selected_targets(context) if keys.rotation_kind(t)]
        if not targets:
            self.report({"ERROR"}, "Nothing selected has keyed rotation")
            return {"CANCELLED"}
        baked = 0
        for t in targets:
            kind = keys.rotation_kind(t)
            frames = keys.key_frames(t)
            if len(frames) < 2:
                self.report({"WARNING"}, f"{t.label}: fewer than two rotation keys, skipped")
                continue
            q = keys.rotations_at(t, frames)
            at = _frames_between(float(frames[0]), float(frames[-1]), self.step, frames)
            samples = dqskin.sample_rotations(frames, q, at, method=self.method.lower())
            if kind == "EULER":
                keys.remove_channels(t, "rotation_euler", 3)
                t.item.rotation_mode = "QUATERNION"
            keys.write(t, "rotation_quaternion", at, samples, replace_between=(float(frames[0]), float(frames[-1])))
            baked += len(at)
        self.report({"INFO"}, f"Spherical Rotation Bake ({self.method.title()}): {baked} keys on {len(targets)} item(s)")
        return {"FINISHED"}


class ANIM_OT_dq_screw_inbetweens(bpy.types.Operator):
    """Bake location and rotation between neighbouring keys along the screw motion (ScLERP),
    every Step frames, keeping the keys' timing"""

    bl_idname = "anim.dq_screw_inbetweens"
    bl_label = "Screw In-betweens"
    bl_options = {"REGISTER", "UNDO"}

    step: bpy.props.FloatProperty(name="Step", description="Frames between baked keys (sub-frames allowed)", default=1.0, min=0.01, soft_max=10.0)

    def execute(self, context):
        targets = keys.selected_targets(context)
        done = 0
        for t in targets:
            frames = keys.key_frames(t, ("location", "rotation_quaternion", "rotation_euler"))
            if len(frames) < 2:
                continue
            kind = keys.rotation_kind(t)
            locations = keys.locations_at(t, frames)
            rotations = keys.rotations_at(t, frames)
            transforms = np.stack([
                dqskin.DualQuat.from_rotation_translation(r, loc).to_array() for r, loc in zip(rotations, locations)
            ])
            at = _frames_between(float(frames[0]), float(frames[-1]), self.step, frames)
            samples = dqskin.sample_transforms(frames, transforms, at)
            matrices = dqskin.matrices_from_dual_quats(samples)
            span = (float(frames[0]), float(frames[-1]))
            if kind == "EULER":
                keys.remove_channels(t, "rotation_euler", 3)
                t.item.rotation_mode = "QUATERNION"
            keys.write(t, "location", at, matrices[:, :3, 3], replace_between=span)
            keys.write(t, "rotation_quaternion", at, samples[:, :4], replace_between=span)
            done += 1
        if not done:
            self.report({"ERROR"}, "Nothing selected has two or more transform keys")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Screw In-betweens on {done} item(s)")
        return {"FINISHED"}


class ANIM_OT_dq_blend_transforms(bpy.types.Operator):
    """Set the active object's (or pose bone's) transform to the weighted blend of the other
    selected ones' world transforms (weights in selection order by name)"""

    bl_idname = "anim.dq_blend_transforms"
    bl_label = "Blend Transforms"
    bl_options = {"REGISTER", "UNDO"}

    method: bpy.props.EnumProperty(
        name="Method",
        items=(("DLB", "DLB", "Dual quaternion linear blending (fast)"),
               ("DIB", "DIB", "Dual quaternion iterative blending (exact)"),
               ("SCLERP", "ScLERP", "Screw interpolation (two inputs)")),
        default="DLB",
    )
    weights: bpy.props.FloatVectorProperty(name="Weights", size=16, default=(1.0,) * 16, min=0.0)
    keyframe: bpy.props.BoolProperty(name="Insert Keyframe", default=False)

    def execute(self, context):
        pose = context.mode == "POSE"
        if pose:
            active = context.active_pose_bone
            sources = sorted((pb for pb in context.selected_pose_bones if pb != active), key=lambda pb: pb.name)
            world = lambda pb: pb.id_data.matrix_world @ pb.matrix  # noqa: E731
        else:
            active = context.active_object
            sources = sorted((o for o in context.selected_objects if o != active), key=lambda o: o.name)
            world = lambda o: o.matrix_world  # noqa: E731
        if active is None or not sources:
            self.report({"ERROR"}, "Select the transforms to blend and make the target active")
            return {"CANCELLED"}
        if len(sources) > len(self.weights):
            self.report({"ERROR"}, f"At most {len(self.weights)} transforms can be blended")
            return {"CANCELLED"}
        w = np.array(self.weights[: len(sources)], F32)
        if not w.sum() > 0:
            self.report({"ERROR"}, "The weights must not all be zero")
            return {"CANCELLED"}
        dqs = np.stack([dqskin.DualQuat.from_matrix(np.array(world(s), F32), check=False).to_array() for s in sources])
        if self.method == "SCLERP":
            if len(sources) != 2:
                self.report({"ERROR"}, f"ScLERP blends exactly two transforms, {len(sources)} are selected")
                return {"CANCELLED"}
            blend = dqskin.sclerp(dqs[0], dqs[1], float(w[1] / w.sum()))
        elif self.method == "DIB":
            blend, iterations, converged = dqskin.dib(dqs, w)
            self.report({"INFO"}, f"DIB: {iterations} iterations" + ("" if converged else " (not converged)"))
        else:
            blend = dqskin.dlb(dqs, w)
        rigid = Matrix(dqskin.matrices_from_dual_quats(blend[None])[0].tolist())
        scale = Matrix.Diagonal((*world(active).to_scale(), 1.0))
        target = rigid @ scale
        if pose:
            active.matrix = active.id_data.matrix_world.inverted() @ target
        else:
            active.matrix_world = target
        if self.keyframe:
            active.keyframe_insert("location")
            active.keyframe_insert("rotation_quaternion" if active.rotation_mode == "QUATERNION" else "rotation_euler")
        return {"FINISHED"}


CLASSES = (
    ANIM_OT_dq_quaternion_cleanup,
    ANIM_OT_dq_rotation_bake,
    ANIM_OT_dq_screw_inbetweens,
    ANIM_OT_dq_blend_transforms,
)

# SPDX-License-Identifier: GPL-3.0-or-later
"""Animation tools: blend transforms, screw in-betweens, spherical rotation bake and quaternion
cleanup. Each works on the selected objects, or the selected pose bones in Pose Mode, is
undoable, and reports what it did or why it could not. The math is the bundled core's.
"""

from __future__ import annotations

import math

import numpy as np

import bpy

from mathutils import Matrix

from .. import dqskin
from . import keys

F32 = np.float32


def _frames_between(first: float, last: float, step: float, extra) -> np.ndarray:
    """Every `step` from `first` to `last`, plus the `extra` frames (the keys), sorted."""
    grid = np.arange(first, last + step * 1e-3, step, dtype=np.float64)
    return np.unique(np.round(np.concatenate([grid, np.asarray(extra, np.float64)]), 4)).astype(F32)


def _keyed_rotation_targets(context) -> list:
    """The selected targets with keyed rotation, their speeds remembered for the plot first."""
    targets = [t for t in keys.selected_targets(context) if keys.rotation_kind(t)]
    remember_speeds(context, targets)
    return targets


def _allowed(cls, ok: bool, why: str) -> bool:
    """A poll's answer: greyed out with `why` in the tooltip (and a script's error) unless `ok`."""
    if not ok:
        cls.poll_message_set(why)
    return ok


def _any_rotation(context, kind: str | None = None) -> bool:
    """Whether a selected object or pose bone has keyed rotation (of `kind`, if given)."""
    return any(keys.rotation_kind(t) in ((kind,) if kind else ("QUATERNION", "EULER")) for t in keys.selected_targets(context))


class ANIM_OT_dq_quaternion_cleanup(bpy.types.Operator):
    """Make quaternion rotation keys sign-continuous (no sudden 360° spins) and normalize them"""

    bl_idname = "anim.dq_quaternion_cleanup"
    bl_label = "Quaternion Cleanup"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return _allowed(cls, _any_rotation(context, "QUATERNION"), "Nothing selected has keyed quaternion rotation")

    def execute(self, context):
        targets = [t for t in keys.selected_targets(context) if keys.rotation_kind(t) == "QUATERNION"]
        if not targets:
            self.report({"ERROR"}, "Nothing selected has keyed quaternion rotation")
            return {"CANCELLED"}
        remember_speeds(context, targets)
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
        description="How rotations go from key to key",
        items=(
            ("SLERP", "Slerp", "Shortest arc at constant speed between neighbouring keys"),
            ("SQUAD", "Squad", "Smooth through the keys (continuous angular velocity)"),
        ),
        default="SQUAD",
    )
    step: bpy.props.FloatProperty(
        name="Step", description="Frames between baked keys (sub-frames allowed)", default=1.0, min=0.01, soft_max=10.0
    )

    @classmethod
    def poll(cls, context):
        return _allowed(cls, _any_rotation(context), "Nothing selected has keyed rotation")

    def execute(self, context):
        targets = _keyed_rotation_targets(context)
        if not targets:
            self.report({"ERROR"}, "Nothing selected has keyed rotation")
            return {"CANCELLED"}
        baked = 0
        for t in targets:
            frames = keys.key_frames(t)
            if len(frames) < 2:
                self.report({"WARNING"}, f"{t.label}: fewer than two rotation keys, skipped")
                continue
            q = keys.rotations_at(t, frames)
            at = _frames_between(float(frames[0]), float(frames[-1]), self.step, frames)
            samples = dqskin.sample_rotations(frames, q, at, method=self.method.lower())
            keys.switch_to_quaternion(t)
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

    step: bpy.props.FloatProperty(
        name="Step", description="Frames between baked keys (sub-frames allowed)", default=1.0, min=0.01, soft_max=10.0
    )
    use_frame_range: bpy.props.BoolProperty(
        name="Frame Range", description="Bake only between Start and End (else between all keys)", default=False
    )
    frame_start: bpy.props.FloatProperty(name="Start", description="First frame to bake (with Frame Range)", default=1.0)
    frame_end: bpy.props.FloatProperty(name="End", description="Last frame to bake (with Frame Range)", default=250.0)

    @classmethod
    def poll(cls, context):
        animated = any(keys.fcurves(t.owner) for t in keys.selected_targets(context))
        return _allowed(cls, animated, "Nothing selected has keyed transforms")

    def execute(self, context):
        if self.use_frame_range and not self.frame_end > self.frame_start:
            self.report({"ERROR"}, "The frame range's End must be after its Start")
            return {"CANCELLED"}
        targets = keys.selected_targets(context)
        remember_speeds(context, [t for t in targets if keys.rotation_kind(t)])
        done = 0
        for t in targets:
            frames = keys.key_frames(t, ("location", "rotation_quaternion", "rotation_euler"))
            if self.use_frame_range:
                # The keys inside the range, plus the transforms at its ends.
                inside = frames[(frames > self.frame_start) & (frames < self.frame_end)]
                frames = np.concatenate([[self.frame_start], inside, [self.frame_end]]).astype(F32)
            if len(frames) < 2:
                continue
            locations = keys.locations_at(t, frames)
            rotations = keys.rotations_at(t, frames)
            transforms = np.stack([dqskin.DualQuat.from_rotation_translation(r, loc).to_array() for r, loc in zip(rotations, locations)])
            at = _frames_between(float(frames[0]), float(frames[-1]), self.step, frames)
            samples = dqskin.sample_transforms(frames, transforms, at)
            matrices = dqskin.matrices_from_dual_quats(samples)
            span = (float(frames[0]), float(frames[-1]))
            keys.switch_to_quaternion(t)
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
        description="How the selected transforms are blended",
        items=(
            ("DLB", "DLB", "Dual quaternion linear blending (fast)"),
            ("DIB", "DIB", "Dual quaternion iterative blending (exact)"),
            ("SCLERP", "ScLERP", "Screw interpolation (two inputs)"),
        ),
        default="DLB",
    )
    weights: bpy.props.FloatVectorProperty(
        name="Weights",
        description="How much each of the other selected transforms counts, in selection order",
        size=16,
        default=(1.0,) * 16,
        min=0.0,
    )
    keyframe: bpy.props.BoolProperty(name="Insert Keyframe", description="Key the blended transform at the current frame", default=False)

    @classmethod
    def poll(cls, context):
        if context.mode == "POSE":
            ok = context.active_pose_bone is not None and len(context.selected_pose_bones or ()) >= 2
        else:
            ok = context.active_object is not None and len(context.selected_objects) >= 2
        return _allowed(cls, ok, "Select the transforms to blend and make the target active")

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


class ANIM_OT_dq_spring_smoothing(bpy.types.Operator):
    """Experimental: refit rotation between keys with Dam et al.'s curvature-minimizing Spring
    (multi-step gradient descent, extra weight at the keys); the keys stay fixed"""

    bl_idname = "anim.dq_spring_smoothing"
    bl_label = "Spring Smoothing (Experimental)"
    bl_options = {"REGISTER", "UNDO"}

    step: bpy.props.FloatProperty(
        name="Step", description="Frames between samples; keys must lie on this grid", default=1.0, min=0.05, soft_max=5.0
    )
    iterations: bpy.props.IntProperty(name="Iterations", description="Gradient steps per level", default=400, min=1, max=100000)
    levels: bpy.props.IntProperty(name="Levels", description="Coarse-to-fine levels", default=3, min=1, max=12)
    key_weight: bpy.props.FloatProperty(
        name="Key Weight", description="Extra weight of the curvature at the keys", default=1.2, min=0.01, soft_max=5.0
    )

    @classmethod
    def poll(cls, context):
        return _allowed(cls, _any_rotation(context), "Nothing selected has keyed rotation")

    def execute(self, context):
        targets = _keyed_rotation_targets(context)
        if not targets:
            self.report({"ERROR"}, "Nothing selected has keyed rotation")
            return {"CANCELLED"}
        done = 0
        for t in targets:
            frames = keys.key_frames(t)
            if len(frames) < 2:
                continue
            q = keys.rotations_at(t, frames)
            try:
                samples = dqskin.spring(
                    frames, q, step=self.step, levels=self.levels, iterations=self.iterations, key_weight=self.key_weight
                )
            except ValueError as e:
                self.report({"ERROR"}, f"{t.label}: {e}")
                return {"CANCELLED"}
            at = (frames[0] + self.step * np.arange(len(samples))).astype(F32)
            keys.switch_to_quaternion(t)
            keys.write(t, "rotation_quaternion", at, samples, replace_between=(float(frames[0]), float(frames[-1])))
            done += 1
        if not done:
            self.report({"ERROR"}, "Nothing selected has two or more rotation keys")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Spring Smoothing on {done} item(s)")
        return {"FINISHED"}


def _draw_line(pixels: np.ndarray, xs: np.ndarray, ys: np.ndarray, color) -> None:
    """Draws a polyline into an (H, W, 4) image, one dot per pixel column between points."""
    h, w, _ = pixels.shape
    for x0, y0, x1, y1 in zip(xs[:-1], ys[:-1], xs[1:], ys[1:]):
        n = int(max(abs(x1 - x0), abs(y1 - y0))) + 1
        for u in np.linspace(0.0, 1.0, n + 1):
            x, y = int(round(x0 + u * (x1 - x0))), int(round(y0 + u * (y1 - y0)))
            if 0 <= x < w and 0 <= y < h:
                pixels[y, x] = color


SPEEDS_KEY = "dq_skin_speeds_deg"
BEFORE_KEY = "dq_skin_speeds_before_deg"


class ANIM_OT_dq_rotation_speed_plot(bpy.types.Operator):
    """Plot the angular speed (degrees per frame) of the active object or pose bone over the
    scene's frame range as an image (Image Editor), with the curve before the last DQ Skin
    animation tool if there is one; optionally saved as PNG"""

    bl_idname = "anim.dq_rotation_speed_plot"
    bl_label = "Rotation Speed Plot"
    bl_options = {"REGISTER", "UNDO"}

    width: bpy.props.IntProperty(name="Width", description="Width of the plot image in pixels", default=640, min=64, max=8192)
    height: bpy.props.IntProperty(name="Height", description="Height of the plot image in pixels", default=320, min=64, max=8192)
    filepath: bpy.props.StringProperty(name="Save As", description="PNG to write (optional)", subtype="FILE_PATH", default="")

    @classmethod
    def poll(cls, context):
        target = active_target(context)
        return _allowed(cls, target is not None and bool(keys.rotation_kind(target)), "The active object or bone has no keyed rotation")

    def execute(self, context):
        target = active_target(context)
        if target is None or not keys.rotation_kind(target):
            self.report({"ERROR"}, "The active object or bone has no keyed rotation")
            return {"CANCELLED"}
        scene = context.scene
        speeds = rotation_speeds(target, scene.frame_start, scene.frame_end)
        before = target.owner.get(BEFORE_KEY, {}).get(target.label)
        image = plot_image(f"Rotation Speed {target.label}", speeds, before, self.width, self.height)
        if self.filepath:
            image.filepath_raw = bpy.path.abspath(self.filepath)
            image.file_format = "PNG"
            image.save()
        self.report({"INFO"}, f"Rotation speed of {target.label}: max {max(speeds):.2f}°/frame, image {image.name!r}")
        return {"FINISHED"}


def active_target(context):
    if context.mode == "POSE" and context.active_pose_bone is not None:
        return keys.Target(context.active_pose_bone.id_data, context.active_pose_bone.name)
    return keys.Target(context.active_object) if context.active_object else None


def rotation_speeds(target, start: int, end: int) -> list[float]:
    """Angular speed in degrees per frame between consecutive frames `start..end`."""
    frames = np.arange(start, end + 1, dtype=F32)
    return [math.degrees(s) for s in dqskin.angular_speeds(keys.rotations_at(target, frames))]


def remember_speeds(context, targets) -> None:
    """Stores each target's speeds before a tool changes its keys, for the plot."""
    scene = context.scene
    for t in targets:
        store = dict(t.owner.get(BEFORE_KEY, {}))
        store[t.label] = rotation_speeds(t, scene.frame_start, scene.frame_end)
        t.owner[BEFORE_KEY] = store


def plot_image(name: str, speeds, before, width: int, height: int):
    """An image with the speed curve (white) over the earlier one (orange), axes in grey."""
    pixels = np.zeros((height, width, 4), F32)
    pixels[..., 3] = 1.0
    pixels[..., :3] = 0.12
    margin = 8
    all_values = list(speeds) + list(before or [])
    top = max(all_values) * 1.1 if all_values and max(all_values) > 0 else 1.0
    n = max(len(speeds), 1)
    xs = margin + np.arange(n) * (width - 2 * margin - 1) / max(n - 1, 1)
    to_y = lambda v: margin + np.asarray(v) / top * (height - 2 * margin - 1)  # noqa: E731
    pixels[margin, margin : width - margin, :3] = 0.5
    pixels[margin : height - margin, margin, :3] = 0.5
    if before:
        _draw_line(pixels, xs[: len(before)], to_y(before), (1.0, 0.55, 0.1, 1.0))
    _draw_line(pixels, xs, to_y(speeds), (1.0, 1.0, 1.0, 1.0))
    image = bpy.data.images.get(name)
    if image is None or tuple(image.size) != (width, height):
        if image is not None:
            bpy.data.images.remove(image)
        image = bpy.data.images.new(name, width, height, alpha=True)
    image.pixels.foreach_set(pixels.ravel())
    image.update()
    image[SPEEDS_KEY] = list(map(float, speeds))
    if before:
        image[BEFORE_KEY] = list(map(float, before))
    return image


CLASSES = (
    ANIM_OT_dq_spring_smoothing,
    ANIM_OT_dq_rotation_speed_plot,
    ANIM_OT_dq_quaternion_cleanup,
    ANIM_OT_dq_rotation_bake,
    ANIM_OT_dq_screw_inbetweens,
    ANIM_OT_dq_blend_transforms,
)

# SPDX-License-Identifier: GPL-3.0-or-later
"""Reading and writing the keyed transform channels of objects and pose bones.

Blender glue only: values are read from and written to F-curves; every interpolation happens in
the bundled `dqskin` core. Works with slotted actions (Blender 4.4+) and plain ones (4.2, 4.3).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import bpy

from ..blender import compat


@dataclass
class Target:
    """An object or a pose bone whose transform channels are animated."""

    owner: object  # the ID holding the action (the object, or the armature object)
    bone: str | None = None

    @property
    def label(self) -> str:
        return f"{self.owner.name}:{self.bone}" if self.bone else self.owner.name

    @property
    def item(self):
        return self.owner.pose.bones[self.bone] if self.bone else self.owner

    def path(self, prop: str) -> str:
        return f'pose.bones["{bpy.utils.escape_identifier(self.bone)}"].{prop}' if self.bone else prop


def selected_targets(context) -> list[Target]:
    """Selected pose bones in Pose Mode, else selected objects."""
    if context.mode == "POSE" and context.selected_pose_bones:
        return [Target(pb.id_data, pb.name) for pb in context.selected_pose_bones]
    return [Target(o) for o in context.selected_objects]


def fcurves(owner, create: bool = False):
    """The F-curves of `owner`'s action (its slot's channel bag), or None."""
    ad = owner.animation_data
    if ad is None or ad.action is None:
        if not create:
            return None
        ad = owner.animation_data_create()
        ad.action = bpy.data.actions.new(f"{owner.name}Action")
    action = ad.action
    if hasattr(action, "fcurves") and not hasattr(action, "layers"):
        return action.fcurves  # Blender before slotted actions
    from bpy_extras import anim_utils

    if ad.action_slot is None and create:
        ad.action_slot = action.slots.new(owner.id_type, owner.name) if not action.slots else action.slots[0]
    bag = anim_utils.action_get_channelbag_for_slot(action, ad.action_slot) if ad.action_slot else None
    if bag is None and create:
        bag = anim_utils.action_ensure_channelbag_for_slot(action, ad.action_slot)
    return None if bag is None else bag.fcurves


def channel(target: Target, prop: str, index: int, create: bool = False):
    curves = fcurves(target.owner, create)
    if curves is None:
        return None
    path = target.path(prop)
    found = curves.find(path, index=index)
    if found is None and create:
        found = compat.new_fcurve(curves, path, index, target.bone or "Object Transforms")
    return found


def rotation_kind(target: Target) -> str | None:
    """'QUATERNION' or 'EULER' for the rotation channels that are keyed, else None."""
    if any(channel(target, "rotation_quaternion", i) for i in range(4)):
        return "QUATERNION"
    if any(channel(target, "rotation_euler", i) for i in range(3)):
        return "EULER"
    return None


def key_frames(target: Target, props=("rotation_quaternion", "rotation_euler")) -> np.ndarray:
    """Sorted frames of all keys on the given channels."""
    frames = set()
    for prop in props:
        for i in range(4):
            fc = channel(target, prop, i)
            if fc is not None:
                frames.update(round(k.co[0], 4) for k in fc.keyframe_points)
    return np.array(sorted(frames), np.float32)


def evaluate(target: Target, prop: str, size: int, frames, default) -> np.ndarray:
    out = np.empty((len(frames), size), np.float32)
    for i in range(size):
        fc = channel(target, prop, i)
        out[:, i] = [fc.evaluate(f) for f in frames] if fc is not None else default[i]
    return out


def rotations_at(target: Target, frames) -> np.ndarray:
    """Keyed rotation at `frames` as `(N, 4)` quaternions (Euler channels converted)."""
    kind = rotation_kind(target)
    item = target.item
    if kind == "EULER":
        from mathutils import Euler

        eul = evaluate(target, "rotation_euler", 3, frames, item.rotation_euler)
        order = item.rotation_mode if item.rotation_mode != "QUATERNION" else "XYZ"
        return np.array([tuple(Euler(e, order).to_quaternion()) for e in eul], np.float32)
    return evaluate(target, "rotation_quaternion", 4, frames, item.rotation_quaternion)


def locations_at(target: Target, frames) -> np.ndarray:
    return evaluate(target, "location", 3, frames, target.item.location)


def write(target: Target, prop: str, frames, values, replace_between=None) -> None:
    """Keys `values` `(N, size)` at `frames` on `prop`'s channels, as LINEAR keys. With
    `replace_between=(a, b)`, existing keys in `[a, b]` are removed first."""
    values = np.asarray(values)
    for i in range(values.shape[1]):
        fc = channel(target, prop, i, create=True)
        if replace_between is not None:
            a, b = replace_between
            for k in [k for k in fc.keyframe_points if a - 1e-4 <= k.co[0] <= b + 1e-4][::-1]:
                fc.keyframe_points.remove(k, fast=True)
        for f, v in zip(frames, values[:, i]):
            k = fc.keyframe_points.insert(float(f), float(v), options={"FAST"})
            k.interpolation = "LINEAR"
        fc.update()


def remove_channels(target: Target, prop: str, size: int) -> None:
    curves = fcurves(target.owner)
    for i in range(size):
        fc = channel(target, prop, i)
        if fc is not None:
            curves.remove(fc)


def set_values(target: Target, prop: str, frames, values) -> None:
    """Changes the values of the existing keys at `frames` (moving their handles with them),
    keeping their interpolation."""
    values = np.asarray(values)
    index_of = {round(float(f), 4): i for i, f in enumerate(frames)}
    for c in range(values.shape[1]):
        fc = channel(target, prop, c)
        if fc is None:
            continue
        for k in fc.keyframe_points:
            i = index_of.get(round(k.co[0], 4))
            if i is None:
                continue
            delta = float(values[i, c]) - k.co[1]
            k.co[1] += delta
            k.handle_left[1] += delta
            k.handle_right[1] += delta
        fc.update()


def switch_to_quaternion(target: Target) -> None:
    """Before writing quaternion keys: drops keyed Euler channels and sets quaternion mode."""
    if rotation_kind(target) == "EULER":
        remove_channels(target, "rotation_euler", 3)
        target.item.rotation_mode = "QUATERNION"

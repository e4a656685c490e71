# SPDX-License-Identifier: GPL-3.0-or-later
"""The bones of a frame for envelopes and B-Bones, from Blender's memory.

One `dqskin.memory.PoseMemory.read` per frame gives what the Armature modifier deforms with: every
deforming bone's channel matrix and rest data, and Blender's own B-Bone cache (the joints'
deform and rest matrices, the Curved mapping's boundary planes), with signatures of the binding
and of the pose. The per-vertex segment mapping (Straight and Curved) then runs in the Rust core,
and the influences it gives are kept until the vertices, the spaces or the bones' rest data
change (the pose alone does not change them), so a frame costs one read and the kernel.

If the reader cannot be built or refuses an object (`PoseReads.error` says why), `rig`'s
Python path does the same through `PoseBone.bbone_segment_matrix` and `bbone_segment_index`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import dqskin
from ..model.keys import PoseKey
from . import rig


class PoseReads:
    """Poses read from memory within one handler call or one driver run: each armature is read
    once (a full evaluation needs the pose for the binding's signature and for the frame).
    `reader`: `dqskin.memory.PoseMemory` or None, `unavailable`: why there is none."""

    def __init__(self, reader, unavailable: str = ""):
        self.reader = reader
        self.unavailable = unavailable
        self.error = ""  # why the last read was refused ("" if it was not)
        self._read: dict[int, tuple] = {}

    def read(self, arm_eval) -> dqskin.PoseData | None:
        """The pose of an (evaluated) armature object from memory, or None (see `error`)."""
        # (An evaluated object's `session_uid` is 0: its address tells armatures apart.)
        key = arm_eval.as_pointer()
        got = self._read.get(key)
        if got is None:
            got = self._read[key] = self._read_now(arm_eval)
        data, self.error = got
        return data

    def adopt(self, other: PoseReads) -> None:
        """Takes the poses `other` read in the same evaluation (the feed's run, before the frame
        handler) where it read none itself: they are what reading them again would give."""
        for key, got in other._read.items():
            self._read.setdefault(key, got)

    def update(self, newer: PoseReads) -> None:
        """The poses `newer` read (a later run in the same evaluation) in place of these."""
        self._read.update(newer._read)

    def _read_now(self, arm_eval) -> tuple:
        if self.reader is None:
            return None, self.unavailable
        try:
            return self.reader.read(arm_eval), ""
        except (TypeError, ValueError) as e:
            return None, str(e)


def armature_signature(arm_eval, reads: PoseReads):
    """What of the armature's bones a binding depends on: the memory's binding signature (names,
    order, deform flags, rest matrices, envelopes, B-Bone segments, mapping modes and rest
    shapes), or `rig.armature_signature` through the Python API."""
    data = reads.read(arm_eval)
    if data is not None:
        return ("memory", data.binding_signature)
    return rig.armature_signature(arm_eval)


@dataclass
class Bones:
    """The bound bones in one frame, expanded with every B-Bone's joints (the bones, then each
    B-Bone's `segments + 1` joints, in bone order)."""

    deform: np.ndarray
    rest: np.ndarray | None
    """None where the caller reads them from `data` only if it needs them (the feed)."""
    key: PoseKey
    """Changes whenever the deformation may: the pose signature, or the matrices themselves."""
    data: dqskin.PoseData | None
    """The pose from memory (None: read through the Python API)."""


def frame(arm_eval, binding: rig.Binding, segments: np.ndarray, reads: PoseReads) -> Bones:
    """This frame's bones for `binding` (made for `arm_eval`'s deforming bones): from memory when
    the reader gives the binding's bones, else through the Python API (`segments`: the bones'
    segment counts, `rig.bbone_segments`)."""
    data = reads.read(arm_eval)
    if data is not None and same_bones(data, binding):
        return Bones(data.deform, data.rest, memory_key(data), data)
    deform = rig.pose_matrices(arm_eval)
    if len(binding.bone_indices) != len(deform):
        deform = deform[binding.bone_indices]
    joints = rig.with_bbone_joints(rig.Frame(np.ascontiguousarray(deform), binding.rest, None, None), arm_eval, binding, segments)
    return Bones(joints.deform, joints.rest, PoseKey.of_matrices(joints.deform), None)


def memory_key(data) -> PoseKey:
    """The key of a pose read from memory."""
    return PoseKey(pose_signature=data.pose_signature, binding_signature=data.binding_signature)


def same_bones(data, binding: rig.Binding) -> bool:
    """Whether the pose's bones are the binding's (checked by name once per binding signature)."""
    if binding.pose_signature == data.binding_signature:
        return True
    if data.names != binding.bone_names:
        return False
    binding.pose_signature = data.binding_signature
    return True


def influences(
    bones: Bones,
    binding: rig.Binding,
    arm_eval,
    positions: np.ndarray,
    input_key,
    premat: np.ndarray,
    use_vertex_groups: bool,
    use_envelopes: bool,
    envelopes: np.ndarray,
    segments: np.ndarray,
) -> dqskin.Influences:
    """This frame's influences over `bones` (see `Influences.effective`): `positions` are what
    reaches the modifier and `input_key` changes with them. From memory, kept in the binding
    until the vertices, the spaces, the settings or the bones' rest data change; through the
    Python API (`envelopes`, `segments`), computed every frame."""
    data = bones.data
    if data is not None:
        key = (input_key, premat.tobytes(), data.binding_signature, use_vertex_groups, use_envelopes)
        if binding.effective is None or binding.effective[0] != key:
            found = binding.influences.effective(
                positions, premat, pose=data, use_vertex_groups=use_vertex_groups, use_envelopes=use_envelopes
            )
            binding.effective = (key, found)
        return binding.effective[1]
    return binding.influences.effective(
        positions,
        premat,
        envelopes=envelopes,
        use_vertex_groups=use_vertex_groups,
        use_envelopes=use_envelopes,
        bbone_segments=segments,
        rest=binding.rest,
        lengths=rig.bone_lengths(arm_eval, binding),
        bbone_mapping=rig.curved_bbone_mapping(arm_eval, binding, positions, premat, use_envelopes),
    )

# SPDX-License-Identifier: GPL-3.0-or-later
"""Typed keys: equal keys, equal results. Each says what one cached thing was computed from,
so that it is computed again exactly when one of those inputs changes."""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import NamedTuple


class ModKey(NamedTuple):
    """One DQ Skin modifier: its object's session uid and the modifier's persistent id (renames
    keep it; a copied object or modifier gets its own). A named tuple: hashed and compared in C,
    a few times per character and frame."""

    object_uid: int
    modifier_uid: str


class Source(enum.Enum):
    """What reaches a DQ Skin modifier in its stack."""

    MESH = "mesh"  # nothing enabled before it: the mesh, with its shape keys mixed here
    CHAIN = "chain"  # only live DQ Skin modifiers before it: the previous one's output
    CAPTURE = "capture"  # other modifiers before it: what the node group stored on its way


class InputKey(NamedTuple):
    """What reached the modifier: its source and what that was computed from (the mesh's
    version; the shape keys' values; the captured coordinates; the previous DQ Skin's output).
    A named tuple, as `PoseKey` and `FrameKey`: the feed makes them for every character on every
    frame, where a frozen dataclass took three times as long to make and compare."""

    source: Source
    version: int = 0
    detail: bytes | tuple = ()


class PoseKey(NamedTuple):
    """The bones of one frame: a digest of their matrices (read through Blender's Python API), or
    the signatures of a pose read from Blender's memory (pose and binding)."""

    matrices_digest: int | None = None
    pose_signature: int | None = None
    binding_signature: int | None = None

    @classmethod
    def of_matrices(cls, matrices) -> PoseKey:
        """The key of matrices read through the Python API: a 64-bit digest of their bytes
        (SipHash, Python's own hash of bytes, as wide as the memory reader's signatures). Each
        character keeps its last frame's key for the whole session, where the matrices are 64
        bytes a bone (about 10 KB on a Rigify character)."""
        return cls(hash(matrices.tobytes()))

    @property
    def from_memory(self) -> bool:
        return self.pose_signature is not None


@dataclass(frozen=True)
class BindingKey:
    """Everything a binding (influences, mask, blend weights) is computed from."""

    mesh: int  # MeshData.uid
    mesh_version: int
    armature: int  # session uid of the armature object
    bones: object  # the armature's binding signature (`pose.armature_signature`)
    mask_group: str
    invert_mask: bool
    blend_group: str
    use_vertex_groups: bool


class FrameKey(NamedTuple):
    """What one written result was computed from."""

    settings: tuple
    source: InputKey
    pose: PoseKey
    spaces: bytes
    result: int  # session uid of the result object
    mesh_version: tuple  # (MeshData.version, the mesh's revision)

    def with_pose(self, pose: PoseKey) -> FrameKey:
        return FrameKey(self.settings, self.source, pose, self.spaces, self.result, self.mesh_version)

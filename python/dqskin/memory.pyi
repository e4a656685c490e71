"""Type stubs of `dqskin.memory`: the Blender extension's readers of Blender's memory."""

import numpy as np
import numpy.typing as npt

from . import PoseData

class MeshMemory:
    """Reads vertex-group weights and positions from Blender's memory (the layout from ``blend_file``'s SDNA)."""
    def __init__(self, blend_file: bytes) -> None: ...
    def positions(self, mesh: object) -> npt.NDArray[np.float32] | None:
        """The ``(V, 3)`` vertex positions of a ``bpy.types.Mesh`` (None where this Blender keeps them elsewhere)."""
    def positions_in_place(self, mesh: object) -> MeshPositions | None:
        """The positions of an original ``bpy.types.Mesh`` where Blender keeps them (None where this Blender keeps them elsewhere)."""
    def deform_verts(self, mesh: object) -> tuple[npt.NDArray[np.uint32], npt.NDArray[np.uint32], npt.NDArray[np.float32]] | None:
        """The vertex-group weights of a ``bpy.types.Mesh`` in CSR form (None without any)."""

class MeshPositions:
    """A mesh's positions where Blender keeps them: a ``SkinJob`` given one reads Blender's array on every run."""
    @property
    def mesh(self) -> object: ...
    def __len__(self) -> int: ...
    def read(self) -> npt.NDArray[np.float32]:
        """A ``(V, 3)`` copy of the positions as they are now."""

def positions_digest(positions: npt.NDArray[np.float32] | MeshPositions) -> bytes:
    """16 bytes that change whenever the positions do (the same for an array and a handle of the same positions)."""

class PoseMemory:
    """Reads armature poses from Blender's memory (the layout from ``blend_file``'s SDNA)."""
    def __init__(self, blend_file: bytes) -> None: ...
    def read(self, armature: object) -> PoseData:
        """The pose of a ``bpy.types.Object`` of type ``'ARMATURE'`` (evaluated for this frame)."""
    def channel_matrices(self, armature: object) -> npt.NDArray[np.float32]:
        """``(N, 4, 4)`` row-major: every pose bone's ``matrix_channel``, in ``pose.bones`` order."""

class ObjectStateMemory:
    """Reads what decides whether a DQ Skin object's fed frame stands from Blender's memory (the layout from ``blend_file``'s SDNA)."""
    def __init__(self, blend_file: bytes) -> None: ...
    def digest(self, obj: object) -> bytes:
        """16 bytes that change whenever the state of a ``bpy.types.Object`` does (its modes, modifier stack, inputs, vertex-group names)."""
    def unchanged(self, obj: object, previous: bytes) -> bool:
        """Whether the state of ``obj`` still has the digest ``previous``."""
    def describe(self, obj: object) -> dict[str, object]:
        """The same reads as values, for checking them against Blender's Python API."""

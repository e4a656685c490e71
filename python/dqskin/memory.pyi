"""Type stubs of `dqskin.memory`: the Blender extension's readers of Blender's memory."""

import numpy as np
import numpy.typing as npt

from . import PoseData

class MeshMemory:
    """Reads vertex-group weights and positions from Blender's memory (the layout from ``blend_file``'s SDNA)."""
    def __init__(self, blend_file: bytes) -> None: ...
    def positions(self, mesh: object) -> npt.NDArray[np.float32] | None:
        """The ``(V, 3)`` vertex positions of a ``bpy.types.Mesh`` (None where this Blender keeps them elsewhere)."""
    def deform_verts(self, mesh: object) -> tuple[npt.NDArray[np.uint32], npt.NDArray[np.uint32], npt.NDArray[np.float32]] | None:
        """The vertex-group weights of a ``bpy.types.Mesh`` in CSR form (None without any)."""

class PoseMemory:
    """Reads armature poses from Blender's memory (the layout from ``blend_file``'s SDNA)."""
    def __init__(self, blend_file: bytes) -> None: ...
    def read(self, armature: object) -> PoseData:
        """The pose of a ``bpy.types.Object`` of type ``'ARMATURE'`` (evaluated for this frame)."""

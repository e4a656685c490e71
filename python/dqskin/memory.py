"""The Blender extension's readers of Blender's memory, kept out of the numpy API's namespace:
`MeshMemory` (vertex-group weights and positions, or `MeshPositions`: a mesh's positions where
Blender keeps them, which a `dqskin.SkinJob` reads without a copy) and `PoseMemory` (armature
poses, as `dqskin.PoseData`),
each built from the bytes of a .blend file the running Blender wrote, whose SDNA describes the
structs in memory. They read raw memory: only the extension uses them, on the objects of the
Blender that wrote the file (see `rust/blend`)."""

from ._dqskin import MeshMemory, MeshPositions, PoseMemory, positions_digest

__all__ = ["MeshMemory", "MeshPositions", "PoseMemory", "positions_digest"]

"""The Blender extension's readers of Blender's memory, kept out of the numpy API's namespace:
`MeshMemory` (vertex-group weights and positions, or `MeshPositions`: a mesh's positions where
Blender keeps them, which a `dqskin.SkinJob` reads without a copy), `PoseMemory` (armature
poses, as `dqskin.PoseData`) and `ObjectStateMemory` (what decides whether an object's fed frame
stands: its modes, modifier stack, inputs and vertex-group names, as bytes to compare),
each built from the bytes of a .blend file the running Blender wrote, whose SDNA describes the
structs in memory. They read raw memory: only the extension uses them, on the objects of the
Blender that wrote the file (see `rust/blend`)."""

from ._dqskin import MeshMemory, MeshPositions, ObjectStateMemory, PoseMemory, positions_digest

__all__ = ["MeshMemory", "MeshPositions", "ObjectStateMemory", "PoseMemory", "positions_digest"]

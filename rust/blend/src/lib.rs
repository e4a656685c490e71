//! # dqskin-blend
//!
//! Blender keeps vertex-group weights in per-vertex arrays of `(group, weight)` pairs that its
//! Python API only exposes one vertex at a time (`MeshVertex.groups`), which costs about a
//! second per 250,000 vertices. This crate reads them straight from the running Blender's
//! memory instead, in their stored order (dual quaternion skinning depends on it), using the
//! struct layout that Blender itself describes in its SDNA: every `.blend` file carries the
//! SDNA of the Blender that wrote it, so writing an empty file gives the layout of the structs
//! in memory, whatever the version. Armature poses are read the same way: the channel matrices,
//! the bones' rest data and Blender's runtime B-Bone cache, which its Python API gives only one
//! joint or one vertex per call.
//!
//! - [`Sdna`]: parses the `DNA1` block of a `.blend` file (both the 4.x and the 5.x headers)
//!   and answers field offsets and struct sizes.
//! - [`MeshLayout`]: the offsets needed to reach a mesh's deform vertices, checked against the
//!   sizes the SDNA states.
//! - [`read_deform_verts`]: copies the weights of a `Mesh` out of memory into CSR arrays, with
//!   every count checked for sanity before it is used.
//! - [`PoseLayout`] and [`read_pose`]: an armature object's pose channels as the Armature
//!   modifier deforms with them (channel matrices, bones' rest data and envelopes, and the
//!   runtime B-Bone cache), into `dqskin-core`'s [`PoseChannel`](dqskin_core::skin::PoseChannel)s;
//!   [`read_channel_matrices`]: only the channel matrices, for rigs without B-Bones or envelopes.
//! - [`ObjectStateLayout`] and [`read_object_state`]: what decides whether a DQ Skin object's fed
//!   frame stands (its modes, modifier stack, inputs, vertex-group names), as bytes to compare.
//!
//! No Python and no Blender headers: the only unsafe code is the raw reads in
//! [`read_deform_verts`], [`read_pose`] and [`read_object_state`], whose callers guarantee the pointer.

mod memory;
mod mesh;
mod object_state;
mod pose;
mod sdna;
#[cfg(test)]
mod test_dna;

pub use memory::ReadError;
pub use mesh::{positions_in_memory, read_deform_verts, read_positions, DeformVerts, MeshLayout};
pub use object_state::{
    describe_object, read_object_state, ModifierSummary, ObjectStateLayout, ObjectSummary, PropertyValue, StateHints,
};
pub use pose::{read_channel_matrices, read_pose, PoseLayout, PoseRead, ReadHints, MAX_CHANNELS};
pub use sdna::{DnaError, Field, Sdna};

//! # dqskin-core
//!
//! Dual quaternions, rigid-transform blending and interpolation, and multithreaded skinning
//! kernels, in pure Rust on [`glam`] and [`rayon`].
//!
//! - [`DualQuat`]: algebra, conversions, screw parameters, exp/log/power.
//! - [`blend`]: ScLERP, DLB and DIB (Kavan et al. 2006).
//! - [`quat_interp`]: Slerp and Squad (Dam et al. 1998).
//! - [`hierarchy`]: forward kinematics with dual quaternions (Kenwright 2012).
//! - [`skin`]: LBS, DQS (exactly Blender's Armature modifier), their per-vertex blend, and
//!   skinning with optimized centers of rotation (Le & Hodgins 2016).
//! - [`pool`]: the thread pool the kernels run on.
//! - [`shape_keys`]: Blender's relative shape-key mix.
//! - [`tracks`]: keyed rotation and transform tracks (Slerp, Squad in time, ScLERP, Spring).
//! - [`weights`]: automatic skin weights (geodesic voxel binding) and weight transfer to
//!   clothing (closest-point matching and weight inpainting).
//! - [`rigs`]: procedural test rigs (the twisted cylinder, a branching creature) and mesh
//!   measurements.

// `!(x >= 0.0)` is deliberate throughout: unlike `x < 0.0` it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// The kernels index several per-lane arrays with one lane index; iterators would obscure that.
#![allow(clippy::needless_range_loop)]

pub mod blend;
pub mod digest;
pub mod dual_quat;
pub mod hierarchy;
pub mod pool;
pub mod quat_interp;
pub mod rigs;
mod scalar;
pub mod shape_keys;
pub mod skin;
#[cfg(test)]
mod test_support;
pub mod tracks;
pub mod weights;

pub use blend::{dib, dlb, sclerp, BlendError, DibResult};
pub use dual_quat::{DualNumber, DualQuat, NotRigid, Screw};
pub use glam;
pub use hierarchy::{forward_kinematics, HierarchyError};
pub use quat_interp::{make_signs_continuous, slerp, Squad};
pub use skin::{
    armature_spaces, centers_of_rotation, centers_of_rotation_interruptible, centers_of_rotation_update,
    centers_of_rotation_update_keeping, centers_of_rotation_with_progress, check_centers_inputs, deform_group_weights,
    first_not_finite, kernel_copies, set_kernel_copy, skin, skin_many, BBone, CenterSums, Centers, DeformGroups,
    Effective, Envelope, Influence, Influences, ManyJob, Method, Pose, PreviousCenters, SkinError, SkinOptions,
    MAX_BONES, MAX_INFLUENCES_PER_VERTEX,
};

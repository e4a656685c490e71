//! Skinning: linear blend skinning (LBS), dual quaternion skinning (DQS) exactly as Blender's
//! Armature modifier computes them (with and without Preserve Volume), and a per-vertex blend of
//! the two.
//!
//! Per vertex `p` (Blender's `armature_deform.cc`):
//! 1. with a mask weight `a` of 0 the vertex is copied unchanged;
//! 2. `co = premat·p` (mesh space to armature space);
//! 3. the vertex's influences are visited in the given order, zero weights skipped, and their
//!    weights summed into `contrib`; if `contrib ≤ 0.0001` the vertex does not move;
//! 4. LBS: `co += (a/contrib)·Σ wᵢ·(Mᵢ·co − co)`;
//!    DQS: each bone's dual quaternion is added with weight `±wᵢ`, the sign chosen against the
//!    running sum; bones with scale or shear move rigidly to where their matrix puts `co`;
//!    the sum is applied with `mul_v3m3_dq` and `co += a·(r − co)`;
//!    Blend: `(1−α)·LBS + α·DQS`;
//! 5. `p' = postmat·co`.

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx512;
mod envelope;
mod groups;
mod influences;
mod kernels;
mod pose;

pub use envelope::{bbone_segment_matrices, distance_factor, BBone, Effective, Envelope};
pub use groups::{armature_spaces, deform_group_weights, DeformGroups};
pub use influences::{Influence, Influences, MAX_INFLUENCES_PER_VERTEX};
pub use pose::{affine_problem, Pose};


use glam::Mat4;

/// Skinning method.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Method<'a> {
    /// Linear blend skinning (Blender: Preserve Volume off).
    Linear,
    /// Dual quaternion skinning (Blender: Preserve Volume on).
    DualQuaternion,
    /// Per-vertex mix `(1−α)·Linear + α·DualQuaternion` with `α = factor·amount[v]`
    /// (`α = factor` when `amount` is `None`). `factor` and every amount must lie in `[0, 1]`.
    Blend { amount: Option<&'a [f32]>, factor: f32 },
}

/// Optional inputs shared by all methods.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SkinOptions<'a> {
    /// Mesh space to armature space (Blender's `premat`); identity when `None`.
    pub premat: Option<Mat4>,
    /// Armature space back to mesh space (Blender's `postmat`); identity when `None`.
    pub postmat: Option<Mat4>,
    /// Per-vertex strength in `[0, 1]` (the Armature modifier's vertex group mask, already
    /// inverted if wanted). Vertices with 0 are copied unchanged.
    pub mask: Option<&'a [f32]>,
}

/// Why skinning inputs were rejected. Every variant names the offending input.
#[derive(Clone, Debug, PartialEq)]
pub enum SkinError {
    /// Influences are not a consistent CSR structure (the message says what is wrong).
    InvalidInfluences(String),
    /// An array has the wrong length.
    LengthMismatch { what: &'static str, expected: usize, got: usize },
    /// A bone matrix is unusable.
    InvalidMatrix { what: &'static str, bone: usize, problem: &'static str },
    /// `premat` or `postmat` is unusable.
    InvalidSpaceMatrix { what: &'static str, problem: &'static str },
    /// A per-vertex value (mask or blend amount) is outside `[0, 1]` or not finite.
    OutOfRange { what: &'static str, index: Option<usize>, value: f32 },
    /// Dual quaternion skinning was asked for but the pose has no rest matrices.
    MissingRestMatrices,
}

impl core::fmt::Display for SkinError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            SkinError::InvalidInfluences(msg) => write!(f, "invalid influences: {msg}"),
            SkinError::LengthMismatch { what, expected, got } => {
                write!(f, "{what}: expected {expected} entries, got {got}")
            }
            SkinError::InvalidMatrix { what, bone, problem } => {
                write!(f, "{what} matrix of bone {bone} {problem}")
            }
            SkinError::InvalidSpaceMatrix { what, problem } => write!(f, "{what} {problem}"),
            SkinError::OutOfRange { what, index: Some(i), value } => {
                write!(f, "{what}[{i}] = {value} is outside [0, 1]")
            }
            SkinError::OutOfRange { what, index: None, value } => {
                write!(f, "{what} = {value} is outside [0, 1]")
            }
            SkinError::MissingRestMatrices => write!(
                f,
                "dual quaternion skinning needs the bones' rest matrices (Bone.matrix_local) for the scale path"
            ),
        }
    }
}

impl std::error::Error for SkinError {}

/// Below or at this total weight a vertex is left where it is (Blender's threshold).
pub const MIN_TOTAL_WEIGHT: f32 = 0.0001;

/// Deforms `positions` into `out` (same length, caller-owned, fully overwritten). Runs on the
/// crate's thread pool (see [`crate::pool`]). Validates everything first; on error `out` is
/// untouched.
pub fn skin(
    method: Method<'_>,
    positions: &[[f32; 3]],
    influences: &Influences,
    pose: &Pose,
    options: &SkinOptions<'_>,
    out: &mut [[f32; 3]],
) -> Result<(), SkinError> {
    skin_with(kernels::Simd::detect(), method, positions, influences, pose, options, out)
}

/// [`skin`] on a given compiled copy of the kernels (tests run every copy the CPU has).
fn skin_with(
    simd: kernels::Simd,
    method: Method<'_>,
    positions: &[[f32; 3]],
    influences: &Influences,
    pose: &Pose,
    options: &SkinOptions<'_>,
    out: &mut [[f32; 3]],
) -> Result<(), SkinError> {
    let n = influences.vertex_count();
    check_len("positions", n, positions.len())?;
    check_len("out", n, out.len())?;
    if pose.bone_count() != influences.bone_count() {
        return Err(SkinError::LengthMismatch {
            what: "deform matrices (one per bone the influences refer to)",
            expected: influences.bone_count(),
            got: pose.bone_count(),
        });
    }
    if let Some(mask) = options.mask {
        check_len("mask", n, mask.len())?;
        check_unit_interval("mask", mask)?;
    }
    for (what, m) in [("premat", options.premat), ("postmat", options.postmat)] {
        if let Some(m) = m {
            check_space_matrix(what, &m)?;
        }
    }
    let needs_rest = |kind| {
        if pose.has_dual_quaternions() {
            Ok(kind)
        } else {
            Err(SkinError::MissingRestMatrices)
        }
    };
    let (kind, blend_amount, blend_factor) = match method {
        Method::Linear => (kernels::Kind::Linear, None, 0.0),
        Method::DualQuaternion => (needs_rest(kernels::Kind::DualQuaternion)?, None, 0.0),
        Method::Blend { amount, factor } => {
            let kind = needs_rest(kernels::Kind::Blend)?;
            if !(0.0..=1.0).contains(&factor) {
                return Err(SkinError::OutOfRange { what: "blend_factor", index: None, value: factor });
            }
            if let Some(amount) = amount {
                check_len("blend amount", n, amount.len())?;
                check_unit_interval("blend amount", amount)?;
            }
            (kind, amount, factor)
        }
    };
    let job = kernels::Job {
        kind,
        positions,
        influences,
        pose,
        premat: options.premat,
        postmat: options.postmat,
        mask: options.mask,
        blend_amount,
        blend_factor,
    };
    if n <= kernels::CHUNK {
        // One task's worth: run it here. Handing it to the pool would cost more than the work
        // (a thread wake-up), which matters for scenes with many small meshes.
        kernels::run(&job, out, simd);
    } else {
        crate::pool::run(|| kernels::run(&job, out, simd));
    }
    Ok(())
}

/// One skinning in a batch (see [`skin_many`]).
pub struct ManyJob<'a> {
    pub method: Method<'a>,
    pub positions: &'a [[f32; 3]],
    pub influences: &'a Influences,
    pub deform: &'a [Mat4],
    pub rest: Option<&'a [Mat4]>,
    pub options: SkinOptions<'a>,
    pub out: &'a mut [[f32; 3]],
}

/// Skins many meshes at once, in parallel across meshes (large ones also within), on the
/// crate's thread pool: for scenes with many small characters, where one call per mesh would
/// run each on one thread. Returns one result per job; a failed job leaves its `out` untouched.
pub fn skin_many(jobs: &mut [ManyJob<'_>]) -> Vec<Result<(), SkinError>> {
    use rayon::prelude::*;
    let simd = kernels::Simd::detect();
    let one = move |j: &mut ManyJob<'_>| {
        let pose = Pose::new(j.deform, j.rest)?;
        skin_with(simd, j.method, j.positions, j.influences, &pose, &j.options, j.out)
    };
    if jobs.len() <= 1 {
        return jobs.iter_mut().map(one).collect();
    }
    crate::pool::run(|| jobs.par_iter_mut().with_max_len(1).map(one).collect())
}

fn check_len(what: &'static str, expected: usize, got: usize) -> Result<(), SkinError> {
    if expected != got {
        return Err(SkinError::LengthMismatch { what, expected, got });
    }
    Ok(())
}

fn check_unit_interval(what: &'static str, values: &[f32]) -> Result<(), SkinError> {
    match values.iter().position(|v| !(0.0..=1.0).contains(v)) {
        Some(i) => Err(SkinError::OutOfRange { what, index: Some(i), value: values[i] }),
        None => Ok(()),
    }
}

fn check_space_matrix(what: &'static str, m: &Mat4) -> Result<(), SkinError> {
    match pose::affine_problem(m) {
        Some(problem) => Err(SkinError::InvalidSpaceMatrix { what, problem }),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests;

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
//!    Centers of rotation (Le & Hodgins 2016, see [`centers_of_rotation`]): with the vertex's
//!    center `c = premat·p*`, `co' = Σ wᵢ·Mᵢ·c + R·Sw·(co − c)` (weights divided by `contrib`),
//!    `R` the rotation of the sign-aligned quaternion sum, `Sw = Σ wᵢ·Sᵢ` the blended scale/shear
//!    parts (identity for rigid bones); then `co += a·(co' − co)`;
//! 5. `p' = postmat·co`.

mod armature;
#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx512;
mod baseline;
mod batch;
mod bbone;
mod calibration;
mod centers;
mod envelope;
mod groups;
mod influences;
mod isa;
mod job;
mod kernels;
#[cfg(target_arch = "aarch64")]
mod neon;
mod pose;
mod spaces;

pub use armature::{ArmaturePose, BBoneCache, PoseChannel};
pub use bbone::{
    bbone_joint_starts, bbone_segment_matrices, bbones_from_rest, bsp_depth, curved_segment, BBone, Mapping,
    SegmentBoundary, MAX_BBONE_SEGMENTS,
};
pub use calibration::set_kernel_copy;
pub use centers::{
    centers_of_rotation, centers_of_rotation_interruptible, centers_of_rotation_update,
    centers_of_rotation_update_keeping, centers_of_rotation_with_progress, check_centers_inputs, CenterSums, Centers,
    PreviousCenters, DEFAULT_SIGMA,
};
pub use envelope::{distance_factor, Effective, Envelope};
pub use groups::{armature_spaces, deform_group_weights, DeformGroups};
pub use influences::{Influence, Influences, MAX_BONES, MAX_INFLUENCES_PER_VERTEX};
use pose::Tables;
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
    /// Skinning with optimized centers of rotation (Le & Hodgins 2016): `centers` holds one
    /// center per vertex in mesh space, from [`centers_of_rotation`] (a vertex's own position
    /// gives exactly LBS). Needs the rest matrices, like dual quaternion skinning.
    ///
    /// Per vertex (weights divided by their total): the blended rotation `R` is that of the
    /// normalized sum of the bones' rotations with signs aligned against the running sum (as in
    /// DQS), the center goes where LBS puts it, and the offset from the center to the vertex
    /// turns with `R`: `v' = Σ wⱼ·Mⱼ·p* + R·(v − p*)`, which is the paper's
    /// `R·v + Σ wⱼ·(Rⱼ·p* + tⱼ) − R·p*` for rigid bones.
    ///
    /// Bones with scale or shear (Kavan et al.'s two phases, as Blender's Preserve Volume splits
    /// them): each bone's matrix is its rotation `Rⱼ` (the one DQS uses) after a scale/shear
    /// part `Sⱼ = Rⱼᵀ·M₃ⱼ`. The parts are blended linearly and applied to the vertex and to its
    /// center alike, so the offset becomes `Σ wⱼ·Sⱼ·(v − p*)` before it turns; the center still
    /// goes exactly where each bone's full matrix puts it (the DQS scale path with the center as
    /// the pivot): `v' = Σ wⱼ·Mⱼ·p* + R·Σ wⱼ·Sⱼ·(v − p*)`. A uniformly scaled rig thus gives the
    /// scaled rigid result, and a row without a center still gives LBS.
    CentersOfRotation { centers: &'a [[f32; 3]] },
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
    /// Dual quaternion or centers-of-rotation skinning was asked for but the pose has no rest
    /// matrices.
    MissingRestMatrices,
    /// An array of points has a NaN or infinite coordinate.
    NotFinite { what: &'static str, index: usize },
    /// A triangle refers to a vertex that does not exist.
    InvalidTriangle { index: usize, vertex: u32, vertex_count: usize },
    /// The similarity width σ of the centers of rotation is not a finite number > 0.
    InvalidSigma(f32),
    /// The progress callback asked to stop.
    Cancelled,
    /// [`set_kernel_copy`] named a compiled copy of the kernels that this CPU cannot run.
    UnavailableKernelCopy(String),
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
                "dual quaternion and centers-of-rotation skinning need the bones' rest matrices (Bone.matrix_local) for the scale path"
            ),
            SkinError::NotFinite { what, index } => write!(f, "{what}[{index}] has a NaN or infinite coordinate"),
            SkinError::InvalidTriangle { index, vertex, vertex_count } => write!(
                f,
                "triangles[{index}] refers to vertex {vertex}, but there are {vertex_count} positions"
            ),
            SkinError::InvalidSigma(s) => write!(f, "sigma = {s} must be a finite number greater than 0"),
            SkinError::Cancelled => write!(f, "cancelled"),
            SkinError::UnavailableKernelCopy(name) => {
                let available: Vec<&str> = isa::Simd::copies().into_iter().map(isa::Simd::name).collect();
                write!(f, "no kernel copy '{name}' on this CPU (it has: {})", available.join(", "))
            }
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
    skin_with(None, method, positions, influences, pose, options, out)
}

/// The compiled copy of the kernels that [`skin`] and [`skin_many`] run here for each kernel
/// variant (`linear`, `dual_quaternion`, `dual_quaternion_scaled`, `blend`, `blend_scaled`,
/// `centers`, `centers_scaled`) and size of job (`cached`: fewer vertices than
/// [`STREAMED_FROM`], else `streamed`): `baseline`, `avx2`, `avx512` or `neon` (on x86-64 with
/// `-noprefetch` where its batches do not ask for their inputs ahead), the one measured
/// fastest on this process's own calls unless [`set_kernel_copy`] or `DQSKIN_SIMD` asks for
/// another; None while it is being measured (the first calls of that variant and size).
pub fn kernel_copies() -> Vec<(&'static str, &'static str, Option<&'static str>)> {
    calibration::chosen_copies()
        .into_iter()
        .map(|(variant, size, simd)| (variant.name(), size.name(), simd.map(isa::Simd::name)))
        .collect()
}

/// Jobs of at least this many vertices have their kernel copy chosen apart from smaller ones
/// (see [`kernel_copies`]).
pub const STREAMED_FROM: usize = calibration::Size::STREAMED_FROM;

/// [`skin`] on a given compiled copy of the kernels (tests run every copy the CPU has), or with
/// `None` on the one chosen for the method (see [`kernel_copies`]).
fn skin_with(
    simd: Option<isa::Simd>,
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
    let mut centers = None;
    let (kind, blend_amount, blend_factor) = match method {
        Method::Linear => (job::Kind::Linear, None, 0.0),
        Method::DualQuaternion => (needs_rest(job::Kind::DualQuaternion)?, None, 0.0),
        Method::CentersOfRotation { centers: c } => {
            let kind = needs_rest(job::Kind::CentersOfRotation)?;
            check_len("centers", n, c.len())?;
            if let Some(index) = first_point_not_finite(c) {
                return Err(SkinError::NotFinite { what: "centers", index });
            }
            centers = Some(c);
            (kind, None, 0.0)
        }
        Method::Blend { amount, factor } => {
            let kind = needs_rest(job::Kind::Blend)?;
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
    let mut job = job::Job::new(kind, positions, influences, pose);
    job.premat = options.premat;
    job.postmat = options.postmat;
    job.mask = options.mask;
    job.blend_amount = blend_amount;
    job.blend_factor = blend_factor;
    job.centers = centers;
    // (One task's worth of vertices runs here alone: a thread wake-up would cost more than the
    // work, which matters for scenes with many small meshes. More share the work with the pool.)
    let mut run = |simd| kernels::run(&job, out, simd);
    match simd {
        Some(simd) => run(simd),
        None => {
            // What the call moves: its points in and out, its influences.
            let bytes = 2 * std::mem::size_of_val(positions) + influences.byte_size();
            calibration::run_on_copy(calibration::Variant::of(kind, pose.any_scaled()), n, bytes, run)
        }
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
    let one = move |j: &mut ManyJob<'_>| {
        let tables = match j.method {
            Method::Linear => Tables::Linear,
            Method::DualQuaternion | Method::Blend { .. } => Tables::DualQuaternion,
            Method::CentersOfRotation { .. } => Tables::Centers,
        };
        let pose = Pose::with_tables(j.deform, j.rest, tables)?;
        skin_with(None, j.method, j.positions, j.influences, &pose, &j.options, j.out)
    };
    if jobs.len() <= 1 || crate::pool::is_alone() {
        // (Its tables and kernel share their work with the pool from here: `pool::share`.)
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

/// Index of the first NaN or infinite value of `values`. Scans blocks branch-free (the largest
/// exponent field of a block is all ones only for a non-finite value), so the scan vectorizes:
/// an early-exit scalar scan of a Rigify rig's 720 bone matrices, checked on every call, cost 12
/// µs. Only a failing block is searched for the exact index.
pub fn first_not_finite(values: &[f32]) -> Option<usize> {
    let block = values.chunks(FINITE_BLOCK).position(block_not_finite)?;
    first_in_block(values, block)
}

const FINITE_BLOCK: usize = 1024;

fn block_not_finite(block: &[f32]) -> bool {
    const EXPONENT: u32 = 0x7f80_0000;
    block.iter().fold(0u32, |m, x| m.max(x.to_bits() & EXPONENT)) == EXPONENT
}

fn first_in_block(values: &[f32], block: usize) -> Option<usize> {
    let start = block * FINITE_BLOCK;
    values[start..].iter().position(|x| !x.is_finite()).map(|i| start + i)
}

/// Index of the first point with a NaN or infinite coordinate ([`first_not_finite`]), in
/// parallel on the pool for large arrays: a serial scan costs about a tenth of a skinning pass
/// and does not shrink with more threads.
fn first_point_not_finite(points: &[[f32; 3]]) -> Option<usize> {
    let values = points.as_flattened();
    if points.len() <= kernels::CHUNK || crate::pool::is_alone() {
        return first_not_finite(values).map(|i| i / 3);
    }
    use rayon::prelude::*;
    let block = crate::pool::run(|| values.par_chunks(FINITE_BLOCK).position_first(block_not_finite))?;
    first_in_block(values, block).map(|i| i / 3)
}

/// Every triangle names vertices below `vertex_count`.
pub(crate) fn check_triangles(triangles: &[[u32; 3]], vertex_count: usize) -> Result<(), SkinError> {
    for (index, t) in triangles.iter().enumerate() {
        if let Some(&vertex) = t.iter().find(|&&v| v as usize >= vertex_count) {
            return Err(SkinError::InvalidTriangle { index, vertex, vertex_count });
        }
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

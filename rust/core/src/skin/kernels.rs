//! The kernels and their parallel driver. Inputs are validated by [`super::skin`]; nothing here
//! can fail or panic on valid inputs.
//!
//! Vertices are processed [`LANES`] at a time from the lane-ordered influence slots: every lane
//! is an independent vertex, so the serial chain of DQS's running-sum sign choice runs in all
//! lanes at once (SIMD where the compiler vectorizes the lane loops, instruction-level
//! parallelism where it does not). On x86-64 a copy compiled for AVX2+FMA is chosen at run time.

use glam::{Affine3A, Mat4, Vec4};
use rayon::prelude::*;

use super::influences::{Slot, LANES};
use super::pose::{AffineRows, DqBone, PivotBone};
use super::{Influences, Pose, MIN_TOTAL_WEIGHT};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    Linear,
    DualQuaternion,
    Blend,
}

pub(crate) struct Job<'a> {
    pub kind: Kind,
    pub positions: &'a [[f32; 3]],
    pub influences: &'a Influences,
    pub pose: &'a Pose,
    pub premat: Option<Mat4>,
    pub postmat: Option<Mat4>,
    pub mask: Option<&'a [f32]>,
    pub blend_amount: Option<&'a [f32]>,
    pub blend_factor: f32,
}

/// Vertices per parallel task: large enough to amortize scheduling, small enough to balance.
/// A multiple of [`LANES`], so tasks start on batch boundaries.
const CHUNK: usize = 4096;
const _: () = assert!(CHUNK % LANES == 0);

pub(crate) fn run(job: &Job<'_>, out: &mut [[f32; 3]]) {
    let simd = Simd::detect();
    let task = |(i, chunk): (usize, &mut [[f32; 3]])| simd.chunk(job, i * CHUNK, chunk);
    if rayon::current_num_threads() <= 1 || out.len() <= CHUNK {
        out.chunks_mut(CHUNK).enumerate().for_each(task);
    } else {
        out.par_chunks_mut(CHUNK).enumerate().for_each(task);
    }
}

/// Which compiled copy of the kernels to run.
#[derive(Clone, Copy)]
enum Simd {
    Baseline,
    #[cfg(target_arch = "x86_64")]
    Avx2Fma,
}

impl Simd {
    fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
            return Simd::Avx2Fma;
        }
        Simd::Baseline
    }

    fn chunk(self, job: &Job<'_>, start: usize, out: &mut [[f32; 3]]) {
        match self {
            Simd::Baseline => chunk::<false>(job, start, out),
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `detect` checked that the CPU has AVX2 and FMA.
            Simd::Avx2Fma => unsafe { chunk_avx2_fma(job, start, out) },
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn chunk_avx2_fma(job: &Job<'_>, start: usize, out: &mut [[f32; 3]]) {
    chunk::<true>(job, start, out)
}

#[inline(always)]
fn chunk<const FMA: bool>(job: &Job<'_>, start: usize, out: &mut [[f32; 3]]) {
    match (job.kind, job.pose.any_scaled()) {
        (Kind::Linear, _) => batches::<FMA, LINEAR, false>(job, start, out),
        (Kind::DualQuaternion, false) => batches::<FMA, DUAL_QUATERNION, false>(job, start, out),
        (Kind::DualQuaternion, true) => batches::<FMA, DUAL_QUATERNION, true>(job, start, out),
        (Kind::Blend, false) => batches::<FMA, BLEND, false>(job, start, out),
        (Kind::Blend, true) => batches::<FMA, BLEND, true>(job, start, out),
    }
}

const LINEAR: u8 = 0;
const DUAL_QUATERNION: u8 = 1;
const BLEND: u8 = 2;

type Lanes = [f32; LANES];
const ZERO: Lanes = [0.0; LANES];

/// `a·b + c`, fused where the copy is compiled with FMA (where `mul_add` is one instruction; in
/// the baseline copy it would be a slow library call).
#[inline(always)]
fn madd<const FMA: bool>(a: f32, b: f32, c: f32) -> f32 {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// Positions of one batch, one coordinate array per axis.
#[derive(Clone, Copy)]
pub(super) struct Points {
    pub x: Lanes,
    pub y: Lanes,
    pub z: Lanes,
}

impl Points {
    #[inline(always)]
    fn transform<const FMA: bool>(&self, m: &Affine3A) -> Self {
        let (c0, c1, c2, t) = (m.matrix3.x_axis, m.matrix3.y_axis, m.matrix3.z_axis, m.translation);
        let mut r = Points { x: ZERO, y: ZERO, z: ZERO };
        for l in 0..LANES {
            let (x, y, z) = (self.x[l], self.y[l], self.z[l]);
            r.x[l] = madd::<FMA>(c0.x, x, madd::<FMA>(c1.x, y, madd::<FMA>(c2.x, z, t.x)));
            r.y[l] = madd::<FMA>(c0.y, x, madd::<FMA>(c1.y, y, madd::<FMA>(c2.y, z, t.y)));
            r.z[l] = madd::<FMA>(c0.z, x, madd::<FMA>(c1.z, y, madd::<FMA>(c2.z, z, t.z)));
        }
        r
    }
}

/// Skins vertices `start..start + out.len()` batch by batch.
#[inline(always)]
fn batches<const FMA: bool, const KIND: u8, const SCALED: bool>(
    job: &Job<'_>,
    start: usize,
    out: &mut [[f32; 3]],
) {
    let premat = job.premat.map(Affine3A::from_mat4);
    let postmat = job.postmat.map(Affine3A::from_mat4);
    let pose = job.pose;
    for (k, out) in out.chunks_mut(LANES).enumerate() {
        let first = start + k * LANES;
        let n = out.len();
        let positions = &job.positions[first..first + n];
        let mut co = Points { x: ZERO, y: ZERO, z: ZERO };
        for l in 0..n {
            [co.x[l], co.y[l], co.z[l]] = positions[l];
        }
        let mut strength: Lanes = [1.0; LANES];
        if let Some(mask) = job.mask {
            strength[..n].copy_from_slice(&mask[first..first + n]);
        }
        if let Some(m) = &premat {
            co = co.transform::<FMA>(m);
        }
        let slots = job.influences.batch(first / LANES);
        let moved = match KIND {
            LINEAR => linear::<FMA>(&co, slots, &pose.linear, &strength),
            DUAL_QUATERNION => {
                let sum = accumulate_dual_quaternion::<FMA, SCALED>(&co, slots, &pose.dq, &pose.pivot);
                finish_dual_quaternion::<FMA>(&co, &sum, &strength)
            }
            _ => {
                let lbs = linear::<FMA>(&co, slots, &pose.linear, &strength);
                let sum = accumulate_dual_quaternion::<FMA, SCALED>(&co, slots, &pose.dq, &pose.pivot);
                let dqs = finish_dual_quaternion::<FMA>(&co, &sum, &strength);
                let mut alpha: Lanes = [job.blend_factor; LANES];
                if let Some(amount) = job.blend_amount {
                    for l in 0..n {
                        alpha[l] *= amount[first + l];
                    }
                }
                let mut r = lbs;
                for l in 0..LANES {
                    r.x[l] = madd::<FMA>(alpha[l], dqs.x[l] - lbs.x[l], lbs.x[l]);
                    r.y[l] = madd::<FMA>(alpha[l], dqs.y[l] - lbs.y[l], lbs.y[l]);
                    r.z[l] = madd::<FMA>(alpha[l], dqs.z[l] - lbs.z[l], lbs.z[l]);
                }
                r
            }
        };
        let result = match &postmat {
            Some(m) => moved.transform::<FMA>(m),
            None => moved,
        };
        for l in 0..n {
            // A mask weight of 0 leaves the vertex bit-identical (no space round trip).
            out[l] = if strength[l] == 0.0 { positions[l] } else { [result.x[l], result.y[l], result.z[l]] };
        }
    }
}

/// Bone data for the lanes of one slot. Bone indices were validated against the bone count when
/// the influences were built, and [`super::skin`] checked that the pose has that many bones;
/// padding lanes use bone 0, which exists whenever there is a slot at all.
#[inline(always)]
fn bone<T>(table: &[T], index: u32) -> &T {
    debug_assert!((index as usize) < table.len());
    // SAFETY: see above; the index is in range.
    unsafe { table.get_unchecked(index as usize) }
}

/// LBS: `co + (a/contrib)·(Σ wᵢ·Mᵢ·co − contrib·co)`; `co` where `contrib ≤ 0.0001`.
/// Lane by lane with 4-wide rows: LBS has no serial dependency between influences, so this keeps
/// the accumulators in registers.
#[inline(always)]
fn linear<const FMA: bool>(co: &Points, slots: &[Slot], linear: &[AffineRows], strength: &Lanes) -> Points {
    let mut r = *co;
    for l in 0..LANES {
        let mut acc = [Vec4::ZERO; 3];
        let mut contrib = 0.0f32;
        for slot in slots {
            let m = bone(linear, slot.bones[l]);
            let w = slot.weights[l];
            let ws = Vec4::splat(w);
            for (a, row) in acc.iter_mut().zip(&m.rows) {
                *a = if FMA { row.mul_add(ws, *a) } else { *row * ws + *a };
            }
            contrib += w;
        }
        let h = Vec4::new(co.x[l], co.y[l], co.z[l], 1.0);
        let f = if contrib > MIN_TOTAL_WEIGHT { strength[l] / contrib } else { 0.0 };
        r.x[l] = madd::<FMA>(acc[0].dot(h) - h.x * contrib, f, h.x);
        r.y[l] = madd::<FMA>(acc[1].dot(h) - h.y * contrib, f, h.y);
        r.z[l] = madd::<FMA>(acc[2].dot(h) - h.z * contrib, f, h.z);
    }
    r
}

/// An unnormalized dual quaternion per lane: real (x, y, z, w), dual (x, y, z, w), total weight.
pub(super) struct DqSum {
    pub real: [Lanes; 4],
    pub dual: [Lanes; 4],
    pub contrib: Lanes,
}

/// Sums `±wᵢ·q̂ᵢ` with each sign chosen against the running sum (Blender's
/// `add_weighted_dq_dq`); for bones with scale the dual part moves `co` exactly where the bone's
/// matrix puts it (`add_weighted_dq_dq_pivot`).
#[inline(always)]
fn accumulate_dual_quaternion<const FMA: bool, const SCALED: bool>(
    co: &Points,
    slots: &[Slot],
    dq: &[DqBone],
    pivot: &[PivotBone],
) -> DqSum {
    #[cfg(target_arch = "x86_64")]
    if FMA {
        // SAFETY: `FMA` is only true in the copy that runs after AVX2 and FMA were detected;
        // bone indices were validated against the pose's bone count.
        return unsafe {
            if SCALED {
                super::avx2::accumulate_scaled(co, slots, pivot)
            } else {
                super::avx2::accumulate_rigid(slots, dq)
            }
        };
    }
    let mut s = DqSum { real: [ZERO; 4], dual: [ZERO; 4], contrib: ZERO };
    for slot in slots {
        for l in 0..LANES {
            let (q, d) = if SCALED {
                let p = bone(pivot, slot.bones[l]);
                let q = [p.real.x, p.real.y, p.real.z, p.real.w];
                let (x, y, z) = (co.x[l], co.y[l], co.z[l]);
                let t = |r: usize| {
                    let row = p.translation.rows[r];
                    madd::<FMA>(row.x, x, madd::<FMA>(row.y, y, madd::<FMA>(row.z, z, row.w)))
                };
                let (tx, ty, tz) = (t(0), t(1), t(2));
                // ½·(0, t)·q = ½·(w·t + t × v, −t·v)
                let d = [
                    0.5 * (tx * q[3] + ty * q[2] - tz * q[1]),
                    0.5 * (ty * q[3] + tz * q[0] - tx * q[2]),
                    0.5 * (tz * q[3] + tx * q[1] - ty * q[0]),
                    -0.5 * (tx * q[0] + ty * q[1] + tz * q[2]),
                ];
                (q, d)
            } else {
                let b = bone(dq, slot.bones[l]);
                ([b.real.x, b.real.y, b.real.z, b.real.w], [b.dual.x, b.dual.y, b.dual.z, b.dual.w])
            };
            let dot = q[0] * s.real[0][l] + q[1] * s.real[1][l] + q[2] * s.real[2][l] + q[3] * s.real[3][l];
            let w = slot.weights[l];
            let w = if dot < 0.0 { -w } else { w };
            for c in 0..4 {
                s.real[c][l] = madd::<FMA>(q[c], w, s.real[c][l]);
                s.dual[c][l] = madd::<FMA>(d[c], w, s.dual[c][l]);
            }
            s.contrib[l] += slot.weights[l];
        }
    }
    s
}

/// Applies the summed dual quaternions (Blender's `mul_v3m3_dq`, dividing by `|q|²` instead of
/// normalizing), then the strength: `co + a·(r − co) = r·a + co·(1 − a)`; `co` where
/// `contrib ≤ 0.0001`. Written with selects, not branches, so the lane loop vectorizes.
#[inline(always)]
fn finish_dual_quaternion<const FMA: bool>(co: &Points, s: &DqSum, strength: &Lanes) -> Points {
    let mut r = *co;
    for l in 0..LANES {
        let (x, y, z, w) = (s.real[0][l], s.real[1][l], s.real[2][l], s.real[3][l]);
        let (t0, t1, t2, t3) = (s.dual[3][l], s.dual[0][l], s.dual[1][l], s.dual[2][l]);
        let len2 = w * w + x * x + y * y + z * z;
        let (px, py, pz) = (co.x[l], co.y[l], co.z[l]);
        let m00 = w * w + x * x - y * y - z * z;
        let m11 = w * w + y * y - x * x - z * z;
        let m22 = w * w + z * z - x * x - y * y;
        let (xy, xz, yz, wx, wy, wz) = (x * y, x * z, y * z, w * x, w * y, w * z);
        let nx = m00 * px + 2.0 * (xy - wz) * py + 2.0 * (xz + wy) * pz + 2.0 * (-t0 * x + w * t1 - t2 * z + y * t3);
        let ny = 2.0 * (xy + wz) * px + m11 * py + 2.0 * (yz - wx) * pz + 2.0 * (-t0 * y + t1 * z - x * t3 + w * t2);
        let nz = 2.0 * (xz - wy) * px + 2.0 * (yz + wx) * py + m22 * pz + 2.0 * (-t0 * z + x * t2 + w * t3 - t1 * y);
        let valid = s.contrib[l] > MIN_TOTAL_WEIGHT && len2 > 0.0;
        let a = strength[l];
        let f = if valid { a / len2 } else { 0.0 };
        let keep = if valid { 1.0 - a } else { 1.0 };
        r.x[l] = madd::<FMA>(nx, f, px * keep);
        r.y[l] = madd::<FMA>(ny, f, py * keep);
        r.z[l] = madd::<FMA>(nz, f, pz * keep);
    }
    r
}

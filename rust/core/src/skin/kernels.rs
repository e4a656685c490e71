//! The per-vertex kernels and their parallel driver. Inputs are validated by [`super::skin`];
//! nothing here can fail or panic on valid inputs.

use glam::{Affine3A, Mat4, Vec3, Vec3A, Vec4};
use rayon::prelude::*;

use super::influences::{Influence, Influences};
use super::pose::{AffineRows, DqBone, Pose};
use super::MIN_TOTAL_WEIGHT;

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
const CHUNK: usize = 4096;

pub(crate) fn run(job: &Job<'_>, out: &mut [[f32; 3]]) {
    let scaled = job.pose.any_scaled();
    let task = |(i, chunk): (usize, &mut [[f32; 3]])| match (job.kind, scaled) {
        (Kind::Linear, _) => chunk_kernel::<LINEAR, false>(job, i * CHUNK, chunk),
        (Kind::DualQuaternion, false) => chunk_kernel::<DUAL_QUATERNION, false>(job, i * CHUNK, chunk),
        (Kind::DualQuaternion, true) => chunk_kernel::<DUAL_QUATERNION, true>(job, i * CHUNK, chunk),
        (Kind::Blend, false) => chunk_kernel::<BLEND, false>(job, i * CHUNK, chunk),
        (Kind::Blend, true) => chunk_kernel::<BLEND, true>(job, i * CHUNK, chunk),
    };
    if rayon::current_num_threads() <= 1 || out.len() <= CHUNK {
        out.chunks_mut(CHUNK).enumerate().for_each(task);
    } else {
        out.par_chunks_mut(CHUNK).enumerate().for_each(task);
    }
}

const LINEAR: u8 = 0;
const DUAL_QUATERNION: u8 = 1;
const BLEND: u8 = 2;

/// Skins vertices `start..start + out.len()`. `KIND` and `SCALED` are compile-time so that each
/// combination gets its own tight loop.
fn chunk_kernel<const KIND: u8, const SCALED: bool>(job: &Job<'_>, start: usize, out: &mut [[f32; 3]]) {
    let premat = job.premat.map(|m| Affine3A::from_mat4(m));
    let postmat = job.postmat.map(|m| Affine3A::from_mat4(m));
    let linear = &job.pose.linear[..];
    let dq = &job.pose.dq[..];
    let pivot = &job.pose.pivot[..];
    let offsets = job.influences.offsets();
    let entries = job.influences.entries();
    for (k, dst) in out.iter_mut().enumerate() {
        let v = start + k;
        let p = job.positions[v];
        let a = job.mask.map_or(1.0, |m| m[v]);
        if a == 0.0 {
            *dst = p;
            continue;
        }
        let mut co = Vec3A::from_array(p);
        if let Some(pre) = &premat {
            co = pre.transform_point3a(co);
        }
        let infl = &entries[offsets[v] as usize..offsets[v + 1] as usize];
        co = match KIND {
            LINEAR => linear_vertex(co, infl, linear, a),
            DUAL_QUATERNION => dual_quaternion_vertex::<SCALED>(co, infl, dq, pivot, a),
            _ => {
                let alpha = job.blend_factor * job.blend_amount.map_or(1.0, |b| b[v]);
                blend_vertex::<SCALED>(co, infl, linear, dq, pivot, a, alpha)
            }
        };
        if let Some(post) = &postmat {
            co = post.transform_point3a(co);
        }
        *dst = co.to_array();
    }
}

/// Weighted sum of the bones' affine rows and the total weight.
#[inline(always)]
fn accumulate_linear(infl: &[Influence], linear: &[AffineRows]) -> ([Vec4; 3], f32) {
    let mut acc = [Vec4::ZERO; 3];
    let mut contrib = 0.0f32;
    for i in infl {
        // SAFETY-free: indices were validated against the bone count when the influences were built.
        let m = &linear[i.bone as usize];
        let w = Vec4::splat(i.weight);
        acc[0] = m.rows[0].mul_add(w, acc[0]);
        acc[1] = m.rows[1].mul_add(w, acc[1]);
        acc[2] = m.rows[2].mul_add(w, acc[2]);
        contrib += i.weight;
    }
    (acc, contrib)
}

/// LBS: `co + (a/contrib)·(Σ wᵢ·Mᵢ·co − contrib·co)`.
#[inline(always)]
fn linear_vertex(co: Vec3A, infl: &[Influence], linear: &[AffineRows], a: f32) -> Vec3A {
    let (acc, contrib) = accumulate_linear(infl, linear);
    if !(contrib > MIN_TOTAL_WEIGHT) {
        return co;
    }
    linear_finish(co, &acc, contrib, a)
}

#[inline(always)]
fn linear_finish(co: Vec3A, acc: &[Vec4; 3], contrib: f32, a: f32) -> Vec3A {
    let h = co.extend(1.0);
    let moved = Vec3A::new(acc[0].dot(h), acc[1].dot(h), acc[2].dot(h));
    co + (moved - co * contrib) * (a / contrib)
}

/// Sums `±wᵢ·q̂ᵢ` with the sign chosen against the running sum (Blender's `add_weighted_dq_dq`).
#[inline(always)]
fn accumulate_dual_quaternion<const SCALED: bool>(
    co: Vec3A,
    infl: &[Influence],
    dq: &[DqBone],
    pivot: &[AffineRows],
) -> (Vec4, Vec4, f32) {
    let mut real = Vec4::ZERO;
    let mut dual = Vec4::ZERO;
    let mut contrib = 0.0f32;
    let h = co.extend(1.0);
    for i in infl {
        let bone = &dq[i.bone as usize];
        let d = if SCALED {
            // Rigid motion that takes `co` exactly where the bone's matrix puts it.
            let t = pivot[i.bone as usize].transform_point(h);
            dual_from_translation(t, bone.real)
        } else {
            bone.dual
        };
        let w = if bone.real.dot(real) < 0.0 { -i.weight } else { i.weight };
        let ws = Vec4::splat(w);
        real = bone.real.mul_add(ws, real);
        dual = d.mul_add(ws, dual);
        contrib += i.weight;
    }
    (real, dual, contrib)
}

/// `½·(0, t)·q` for `q` stored as (x, y, z, w).
#[inline(always)]
fn dual_from_translation(t: Vec3, q: Vec4) -> Vec4 {
    let v = Vec3::new(q.x, q.y, q.z);
    let vec = t * q.w + t.cross(v);
    Vec4::new(vec.x, vec.y, vec.z, -t.dot(v)) * 0.5
}

/// Applies an unnormalized dual quaternion sum to `co` (Blender's `mul_v3m3_dq`).
#[inline(always)]
fn apply_dual_quaternion(co: Vec3A, real: Vec4, dual: Vec4) -> Vec3A {
    let (x, y, z, w) = (real.x, real.y, real.z, real.w);
    let (t0, t1, t2, t3) = (dual.w, dual.x, dual.y, dual.z);
    let len2 = real.length_squared();
    let inv = if len2 > 0.0 { 1.0 / len2 } else { 0.0 };
    // Rotation matrix of the unnormalized quaternion, scaled by |q|².
    let rx = Vec3A::new(w * w + x * x - y * y - z * z, 2.0 * (x * y + w * z), 2.0 * (x * z - w * y));
    let ry = Vec3A::new(2.0 * (x * y - w * z), w * w + y * y - x * x - z * z, 2.0 * (y * z + w * x));
    let rz = Vec3A::new(2.0 * (x * z + w * y), 2.0 * (y * z - w * x), w * w + z * z - x * x - y * y);
    let t = Vec3A::new(
        2.0 * (-t0 * x + w * t1 - t2 * z + y * t3),
        2.0 * (-t0 * y + t1 * z - x * t3 + w * t2),
        2.0 * (-t0 * z + x * t2 + w * t3 - t1 * y),
    );
    (rx * co.x + ry * co.y + rz * co.z + t) * inv
}

#[inline(always)]
fn dual_quaternion_vertex<const SCALED: bool>(
    co: Vec3A,
    infl: &[Influence],
    dq: &[DqBone],
    pivot: &[AffineRows],
    a: f32,
) -> Vec3A {
    let (real, dual, contrib) = accumulate_dual_quaternion::<SCALED>(co, infl, dq, pivot);
    if !(contrib > MIN_TOTAL_WEIGHT) {
        return co;
    }
    let moved = apply_dual_quaternion(co, real, dual);
    if a == 1.0 {
        moved
    } else {
        co + (moved - co) * a
    }
}

#[inline(always)]
fn blend_vertex<const SCALED: bool>(
    co: Vec3A,
    infl: &[Influence],
    linear: &[AffineRows],
    dq: &[DqBone],
    pivot: &[AffineRows],
    a: f32,
    alpha: f32,
) -> Vec3A {
    let (acc, contrib) = accumulate_linear(infl, linear);
    if !(contrib > MIN_TOTAL_WEIGHT) {
        return co;
    }
    let lbs = linear_finish(co, &acc, contrib, a);
    let (real, dual, _) = accumulate_dual_quaternion::<SCALED>(co, infl, dq, pivot);
    let dqs = co + (apply_dual_quaternion(co, real, dual) - co) * a;
    lbs * (1.0 - alpha) + dqs * alpha
}

//! The baseline copy's hand-written LBS, kept where it measured faster than the one body of
//! `batch.rs` (docs/performance.md): lane by lane over a batch of up to [`LANES`] vertices, each
//! lane's three rows summed 4-wide, which the compiler vectorizes. The same arithmetic as the
//! other copies, which the tests hold them to.

use glam::{Affine3A, Vec4};

use super::super::influences::{lane_record, BoneIndex, Slot, LANES};
use super::super::pose::LinearBone;
use super::super::MIN_TOTAL_WEIGHT;

type Lanes = [f32; LANES];
const ZERO: Lanes = [0.0; LANES];

/// `a·b + c`, not fused: the baseline target may have no FMA instruction (in the x86-64
/// baseline a fused `mul_add` would be a slow library call).
#[inline(always)]
fn madd(a: f32, b: f32, c: f32) -> f32 {
    a * b + c
}

/// Positions of one batch, one coordinate array per axis.
#[derive(Clone, Copy)]
struct Points {
    x: Lanes,
    y: Lanes,
    z: Lanes,
}

impl Points {
    #[inline(always)]
    fn transform(&self, m: &Affine3A) -> Self {
        let (c0, c1, c2, t) = (m.matrix3.x_axis, m.matrix3.y_axis, m.matrix3.z_axis, m.translation);
        let mut r = Points { x: ZERO, y: ZERO, z: ZERO };
        for l in 0..LANES {
            let (x, y, z) = (self.x[l], self.y[l], self.z[l]);
            r.x[l] = madd(c0.x, x, madd(c1.x, y, madd(c2.x, z, t.x)));
            r.y[l] = madd(c0.y, x, madd(c1.y, y, madd(c2.y, z, t.y)));
            r.z[l] = madd(c0.z, x, madd(c1.z, y, madd(c2.z, z, t.z)));
        }
        r
    }
}

/// LBS on one batch of up to [`LANES`] vertices (`positions` and `mask` from its first, `out`
/// holds its results; `slots` its influences) with the bone matrices `table` (the pose's, or with the spaces folded in):
/// load, `premat`, the sums, strength, `postmat`, mask, store.
///
/// # Safety
/// Every bone index of the slots indexes `table` (one record per bone of the pose: `Job::new`
/// makes sure the indices fit the pose).
#[inline(always)]
pub(in crate::skin) unsafe fn linear_batch<I: BoneIndex>(
    positions: &[[f32; 3]],
    mask: Option<&[f32]>,
    table: &[LinearBone],
    premat: Option<&Affine3A>,
    postmat: Option<&Affine3A>,
    slots: &[Slot<I>],
    out: &mut [[f32; 3]],
) {
    let n = out.len();
    let original = load_points(&positions[..n]);
    let mut strength: Lanes = [1.0; LANES];
    if let Some(mask) = mask {
        strength[..n].copy_from_slice(&mask[..n]);
    }
    let co = match premat {
        Some(m) => original.transform(m),
        None => original,
    };
    // SAFETY: the caller's contract.
    let moved = unsafe { linear(&co, slots, table, &strength) };
    let mut result = match postmat {
        Some(m) => moved.transform(m),
        None => moved,
    };
    // A mask weight of 0 leaves the vertex bit-identical (no space round trip).
    for l in 0..LANES {
        if strength[l] == 0.0 {
            result.x[l] = original.x[l];
            result.y[l] = original.y[l];
            result.z[l] = original.z[l];
        }
    }
    store_points(&result, out);
}

/// Coordinates of up to [`LANES`] points (missing lanes zero).
#[inline(always)]
fn load_points(points: &[[f32; 3]]) -> Points {
    let mut p = Points { x: ZERO, y: ZERO, z: ZERO };
    for (l, v) in points.iter().enumerate() {
        [p.x[l], p.y[l], p.z[l]] = *v;
    }
    p
}

/// Writes the first `out.len()` lanes.
#[inline(always)]
fn store_points(p: &Points, out: &mut [[f32; 3]]) {
    for (l, v) in out.iter_mut().enumerate() {
        *v = [p.x[l], p.y[l], p.z[l]];
    }
}

/// Bone data for one lane of a slot (its entry `bone`), without a bounds check (the kernel's
/// innermost loads).
///
/// # Safety
/// `bone < table.len()`. For a slot of a [`Job`]'s influences and a table of its pose this
/// holds: bone indices were validated against the bone count when the influences were built,
/// `Job::new` checked that the pose has that many bones (and the rest tables the method reads),
/// and padding lanes use bone 0, which exists whenever there is a slot at all.
#[inline(always)]
unsafe fn bone<T, I: BoneIndex>(table: &[T], bone: I) -> &T {
    // SAFETY: the caller's contract; the record is a whole, aligned `T` of `table`.
    unsafe { &*lane_record(table, bone).cast::<T>() }
}

/// LBS: `co + (a/contrib)·(Σ wᵢ·Mᵢ·co − contrib·co)`; `co` where `contrib ≤ 0.0001`.
/// Lane by lane with 4-wide rows: LBS has no serial dependency between influences, so this keeps
/// the accumulators in registers.
///
/// # Safety
/// Every bone index of `slots` indexes `linear` (see [`bone`]).
#[inline(always)]
unsafe fn linear<I: BoneIndex>(co: &Points, slots: &[Slot<I>], linear: &[LinearBone], strength: &Lanes) -> Points {
    let mut r = *co;
    for l in 0..LANES {
        let mut acc = [Vec4::ZERO; 3];
        let mut contrib = 0.0f32;
        for slot in slots {
            // SAFETY: the caller's contract.
            let m = unsafe { bone(linear, slot.bones[l]) };
            let w = slot.weights[l];
            let ws = Vec4::splat(w);
            for (a, row) in acc.iter_mut().zip(&m.matrix.rows) {
                *a = *row * ws + *a;
            }
            contrib += w;
        }
        let h = Vec4::new(co.x[l], co.y[l], co.z[l], 1.0);
        let f = if contrib > MIN_TOTAL_WEIGHT { strength[l] / contrib } else { 0.0 };
        r.x[l] = madd(acc[0].dot(h) - h.x * contrib, f, h.x);
        r.y[l] = madd(acc[1].dot(h) - h.y * contrib, f, h.y);
        r.z[l] = madd(acc[2].dot(h) - h.z * contrib, f, h.z);
    }
    r
}

//! The portable kernels: the baseline copy, compiled for the target's baseline instruction set
//! and run where no SIMD copy is (or where `DQSKIN_SIMD=baseline` asks for it). Lane by lane over
//! a batch of [`LANES`] vertices, written so that the compiler vectorizes what it can; the same
//! arithmetic as the SIMD copies (`batch.rs`, `avx512.rs`), which the tests hold them to.

use glam::{Affine3A, Vec4};

use super::influences::{lane_record, Slot, LANES};
use super::job::{Job, BLEND, CENTERS, DUAL_QUATERNION, LINEAR};
use super::pose::{CorBone, CorRigidBone, DqBone, LinearBone, PivotBone};
use super::MIN_TOTAL_WEIGHT;

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
pub(super) struct Points {
    pub x: Lanes,
    pub y: Lanes,
    pub z: Lanes,
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

/// One batch of up to [`LANES`] vertices, loaded and moved into armature space.
struct Batch<'a> {
    first: usize,
    n: usize,
    original: Points,
    co: Points,
    strength: Lanes,
    slots: &'a [Slot],
}

/// Skins one batch of up to [`LANES`] vertices from `first` (`out` holds its results; `slots`
/// its influences) with the portable kernels.
///
/// # Safety
/// Every bone index of the slots indexes every table of the job's pose that the method reads
/// (`Job::new` makes sure of it).
#[inline(always)]
pub(super) unsafe fn batch<const KIND: u8, const SCALED: bool>(
    job: &Job<'_>,
    premat: Option<&Affine3A>,
    postmat: Option<&Affine3A>,
    first: usize,
    slots: &[Slot],
    out: &mut [[f32; 3]],
) {
    let (n, pose) = (out.len(), job.pose());
    let original = load_points(&job.positions[first..first + n]);
    let mut strength: Lanes = [1.0; LANES];
    if let Some(mask) = job.mask {
        strength[..n].copy_from_slice(&mask[first..first + n]);
    }
    let co = match &premat {
        Some(m) => original.transform(m),
        None => original,
    };
    let batch = Batch { first, n, original, co, strength, slots };
    if let (CENTERS, Some(centers)) = (KIND, job.centers) {
        let center = load_points(&centers[first..first + n]);
        let center = match &premat {
            Some(m) => center.transform(m),
            None => center,
        };
        // SAFETY: the caller's contract.
        let sum = unsafe { accumulate_centers::<SCALED>(&batch.co, &center, batch.slots, &pose.cor, &pose.cor_rigid) };
        let moved = finish_centers::<SCALED>(&batch.co, &center, &sum, &batch.strength);
        finish_points(&batch, moved, postmat, out);
        return;
    }
    let sum = (KIND != LINEAR).then(|| {
        // SAFETY: the caller's contract.
        unsafe { accumulate_dual_quaternion::<SCALED>(&batch.co, batch.slots, &pose.dq, &pose.pivot) }
    });
    // SAFETY: the caller's contract.
    unsafe { finish_batch::<KIND>(job, &batch, sum.as_ref(), postmat, out) };
}

/// Finishes a loaded batch (LBS, DQS from its sums, or their blend), applies `postmat` and the
/// mask, and writes it.
///
/// # Safety
/// Every bone index of the batch's slots indexes the pose's `linear` table.
#[inline(always)]
unsafe fn finish_batch<const KIND: u8>(
    job: &Job<'_>,
    batch: &Batch<'_>,
    sum: Option<&DqSum>,
    postmat: Option<&Affine3A>,
    out: &mut [[f32; 3]],
) {
    let pose = job.pose();
    let (co, strength) = (&batch.co, &batch.strength);
    let moved = match (KIND, sum) {
        (DUAL_QUATERNION, Some(sum)) => finish_dual_quaternion(co, sum, strength),
        (BLEND, Some(sum)) => {
            // SAFETY: the caller's contract.
            let lbs = unsafe { linear(co, batch.slots, &pose.linear, strength) };
            let dqs = finish_dual_quaternion(co, sum, strength);
            let mut alpha: Lanes = [job.blend_factor; LANES];
            if let Some(amount) = job.blend_amount {
                for l in 0..batch.n {
                    alpha[l] *= amount[batch.first + l];
                }
            }
            let mut r = lbs;
            for l in 0..LANES {
                r.x[l] = madd(alpha[l], dqs.x[l] - lbs.x[l], lbs.x[l]);
                r.y[l] = madd(alpha[l], dqs.y[l] - lbs.y[l], lbs.y[l]);
                r.z[l] = madd(alpha[l], dqs.z[l] - lbs.z[l], lbs.z[l]);
            }
            r
        }
        // SAFETY: the caller's contract.
        _ => unsafe { linear(co, batch.slots, &pose.linear, strength) },
    };
    finish_points(batch, moved, postmat, out);
}

/// Applies `postmat` and the mask to a batch's moved points and writes them.
#[inline(always)]
fn finish_points(batch: &Batch<'_>, moved: Points, postmat: Option<&Affine3A>, out: &mut [[f32; 3]]) {
    let strength = &batch.strength;
    let mut result = match postmat {
        Some(m) => moved.transform(m),
        None => moved,
    };
    // A mask weight of 0 leaves the vertex bit-identical (no space round trip).
    for l in 0..LANES {
        if strength[l] == 0.0 {
            result.x[l] = batch.original.x[l];
            result.y[l] = batch.original.y[l];
            result.z[l] = batch.original.z[l];
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

/// Bone data for one lane of a slot (its entry `scaled`, see [`RECORD_UNIT`]), without a bounds
/// check (the kernels' innermost loads).
///
/// # Safety
/// `scaled / RECORD_UNIT < table.len()`. For a slot of a [`Job`]'s influences and a table of its
/// pose this holds: bone indices were validated against the bone count when the influences were
/// built, `Job::new` checked that the pose has that many bones (and the rest tables the method
/// reads), and padding lanes use bone 0, which exists whenever there is a slot at all.
///
/// [`RECORD_UNIT`]: super::influences::RECORD_UNIT
#[inline(always)]
unsafe fn bone<T>(table: &[T], scaled: u32) -> &T {
    // SAFETY: the caller's contract; the record is a whole, aligned `T` of `table`.
    unsafe { &*lane_record(table, scaled).cast::<T>() }
}

/// LBS: `co + (a/contrib)·(Σ wᵢ·Mᵢ·co − contrib·co)`; `co` where `contrib ≤ 0.0001`.
/// Lane by lane with 4-wide rows: LBS has no serial dependency between influences, so this keeps
/// the accumulators in registers.
///
/// # Safety
/// Every bone index of `slots` indexes `linear` (see [`bone`]).
#[inline(always)]
unsafe fn linear(co: &Points, slots: &[Slot], linear: &[LinearBone], strength: &Lanes) -> Points {
    let mut r = *co;
    for l in 0..LANES {
        let mut acc = [Vec4::ZERO; 3];
        let mut contrib = 0.0f32;
        for slot in slots {
            // SAFETY: the caller's contract.
            let m = unsafe { bone(linear, slot.records[l]) };
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

/// An unnormalized dual quaternion per lane: real (x, y, z, w), dual (x, y, z, w), total weight.
pub(super) struct DqSum {
    pub real: [Lanes; 4],
    pub dual: [Lanes; 4],
    pub contrib: Lanes,
}

/// Sums `±wᵢ·q̂ᵢ` with each sign chosen against the running sum (Blender's
/// `add_weighted_dq_dq`); for bones with scale the dual part moves `co` exactly where the bone's
/// matrix puts it (`add_weighted_dq_dq_pivot`).
///
/// # Safety
/// Every bone index of `slots` indexes `dq` and `pivot` (see [`bone`]).
#[inline(always)]
unsafe fn accumulate_dual_quaternion<const SCALED: bool>(
    co: &Points,
    slots: &[Slot],
    dq: &[DqBone],
    pivot: &[PivotBone],
) -> DqSum {
    let mut s = DqSum { real: [ZERO; 4], dual: [ZERO; 4], contrib: ZERO };
    for slot in slots {
        for l in 0..LANES {
            let (q, d) = if SCALED {
                // SAFETY: the caller's contract.
                let p = unsafe { bone(pivot, slot.records[l]) };
                let q = [p.real.x, p.real.y, p.real.z, p.real.w];
                let (x, y, z) = (co.x[l], co.y[l], co.z[l]);
                let t = |r: usize| {
                    let row = p.translation.rows[r];
                    madd(row.x, x, madd(row.y, y, madd(row.z, z, row.w)))
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
                // SAFETY: the caller's contract.
                let b = unsafe { bone(dq, slot.records[l]) };
                ([b.real.x, b.real.y, b.real.z, b.real.w], [b.dual.x, b.dual.y, b.dual.z, b.dual.w])
            };
            let dot = q[0] * s.real[0][l] + q[1] * s.real[1][l] + q[2] * s.real[2][l] + q[3] * s.real[3][l];
            let w = slot.weights[l];
            let w = if dot < 0.0 { -w } else { w };
            for c in 0..4 {
                s.real[c][l] = madd(q[c], w, s.real[c][l]);
                s.dual[c][l] = madd(d[c], w, s.dual[c][l]);
            }
            s.contrib[l] += slot.weights[l];
        }
    }
    s
}

/// Applies the summed dual quaternions (Blender's `mul_v3m3_dq`: `(M·co + t)/|q|²`), then the
/// strength: `co + a·(r − co)`; `co` where `contrib ≤ 0.0001` or the sum is zero. Computed as
/// `co + u·(2a/|q|²)` without the matrix (see `dual_quaternion` in `batch.rs`, which the SIMD
/// copies run). Written with selects, not branches, so the lane loop vectorizes.
#[inline(always)]
fn finish_dual_quaternion(co: &Points, s: &DqSum, strength: &Lanes) -> Points {
    let mut r = *co;
    for l in 0..LANES {
        let q = [s.real[0][l], s.real[1][l], s.real[2][l], s.real[3][l]];
        let (x, y, z) = (q[0], q[1], q[2]);
        let (tx, ty, tz, t0) = (s.dual[0][l], s.dual[1][l], s.dual[2][l], s.dual[3][l]);
        let p = [co.x[l], co.y[l], co.z[l]];
        // b = v × p + t⃗, u = w·b + v × b − t₀·v
        let b =
            [madd(-z, p[1], madd(y, p[2], tx)), madd(-x, p[2], madd(z, p[0], ty)), madd(-y, p[0], madd(x, p[1], tz))];
        let t = turn(q, b);
        let u = [madd(-t0, x, t[0]), madd(-t0, y, t[1]), madd(-t0, z, t[2])];
        let len2 = length_squared(q);
        let valid = s.contrib[l] > MIN_TOTAL_WEIGHT && len2 > 0.0;
        let a = strength[l];
        let g = if valid { (a + a) / len2 } else { 0.0 };
        r.x[l] = madd(u[0], g, p[0]);
        r.y[l] = madd(u[1], g, p[1]);
        r.z[l] = madd(u[2], g, p[2]);
    }
    r
}

/// `|q|²` of a quaternion sum `(x, y, z, w)`, in the SIMD copies' order.
#[inline(always)]
fn length_squared([x, y, z, w]: [f32; 4]) -> f32 {
    madd(z, z, madd(y, y, madd(x, x, w * w)))
}

/// `w·b + v × b` for the quaternion sum `(v, w)` (see `turn` in `batch.rs`).
#[inline(always)]
fn turn([x, y, z, w]: [f32; 4], b: [f32; 3]) -> [f32; 3] {
    [
        madd(-z, b[1], madd(y, b[2], w * b[0])),
        madd(-x, b[2], madd(z, b[0], w * b[1])),
        madd(-y, b[0], madd(x, b[1], w * b[2])),
    ]
}

/// `w·b + v × b` with `b = v × d` for the quaternion sum `(v, w)`: half of `|q|²·(R·d − d)`, `R`
/// its rotation (see `rotation_terms` in `batch.rs`).
#[inline(always)]
fn rotation_terms(q: [f32; 4], d: [f32; 3]) -> [f32; 3] {
    let [x, y, z, _] = q;
    turn(q, [madd(-z, d[1], y * d[2]), madd(-x, d[2], z * d[0]), madd(-y, d[0], x * d[1])])
}

/// Per-lane sums for centers of rotation: where LBS puts the center, `Σ wᵢ·Mᵢ·c` (scaled poses)
/// or how far it moves it, `Σ wᵢ·(Mᵢ·c − c)` (rigid poses, where that is cheaper: see
/// [`rotation_offset`]); the sign-aligned quaternion sum, `Σ wᵢ·Sᵢ·(co − c)` (scaled poses only)
/// and the total weight.
pub(super) struct CorSum {
    pub anchor: [Lanes; 3],
    pub real: [Lanes; 4],
    pub offset: [Lanes; 3],
    pub contrib: Lanes,
}

/// Sums for centers of rotation; the quaternion signs are chosen against the running sum as in
/// [`accumulate_dual_quaternion`].
///
/// # Safety
/// Every bone index of `slots` indexes `cor` and `cor_rigid` (see [`bone`]).
#[inline(always)]
unsafe fn accumulate_centers<const SCALED: bool>(
    co: &Points,
    center: &Points,
    slots: &[Slot],
    cor: &[CorBone],
    cor_rigid: &[CorRigidBone],
) -> CorSum {
    let mut s = CorSum { anchor: [ZERO; 3], real: [ZERO; 4], offset: [ZERO; 3], contrib: ZERO };
    for slot in slots {
        for l in 0..LANES {
            let w = slot.weights[l];
            let (cx, cy, cz) = (center.x[l], center.y[l], center.z[l]);
            let q = if SCALED {
                // SAFETY: the caller's contract.
                let b = unsafe { bone(cor, slot.records[l]) };
                for r in 0..3 {
                    let row = b.matrix_row(r);
                    let moved = madd(row.x, cx, madd(row.y, cy, madd(row.z, cz, row.w)));
                    s.anchor[r][l] = madd(w, moved, s.anchor[r][l]);
                }
                let (dx, dy, dz) = (co.x[l] - cx, co.y[l] - cy, co.z[l] - cz);
                for r in 0..3 {
                    let row = b.stretch_row(r);
                    let stretched = madd(row[0], dx, madd(row[1], dy, row[2] * dz));
                    s.offset[r][l] = madd(w, stretched, s.offset[r][l]);
                }
                b.real
            } else {
                // SAFETY: the caller's contract.
                let r = unsafe { bone(cor_rigid, slot.records[l]) };
                let moved = rotation_offset(r.real, r.half_translation, [cx, cy, cz]);
                let w2 = w + w;
                for k in 0..3 {
                    s.anchor[k][l] = madd(w2, moved[k], s.anchor[k][l]);
                }
                r.real
            };
            let q = [q.x, q.y, q.z, q.w];
            let dot = q[0] * s.real[0][l] + q[1] * s.real[1][l] + q[2] * s.real[2][l] + q[3] * s.real[3][l];
            let ws = if dot < 0.0 { -w } else { w };
            for c in 0..4 {
                s.real[c][l] = madd(q[c], ws, s.real[c][l]);
            }
            s.contrib[l] += w;
        }
    }
    s
}

/// `½·(R·p + t − p)` for the unit quaternion `q = (v, w)` of `R`, given `h = t/2`:
/// `R·p = p + 2·(w·(v × p) + v × (v × p))`, so this is `w·a + (v × a + h)` with `a = v × p`,
/// where `h` enters as the addend of `v × a`'s second product (no extra instruction). Weighted by
/// `2·wᵢ` it sums to `Σ wᵢ·(Mᵢ·c − c)`; the `c` comes back once per vertex (`contrib·c`).
#[inline(always)]
fn rotation_offset(q: Vec4, h: Vec4, p: [f32; 3]) -> [f32; 3] {
    let v = [q.x, q.y, q.z];
    let a = [madd(v[1], p[2], -(v[2] * p[1])), madd(v[2], p[0], -(v[0] * p[2])), madd(v[0], p[1], -(v[1] * p[0]))];
    let b = [
        madd(v[1], a[2], -madd(v[2], a[1], -h.x)),
        madd(v[2], a[0], -madd(v[0], a[2], -h.y)),
        madd(v[0], a[1], -madd(v[1], a[0], -h.z)),
    ];
    core::array::from_fn(|k| madd(q.w, a[k], b[k]))
}

/// `co' = c + anchor/contrib + R·d` (rigid: `anchor = Σ wᵢ·(Mᵢ·c − c)`, `d = co − c`) or
/// `co' = anchor/contrib + R·o/contrib` (scaled: `anchor = Σ wᵢ·Mᵢ·c`, `o` the offset sum), `R` the
/// rotation of the summed quaternion, through [`rotation_terms`] `u` of `d` or `o`:
/// `R·d = d + 2u/|q|²`; then the strength: `co + a·(co' − co)`, that is
/// `co + anchor·(a/contrib) + u·(2a/|q|²)` (rigid) or
/// `co + (anchor + o − contrib·co)·(a/contrib) + u·(2a/(|q|²·contrib))` (scaled); `co` where
/// `contrib ≤ 0.0001` or the sum is zero. One division, `a/(|q|²·contrib)`, serves both factors.
/// Selects, not branches, so the lane loop vectorizes.
#[inline(always)]
fn finish_centers<const SCALED: bool>(co: &Points, center: &Points, s: &CorSum, strength: &Lanes) -> Points {
    let mut r = *co;
    for l in 0..LANES {
        let q = [s.real[0][l], s.real[1][l], s.real[2][l], s.real[3][l]];
        let len2 = length_squared(q);
        let p = [co.x[l], co.y[l], co.z[l]];
        let d = if SCALED {
            [s.offset[0][l], s.offset[1][l], s.offset[2][l]]
        } else {
            [p[0] - center.x[l], p[1] - center.y[l], p[2] - center.z[l]]
        };
        let u = rotation_terms(q, d);
        let contrib = s.contrib[l];
        let valid = contrib > MIN_TOTAL_WEIGHT && len2 > 0.0;
        let a = strength[l];
        let inv = if valid { a / (len2 * contrib) } else { 0.0 };
        let fa = inv * len2;
        let fr = if SCALED { inv + inv } else { (inv + inv) * contrib };
        let anchor = |k: usize| if SCALED { madd(-p[k], contrib, s.anchor[k][l] + d[k]) } else { s.anchor[k][l] };
        r.x[l] = madd(anchor(0), fa, madd(u[0], fr, p[0]));
        r.y[l] = madd(anchor(1), fa, madd(u[1], fr, p[1]));
        r.z[l] = madd(anchor(2), fa, madd(u[2], fr, p[2]));
    }
    r
}

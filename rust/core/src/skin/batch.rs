//! The batch kernels written once for every SIMD instruction set that implements [`VectorOps`]
//! (AVX2+FMA in `avx2.rs`, NEON in `neon.rs`): everything skinning does to a full batch of
//! [`LANES`] vertices, as `LANES / WIDTH` parts of one vector each. The arithmetic is the
//! portable copy's in `kernels.rs`; what is summed per influence is arranged for throughput:
//!
//! 1. **Signs.** The quaternion sum whose running value picks each influence's sign (DQS, Blend,
//!    centers of rotation) is a serial chain per vertex. All parts' chains run in one loop, so
//!    that they overlap instead of waiting on each other; the signed weights are kept.
//! 2. **Linear sums.** Everything else is linear in the bones' per-frame records: `Σ wᵢ·Mᵢ`
//!    (LBS, the centers' anchor), `Σ ±wᵢ·dᵢ` (the rigid dual parts), `Σ ±wᵢ·Pᵢ` (the dual parts of
//!    bones with scale, see `PivotDualBone`), `Σ wᵢ·Sᵢ` (the scale/shear parts). Each is a sum of
//!    record windows that an instruction set may accumulate per lane and transpose once per
//!    vertex ([`VectorOps::window_sums`]), instead of transposing every influence's record.
//! 3. **Finish** per part: apply the sums to the point (and its center), the strength,
//!    `postmat`, the untouched lanes, store.

use glam::Affine3A;

use super::influences::{Slot, LANES};
use super::kernels::{BLEND, CENTERS, DUAL_QUATERNION, LINEAR};
#[cfg(target_arch = "x86_64")]
use super::pose::CorRigidBone;
use super::pose::{CorBone, DqBone, LinearBone, PivotBone, PivotDualBone};
use super::MIN_TOTAL_WEIGHT;

/// The vector operations of one SIMD instruction set, `WIDTH` f32 lanes (one vertex per lane).
///
/// Implementors are zero-sized proofs that the CPU has the instruction set: a value can only
/// be made where it was detected (see each implementation's constructor), so every method is
/// safe to call. The batch kernels are instantiated inside a function compiled for the set
/// (`#[target_feature]`), where the methods inline to single instructions.
pub(super) trait VectorOps: Copy {
    /// Lanes per vector; divides [`LANES`], at least `LANES / MAX_PARTS`.
    const WIDTH: usize;
    /// `WIDTH` floats.
    type F: Copy;
    /// A per-lane condition.
    type Mask: Copy;

    fn splat(self, x: f32) -> Self::F;
    /// The first `WIDTH` floats of `a` (which must have that many).
    fn load(self, a: &[f32]) -> Self::F;
    /// Writes the first `WIDTH` floats of `a` (which must have that many).
    fn store(self, v: Self::F, a: &mut [f32]);
    fn add(self, a: Self::F, b: Self::F) -> Self::F;
    fn sub(self, a: Self::F, b: Self::F) -> Self::F;
    fn mul(self, a: Self::F, b: Self::F) -> Self::F;
    fn div(self, a: Self::F, b: Self::F) -> Self::F;
    fn neg(self, a: Self::F) -> Self::F;
    /// `a·b + c`, fused.
    fn mul_add(self, a: Self::F, b: Self::F, c: Self::F) -> Self::F;
    /// `c − a·b`, fused.
    fn neg_mul_add(self, a: Self::F, b: Self::F, c: Self::F) -> Self::F;
    fn lt(self, a: Self::F, b: Self::F) -> Self::Mask;
    fn gt(self, a: Self::F, b: Self::F) -> Self::Mask;
    fn eq(self, a: Self::F, b: Self::F) -> Self::Mask;
    fn and(self, a: Self::Mask, b: Self::Mask) -> Self::Mask;
    /// `a` in the lanes where `m` holds, `b` elsewhere.
    fn select(self, m: Self::Mask, a: Self::F, b: Self::F) -> Self::F;

    /// Four floats from float `offset` of each lane's bone record (`records[l]`, a slot's entries:
    /// see [`lane_record`]), transposed: vector `k` holds float `offset + k` of every lane's
    /// record.
    ///
    /// # Safety
    /// `records` has at least `WIDTH` entries, each of which names a record of `table`; `T` is
    /// made of f32 (`repr(C)`) and `offset + 4` floats lie inside it.
    ///
    /// [`lane_record`]: super::influences::lane_record
    unsafe fn load_columns4<T>(self, table: &[T], records: &[u32], offset: usize) -> [Self::F; 4];

    /// `WIDTH` points `x y z x y z …` split into coordinate vectors.
    fn load_points(self, points: &[[f32; 3]]) -> [Self::F; 3];
    /// Coordinate vectors written back as `WIDTH` points.
    fn store_points(self, p: [Self::F; 3], out: &mut [[f32; 3]]);

    /// For the lanes `lane0 .. lane0 + WIDTH`: the sum over the slots of each lane's weight
    /// times the floats `offset .. offset + 4·ROWS` of its bone record, as `ROWS` rows of four
    /// component vectors. The weight of slot `s` is `signed[s]` if given, else the slot's own.
    /// By default from transposed records ([`transposed_window_sums`]).
    ///
    /// # Safety
    /// Every bone index of those lanes of `slots` indexes `table`; `T` is made of f32 and the
    /// window lies inside it; `signed`, if given, has one entry per slot.
    #[inline(always)]
    unsafe fn window_sums<T, const ROWS: usize>(
        self,
        slots: &[Slot],
        signed: Option<&[[f32; LANES]]>,
        lane0: usize,
        table: &[T],
        offset: usize,
    ) -> [[Self::F; 4]; ROWS] {
        // SAFETY: the caller's contract.
        unsafe { transposed_window_sums(self, slots, signed, lane0, table, offset) }
    }
}

/// [`VectorOps::window_sums`] from transposed records: one transpose per slot and row (the
/// default; the AVX2 copy uses it for a single row, where it takes fewer instructions than
/// per-lane sums).
///
/// # Safety
/// As [`VectorOps::window_sums`].
#[inline(always)]
pub(super) unsafe fn transposed_window_sums<V: VectorOps, T, const ROWS: usize>(
    v: V,
    slots: &[Slot],
    signed: Option<&[[f32; LANES]]>,
    lane0: usize,
    table: &[T],
    offset: usize,
) -> [[V::F; 4]; ROWS] {
    let mut acc = [[v.splat(0.0); 4]; ROWS];
    for (s, slot) in slots.iter().enumerate() {
        let w = v.load(&signed.map_or(&slot.weights, |w| &w[s])[lane0..]);
        for (r, row) in acc.iter_mut().enumerate() {
            // SAFETY: the caller's contract.
            let c = unsafe { v.load_columns4(table, &slot.records[lane0..], offset + 4 * r) };
            for k in 0..4 {
                row[k] = v.mul_add(c[k], w, row[k]);
            }
        }
    }
    acc
}

/// The most parts a batch has (four for NEON's four lanes).
const MAX_PARTS: usize = 4;

/// Inputs of the batch kernels that are the same for every batch of a call.
pub(super) struct BatchJob<'a> {
    pub linear: &'a [LinearBone],
    pub dq: &'a [DqBone],
    pub pivot: &'a [PivotBone],
    pub pivot_dual: &'a [PivotDualBone],
    pub cor: &'a [CorBone],
    /// These two are read by the AVX-512 kernels only (the others have `SCALED`).
    #[cfg(target_arch = "x86_64")]
    pub cor_rigid: &'a [CorRigidBone],
    #[cfg(target_arch = "x86_64")]
    pub scaled: bool,
    pub premat: Option<&'a Affine3A>,
    pub postmat: Option<&'a Affine3A>,
    pub blend_factor: f32,
}

/// Working memory of the batch kernels, reused for every batch of a call.
pub(super) struct Scratch {
    /// The signed weights of a batch's slots (written by the sign pass before they are read).
    signed: Vec<[f32; LANES]>,
}

impl Scratch {
    /// For batches of up to `slots` slots (the most influences of any vertex).
    pub(super) fn new(slots: usize) -> Self {
        Scratch { signed: vec![[0.0; LANES]; slots] }
    }
}

/// One full batch: its points and slots and, where the method has them, its mask weights,
/// blend amounts and centers.
pub(super) struct FullBatch<'a> {
    pub positions: &'a [[f32; 3]; LANES],
    pub out: &'a mut [[f32; 3]; LANES],
    pub slots: &'a [Slot],
    pub strength: Option<&'a [f32; LANES]>,
    pub blend_amount: Option<&'a [f32; LANES]>,
    pub centers: Option<&'a [[f32; 3]; LANES]>,
}

/// Skins one full batch with the method `KIND` (`SCALED`: some bone takes Blender's scale path).
///
/// # Safety
/// Every bone index of the batch's slots indexes the tables of `job` that the method reads
/// (all of them except for LBS, which reads `linear` only).
#[inline(always)]
pub(super) unsafe fn skin_batch<V: VectorOps, const KIND: u8, const SCALED: bool>(
    v: V,
    job: &BatchJob<'_>,
    batch: FullBatch<'_>,
    scratch: &mut Scratch,
) {
    let parts = LANES / V::WIDTH;
    debug_assert!(LANES.is_multiple_of(V::WIDTH) && parts <= MAX_PARTS);
    let slots = batch.slots;
    let zero = v.splat(0.0);
    let centers = KIND == CENTERS && batch.centers.is_some();
    let signed = &mut scratch.signed[..slots.len()];
    let mut real = [[zero; 4]; MAX_PARTS];
    // `if`s rather than closures here and below: a closure compiled on its own would not have
    // the instruction set of the function it is written in, and its vector operations would
    // become calls.
    if KIND != LINEAR {
        // The rotation is floats 12–15 of a CorBone and of a PivotBone, 0–3 of a DqBone.
        if centers && SCALED {
            // SAFETY: the caller's contract.
            unsafe { sign_pass(v, slots, job.cor, 12, &mut real, signed) };
        } else if !centers && SCALED {
            // SAFETY: the caller's contract.
            unsafe { sign_pass(v, slots, job.pivot, 12, &mut real, signed) };
        } else {
            // SAFETY: the caller's contract.
            unsafe { sign_pass(v, slots, job.dq, 0, &mut real, signed) };
        }
    }
    let signed = &*signed;
    for (p, real) in real.iter().enumerate().take(parts) {
        let lanes = p * V::WIDTH..(p + 1) * V::WIDTH;
        let lane0 = lanes.start;
        let o = v.load_points(&batch.positions[lanes.clone()]);
        let a = match batch.strength {
            Some(s) => v.load(&s[lanes.clone()]),
            None => v.splat(1.0),
        };
        let mut contrib = zero;
        for slot in slots {
            contrib = v.add(contrib, v.load(&slot.weights[lanes.clone()]));
        }
        let p = match job.premat {
            Some(m) => apply(v, m, o),
            None => o,
        };
        // The windows: a LinearBone's rows (floats 0–11), a DqBone's dual part (4–7), a
        // PivotDualBone (0–15), a CorBone's rows, rotation and scale/shear part (0–27).
        let moved = if let (true, Some(c)) = (centers, batch.centers) {
            let c = v.load_points(&c[lanes.clone()]);
            let c = match job.premat {
                Some(m) => apply(v, m, c),
                None => c,
            };
            if SCALED {
                // One window over the rows, the rotation (its sum unused) and the scale/shear
                // part: one index and weight per influence for both sums. SAFETY: the caller's
                // contract.
                let [m0, m1, m2, _, s0, s1, s2] = unsafe { v.window_sums::<_, 7>(slots, None, lane0, job.cor, 0) };
                let matrix = [m0, m1, m2];
                // Σ wᵢ·Sᵢ from the window s00 s01 s02 s10 | s11 s12 s20 s21 | s22 0 0 0.
                let [[s00, s01, s02, s10], [s11, s12, s20, s21], [s22, ..]] = [s0, s1, s2];
                let d: [V::F; 3] = each3(|k| v.sub(p[k], c[k]));
                let row = |a, b, c| v.mul_add(a, d[0], v.mul_add(b, d[1], v.mul(c, d[2])));
                let offset = [row(s00, s01, s02), row(s10, s11, s12), row(s20, s21, s22)];
                finish_centers::<V, SCALED>(v, &matrix, real, offset, contrib, p, c, a)
            } else {
                // SAFETY: the caller's contract.
                let matrix = unsafe { v.window_sums::<_, 3>(slots, None, lane0, job.linear, 0) };
                let d = each3(|k| v.sub(p[k], c[k]));
                finish_centers::<V, SCALED>(v, &matrix, real, d, contrib, p, c, a)
            }
        } else {
            let lbs = if KIND == LINEAR || KIND == BLEND {
                // SAFETY: the caller's contract.
                let matrix = unsafe { v.window_sums::<_, 3>(slots, None, lane0, job.linear, 0) };
                linear(v, &matrix, contrib, p, a)
            } else {
                p
            };
            let dqs = if KIND == DUAL_QUATERNION || KIND == BLEND {
                let dual = if SCALED {
                    // SAFETY: the caller's contract.
                    let rows = unsafe { v.window_sums::<_, 4>(slots, Some(signed), lane0, job.pivot_dual, 0) };
                    each4(|c| affine_row(v, &rows[c], &p))
                } else {
                    // SAFETY: the caller's contract.
                    let [dual] = unsafe { v.window_sums::<_, 1>(slots, Some(signed), lane0, job.dq, 4) };
                    dual
                };
                apply_dual_quaternion(v, *real, dual, contrib, p, a)
            } else {
                p
            };
            match KIND {
                LINEAR => lbs,
                BLEND => {
                    let factor = v.splat(job.blend_factor);
                    let alpha = match batch.blend_amount {
                        Some(amount) => v.mul(factor, v.load(&amount[lanes.clone()])),
                        None => factor,
                    };
                    each3(|k| v.mul_add(alpha, v.sub(dqs[k], lbs[k]), lbs[k]))
                }
                _ => dqs,
            }
        };
        let r = match job.postmat {
            Some(m) => apply(v, m, moved),
            None => moved,
        };
        // A mask weight of 0 leaves the vertex bit-identical (no space round trip).
        let untouched = v.eq(a, zero);
        let r = each3(|k| v.select(untouched, o[k], r[k]));
        v.store_points(r, &mut batch.out[lanes]);
    }
}

/// Pass 1: the sign-aligned quaternion sums of every part over the slots, the parts' chains
/// interleaved; each slot's signed weights go to `signed`. The rotation of a lane's bone is
/// floats `offset .. offset + 4` (x, y, z, w) of its record.
///
/// # Safety
/// Every bone index of the slots indexes `table`, whose records hold the rotation there.
#[inline(always)]
unsafe fn sign_pass<V: VectorOps, T>(
    v: V,
    slots: &[Slot],
    table: &[T],
    offset: usize,
    real: &mut [[V::F; 4]; MAX_PARTS],
    signed: &mut [[f32; LANES]],
) {
    for (slot, out) in slots.iter().zip(signed.iter_mut()) {
        for (p, real) in real.iter_mut().enumerate().take(LANES / V::WIDTH) {
            let lane0 = p * V::WIDTH;
            // SAFETY: the caller's contract.
            let q = unsafe { v.load_columns4(table, &slot.records[lane0..], offset) };
            let w = v.load(&slot.weights[lane0..]);
            let ws = v.select(v.lt(dot4(v, &q, real), v.splat(0.0)), v.neg(w), w);
            for c in 0..4 {
                real[c] = v.mul_add(q[c], ws, real[c]);
            }
            v.store(ws, &mut out[lane0..]);
        }
    }
}

/// `[f(0), f(1), f(2)]`. The kernels build their small arrays with this and [`each4`] rather
/// than `array::from_fn` or `array::map`, whose generic machinery the compiler may leave out of
/// line, compiled without the instruction set of the kernel that uses it.
#[inline(always)]
fn each3<T>(f: impl Fn(usize) -> T) -> [T; 3] {
    [f(0), f(1), f(2)]
}

/// `[f(0), f(1), f(2), f(3)]` (see [`each3`]).
#[inline(always)]
pub(super) fn each4<T>(f: impl Fn(usize) -> T) -> [T; 4] {
    [f(0), f(1), f(2), f(3)]
}

/// `m·p` for an affine `m` (its entries broadcast).
#[inline(always)]
fn apply<V: VectorOps>(v: V, m: &Affine3A, p: [V::F; 3]) -> [V::F; 3] {
    let c = [m.matrix3.x_axis, m.matrix3.y_axis, m.matrix3.z_axis, m.translation];
    let e = |k: usize, r: usize| v.splat(c[k][r]);
    each3(|r| v.mul_add(e(0, r), p[0], v.mul_add(e(1, r), p[1], v.mul_add(e(2, r), p[2], e(3, r)))))
}

/// `row·(p, 1)` for a row of four component vectors.
#[inline(always)]
fn affine_row<V: VectorOps>(v: V, m: &[V::F; 4], p: &[V::F; 3]) -> V::F {
    v.mul_add(m[0], p[0], v.mul_add(m[1], p[1], v.mul_add(m[2], p[2], m[3])))
}

/// `a·b` of quaternions per lane, in two independent halves: the sign choice that waits on it is
/// the serial chain, so keep it short.
#[inline(always)]
fn dot4<V: VectorOps>(v: V, a: &[V::F; 4], b: &[V::F; 4]) -> V::F {
    v.add(v.mul_add(a[1], b[1], v.mul(a[0], b[0])), v.mul_add(a[3], b[3], v.mul(a[2], b[2])))
}

/// LBS of one part's points `p` (armature space) with strength `a`, from `Σ wᵢ·Mᵢ`:
/// `co + (a/contrib)·(Σ wᵢ·Mᵢ·co − contrib·co)`.
#[inline(always)]
fn linear<V: VectorOps>(v: V, matrix: &[[V::F; 4]; 3], contrib: V::F, p: [V::F; 3], a: V::F) -> [V::F; 3] {
    let f = v.select(v.gt(contrib, v.splat(MIN_TOTAL_WEIGHT)), v.div(a, contrib), v.splat(0.0));
    each3(|r| v.mul_add(v.neg_mul_add(p[r], contrib, affine_row(v, &matrix[r], &p)), f, p[r]))
}

/// Applies summed dual quaternions to `p` (Blender's `mul_v3m3_dq`, dividing by `|q|²` instead
/// of normalizing), then the strength: `p·(1 − a) + r·a`; `p` where `contrib ≤ 0.0001` or the sum
/// is zero.
#[inline(always)]
fn apply_dual_quaternion<V: VectorOps>(v: V, real: [V::F; 4], dual: [V::F; 4], contrib: V::F, p: [V::F; 3], a: V::F) -> [V::F; 3] {
    let [x, y, z, w] = real;
    // Blender's order: t0 = dual w, t1..t3 = dual x, y, z.
    let (t0, t1, t2, t3) = (dual[3], dual[0], dual[1], dual[2]);
    let (mul, add, sub) = (|a, b| v.mul(a, b), |a, b| v.add(a, b), |a, b| v.sub(a, b));
    let two = v.splat(2.0);
    let q = quaternion_matrix(v, real);
    // 2·(−t0·x + w·t1 − t2·z + y·t3) and its two siblings.
    let tx = mul(two, add(sub(mul(w, t1), mul(t0, x)), sub(mul(y, t3), mul(t2, z))));
    let ty = mul(two, add(sub(mul(t1, z), mul(t0, y)), sub(mul(w, t2), mul(x, t3))));
    let tz = mul(two, add(sub(mul(x, t2), mul(t0, z)), sub(mul(w, t3), mul(t1, y))));
    let t = [tx, ty, tz];
    let n = each3(|r| {
        let m = &q.rows[r];
        v.mul_add(m[0], p[0], v.mul_add(m[1], p[1], v.mul_add(m[2], p[2], t[r])))
    });
    let valid = v.and(v.gt(contrib, v.splat(MIN_TOTAL_WEIGHT)), v.gt(q.len2, v.splat(0.0)));
    let one = v.splat(1.0);
    let f = v.select(valid, v.div(a, q.len2), v.splat(0.0));
    let keep = v.select(valid, v.sub(one, a), one);
    // co + a·(n/|q|² − co) = n·(a/|q|²) + co·(1 − a)
    each3(|k| v.mul_add(n[k], f, v.mul(p[k], keep)))
}

/// The unnormalized rotation matrix of a quaternion sum, `|q|²·R` (rows), and `|q|²`.
struct QuaternionMatrix<F> {
    rows: [[F; 3]; 3],
    len2: F,
}

#[inline(always)]
fn quaternion_matrix<V: VectorOps>(v: V, [x, y, z, w]: [V::F; 4]) -> QuaternionMatrix<V::F> {
    let (mul, add, sub) = (|a, b| v.mul(a, b), |a, b| v.add(a, b), |a, b| v.sub(a, b));
    let two = v.splat(2.0);
    let (ww, xx, yy, zz) = (mul(w, w), mul(x, x), mul(y, y), mul(z, z));
    let (xy, xz, yz) = (mul(x, y), mul(x, z), mul(y, z));
    let (wx, wy, wz) = (mul(w, x), mul(w, y), mul(w, z));
    QuaternionMatrix {
        rows: [
            [sub(add(ww, xx), add(yy, zz)), mul(two, sub(xy, wz)), mul(two, add(xz, wy))],
            [mul(two, add(xy, wz)), sub(add(ww, yy), add(xx, zz)), mul(two, sub(yz, wx))],
            [mul(two, sub(xz, wy)), mul(two, add(yz, wx)), sub(add(ww, zz), add(xx, yy))],
        ],
        len2: add(add(ww, xx), add(yy, zz)),
    }
}

/// Skinning with centers of rotation of one part's points `p` with centers `c` (both in armature
/// space), from `Σ wᵢ·Mᵢ` (`matrix`), the quaternion sum and the offset `dd`: `co − c` for rigid
/// bones, `Σ wᵢ·Sᵢ·(co − c)` with scale. `co' = Σ wᵢ·Mᵢ·c/contrib + R·dd` (`dd/contrib` with
/// scale), `R` the rotation of the quaternion sum; then the strength (see `finish_centers` in
/// `kernels.rs`, which sums the rigid anchor as `Σ wᵢ·(Mᵢ·c − c)`).
#[allow(clippy::too_many_arguments)] // the sums and the part's points, one by one
#[inline(always)]
fn finish_centers<V: VectorOps, const SCALED: bool>(
    v: V,
    matrix: &[[V::F; 4]; 3],
    real: &[V::F; 4],
    dd: [V::F; 3],
    contrib: V::F,
    p: [V::F; 3],
    c: [V::F; 3],
    a: V::F,
) -> [V::F; 3] {
    let zero = v.splat(0.0);
    let one = v.splat(1.0);
    let anchor = each3(|r| affine_row(v, &matrix[r], &c));
    let q = quaternion_matrix(v, *real);
    let n = each3(|r| {
        let m = &q.rows[r];
        v.mul_add(m[0], dd[0], v.mul_add(m[1], dd[1], v.mul(m[2], dd[2])))
    });
    let valid = v.and(v.gt(contrib, v.splat(MIN_TOTAL_WEIGHT)), v.gt(q.len2, zero));
    // One division serves both factors: a/contrib = inv·|q|², a/|q|² = inv·contrib.
    let inv = v.select(valid, v.div(a, v.mul(q.len2, contrib)), zero);
    let fa = v.mul(inv, q.len2);
    let fr = if SCALED { inv } else { v.mul(inv, contrib) };
    let keep = v.select(valid, v.sub(one, a), one);
    // anchor·(a/contrib) + n·fr + co·(1 − a)
    each3(|k| v.mul_add(anchor[k], fa, v.mul_add(n[k], fr, v.mul(p[k], keep))))
}

//! The batch kernels written once for every SIMD instruction set that implements [`VectorOps`]
//! (AVX2+FMA in `avx2.rs`, NEON in `neon.rs`): everything skinning does to [`VectorOps::WIDTH`]
//! vertices of a full batch, in registers: load, `premat`, the sums over the influence slots,
//! LBS, DQS (Blender's `mul_v3m3_dq`), their blend or the centers-of-rotation step, strength,
//! `postmat`, the untouched lanes, store. The arithmetic is the portable copy's in
//! `kernels.rs`, term for term.
//!
//! What differs between instruction sets is behind the trait: the vector type, loading a lane's
//! bone record window transposed into component vectors, (de)interleaving points, and the LBS
//! sums (which each set accumulates in the layout its registers suit best).

use glam::Affine3A;

use super::influences::{Slot, LANES};
use super::kernels::{CENTERS, DUAL_QUATERNION, LINEAR};
use super::pose::{CorBone, CorRigidBone, DqBone, LinearBone, PivotBone};
use super::MIN_TOTAL_WEIGHT;

/// The vector operations of one SIMD instruction set, `WIDTH` f32 lanes (one vertex per lane).
///
/// Implementors are zero-sized proofs that the CPU has the instruction set: a value can only
/// be made where it was detected (see each implementation's constructor), so every method is
/// safe to call. The batch kernels are instantiated inside a function compiled for the set
/// (`#[target_feature]`, or the target's baseline), where the methods inline to single
/// instructions.
pub(super) trait VectorOps: Copy {
    /// Lanes per vector; divides [`LANES`].
    const WIDTH: usize;
    /// `WIDTH` floats.
    type F: Copy;
    /// A per-lane condition.
    type Mask: Copy;

    fn splat(self, x: f32) -> Self::F;
    /// The first `WIDTH` floats of `a` (which must have that many).
    fn load(self, a: &[f32]) -> Self::F;
    fn add(self, a: Self::F, b: Self::F) -> Self::F;
    fn sub(self, a: Self::F, b: Self::F) -> Self::F;
    fn mul(self, a: Self::F, b: Self::F) -> Self::F;
    fn div(self, a: Self::F, b: Self::F) -> Self::F;
    fn neg(self, a: Self::F) -> Self::F;
    /// `a·b + c`, fused.
    fn mul_add(self, a: Self::F, b: Self::F, c: Self::F) -> Self::F;
    /// `a·b − c`, fused.
    fn mul_sub(self, a: Self::F, b: Self::F, c: Self::F) -> Self::F;
    /// `c − a·b`, fused.
    fn neg_mul_add(self, a: Self::F, b: Self::F, c: Self::F) -> Self::F;
    fn lt(self, a: Self::F, b: Self::F) -> Self::Mask;
    fn gt(self, a: Self::F, b: Self::F) -> Self::Mask;
    fn eq(self, a: Self::F, b: Self::F) -> Self::Mask;
    fn and(self, a: Self::Mask, b: Self::Mask) -> Self::Mask;
    /// `a` in the lanes where `m` holds, `b` elsewhere.
    fn select(self, m: Self::Mask, a: Self::F, b: Self::F) -> Self::F;

    /// Four floats from float `offset` of each lane's bone record `table[bones[l]]`, transposed:
    /// vector `k` holds float `offset + k` of every lane's record.
    ///
    /// # Safety
    /// `bones` has at least `WIDTH` entries, each of which indexes `table`; `T` is made of f32
    /// (`repr(C)`) and `offset + 4` floats lie inside it.
    unsafe fn load_columns4<T>(self, table: &[T], bones: &[u32], offset: usize) -> [Self::F; 4];

    /// [`Self::load_columns4`] for eight floats.
    ///
    /// # Safety
    /// As [`Self::load_columns4`], with `offset + 8` floats inside `T`.
    #[inline(always)]
    unsafe fn load_columns<T>(self, table: &[T], bones: &[u32], offset: usize) -> [Self::F; 8] {
        // SAFETY: the caller's contract.
        let ([a, b, c, d], [e, f, g, h]) = unsafe { (self.load_columns4(table, bones, offset), self.load_columns4(table, bones, offset + 4)) };
        [a, b, c, d, e, f, g, h]
    }

    /// `WIDTH` points `x y z x y z …` split into coordinate vectors.
    fn load_points(self, points: &[[f32; 3]]) -> [Self::F; 3];
    /// Coordinate vectors written back as `WIDTH` points.
    fn store_points(self, p: [Self::F; 3], out: &mut [[f32; 3]]);

    /// LBS sums over the slots for lanes `lane0 .. lane0 + WIDTH`: `Σ wᵢ·Mᵢ` (row-major 3×4,
    /// 12 vectors) and `Σ wᵢ`. By default from transposed record windows.
    ///
    /// # Safety
    /// Every bone index of those lanes of `slots` indexes `linear`.
    #[inline(always)]
    unsafe fn linear_sums(self, slots: &[Slot], lane0: usize, linear: &[LinearBone]) -> ([Self::F; 12], Self::F) {
        let mut acc = [self.splat(0.0); 12];
        let mut contrib = self.splat(0.0);
        for slot in slots {
            let bones = &slot.bones[lane0..];
            // SAFETY: the caller's contract; a LinearBone's first 12 floats are its three rows.
            let (a, b) = unsafe { (self.load_columns(linear, bones, 0), self.load_columns4(linear, bones, 8)) };
            let w = self.load(&slot.weights[lane0..]);
            for k in 0..8 {
                acc[k] = self.mul_add(a[k], w, acc[k]);
            }
            for k in 0..4 {
                acc[8 + k] = self.mul_add(b[k], w, acc[8 + k]);
            }
            contrib = self.add(contrib, w);
        }
        (acc, contrib)
    }
}

/// Inputs of the batch kernels that are the same for every batch of a call.
pub(super) struct BatchJob<'a> {
    pub linear: &'a [LinearBone],
    pub dq: &'a [DqBone],
    pub pivot: &'a [PivotBone],
    pub cor: &'a [CorBone],
    pub cor_rigid: &'a [CorRigidBone],
    pub scaled: bool,
    pub premat: Option<&'a Affine3A>,
    pub postmat: Option<&'a Affine3A>,
    pub blend_factor: f32,
}

/// `WIDTH` vertices of a full batch: lanes `lane0 ..` of its slots.
pub(super) struct Part<'a> {
    pub positions: &'a [[f32; 3]],
    pub out: &'a mut [[f32; 3]],
    pub slots: &'a [Slot],
    pub lane0: usize,
    /// The mask weights, if any.
    pub strength: Option<&'a [f32]>,
    pub blend_amount: Option<&'a [f32]>,
    pub centers: Option<&'a [[f32; 3]]>,
}

/// Skins one part with the method `KIND` (`SCALED`: some bone takes Blender's scale path).
///
/// # Safety
/// Every bone index of the part's lanes of its slots indexes the tables of `job` that the
/// method reads (all of them except for LBS, which reads `linear` only); with `CENTERS`, the
/// part has its centers.
#[inline(always)]
pub(super) unsafe fn skin_part<V: VectorOps, const KIND: u8, const SCALED: bool>(v: V, job: &BatchJob<'_>, part: Part<'_>) {
    debug_assert!(LANES.is_multiple_of(V::WIDTH) && part.lane0 + V::WIDTH <= LANES);
    let o = v.load_points(part.positions);
    let one = v.splat(1.0);
    let a = part.strength.map_or(one, |s| v.load(s));
    let moved = if let (CENTERS, Some(centers)) = (KIND, part.centers) {
        let c = v.load_points(centers);
        let (p, c) = match job.premat {
            Some(m) => (apply(v, m, o), apply(v, m, c)),
            None => (o, c),
        };
        // SAFETY: the caller's contract.
        unsafe { centers_step::<V, SCALED>(v, job, &part, p, c, a) }
    } else {
        let p = job.premat.map_or(o, |m| apply(v, m, o));
        // SAFETY: the caller's contract.
        unsafe { blend_step::<V, KIND>(v, job, &part, p, a) }
    };
    let r = job.postmat.map_or(moved, |m| apply(v, m, moved));
    // A mask weight of 0 leaves the vertex bit-identical (no space round trip).
    let untouched = v.eq(a, v.splat(0.0));
    let r = core::array::from_fn(|k| v.select(untouched, o[k], r[k]));
    v.store_points(r, part.out);
}

/// `m·p` for an affine `m` (its entries broadcast).
#[inline(always)]
fn apply<V: VectorOps>(v: V, m: &Affine3A, p: [V::F; 3]) -> [V::F; 3] {
    let c = [m.matrix3.x_axis, m.matrix3.y_axis, m.matrix3.z_axis, m.translation];
    core::array::from_fn(|r| {
        let e = |k: usize| v.splat(c[k][r]);
        v.mul_add(e(0), p[0], v.mul_add(e(1), p[1], v.mul_add(e(2), p[2], e(3))))
    })
}

/// `w`, negated in the lanes where `dot < 0`: a quaternion's sign chosen against the running sum.
#[inline(always)]
fn signed_weight<V: VectorOps>(v: V, dot: V::F, w: V::F) -> V::F {
    v.select(v.lt(dot, v.splat(0.0)), v.neg(w), w)
}

/// `a·b` of quaternions per lane, in two independent halves: the sign choice that waits on it is
/// the serial chain, so keep it short.
#[inline(always)]
fn dot4<V: VectorOps>(v: V, a: &[V::F], b: &[V::F]) -> V::F {
    v.add(v.mul_add(a[1], b[1], v.mul(a[0], b[0])), v.mul_add(a[3], b[3], v.mul(a[2], b[2])))
}

/// LBS, DQS or their blend of points `p` (armature space) with strength `a`.
///
/// # Safety
/// As [`skin_part`].
#[inline(always)]
unsafe fn blend_step<V: VectorOps, const KIND: u8>(v: V, job: &BatchJob<'_>, part: &Part<'_>, p: [V::F; 3], a: V::F) -> [V::F; 3] {
    let zero = v.splat(0.0);
    let threshold = v.splat(MIN_TOTAL_WEIGHT);
    // `if`s rather than closures: a closure compiled on its own would not have the instruction
    // set of the function it is written in, and its vector operations would become calls.
    let lbs = if KIND != DUAL_QUATERNION {
        // SAFETY: the caller's contract.
        let (acc, contrib) = unsafe { v.linear_sums(part.slots, part.lane0, job.linear) };
        let f = v.select(v.gt(contrib, threshold), v.div(a, contrib), zero);
        // co + (a/contrib)·(Σ wᵢ·Mᵢ·co − contrib·co)
        let axis = |r: usize| {
            let m = &acc[4 * r..4 * r + 4];
            let moved = v.mul_add(m[0], p[0], v.mul_add(m[1], p[1], v.mul_add(m[2], p[2], m[3])));
            v.mul_add(v.neg_mul_add(p[r], contrib, moved), f, p[r])
        };
        Some([axis(0), axis(1), axis(2)])
    } else {
        None
    };
    let dqs = if KIND != LINEAR {
        // SAFETY: the caller's contract.
        let (real, dual, contrib) =
            unsafe { if job.scaled { scaled_sums(v, part, job.pivot, p) } else { rigid_sums(v, part, job.dq) } };
        Some(apply_dual_quaternion(v, real, dual, contrib, p, a))
    } else {
        None
    };
    match (lbs, dqs) {
        (Some(l), Some(d)) => {
            let mut alpha = v.splat(job.blend_factor);
            if let Some(amount) = part.blend_amount {
                alpha = v.mul(alpha, v.load(amount));
            }
            core::array::from_fn(|k| v.mul_add(alpha, v.sub(d[k], l[k]), l[k]))
        }
        (Some(l), None) => l,
        (None, Some(d)) => d,
        (None, None) => p,
    }
}

/// The sums in registers: real (x, y, z, w), dual (x, y, z, w), total weight.
type Sums<F> = ([F; 4], [F; 4], F);

/// Adds `±w·q` to the rotation sum, the sign chosen by `q·sum < 0` per lane; returns `±w`.
#[inline(always)]
fn add_signed_rotation<V: VectorOps>(v: V, real: &mut [V::F; 4], q: &[V::F; 4], w: V::F) -> V::F {
    let ws = signed_weight(v, dot4(v, q, real), w);
    for c in 0..4 {
        real[c] = v.mul_add(q[c], ws, real[c]);
    }
    ws
}

/// Adds `±w·(q, d)` to the sums, the sign chosen by `q·sum < 0` per lane.
#[inline(always)]
fn add_signed<V: VectorOps>(v: V, s: &mut Sums<V::F>, q: &[V::F; 4], d: &[V::F; 4], w: V::F) {
    let ws = add_signed_rotation(v, &mut s.0, q, w);
    for c in 0..4 {
        s.1[c] = v.mul_add(d[c], ws, s.1[c]);
    }
    s.2 = v.add(s.2, w);
}

/// DQS sums for rigid bones.
///
/// # Safety
/// Every bone index of the part's lanes indexes `dq`.
#[inline(always)]
unsafe fn rigid_sums<V: VectorOps>(v: V, part: &Part<'_>, dq: &[DqBone]) -> Sums<V::F> {
    let zero = v.splat(0.0);
    let (mut real, mut dual, mut contrib) = ([zero; 4], [zero; 4], zero);
    for slot in part.slots {
        let bones = &slot.bones[part.lane0..];
        let w = v.load(&slot.weights[part.lane0..]);
        // The rotation first and the dual part once its sign is known, so that only one half of
        // the record is in registers beside the sums. SAFETY: the caller's contract; a DqBone is
        // 8 floats.
        let q = unsafe { v.load_columns4(dq, bones, 0) };
        let ws = add_signed_rotation(v, &mut real, &q, w);
        // SAFETY: as above.
        let d = unsafe { v.load_columns4(dq, bones, 4) };
        for c in 0..4 {
            dual[c] = v.mul_add(d[c], ws, dual[c]);
        }
        contrib = v.add(contrib, w);
    }
    (real, dual, contrib)
}

/// DQS sums when some bone has scale: each bone moves `p` rigidly to where its matrix puts it.
///
/// # Safety
/// Every bone index of the part's lanes indexes `pivot`.
#[inline(always)]
unsafe fn scaled_sums<V: VectorOps>(v: V, part: &Part<'_>, pivot: &[PivotBone], [x, y, z]: [V::F; 3]) -> Sums<V::F> {
    let zero = v.splat(0.0);
    let half = v.splat(0.5);
    let mut s = ([zero; 4], [zero; 4], zero);
    for slot in part.slots {
        let bones = &slot.bones[part.lane0..];
        // SAFETY: the caller's contract; a PivotBone is 16 floats: rows 0–1, then row 2 and the
        // rotation.
        let (a, b) = unsafe { (v.load_columns(pivot, bones, 0), v.load_columns(pivot, bones, 8)) };
        let row = |m0, m1, m2, t| v.mul_add(m0, x, v.mul_add(m1, y, v.mul_add(m2, z, t)));
        let tx = row(a[0], a[1], a[2], a[3]);
        let ty = row(a[4], a[5], a[6], a[7]);
        let tz = row(b[0], b[1], b[2], b[3]);
        let q = [b[4], b[5], b[6], b[7]];
        // ½·(0, t)·q = ½·(w·t + t × v, −t·v), q = (v, w); each component is
        // 0.5·(p·r − (s·u − tw·w)).
        let cross_plus = |p, r, s, u, tw| v.mul(half, v.mul_sub(p, r, v.mul_sub(s, u, v.mul(tw, q[3]))));
        let d = [
            cross_plus(ty, q[2], tz, q[1], tx),
            cross_plus(tz, q[0], tx, q[2], ty),
            cross_plus(tx, q[1], ty, q[0], tz),
            v.mul(v.splat(-0.5), v.mul_add(tx, q[0], v.mul_add(ty, q[1], v.mul(tz, q[2])))),
        ];
        add_signed(v, &mut s, &q, &d, v.load(&slot.weights[part.lane0..]));
    }
    s
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
    let n: [V::F; 3] = core::array::from_fn(|r| {
        let m = &q.rows[r];
        v.mul_add(m[0], p[0], v.mul_add(m[1], p[1], v.mul_add(m[2], p[2], t[r])))
    });
    let valid = v.and(v.gt(contrib, v.splat(MIN_TOTAL_WEIGHT)), v.gt(q.len2, v.splat(0.0)));
    let one = v.splat(1.0);
    let f = v.select(valid, v.div(a, q.len2), v.splat(0.0));
    let keep = v.select(valid, v.sub(one, a), one);
    // co + a·(n/|q|² − co) = n·(a/|q|²) + co·(1 − a)
    core::array::from_fn(|k| v.mul_add(n[k], f, v.mul(p[k], keep)))
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

/// `½·(R·p + t − p)` for the unit quaternions `q = (v, w)` of `R`, given `h = t/2`: `w·a + (v ×
/// a + h)` with `a = v × p` (see `rotation_offset` in `kernels.rs`).
#[inline(always)]
fn rotation_offset<V: VectorOps>(v: V, q: &[V::F], h: &[V::F], p: &[V::F; 3]) -> [V::F; 3] {
    let a = [
        v.mul_sub(q[1], p[2], v.mul(q[2], p[1])),
        v.mul_sub(q[2], p[0], v.mul(q[0], p[2])),
        v.mul_sub(q[0], p[1], v.mul(q[1], p[0])),
    ];
    let b = [
        v.mul_sub(q[1], a[2], v.mul_sub(q[2], a[1], h[0])),
        v.mul_sub(q[2], a[0], v.mul_sub(q[0], a[2], h[1])),
        v.mul_sub(q[0], a[1], v.mul_sub(q[1], a[0], h[2])),
    ];
    core::array::from_fn(|k| v.mul_add(q[3], a[k], b[k]))
}

/// Skinning with centers of rotation of points `p` with centers `c` (both in armature space):
/// the sums (where each bone puts the center, the sign-aligned rotations, with `SCALED` the
/// blended scale/shear of the offset), then `co' = anchor/contrib (+ c) + R·d` and the strength
/// (see `finish_centers` in `kernels.rs`).
///
/// # Safety
/// Every bone index of the part's lanes indexes `job.cor` and `job.cor_rigid`.
#[inline(always)]
unsafe fn centers_step<V: VectorOps, const SCALED: bool>(
    v: V,
    job: &BatchJob<'_>,
    part: &Part<'_>,
    p: [V::F; 3],
    c: [V::F; 3],
    a: V::F,
) -> [V::F; 3] {
    let zero = v.splat(0.0);
    let d: [V::F; 3] = core::array::from_fn(|k| v.sub(p[k], c[k]));
    let mut anchor = [zero; 3];
    let mut offset = [zero; 3];
    let mut real = [zero; 4];
    let mut contrib = zero;
    for slot in part.slots {
        let bones = &slot.bones[part.lane0..];
        let w = v.load(&slot.weights[part.lane0..]);
        let q = if SCALED {
            // SAFETY: the caller's contract; a CorBone's first 24 floats are matrix rows 0–1,
            // row 2 and the rotation, and the first 8 entries of its scale/shear part.
            let (a, b, s) =
                unsafe { (v.load_columns(job.cor, bones, 0), v.load_columns(job.cor, bones, 8), v.load_columns(job.cor, bones, 16)) };
            let rows = [[a[0], a[1], a[2], a[3]], [a[4], a[5], a[6], a[7]], [b[0], b[1], b[2], b[3]]];
            for r in 0..3 {
                let m = rows[r];
                let moved = v.mul_add(m[0], c[0], v.mul_add(m[1], c[1], v.mul_add(m[2], c[2], m[3])));
                anchor[r] = v.mul_add(w, moved, anchor[r]);
            }
            // SAFETY: the caller's contract.
            let s22 = unsafe { load_s22(v, job.cor, bones) };
            let rows = [[s[0], s[1], s[2]], [s[3], s[4], s[5]], [s[6], s[7], s22]];
            for r in 0..3 {
                let m = rows[r];
                let stretched = v.mul_add(m[0], d[0], v.mul_add(m[1], d[1], v.mul(m[2], d[2])));
                offset[r] = v.mul_add(w, stretched, offset[r]);
            }
            [b[4], b[5], b[6], b[7]]
        } else {
            // SAFETY: the caller's contract; a CorRigidBone is 8 floats: the rotation, half the
            // translation and a zero.
            let r = unsafe { v.load_columns(job.cor_rigid, bones, 0) };
            let moved = rotation_offset(v, &r[0..4], &r[4..7], &c);
            let w2 = v.add(w, w);
            for k in 0..3 {
                anchor[k] = v.mul_add(w2, moved[k], anchor[k]);
            }
            [r[0], r[1], r[2], r[3]]
        };
        add_signed_rotation(v, &mut real, &q, w);
        contrib = v.add(contrib, w);
    }
    let one = v.splat(1.0);
    let q = quaternion_matrix(v, real);
    let dd = if SCALED { offset } else { d };
    let n: [V::F; 3] = core::array::from_fn(|r| {
        let m = &q.rows[r];
        v.mul_add(m[0], dd[0], v.mul_add(m[1], dd[1], v.mul(m[2], dd[2])))
    });
    let valid = v.and(v.gt(contrib, v.splat(MIN_TOTAL_WEIGHT)), v.gt(q.len2, zero));
    // One division serves both factors: a/contrib = inv·|q|², a/|q|² = inv·contrib.
    let inv = v.select(valid, v.div(a, v.mul(q.len2, contrib)), zero);
    let fa = v.mul(inv, q.len2);
    let fr = if SCALED { inv } else { v.mul(inv, contrib) };
    let base: [V::F; 3] = if SCALED {
        let keep = v.select(valid, v.sub(one, a), one);
        core::array::from_fn(|k| v.mul(p[k], keep))
    } else {
        // co + a·(c − co): the rigid anchor is Σ wᵢ·(Mᵢ·c − c).
        let av = v.select(valid, a, zero);
        core::array::from_fn(|k| v.neg_mul_add(av, d[k], p[k]))
    };
    // anchor·(a/contrib) + n·(a/|q|²) + base
    core::array::from_fn(|k| v.mul_add(anchor[k], fa, v.mul_add(n[k], fr, base[k])))
}

/// The last entry `s22` of each lane's scale/shear part (see `CorBone`), by scalar loads through
/// a small buffer: on the load side, none on the vector ports that the transposes fill (a fourth
/// window for one float would cost a whole transpose).
///
/// # Safety
/// The first `WIDTH` entries of `bones` index `cor`.
#[inline(always)]
unsafe fn load_s22<V: VectorOps>(v: V, cor: &[CorBone], bones: &[u32]) -> V::F {
    let mut values = [0.0f32; LANES];
    for l in 0..V::WIDTH {
        debug_assert!((bones[l] as usize) < cor.len());
        // SAFETY: the caller's contract.
        values[l] = unsafe { cor.get_unchecked(bones[l] as usize) }.s22;
    }
    v.load(&values)
}

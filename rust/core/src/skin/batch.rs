//! The batch kernels written once for every instruction set that implements [`VectorOps`]
//! (the baseline in `baseline.rs`, AVX2+FMA in `avx2.rs`, AVX-512 in `avx512.rs`, NEON in
//! `neon.rs`): everything skinning does to a full batch of [`LANES`] vertices, as
//! `LANES / WIDTH` parts of one vector each, skinned one part after the other so that a part's
//! sums stay in registers. The arithmetic is Blender's as the module states it (`skin/mod.rs`);
//! what is summed per influence is arranged for throughput:
//!
//! 1. **Signs.** The quaternion sum whose running value picks each influence's sign (DQS, Blend,
//!    centers of rotation) is a serial chain per vertex, from transposed rotations. Rigid DQS
//!    sums its dual parts in the same loop (both halves of a record from one index); elsewhere
//!    the signed weights are kept where a later sum needs them.
//! 2. **Linear sums.** Everything else is linear in the bones' per-frame records: `Σ wᵢ·Dᵢ` or
//!    `Σ wᵢ·Mᵢ` (LBS's moves or matrices), `Σ ±wᵢ·Pᵢ` (the dual parts of bones with scale, see
//!    `PivotDualBone`), `Σ wᵢ·Sᵢ` (the scale/shear parts). Each is a sum of record windows that an
//!    instruction set may accumulate per lane and transpose once per vertex
//!    ([`VectorOps::window_sums`]), instead of transposing every influence's record. (The rigid
//!    centers' anchor `Σ wᵢ·(Mᵢ·c − c)` is not linear in its records: it is summed with the
//!    signs, [`rigid_center_sums`].)
//! 3. **Finish**: apply the sums to the point (and its center) without building a rotation
//!    matrix (`p + u·(2a/|q|²)`, see [`dual_quaternion`]), the strength, `postmat`, the untouched
//!    lanes, store.
//!
//! Every copy with fused multiply-adds computes each method in the same operations in the same
//! order (the hand-written kernels of `avx2/` and `avx512/` too), so they give the same bits.

use core::mem::offset_of;

use glam::Affine3A;

use super::influences::{BoneIndex, Slot, LANES};
use super::job::{BLEND, CENTERS, DUAL_QUATERNION, LINEAR};
use super::pose::{CorBone, CorRigidBone, DqBone, LinearBone, PivotBone, PivotDualBone};
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
    /// `a·b + c`, fused.
    fn mul_add(self, a: Self::F, b: Self::F, c: Self::F) -> Self::F;
    /// `c − a·b`, fused.
    fn neg_mul_add(self, a: Self::F, b: Self::F, c: Self::F) -> Self::F;
    /// `a·b − c`, fused.
    fn mul_sub(self, a: Self::F, b: Self::F, c: Self::F) -> Self::F;
    fn lt(self, a: Self::F, b: Self::F) -> Self::Mask;
    fn gt(self, a: Self::F, b: Self::F) -> Self::Mask;
    fn eq(self, a: Self::F, b: Self::F) -> Self::Mask;
    fn and(self, a: Self::Mask, b: Self::Mask) -> Self::Mask;
    /// `a` in the lanes where `m` holds, `b` elsewhere.
    fn select(self, m: Self::Mask, a: Self::F, b: Self::F) -> Self::F;
    /// `−a` in the lanes where `m` holds, `a` elsewhere (the sign bit flipped: two cheap bit
    /// operations where a select may take three).
    fn neg_where(self, m: Self::Mask, a: Self::F) -> Self::F;

    /// Four floats from float `offset` of each lane's bone record (`bones[l]`, a slot's entries:
    /// see [`lane_record`]), transposed: vector `k` holds float `offset + k` of every lane's
    /// record.
    ///
    /// # Safety
    /// `bones` has at least `WIDTH` entries, each of which indexes `table`; `T` is
    /// made of f32 (`repr(C)`) and `offset + 4` floats lie inside it.
    ///
    /// [`lane_record`]: super::influences::lane_record
    unsafe fn load_columns4<T, I: BoneIndex>(self, table: &[T], bones: &[I], offset: usize) -> [Self::F; 4];

    /// `WIDTH` points `x y z x y z …` split into coordinate vectors.
    fn load_points(self, points: &[[f32; 3]]) -> [Self::F; 3];
    /// Coordinate vectors written back as `WIDTH` points.
    fn store_points(self, p: [Self::F; 3], out: &mut [[f32; 3]]);

    /// For the lanes `lane0 .. lane0 + WIDTH`: the sum over the slots of each lane's weight
    /// times the floats `offsets[r] .. offsets[r] + 4` of its bone record, for each row `r`, as
    /// `ROWS` rows of four component vectors. The weight of slot `s` is `signed[s]` if given,
    /// else the slot's own. Rows come in pairs of adjacent ones (`offsets[2j + 1] = offsets[2j] + 4`),
    /// which an instruction set may load together; an odd last row's four floats after it must
    /// lie in the record too.
    ///
    /// # Safety
    /// Every bone index of those lanes of `slots` indexes `table`; `T` is made of f32 and the
    /// rows lie inside it; `signed`, if given, has one entry per slot.
    unsafe fn window_sums<T, I: BoneIndex, const ROWS: usize>(
        self,
        slots: &[Slot<I>],
        signed: Option<&[[f32; LANES]]>,
        lane0: usize,
        table: &[T],
        offsets: [usize; ROWS],
    ) -> [[Self::F; 4]; ROWS];
}

/// Checks a window's rows for the copies that load them in adjacent pairs (eight floats at a
/// time): each pair adjacent, and each pair's eight floats inside a record of `T` (an odd last
/// row with the four floats after it, ignored). The offsets are known at compile time, so the
/// checks fold away.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) fn assert_row_pairs<T, const ROWS: usize>(offsets: &[usize; ROWS]) {
    let stride = core::mem::size_of::<T>() / 4;
    for j in 0..ROWS.div_ceil(2) {
        assert!(
            2 * j + 1 >= ROWS || offsets[2 * j + 1] == offsets[2 * j] + 4,
            "the window's rows come in adjacent pairs"
        );
        assert!(offsets[2 * j] + 8 <= stride, "the window's pairs of rows lie inside the record");
    }
}

/// Row offsets `first, first + 4, …`: a contiguous window of `ROWS` rows for
/// [`VectorOps::window_sums`].
const fn window<const ROWS: usize>(first: usize) -> [usize; ROWS] {
    let mut rows = [0; ROWS];
    let mut r = 0;
    while r < ROWS {
        rows[r] = first + 4 * r;
        r += 1;
    }
    rows
}

/// Inputs of the batch kernels that are the same for every batch of a call.
pub(super) struct BatchJob<'a> {
    pub linear: &'a [LinearBone],
    pub dq: &'a [DqBone],
    pub pivot: &'a [PivotBone],
    pub pivot_dual: &'a [PivotDualBone],
    pub cor: &'a [CorBone],
    pub cor_rigid: &'a [CorRigidBone],
    /// Each bone's move in mesh space (`spaces.rs`), when the job's spaces fold: LBS then reads
    /// these rather than `linear`, and has no `premat` or `postmat`.
    pub linear_moves: Option<&'a [LinearBone]>,
    /// The same moves by component (the AVX-512 copy's LBS, `avx512/bone_window.rs`).
    #[cfg(target_arch = "x86_64")]
    pub linear_columns: Option<&'a super::avx512::MoveColumns>,
    /// The moves by column (the AVX2 copy's LBS, `avx2/kept.rs`).
    #[cfg(target_arch = "x86_64")]
    pub column_moves: Option<&'a [super::pose::ColumnMove]>,
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

    /// Room for the signed weights of a batch of `slots` slots (for AVX2's rigid DQS).
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    pub(super) fn signed(&mut self, slots: usize) -> &mut [[f32; LANES]] {
        &mut self.signed[..slots]
    }
}

/// One full batch: its points and slots and, where the method has them, its mask weights,
/// blend amounts and centers.
pub(super) struct FullBatch<'a, I: BoneIndex> {
    pub positions: &'a [[f32; 3]; LANES],
    pub out: &'a mut [[f32; 3]; LANES],
    pub slots: &'a [Slot<I>],
    pub strength: Option<&'a [f32; LANES]>,
    pub blend_amount: Option<&'a [f32; LANES]>,
    pub centers: Option<&'a [[f32; 3]; LANES]>,
}

/// Float offsets of what the batch kernels read in the pose tables' records.
pub(super) const DQ_REAL: usize = offset_of!(DqBone, real) / 4;
pub(super) const DQ_DUAL: usize = offset_of!(DqBone, dual) / 4;
const PIVOT_REAL: usize = offset_of!(PivotBone, real) / 4;
const COR_REAL: usize = offset_of!(CorBone, real) / 4;
/// The rows of a `CorBone` the centers with scale sum: the matrix rows, then the scale/shear part
/// in three rows (`s00 s01 s02 s10`, `s11 s12 s20 s21`, `s22` and zeros); not the rotation.
const COR_WINDOW: [usize; 6] = {
    let (row2, stretch) = (offset_of!(CorBone, row2) / 4, offset_of!(CorBone, stretch) / 4);
    [0, 4, row2, stretch, stretch + 4, offset_of!(CorBone, s22) / 4]
};

/// Skins one full batch with the method `KIND` (`SCALED`: some bone takes Blender's scale path),
/// as `PARTS` parts of one vector each (`PARTS · V::WIDTH = LANES`), one after the other: a part's
/// sums and finish stay in registers (the CPU overlaps one part's sign chain with the previous
/// part's finish).
///
/// # Safety
/// Every bone index of the batch's slots indexes the tables of `job` that the method reads
/// (all of them except for LBS, which reads `linear` only).
#[inline(always)]
pub(super) unsafe fn skin_batch<V: VectorOps, I: BoneIndex, const KIND: u8, const SCALED: bool, const PARTS: usize>(
    v: V,
    job: &BatchJob<'_>,
    mut batch: FullBatch<'_, I>,
    scratch: &mut Scratch,
) {
    const { assert!(PARTS * V::WIDTH == LANES) };
    let signed = &mut scratch.signed[..batch.slots.len()];
    for part in 0..PARTS {
        // SAFETY: the caller's contract.
        unsafe { skin_part::<V, I, KIND, SCALED>(v, job, &mut batch, part * V::WIDTH, signed) };
    }
}

/// One part of a batch: the lanes `lane0 .. lane0 + V::WIDTH`.
///
/// # Safety
/// As [`skin_batch`].
#[inline(always)]
unsafe fn skin_part<V: VectorOps, I: BoneIndex, const KIND: u8, const SCALED: bool>(
    v: V,
    job: &BatchJob<'_>,
    batch: &mut FullBatch<'_, I>,
    lane0: usize,
    signed: &mut [[f32; LANES]],
) {
    let lanes = lane0..lane0 + V::WIDTH;
    let slots = batch.slots;
    let a = match batch.strength {
        Some(s) => v.load(&s[lanes.clone()]),
        None => v.splat(1.0),
    };
    // The sums come first and the points (and centers) are loaded after them, where they are
    // used: AVX2 has sixteen registers, and whatever is live through a sum's loop spills.
    // `if`s rather than closures here and below: a closure compiled on its own would not have
    // the instruction set of the function it is written in, and its vector operations would
    // become calls.
    // The windows: a LinearBone's rows (floats 0–11), a PivotDualBone (0–15), a CorBone's rows
    // and scale/shear part ([`COR_WINDOW`]).
    let moved = if let (true, Some(centers)) = (KIND == CENTERS, batch.centers) {
        // The sign chain first, so that the window's loop overlaps its latency.
        if SCALED {
            // SAFETY: the caller's contract.
            let (real, contrib) = unsafe { sign_pass(v, slots, job.cor, COR_REAL, lane0, None) };
            // One window over the rows and the scale/shear part: one index and weight per
            // influence for both sums. SAFETY: the caller's contract.
            let [m0, m1, m2, s0, s1, s2] = unsafe { v.window_sums(slots, None, lane0, job.cor, COR_WINDOW) };
            let c = armature_points(v, job, &centers[lanes.clone()]);
            let p = armature_points(v, job, &batch.positions[lanes.clone()]);
            let d: [V::F; 3] = each3(|k| v.sub(p[k], c[k]));
            // Σ wᵢ·Sᵢ from the rows s00 s01 s02 s10 | s11 s12 s20 s21 | s22 0 0 0.
            let [[s00, s01, s02, s10], [s11, s12, s20, s21], [s22, ..]] = [s0, s1, s2];
            let row = |a, b, c| v.mul_add(a, d[0], v.mul_add(b, d[1], v.mul(c, d[2])));
            let offset = [row(s00, s01, s02), row(s10, s11, s12), row(s20, s21, s22)];
            let matrix = [m0, m1, m2];
            let sum = each3(|k| v.add(affine_row(v, &matrix[k], &c), offset[k]));
            let u = rotation_terms(v, &real, offset);
            centers_scaled(v, sum, u, real, contrib, p, a)
        } else {
            let c = armature_points(v, job, &centers[lanes.clone()]);
            // SAFETY: the caller's contract.
            let sums = unsafe { rigid_center_sums(v, slots, job.cor_rigid, lane0, &c) };
            let p = armature_points(v, job, &batch.positions[lanes.clone()]);
            let d = each3(|k| v.sub(p[k], c[k]));
            let u = rotation_terms(v, &sums.real, d);
            centers_rigid(v, sums, u, p, a)
        }
    } else {
        // DQS's sums give the points and the total weight to LBS in Blend.
        let (dqs, summed) = if KIND == DUAL_QUATERNION || KIND == BLEND {
            let (real, dual, contrib, p) = if SCALED {
                // SAFETY: the caller's contract.
                let (real, contrib) = unsafe { sign_pass(v, slots, job.pivot, PIVOT_REAL, lane0, Some(&mut *signed)) };
                // SAFETY: the caller's contract.
                let rows = unsafe { v.window_sums(slots, Some(signed), lane0, job.pivot_dual, window::<4>(0)) };
                let p = armature_points(v, job, &batch.positions[lanes.clone()]);
                (real, each4(|c| affine_row(v, &rows[c], &p)), contrib, p)
            } else {
                // SAFETY: the caller's contract.
                let (real, dual, contrib) = unsafe { rigid_sums(v, slots, job.dq, lane0) };
                (real, dual, contrib, armature_points(v, job, &batch.positions[lanes.clone()]))
            };
            (dual_quaternion(v, real, dual, contrib, p, a), Some((p, contrib)))
        } else {
            // Unused by LBS (and so not computed there); the points themselves for a method
            // with neither sum.
            (armature_points(v, job, &batch.positions[lanes.clone()]), None)
        };
        let lbs = if let (LINEAR, Some(moves)) = (KIND, job.linear_moves) {
            // SAFETY: the caller's contract (the moves are one per bone, as `linear`).
            let sums = unsafe { v.window_sums(slots, None, lane0, moves, window::<3>(0)) };
            let contrib = total_weight(v, slots, lane0);
            debug_assert!(job.premat.is_none() && job.postmat.is_none(), "moves are in mesh space");
            linear_in_mesh_space(v, &sums, contrib, v.load_points(&batch.positions[lanes.clone()]), a)
        } else if KIND == LINEAR || KIND == BLEND {
            // SAFETY: the caller's contract.
            let matrix = unsafe { v.window_sums(slots, None, lane0, job.linear, window::<3>(0)) };
            let (p, contrib) = match summed {
                Some(summed) => summed,
                None => (armature_points(v, job, &batch.positions[lanes.clone()]), total_weight(v, slots, lane0)),
            };
            linear(v, &matrix, contrib, p, a)
        } else {
            dqs
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
    let r = if batch.strength.is_some() { keep_masked(v, a, &batch.positions[lanes.clone()], r) } else { r };
    v.store_points(r, &mut batch.out[lanes]);
}

/// `r`, but the original points `points` where the mask weight `a` is 0: a masked vertex is left
/// bit-identical (no space round trip). The points are loaded again for it rather than kept in
/// registers through the sums.
#[inline(always)]
pub(super) fn keep_masked<V: VectorOps>(v: V, a: V::F, points: &[[f32; 3]], r: [V::F; 3]) -> [V::F; 3] {
    let o = v.load_points(points);
    let untouched = v.eq(a, v.splat(0.0));
    each3(|k| v.select(untouched, o[k], r[k]))
}

/// A part's points in armature space (`premat` applied).
#[inline(always)]
fn armature_points<V: VectorOps>(v: V, job: &BatchJob<'_>, points: &[[f32; 3]]) -> [V::F; 3] {
    let o = v.load_points(points);
    match job.premat {
        Some(m) => apply(v, m, o),
        None => o,
    }
}

/// `±wᵢ` for the quaternion `q` of an influence with weight `w`, against the running sum
/// `real` (Blender's `add_weighted_dq_dq`: negated where `q·sum < 0`).
#[inline(always)]
fn signed_weight<V: VectorOps>(v: V, q: &[V::F; 4], real: &[V::F; 4], w: V::F) -> V::F {
    v.neg_where(v.lt(dot4(v, q, real), v.splat(0.0)), w)
}

/// Adds one slot's rotations `q`, weighted `w`, to the running quaternion sum `real` with their
/// signs ([`signed_weight`]), and returns the signed weights. The first slot keeps its weights:
/// the sum is still zero there, and Blender keeps them.
#[inline(always)]
pub(super) fn add_signed<V: VectorOps>(v: V, first: bool, q: &[V::F; 4], w: V::F, real: &mut [V::F; 4]) -> V::F {
    let ws = if first { w } else { signed_weight(v, q, real, w) };
    for c in 0..4 {
        real[c] = v.mul_add(q[c], ws, real[c]);
    }
    ws
}

/// The sign-aligned quaternion sum of one part's lanes (from `lane0`) over the slots, and the
/// total weight; each slot's signed weights go to `signed` if given (one entry per slot). The
/// rotation of a lane's bone is floats `offset .. offset + 4` (x, y, z, w) of its record. The
/// first slot needs no sign: the sum is still zero there, and Blender keeps the weight.
///
/// # Safety
/// Every bone index of the slots indexes `table`, whose records hold the rotation there.
#[inline(always)]
unsafe fn sign_pass<V: VectorOps, T, I: BoneIndex>(
    v: V,
    slots: &[Slot<I>],
    table: &[T],
    offset: usize,
    lane0: usize,
    mut signed: Option<&mut [[f32; LANES]]>,
) -> ([V::F; 4], V::F) {
    let zero = v.splat(0.0);
    let (mut real, mut contrib) = ([zero; 4], zero);
    for (k, slot) in slots.iter().enumerate() {
        // SAFETY: the caller's contract.
        let q = unsafe { v.load_columns4(table, &slot.bones[lane0..], offset) };
        let w = v.load(&slot.weights[lane0..]);
        let ws = add_signed(v, k == 0, &q, w, &mut real);
        contrib = v.add(contrib, w);
        if let Some(signed) = signed.as_deref_mut() {
            v.store(ws, &mut signed[k][lane0..]);
        }
    }
    (real, contrib)
}

/// The total weight of one part's lanes (from `lane0`), summed in slot order.
#[inline(always)]
pub(super) fn total_weight<V: VectorOps, I: BoneIndex>(v: V, slots: &[Slot<I>], lane0: usize) -> V::F {
    slots.iter().fold(v.splat(0.0), |sum, slot| v.add(sum, v.load(&slot.weights[lane0..])))
}

/// The sums of skinning with centers of rotation for rigid bones, of one part's lanes (from
/// `lane0`) with centers `c` ([`RigidCenterSums`]), from one table.
///
/// # Safety
/// Every bone index of the slots indexes `cor_rigid`.
#[inline(always)]
unsafe fn rigid_center_sums<V: VectorOps, I: BoneIndex>(
    v: V,
    slots: &[Slot<I>],
    cor_rigid: &[CorRigidBone],
    lane0: usize,
    c: &[V::F; 3],
) -> RigidCenterSums<V> {
    let mut sums = RigidCenterSums::new(v);
    for (k, slot) in slots.iter().enumerate() {
        // SAFETY: the caller's contract; a CorRigidBone is the rotation at floats 0–3 and half
        // the translation at 4–6 (and a zero).
        let (q, h) = unsafe {
            (v.load_columns4(cor_rigid, &slot.bones[lane0..], 0), v.load_columns4(cor_rigid, &slot.bones[lane0..], 4))
        };
        sums.add(v, k == 0, &q, &h, v.load(&slot.weights[lane0..]), c);
    }
    sums
}

/// The running sums of skinning with centers of rotation for rigid bones: the sign-aligned
/// rotations, the anchor `Σ wᵢ·(Mᵢ·c − c)` (each bone's move of the center from its rotation and
/// half translation, [`rotation_offset`]) and the total weight. The one body and the
/// hand-written AVX-512 centers (`avx512/kept.rs`), which load the records their own way, both
/// add each slot here, so that they give the same bits.
pub(super) struct RigidCenterSums<V: VectorOps> {
    pub real: [V::F; 4],
    pub anchor: [V::F; 3],
    pub contrib: V::F,
}

impl<V: VectorOps> RigidCenterSums<V> {
    #[inline(always)]
    pub(super) fn new(v: V) -> Self {
        let zero = v.splat(0.0);
        RigidCenterSums { real: [zero; 4], anchor: [zero; 3], contrib: zero }
    }

    /// Adds a slot: its bones' rotations `q` and half translations `h` (the fourth a zero), its
    /// weights `w`, for centers `c`. The first slot's weight keeps its sign (the sum is still
    /// zero there, and Blender keeps it).
    #[inline(always)]
    pub(super) fn add(&mut self, v: V, first: bool, q: &[V::F; 4], h: &[V::F; 4], w: V::F, c: &[V::F; 3]) {
        let moved = rotation_offset(v, q, h, c);
        let w2 = v.add(w, w);
        for i in 0..3 {
            self.anchor[i] = v.mul_add(w2, moved[i], self.anchor[i]);
        }
        add_signed(v, first, q, w, &mut self.real);
        self.contrib = v.add(self.contrib, w);
    }
}

/// `½·(R·c + t − c)` for the unit quaternion `q = (v, w)` of `R`, given `h = t/2`: `w·a + (v × a
/// + h)` with `a = v × c`: a rigid bone's move of the center `c`.
#[inline(always)]
fn rotation_offset<V: VectorOps>(v: V, q: &[V::F; 4], h: &[V::F; 4], c: &[V::F; 3]) -> [V::F; 3] {
    let a = [
        v.mul_sub(q[1], c[2], v.mul(q[2], c[1])),
        v.mul_sub(q[2], c[0], v.mul(q[0], c[2])),
        v.mul_sub(q[0], c[1], v.mul(q[1], c[0])),
    ];
    let b = [
        v.mul_sub(q[1], a[2], v.mul_sub(q[2], a[1], h[0])),
        v.mul_sub(q[2], a[0], v.mul_sub(q[0], a[2], h[1])),
        v.mul_sub(q[0], a[1], v.mul_sub(q[1], a[0], h[2])),
    ];
    each3(|k| v.mul_add(q[3], a[k], b[k]))
}

/// Rigid DQS sums of one part's lanes (from `lane0`): the sign-aligned rotations and dual parts
/// of the influences' `DqBone`s, summed as their signs are chosen (both halves of a record from
/// one index), and the total weight.
///
/// # Safety
/// Every bone index of the slots indexes `dq`.
#[inline(always)]
unsafe fn rigid_sums<V: VectorOps, I: BoneIndex>(
    v: V,
    slots: &[Slot<I>],
    dq: &[DqBone],
    lane0: usize,
) -> ([V::F; 4], [V::F; 4], V::F) {
    let zero = v.splat(0.0);
    let (mut real, mut dual, mut contrib) = ([zero; 4], [zero; 4], zero);
    for (k, slot) in slots.iter().enumerate() {
        let bones = &slot.bones[lane0..];
        // SAFETY: the caller's contract; the rotation and the dual part are four floats each.
        let (q, d) = unsafe { (v.load_columns4(dq, bones, DQ_REAL), v.load_columns4(dq, bones, DQ_DUAL)) };
        let w = v.load(&slot.weights[lane0..]);
        // (`add_signed`'s steps, each dual part's sum beside its rotation's: Blend measured
        // faster in this order than after them, docs/performance.md.)
        let ws = if k == 0 { w } else { signed_weight(v, &q, &real, w) };
        for c in 0..4 {
            real[c] = v.mul_add(q[c], ws, real[c]);
            dual[c] = v.mul_add(d[c], ws, dual[c]);
        }
        contrib = v.add(contrib, w);
    }
    (real, dual, contrib)
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
pub(super) fn apply<V: VectorOps>(v: V, m: &Affine3A, p: [V::F; 3]) -> [V::F; 3] {
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

/// LBS in mesh space of one part's points `co` with strength `a`, from the summed moves
/// `Σ wᵢ·Dᵢ` (`spaces.rs`): `co + (a/contrib)·Σ wᵢ·Dᵢ·co`, lanes whose factor is 0 left
/// bit-identical. The hand-written AVX-512 LBS (`avx512/kept.rs`) computes the same, operation
/// for operation (each row as `(d₀·x + d₂·z) + (d₁·y + d₃)`, the order its block sums add in), so
/// that every copy with fused multiply-adds gives the same bits.
#[inline(always)]
fn linear_in_mesh_space<V: VectorOps>(
    v: V,
    moves: &[[V::F; 4]; 3],
    contrib: V::F,
    co: [V::F; 3],
    a: V::F,
) -> [V::F; 3] {
    let f = v.select(v.gt(contrib, v.splat(MIN_TOTAL_WEIGHT)), v.div(a, contrib), v.splat(0.0));
    let still = v.eq(f, v.splat(0.0));
    each3(|r| {
        let [d0, d1, d2, d3] = moves[r];
        let offset = v.add(v.add(v.mul(d0, co[0]), v.mul(d2, co[2])), v.add(v.mul(d1, co[1]), d3));
        v.select(still, co[r], v.mul_add(f, offset, co[r]))
    })
}

/// `|q|²` of a quaternion sum.
#[inline(always)]
fn length_squared<V: VectorOps>(v: V, [x, y, z, w]: &[V::F; 4]) -> V::F {
    v.mul_add(*z, *z, v.mul_add(*y, *y, v.mul_add(*x, *x, v.mul(*w, *w))))
}

/// `w·b + v × b` for the quaternion sum `(v, w)`: the step both [`rotation_terms`] and
/// [`dual_quaternion`] take after their cross product.
#[inline(always)]
fn turn<V: VectorOps>(v: V, [x, y, z, w]: &[V::F; 4], b: [V::F; 3]) -> [V::F; 3] {
    let (x, y, z, w) = (*x, *y, *z, *w);
    [
        v.neg_mul_add(z, b[1], v.mul_add(y, b[2], v.mul(w, b[0]))),
        v.neg_mul_add(x, b[2], v.mul_add(z, b[0], v.mul(w, b[1]))),
        v.neg_mul_add(y, b[0], v.mul_add(x, b[1], v.mul(w, b[2]))),
    ]
}

/// `w·b + v × b` for the quaternion sum `(v, w)` and `b = v × d`: half of `|q|²·(R·d − d)`, `R`
/// the rotation of the sum (`|q|²·R·d = |q|²·d + 2·(w·(v × d) + v × (v × d))`), which is how
/// the kernels rotate: no matrix, and the `d` they already hold is added back at the end.
#[inline(always)]
pub(super) fn rotation_terms<V: VectorOps>(v: V, q: &[V::F; 4], d: [V::F; 3]) -> [V::F; 3] {
    let [x, y, z, _] = *q;
    let b = [
        v.neg_mul_add(z, d[1], v.mul(y, d[2])),
        v.neg_mul_add(x, d[2], v.mul(z, d[0])),
        v.neg_mul_add(y, d[0], v.mul(x, d[1])),
    ];
    turn(v, q, b)
}

/// Applies summed dual quaternions to `p` (Blender's `mul_v3m3_dq`: `(M·p + t)/|q|²`, `M` the
/// unnormalized rotation matrix `|q|²·R` and `t = 2·(w·t⃗ − t₀·v + v × t⃗)` for the real part
/// `(v, w)` and the dual part `(t⃗, t₀)`), then the strength `a`: `p + a·(r − p)`; `p` where
/// `contrib ≤ 0.0001` or the sum is zero. Written as `p + u·(2a/|q|²)` with
/// `u = w·b + v × b − t₀·v`, `b = v × p + t⃗` (since `M·p = |q|²·p + 2·(w·(v × p) + v × (v × p))`):
/// 17 operations per lane instead of the matrix's 40, and `p`'s own term exact.
#[inline(always)]
pub(super) fn dual_quaternion<V: VectorOps>(
    v: V,
    real: [V::F; 4],
    dual: [V::F; 4],
    contrib: V::F,
    p: [V::F; 3],
    a: V::F,
) -> [V::F; 3] {
    let [x, y, z, _] = real;
    let [tx, ty, tz, t0] = dual;
    // b = v × p + t⃗
    let b = [
        v.neg_mul_add(z, p[1], v.mul_add(y, p[2], tx)),
        v.neg_mul_add(x, p[2], v.mul_add(z, p[0], ty)),
        v.neg_mul_add(y, p[0], v.mul_add(x, p[1], tz)),
    ];
    // u = w·b + v × b − t₀·v
    let t = turn(v, &real, b);
    let u = [v.neg_mul_add(t0, x, t[0]), v.neg_mul_add(t0, y, t[1]), v.neg_mul_add(t0, z, t[2])];
    let len2 = length_squared(v, &real);
    let valid = v.and(v.gt(contrib, v.splat(MIN_TOTAL_WEIGHT)), v.gt(len2, v.splat(0.0)));
    let g = v.select(valid, v.div(v.add(a, a), len2), v.splat(0.0));
    each3(|k| v.mul_add(u[k], g, p[k]))
}

/// Skinning with centers of rotation and rigid bones, of one part's points `p` (armature space),
/// from `anchor = Σ wᵢ·(Mᵢ·c − c)` for its centers `c`, `u` ([`rotation_terms`] of `d = p − c`)
/// and the quaternion sum: `co' = Σ wᵢ·Mᵢ·c/contrib + R·d = anchor/contrib + p + 2u/|q|²`, then
/// the strength: `p + anchor·(a/contrib) + u·(2a/|q|²)`; `p` where `contrib ≤ 0.0001` or the
/// sum is zero. One division serves both factors.
#[inline(always)]
pub(super) fn centers_rigid<V: VectorOps>(
    v: V,
    sums: RigidCenterSums<V>,
    u: [V::F; 3],
    p: [V::F; 3],
    a: V::F,
) -> [V::F; 3] {
    let RigidCenterSums { real, anchor, contrib } = sums;
    let len2 = length_squared(v, &real);
    let valid = v.and(v.gt(contrib, v.splat(MIN_TOTAL_WEIGHT)), v.gt(len2, v.splat(0.0)));
    // a/contrib = inv·|q|², 2a/|q|² = 2·inv·contrib.
    let inv = v.select(valid, v.div(a, v.mul(len2, contrib)), v.splat(0.0));
    let fa = v.mul(inv, len2);
    let fr = v.mul(v.add(inv, inv), contrib);
    each3(|k| v.mul_add(anchor[k], fa, v.mul_add(u[k], fr, p[k])))
}

/// Skinning with centers of rotation and bones with scale, of one part's points `p`, from
/// `sum = Σ wᵢ·Mᵢ·c + o` with `o = Σ wᵢ·Sᵢ·(p − c)`, `u` ([`rotation_terms`] of `o`) and the
/// quaternion sum: `co' = Σ wᵢ·Mᵢ·c/contrib + R·o/contrib = sum/contrib + 2u/(|q|²·contrib)`, then
/// the strength: `p + (sum − contrib·p)·(a/contrib) + u·(2a/(|q|²·contrib))`; `p` where
/// `contrib ≤ 0.0001` or the sum is zero.
#[inline(always)]
fn centers_scaled<V: VectorOps>(
    v: V,
    sum: [V::F; 3],
    u: [V::F; 3],
    real: [V::F; 4],
    contrib: V::F,
    p: [V::F; 3],
    a: V::F,
) -> [V::F; 3] {
    let len2 = length_squared(v, &real);
    let valid = v.and(v.gt(contrib, v.splat(MIN_TOTAL_WEIGHT)), v.gt(len2, v.splat(0.0)));
    let inv = v.select(valid, v.div(a, v.mul(len2, contrib)), v.splat(0.0));
    let fa = v.mul(inv, len2);
    let fr = v.add(inv, inv);
    each3(|k| v.mul_add(v.neg_mul_add(p[k], contrib, sum[k]), fa, v.mul_add(u[k], fr, p[k])))
}

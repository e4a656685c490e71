//! The hand-written AVX-512 kernels kept where they measured faster than the one body of
//! `batch.rs` (docs/performance.md): LBS, whose sixteen lanes each sum a whole 16-float record
//! per influence and apply it in mesh space where the lane lies (from the bones' moves of
//! `spaces.rs`), and centers of rotation for poses without scale, which load each slot's
//! rotations and half translations (`CorRigidBone`) in one transpose. Both compute what the one
//! body computes, operation for operation, so that the copies give the same bits (the tests check
//! it): only the loads and shuffles differ.

use core::arch::x86_64::*;

use super::super::batch::{apply, centers_rigid, rotation_terms, BatchJob, RigidCenterSums};
use super::super::influences::{BoneIndex, Slot, LANES};
use super::super::pose::LinearBone;
use super::bone_window::{self, MoveColumns};
use super::{idx, join, load_points, scalar_record, store_points, transpose_blocks, Avx512};

/// Transposes eight rows `[record l | record l + 8]` (8 floats each) into eight 16-lane
/// component vectors.
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
fn transpose(r: [__m512; 8]) -> [__m512; 8] {
    let [u0, u1, u2, u3] = transpose_blocks([r[0], r[1], r[2], r[3]]);
    let [u4, u5, u6, u7] = transpose_blocks([r[4], r[5], r[6], r[7]]);
    // 128-bit blocks: low components from blocks 0 and 2, high ones from blocks 1 and 3.
    let lo = _mm512_setr_epi32(0, 1, 2, 3, 16, 17, 18, 19, 8, 9, 10, 11, 24, 25, 26, 27);
    let hi = _mm512_setr_epi32(4, 5, 6, 7, 20, 21, 22, 23, 12, 13, 14, 15, 28, 29, 30, 31);
    [
        _mm512_permutex2var_ps(u0, lo, u4),
        _mm512_permutex2var_ps(u1, lo, u5),
        _mm512_permutex2var_ps(u2, lo, u6),
        _mm512_permutex2var_ps(u3, lo, u7),
        _mm512_permutex2var_ps(u0, hi, u4),
        _mm512_permutex2var_ps(u1, hi, u5),
        _mm512_permutex2var_ps(u2, hi, u6),
        _mm512_permutex2var_ps(u3, hi, u7),
    ]
}

/// Each lane's weighted sum of its bones' moves `Σ wᵢ·Dᵢ` (row-major 3×4 and four zeros, one
/// vector a lane) and the total weights.
///
/// Summed per lane: each influence adds its weight (a broadcast load) times its bone's whole
/// 16-float record (one load, folded into the FMA) to its lane's accumulator. Transposing every
/// slot's records instead cost 48 shuffles and 16 inserts per slot, which bounded LBS on the
/// vector ports. One FMA per float, in slot order.
///
/// # Safety
/// Every bone index in `slots` must index `moves`.
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn lane_moves<I: BoneIndex>(slots: &[Slot<I>], moves: &[LinearBone]) -> ([__m512; LANES], __m512) {
    const { assert!(core::mem::size_of::<LinearBone>() == 64) };
    let mut lanes = [_mm512_setzero_ps(); LANES];
    let mut contrib = _mm512_setzero_ps();
    for slot in slots {
        for (l, lane) in lanes.iter_mut().enumerate() {
            // SAFETY: indices are in range (this function's contract); a LinearBone is 16
            // floats (rows, zero padding).
            let record = unsafe { _mm512_loadu_ps(scalar_record(moves, &slot.bones, l)) };
            *lane = _mm512_fmadd_ps(record, _mm512_set1_ps(slot.weights[l]), *lane);
        }
        // SAFETY: a slot has 16 weights.
        contrib = _mm512_add_ps(contrib, unsafe { _mm512_loadu_ps(slot.weights.as_ptr()) });
    }
    (lanes, contrib)
}

/// Float `f` of a block of four lanes' sums (`block_sums`): row `f / 4` of lane `f % 4`. Float
/// `e` of part `part` of sixteen points as stored (`x0 y0 z0 x1 …`) is coordinate `g % 3` of
/// lane `g / 3`, `g = 16·part + e`; it comes from block `g / 12` of four lanes, the first
/// (`part`) or the second (`part + 1`) of the two a part spans.
const fn stored_order(part: usize) -> [i32; 16] {
    let mut idx = [0i32; 16];
    let mut e = 0;
    while e < 16 {
        let g = 16 * part + e;
        let (lane, axis) = (g / 3, g % 3);
        let second = if lane / 4 == part { 0 } else { 16 };
        idx[e] = (second + 4 * axis + lane % 4) as i32;
        e += 1;
    }
    idx
}

/// Lane `g / 3` for float `e` of part `part` of sixteen points as stored (`g = 16·part + e`).
const fn lane_of_float(part: usize) -> [i32; 16] {
    let mut idx = [0i32; 16];
    let mut e = 0;
    while e < 16 {
        idx[e] = ((16 * part + e) / 3) as i32;
        e += 1;
    }
    idx
}

const STORED_ORDER: [[i32; 16]; 3] = [stored_order(0), stored_order(1), stored_order(2)];
const LANE_OF_FLOAT: [[i32; 16]; 3] = [lane_of_float(0), lane_of_float(1), lane_of_float(2)];

/// The sums of each 128-bit block of four lanes' vectors: block `k` of the result holds the four
/// lanes' block-`k` sums, in lane order. Every lane's sum is added in the same order.
#[inline]
#[target_feature(enable = "avx512f")]
fn block_sums(v: [__m512; 4]) -> __m512 {
    let pair = |a, b| _mm512_add_ps(_mm512_unpacklo_ps(a, b), _mm512_unpackhi_ps(a, b));
    let (ab, cd) = (_mm512_castps_pd(pair(v[0], v[1])), _mm512_castps_pd(pair(v[2], v[3])));
    _mm512_add_ps(_mm512_castpd_ps(_mm512_unpacklo_pd(ab, cd)), _mm512_castpd_ps(_mm512_unpackhi_pd(ab, cd)))
}

/// The floats of a row block multiplied by a point's coordinates (not the translation).
const ROW_PRODUCTS: __mmask16 = 0x7777;

/// A lane's summed rows times its point `(x, y, z)` (the four floats at `point`, broadcast to
/// every row block), the fourth float of each row, the translation, kept: a broadcast load and
/// one masked multiply. Written out because the compiler otherwise loads each point, broadcasts
/// it with a shuffle and spills it, and splits the masked multiply into a multiply and a blend.
///
/// # Safety
/// The CPU must support AVX-512F; four floats must be readable at `point`.
#[inline]
#[target_feature(enable = "avx512f")]
unsafe fn moved_point(rows: __m512, point: *const f32) -> __m512 {
    let mut out = rows;
    // SAFETY: the caller's contract; reads 16 bytes at `point`, writes only the two registers.
    unsafe {
        core::arch::asm!(
            "vbroadcastf32x4 {p}, xmmword ptr [{point}]",
            "vmulps {out}{{{k}}}, {out}, {p}",
            point = in(reg) point,
            out = inout(zmm_reg) out,
            p = out(zmm_reg) _,
            k = in(kreg) ROW_PRODUCTS,
            options(pure, readonly, nostack, preserves_flags),
        );
    }
    out
}

/// LBS on one full batch of 16 vertices, in mesh space and in the points' own layout:
/// `co + (a/contrib)·Σ wᵢ·Dᵢ·co` with each bone's move `Dᵢ` (`spaces.rs`), lanes whose factor is
/// 0 (strength 0, too little weight) left bit-identical.
///
/// Each lane applies its summed move to its own point where the lane lies: the point's
/// `(x, y, z)` broadcast to every row block, multiplied into the rows (the fourth float kept: the
/// translation), block sums; so the sums need no transpose into coordinate vectors (the 16-lane
/// transpose was a fifth of the kernel's time on a Zen 4) and the results come out in the order
/// points are stored.
///
/// A batch with a bone window (its weighted bones within sixteen consecutive ones from the
/// window's first) takes `bone_window.rs`'s way where the call has the same moves by component:
/// the same bits, fewer loads.
///
/// # Safety
/// The CPU must support AVX-512F, AVX2 and FMA; every bone index in `slots` must index `moves`;
/// `window`, if any, holds `moves` by component and the batch's bone window.
#[target_feature(enable = "avx512f,avx2,fma")]
pub(in crate::skin) unsafe fn linear_batch<I: BoneIndex>(
    moves: &[LinearBone],
    window: Option<(&MoveColumns, u32)>,
    positions: &[[f32; 3]; LANES],
    out: &mut [[f32; 3]; LANES],
    slots: &[Slot<I>],
    strength: Option<&[f32; LANES]>,
) {
    if let Some((columns, start)) = window {
        // SAFETY: as this function's own contract.
        return unsafe { bone_window::linear_batch(columns, start, positions, out, slots, strength) };
    }
    // SAFETY: as this function's own contract.
    let (lanes, contrib) = unsafe { lane_moves(slots, moves) };
    let points = positions.as_ptr().cast::<f32>();
    let moved: [__m512; LANES] = core::array::from_fn(|l| {
        if l + 1 < LANES {
            // SAFETY: point `l` and the next point's first float are floats 3l..3l + 4 of the 48.
            unsafe { moved_point(lanes[l], points.add(3 * l)) }
        } else {
            // The last point's fourth float would lie past the 48: loaded masked (not read).
            // SAFETY: floats 45..48 of the 48.
            let v = unsafe { _mm512_maskz_loadu_ps(0b111, points.add(3 * l)) };
            _mm512_mask_mul_ps(lanes[l], ROW_PRODUCTS, lanes[l], _mm512_shuffle_f32x4::<0>(v, v))
        }
    });
    let quads: [__m512; 4] =
        core::array::from_fn(|q| block_sums([moved[4 * q], moved[4 * q + 1], moved[4 * q + 2], moved[4 * q + 3]]));
    let a = match strength {
        // SAFETY: the mask has 16 lanes.
        Some(s) => unsafe { _mm512_loadu_ps(s.as_ptr()) },
        None => _mm512_set1_ps(1.0),
    };
    let valid = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(contrib, _mm512_set1_ps(super::super::MIN_TOTAL_WEIGHT));
    let f = _mm512_maskz_div_ps(valid, a, contrib);
    let dst = out.as_mut_ptr().cast::<f32>();
    for part in 0..3 {
        let offset = _mm512_permutex2var_ps(quads[part], idx(&STORED_ORDER[part]), quads[part + 1]);
        let factor = _mm512_permutexvar_ps(idx(&LANE_OF_FLOAT[part]), f);
        // Unordered too: a NaN factor moves its lane, as in the one body.
        let moving = _mm512_cmp_ps_mask::<_CMP_NEQ_UQ>(factor, _mm512_setzero_ps());
        // SAFETY: 16 points are 48 floats, in and out.
        unsafe {
            let co = _mm512_loadu_ps(points.add(16 * part));
            _mm512_storeu_ps(dst.add(16 * part), _mm512_mask3_fmadd_ps(factor, offset, co, moving));
        }
    }
}

/// [`load_columns`] with the indices read as scalars (see [`scalar_record`]).
///
/// # Safety
/// As [`load_columns`].
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn load_columns_scalar<T, I: BoneIndex>(table: &[T], bones: &[I; LANES], offset: usize) -> [__m512; 8] {
    // SAFETY: the caller guarantees the records and the offset are in range.
    let row = |l: usize| unsafe { _mm256_loadu_ps(scalar_record(table, bones, l).add(offset)) };
    transpose(core::array::from_fn(|i| join(row(i), row(i + 8))))
}

/// The end of every batch: `postmat`, the lanes with strength `a = 0` left bit-identical to the
/// originals `o` (no space round trip), store.
///
/// # Safety
/// The CPU must support AVX-512F, AVX2 and FMA.
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn write_batch(
    v: Avx512,
    job: &BatchJob<'_>,
    moved: [__m512; 3],
    a: __m512,
    o: [__m512; 3],
    out: &mut [[f32; 3]; LANES],
) {
    let mut r = match job.postmat {
        Some(m) => apply(v, m, moved),
        None => moved,
    };
    let untouched = _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(a, _mm512_setzero_ps());
    for k in 0..3 {
        r[k] = _mm512_mask_mov_ps(r[k], untouched, o[k]);
    }
    // SAFETY: the CPU has AVX-512F (this function's contract).
    unsafe { store_points(r, out) };
}

/// Everything skinning with centers of rotation does to one full batch of 16 vertices, in
/// registers, for poses without scale: load the points and their centers, `premat` on both, the
/// sums, the rotation of the offset, strength, `postmat`, mask, store. The one body's arithmetic
/// (`batch.rs`: each slot added to [`RigidCenterSums`], then [`centers_rigid`]), with each slot's
/// records loaded in one 8-float transpose.
///
/// # Safety
/// The CPU must support AVX-512F, AVX2 and FMA; every bone index in `slots` must index
/// `cor_rigid`.
#[target_feature(enable = "avx512f,avx2,fma")]
pub(in crate::skin) unsafe fn centers_rigid_batch<I: BoneIndex>(
    job: &BatchJob<'_>,
    positions: &[[f32; 3]; LANES],
    centers: &[[f32; 3]; LANES],
    out: &mut [[f32; 3]; LANES],
    slots: &[Slot<I>],
    strength: Option<&[f32; LANES]>,
) {
    // SAFETY: the CPU has AVX-512F, AVX2 and FMA (this function's contract).
    let v = unsafe { Avx512::new() };
    // SAFETY: 16 points; 16 centers.
    let (o, c) = unsafe { (load_points(positions), load_points(centers)) };
    let (p, c) = match job.premat {
        Some(m) => (apply(v, m, o), apply(v, m, c)),
        None => (o, c),
    };
    let mut sums = RigidCenterSums::new(v);
    for (k, slot) in slots.iter().enumerate() {
        // SAFETY: a slot has 16 weights.
        let w = unsafe { _mm512_loadu_ps(slot.weights.as_ptr()) };
        // SAFETY: indices are in range (validated); a CorRigidBone is 8 floats: the rotation,
        // half the translation and a zero.
        let r = unsafe { load_columns_scalar(job.cor_rigid, &slot.bones, 0) };
        sums.add(v, k == 0, &[r[0], r[1], r[2], r[3]], &[r[4], r[5], r[6], r[7]], w, &c);
    }
    let a = match strength {
        // SAFETY: the mask has 16 lanes.
        Some(s) => unsafe { _mm512_loadu_ps(s.as_ptr()) },
        None => _mm512_set1_ps(1.0),
    };
    let d: [__m512; 3] = core::array::from_fn(|k| _mm512_sub_ps(p[k], c[k]));
    let u = rotation_terms(v, &sums.real, d);
    let moved = centers_rigid(v, sums, u, p, a);
    // SAFETY: as this function's own contract.
    unsafe { write_batch(v, job, moved, a, o, out) }
}

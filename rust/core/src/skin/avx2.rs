//! The batch kernels' vector operations for AVX2+FMA: eight lanes per vector, so a 16-vertex
//! batch runs as two parts.
//!
//! The rotations the sign pass needs are loaded as rows and transposed with shuffles (much
//! cheaper than gathering each component); each row pairs lanes `l` and `l + 4`, assembled from
//! two 128-bit loads by `vinsertf128`, so that the transpose needs only in-lane shuffles. The
//! linear sums accumulate each lane's record rows with its weight broadcast (a load), four lanes
//! at a time, and are transposed once per vertex. LBS has a hand-written kernel instead
//! ([`kept`]), which transposes nothing, and so has DQS with rigid bones ([`rigid_dqs`]), which
//! runs the sign chains of a batch's two parts side by side.

use core::arch::x86_64::*;

use super::batch::{assert_row_pairs, VectorOps};
use super::influences::{lane_record, BoneIndex, Slot, LANES};

mod kept;
mod rigid_dqs;

pub(super) use kept::linear_batch;
pub(super) use rigid_dqs::dual_quaternion_batch;

/// Proof that the CPU has AVX2 and FMA.
#[derive(Clone, Copy)]
pub(super) struct Avx2 {
    _detected: (),
}

impl Avx2 {
    /// # Safety
    /// The CPU must support AVX2 and FMA.
    #[inline(always)]
    pub(super) unsafe fn new() -> Self {
        Avx2 { _detected: () }
    }
}

/// Methods that are one AVX instruction each.
macro_rules! instructions {
    ($($name:ident($($arg:ident),*) -> $out:ty = $intrinsic:ident;)*) => {$(
        #[inline(always)]
        fn $name(self, $($arg: __m256),*) -> $out {
            // SAFETY: an `Avx2` exists only where AVX2 and FMA were detected.
            unsafe { $intrinsic($($arg),*) }
        }
    )*};
}

/// The 4×4 transposes within each 128-bit half: rows `r` (floats 0–3 of lane `l` low, of lane
/// `l + 4` high) to columns.
#[inline(always)]
fn transpose_halves(_: Avx2, r: [__m256; 4]) -> [__m256; 4] {
    // SAFETY: as in `instructions!`.
    unsafe {
        let t0 = _mm256_unpacklo_ps(r[0], r[1]);
        let t1 = _mm256_unpackhi_ps(r[0], r[1]);
        let t2 = _mm256_unpacklo_ps(r[2], r[3]);
        let t3 = _mm256_unpackhi_ps(r[2], r[3]);
        [
            _mm256_shuffle_ps::<0x44>(t0, t2),
            _mm256_shuffle_ps::<0xEE>(t0, t2),
            _mm256_shuffle_ps::<0x44>(t1, t3),
            _mm256_shuffle_ps::<0xEE>(t1, t3),
        ]
    }
}

impl VectorOps for Avx2 {
    const WIDTH: usize = 8;
    type F = __m256;
    type Mask = __m256;

    instructions! {
        add(a, b) -> __m256 = _mm256_add_ps;
        sub(a, b) -> __m256 = _mm256_sub_ps;
        mul(a, b) -> __m256 = _mm256_mul_ps;
        div(a, b) -> __m256 = _mm256_div_ps;
        mul_add(a, b, c) -> __m256 = _mm256_fmadd_ps;
        neg_mul_add(a, b, c) -> __m256 = _mm256_fnmadd_ps;
        mul_sub(a, b, c) -> __m256 = _mm256_fmsub_ps;
        and(a, b) -> __m256 = _mm256_and_ps;
    }

    #[inline(always)]
    fn splat(self, x: f32) -> __m256 {
        // SAFETY: as in `instructions!`.
        unsafe { _mm256_set1_ps(x) }
    }

    #[inline(always)]
    fn load(self, a: &[f32]) -> __m256 {
        assert!(a.len() >= 8);
        // SAFETY: eight floats (checked); AVX as in `instructions!`.
        unsafe { _mm256_loadu_ps(a.as_ptr()) }
    }

    #[inline(always)]
    fn store(self, v: __m256, a: &mut [f32]) {
        assert!(a.len() >= 8);
        // SAFETY: eight floats (checked); AVX as in `instructions!`.
        unsafe { _mm256_storeu_ps(a.as_mut_ptr(), v) }
    }

    #[inline(always)]
    fn neg_where(self, m: __m256, a: __m256) -> __m256 {
        // SAFETY: as in `instructions!`.
        unsafe { _mm256_xor_ps(a, _mm256_and_ps(m, _mm256_set1_ps(-0.0))) }
    }

    #[inline(always)]
    fn lt(self, a: __m256, b: __m256) -> __m256 {
        // SAFETY: as in `instructions!`.
        unsafe { _mm256_cmp_ps::<_CMP_LT_OQ>(a, b) }
    }

    #[inline(always)]
    fn gt(self, a: __m256, b: __m256) -> __m256 {
        // SAFETY: as in `instructions!`.
        unsafe { _mm256_cmp_ps::<_CMP_GT_OQ>(a, b) }
    }

    #[inline(always)]
    fn eq(self, a: __m256, b: __m256) -> __m256 {
        // SAFETY: as in `instructions!`.
        unsafe { _mm256_cmp_ps::<_CMP_EQ_OQ>(a, b) }
    }

    #[inline(always)]
    fn select(self, m: __m256, a: __m256, b: __m256) -> __m256 {
        // SAFETY: as in `instructions!`.
        unsafe { _mm256_blendv_ps(b, a, m) }
    }

    #[inline(always)]
    unsafe fn load_columns4<T, I: BoneIndex>(self, table: &[T], bones: &[I], offset: usize) -> [__m256; 4] {
        debug_assert!(bones.len() >= 8 && offset + 4 <= core::mem::size_of::<T>() / 4);
        // The four floats of the records of lanes `l` (low half) and `l + 4` (high half).
        let pair = |l: usize| {
            // SAFETY: the caller guarantees the records and the offset are in range; AVX as in
            // `instructions!`.
            unsafe {
                let (lo, hi) = (lane_record(table, bones[l]).add(offset), lane_record(table, bones[l + 4]).add(offset));
                _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(_mm_loadu_ps(lo)), _mm_loadu_ps(hi))
            }
        };
        transpose_halves(self, [pair(0), pair(1), pair(2), pair(3)])
    }

    #[inline(always)]
    fn load_points(self, points: &[[f32; 3]]) -> [__m256; 3] {
        assert!(points.len() >= 8);
        let f = points.as_ptr() as *const f32;
        // SAFETY: eight points are 24 floats (checked); AVX as in `instructions!`.
        unsafe {
            let half = |lo: usize| {
                _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(_mm_loadu_ps(f.add(lo))), _mm_loadu_ps(f.add(lo + 12)))
            };
            // Each 128-bit half now holds four points: x0 y0 z0 x1 | y1 z1 x2 y2 | z2 x3 y3 z3.
            let (a, b, c) = (half(0), half(4), half(8));
            let xy = _mm256_shuffle_ps::<0x9E>(b, c); // x2 y2 x3 y3
            let yz = _mm256_shuffle_ps::<0x49>(a, b); // y0 z0 y1 z1
            [
                _mm256_shuffle_ps::<0x8C>(a, xy),  // x0 x1 x2 x3
                _mm256_shuffle_ps::<0xD8>(yz, xy), // y0 y1 y2 y3
                _mm256_shuffle_ps::<0xCD>(yz, c),  // z0 z1 z2 z3
            ]
        }
    }

    #[inline(always)]
    fn store_points(self, [x, y, z]: [__m256; 3], out: &mut [[f32; 3]]) {
        assert!(out.len() >= 8);
        let f = out.as_mut_ptr() as *mut f32;
        // SAFETY: eight points are 24 floats (checked); AVX as in `instructions!`.
        unsafe {
            let xy = _mm256_shuffle_ps::<0x88>(x, y); // x0 x2 y0 y2
            let yz = _mm256_shuffle_ps::<0xDD>(y, z); // y1 y3 z1 z3
            let zx = _mm256_shuffle_ps::<0xD8>(z, x); // z0 z2 x1 x3
            let a = _mm256_shuffle_ps::<0x88>(xy, zx); // x0 y0 z0 x1
            let b = _mm256_shuffle_ps::<0xD8>(yz, xy); // y1 z1 x2 y2
            let c = _mm256_shuffle_ps::<0xDD>(zx, yz); // z2 x3 y3 z3
            _mm256_storeu_ps(f, _mm256_permute2f128_ps::<0x20>(a, b));
            _mm256_storeu_ps(f.add(8), _mm256_permute2f128_ps::<0x30>(c, a));
            _mm256_storeu_ps(f.add(16), _mm256_permute2f128_ps::<0x31>(b, c));
        }
    }

    /// Accumulated per lane, lanes `l` and `l + 4` together (rows in pairs, one register each;
    /// all four lane pairs at once for two rows, two for three, one for four or more: at most
    /// eight accumulators), each finished lane pair combined into its rows, and transposed at
    /// the end, which needs per influence only loads (the bone index, the weight broadcast, the
    /// rows) and FMAs.
    #[inline(always)]
    unsafe fn window_sums<T, I: BoneIndex, const ROWS: usize>(
        self,
        slots: &[Slot<I>],
        signed: Option<&[[f32; LANES]]>,
        lane0: usize,
        table: &[T],
        offsets: [usize; ROWS],
    ) -> [[__m256; 4]; ROWS] {
        const { assert!(ROWS <= 8) };
        assert_row_pairs::<T, ROWS>(&offsets);
        debug_assert!(signed.is_none_or(|s| s.len() == slots.len()));
        // Lanes `l` and `l + 4` share the registers of a row after the sums, so the lanes are
        // summed in pairs (l, l + 4), as many pairs at a time as eight accumulators hold, and
        // each finished pair goes straight to its rows: the accumulators of only one group
        // are live at a time.
        let per_lane = ROWS.div_ceil(2);
        // Four rows: the sixteen row registers kept, so one lane pair at a time (two spilled
        // and ran slower, measured).
        let pairs_per_group = if ROWS == 4 { 1 } else { 4 / per_lane.min(4) };
        // SAFETY: AVX as in `instructions!`; the loads as below.
        unsafe {
            // rows[r][l]: row r of lane l (low half) and of lane l + 4 (high half).
            let mut rows = [[_mm256_setzero_ps(); 4]; ROWS];
            for g in 0..4 / pairs_per_group {
                let first = g * pairs_per_group;
                // [lane pair][half][register j]: rows 2j (low half) and 2j + 1 (high half) of lane
                // first + pair (half 0) or first + pair + 4 (half 1).
                let mut acc = [[[_mm256_setzero_ps(); 4]; 2]; 4];
                for (s, slot) in slots.iter().enumerate() {
                    let weights = signed.map_or(&slot.weights, |w| &w[s]);
                    for (k, pair) in acc.iter_mut().enumerate().take(pairs_per_group) {
                        for (half, regs) in pair.iter_mut().enumerate() {
                            let lane = lane0 + first + k + 4 * half;
                            // SAFETY: the caller's contract: the lane's bone indexes `table`; the
                            // pairs of rows lie inside its record (asserted above).
                            let record = lane_record(table, slot.bones[lane]);
                            let w = _mm256_broadcast_ss(&weights[lane]);
                            for (j, reg) in regs.iter_mut().enumerate().take(per_lane) {
                                *reg = _mm256_fmadd_ps(_mm256_loadu_ps(record.add(offsets[2 * j])), w, *reg);
                            }
                        }
                    }
                }
                for (k, pair) in acc.iter().enumerate().take(pairs_per_group) {
                    for (r, row) in rows.iter_mut().enumerate() {
                        let (a, b) = (pair[0][r / 2], pair[1][r / 2]);
                        row[first + k] = if r % 2 == 1 {
                            _mm256_permute2f128_ps::<0x31>(a, b)
                        } else {
                            _mm256_permute2f128_ps::<0x20>(a, b)
                        };
                    }
                }
            }
            // The in-half transposes: row r of lanes l and l + 4 to its four components.
            let mut sums = [[_mm256_setzero_ps(); 4]; ROWS];
            for (sum, row) in sums.iter_mut().zip(rows) {
                *sum = transpose_halves(self, row);
            }
            sums
        }
    }
}

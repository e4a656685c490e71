//! The AVX-512 copy of the kernels: the one arithmetic body of `batch.rs` (the AVX2 and NEON
//! copies' too) with sixteen lanes per vector, a batch in one part ([`Avx512`]), and two
//! hand-written kernels kept where they measured faster than it ([`kept`]: LBS, and centers of
//! rotation for poses without scale; docs/performance.md has the figures and the CPUs).
//!
//! Records are loaded as rows and transposed with shuffles rather than gathered; each lane's
//! bone index is read as a scalar right where its record is loaded ([`scalar_record`]).

use core::arch::x86_64::*;

use super::batch::{assert_row_pairs, VectorOps};
use super::influences::{lane_record, BoneIndex, Slot, LANES};

mod bone_window;
mod kept;

pub(super) use bone_window::MoveColumns;
pub(super) use kept::{centers_rigid_batch, linear_batch};

const _: () = assert!(LANES == 16);

/// `[a | b]` from two 256-bit halves.
#[inline]
#[target_feature(enable = "avx512f")]
fn join(a: __m256, b: __m256) -> __m512 {
    _mm512_castpd_ps(_mm512_insertf64x4::<1>(_mm512_castps_pd(_mm512_castps256_ps512(a)), _mm256_castps_pd(b)))
}

/// The 4×4 transposes within each 128-bit block of four rows: block `b` of output `e` holds
/// float `e` of block `b` of rows 0–3.
#[inline]
#[target_feature(enable = "avx512f")]
fn transpose_blocks(r: [__m512; 4]) -> [__m512; 4] {
    let t0 = _mm512_unpacklo_ps(r[0], r[1]);
    let t1 = _mm512_unpackhi_ps(r[0], r[1]);
    let t2 = _mm512_unpacklo_ps(r[2], r[3]);
    let t3 = _mm512_unpackhi_ps(r[2], r[3]);
    [
        _mm512_shuffle_ps::<0x44>(t0, t2),
        _mm512_shuffle_ps::<0xEE>(t0, t2),
        _mm512_shuffle_ps::<0x44>(t1, t3),
        _mm512_shuffle_ps::<0xEE>(t1, t3),
    ]
}

/// Index vectors that gather every third float of 48 (`a` = floats 0–15, `b` = 16–31,
/// `c` = 32–47): first from `a` and `b`, then the rest from `c`.
const fn deinterleave_indices(axis: i32) -> ([i32; 16], [i32; 16]) {
    let mut first = [0i32; 16];
    let mut second = [0i32; 16];
    let mut l = 0;
    while l < 16 {
        let f = 3 * l as i32 + axis; // position among the 48 floats
        first[l] = if f < 32 { f } else { 0 };
        second[l] = if f < 32 { l as i32 } else { f - 32 + 16 };
        l += 1;
    }
    (first, second)
}

const DEINTERLEAVE: [([i32; 16], [i32; 16]); 3] =
    [deinterleave_indices(0), deinterleave_indices(1), deinterleave_indices(2)];

/// Index vectors that put lane values back as `x0 y0 z0 x1 …`: float `f` of the output comes
/// from lane `f / 3` of axis `f % 3`; three 16-float outputs from three 16-lane axis vectors.
const fn interleave_indices(part: usize) -> ([i32; 16], [i32; 16]) {
    // Step 1 picks from (x, y); step 2 from (step1, z).
    let mut first = [0i32; 16];
    let mut second = [0i32; 16];
    let mut k = 0;
    while k < 16 {
        let f = part * 16 + k;
        let lane = (f / 3) as i32;
        let axis = f % 3;
        first[k] = if axis == 0 {
            lane
        } else if axis == 1 {
            lane + 16
        } else {
            0
        };
        second[k] = if axis == 2 { lane + 16 } else { k as i32 };
        k += 1;
    }
    (first, second)
}

const INTERLEAVE: [([i32; 16], [i32; 16]); 3] = [interleave_indices(0), interleave_indices(1), interleave_indices(2)];

#[inline]
#[target_feature(enable = "avx512f")]
fn idx(v: &[i32; 16]) -> __m512i {
    // SAFETY: 16 i32 are 64 bytes.
    unsafe { _mm512_loadu_si512(v.as_ptr() as *const __m512i) }
}

/// Splits 16 points `x y z x y z …` into coordinate vectors.
///
/// # Safety
/// The CPU must support AVX-512F.
#[inline]
#[target_feature(enable = "avx512f")]
unsafe fn load_points(points: &[[f32; 3]; LANES]) -> [__m512; 3] {
    let p = points.as_ptr() as *const f32;
    // SAFETY: 16 points are 48 floats.
    let (a, b, c) = unsafe { (_mm512_loadu_ps(p), _mm512_loadu_ps(p.add(16)), _mm512_loadu_ps(p.add(32))) };
    core::array::from_fn(|axis| {
        let (first, second) = &DEINTERLEAVE[axis];
        _mm512_permutex2var_ps(_mm512_permutex2var_ps(a, idx(first), b), idx(second), c)
    })
}

/// Writes coordinate vectors back as 16 points `x y z x y z …`.
///
/// # Safety
/// The CPU must support AVX-512F.
#[inline]
#[target_feature(enable = "avx512f")]
unsafe fn store_points([x, y, z]: [__m512; 3], out: &mut [[f32; 3]; LANES]) {
    let dst = out.as_mut_ptr() as *mut f32;
    for (part, (first, second)) in INTERLEAVE.iter().enumerate() {
        let xy = _mm512_permutex2var_ps(x, idx(first), y);
        // SAFETY: 16 points are 48 floats.
        unsafe { _mm512_storeu_ps(dst.add(16 * part), _mm512_permutex2var_ps(xy, idx(second), z)) };
    }
}

/// Lane `l`'s bone record in `table`. The slot entry is read as a scalar (a volatile read keeps
/// the compiler from loading all sixteen as a vector and extracting each lane, two shuffles a
/// lane on the vector ports the transposes need) right where the record is loaded, so that no
/// entry waits in a register (or a spill slot) for its turn.
///
/// # Safety
/// `bones[l]` must name a record of `table` (see [`lane_record`]).
#[inline(always)]
unsafe fn scalar_record<T, I: BoneIndex>(table: &[T], bones: &[I; LANES], l: usize) -> *const f32 {
    // SAFETY: a valid reference to an initialized integer.
    let r = unsafe { core::ptr::read_volatile(&bones[l]) };
    // SAFETY: the caller's contract.
    unsafe { lane_record(table, r) }
}

/// Proof that the CPU has AVX-512F, AVX2 and FMA: the batch kernels of `batch.rs` (the one
/// arithmetic body of the AVX2 and NEON copies) with sixteen lanes per vector, a batch in one part.
#[derive(Clone, Copy)]
pub(super) struct Avx512 {
    _detected: (),
}

impl Avx512 {
    /// # Safety
    /// The CPU must support AVX-512F, AVX2 and FMA.
    #[inline(always)]
    pub(super) unsafe fn new() -> Self {
        Avx512 { _detected: () }
    }
}

/// Methods that are one AVX-512 instruction each.
macro_rules! instructions512 {
    ($($name:ident($($arg:ident),*) = $intrinsic:ident;)*) => {$(
        #[inline(always)]
        fn $name(self, $($arg: __m512),*) -> __m512 {
            // SAFETY: an `Avx512` exists only where AVX-512F, AVX2 and FMA were detected.
            unsafe { $intrinsic($($arg),*) }
        }
    )*};
}

impl VectorOps for Avx512 {
    const WIDTH: usize = 16;
    type F = __m512;
    type Mask = __mmask16;

    instructions512! {
        add(a, b) = _mm512_add_ps;
        sub(a, b) = _mm512_sub_ps;
        mul(a, b) = _mm512_mul_ps;
        div(a, b) = _mm512_div_ps;
        mul_add(a, b, c) = _mm512_fmadd_ps;
        neg_mul_add(a, b, c) = _mm512_fnmadd_ps;
        mul_sub(a, b, c) = _mm512_fmsub_ps;
    }

    #[inline(always)]
    fn splat(self, x: f32) -> __m512 {
        // SAFETY: as in `instructions512!`.
        unsafe { _mm512_set1_ps(x) }
    }

    #[inline(always)]
    fn load(self, a: &[f32]) -> __m512 {
        assert!(a.len() >= 16);
        // SAFETY: sixteen floats (checked); AVX-512F as in `instructions512!`.
        unsafe { _mm512_loadu_ps(a.as_ptr()) }
    }

    #[inline(always)]
    fn store(self, v: __m512, a: &mut [f32]) {
        assert!(a.len() >= 16);
        // SAFETY: sixteen floats (checked); AVX-512F as in `instructions512!`.
        unsafe { _mm512_storeu_ps(a.as_mut_ptr(), v) }
    }

    #[inline(always)]
    fn lt(self, a: __m512, b: __m512) -> __mmask16 {
        // SAFETY: as in `instructions512!`.
        unsafe { _mm512_cmp_ps_mask::<_CMP_LT_OQ>(a, b) }
    }

    #[inline(always)]
    fn gt(self, a: __m512, b: __m512) -> __mmask16 {
        // SAFETY: as in `instructions512!`.
        unsafe { _mm512_cmp_ps_mask::<_CMP_GT_OQ>(a, b) }
    }

    #[inline(always)]
    fn eq(self, a: __m512, b: __m512) -> __mmask16 {
        // SAFETY: as in `instructions512!`.
        unsafe { _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(a, b) }
    }

    #[inline(always)]
    fn and(self, a: __mmask16, b: __mmask16) -> __mmask16 {
        a & b
    }

    #[inline(always)]
    fn select(self, m: __mmask16, a: __m512, b: __m512) -> __m512 {
        // SAFETY: as in `instructions512!`.
        unsafe { _mm512_mask_blend_ps(m, b, a) }
    }

    #[inline(always)]
    fn neg_where(self, m: __mmask16, a: __m512) -> __m512 {
        // The sign bit flipped, as the other copies do (−0.0 for 0.0, bit for bit).
        // SAFETY: as in `instructions512!`.
        unsafe {
            let bits = _mm512_castps_si512(a);
            _mm512_castsi512_ps(_mm512_mask_xor_epi32(bits, m, bits, _mm512_set1_epi32(i32::MIN)))
        }
    }

    #[inline(always)]
    unsafe fn load_columns4<T, I: BoneIndex>(self, table: &[T], bones: &[I], offset: usize) -> [__m512; 4] {
        debug_assert!(bones.len() >= 16 && offset + 4 <= core::mem::size_of::<T>() / 4);
        // SAFETY: the caller's contract; AVX-512F as in `instructions512!`.
        unsafe { columns4(table, bones, offset) }
    }

    #[inline(always)]
    fn load_points(self, points: &[[f32; 3]]) -> [__m512; 3] {
        let points: &[[f32; 3]; LANES] = points[..LANES].try_into().expect("sixteen points");
        // SAFETY: AVX-512F as in `instructions512!`.
        unsafe { load_points(points) }
    }

    #[inline(always)]
    fn store_points(self, p: [__m512; 3], out: &mut [[f32; 3]]) {
        let out: &mut [[f32; 3]; LANES] = (&mut out[..LANES]).try_into().expect("sixteen points");
        // SAFETY: AVX-512F as in `instructions512!`.
        unsafe { store_points(p, out) }
    }

    /// Accumulated per lane, as the hand-written LBS sums are: up to four rows of a lane's
    /// record in one register (one load, or two where the pairs of rows are apart), times its
    /// weight broadcast (a load), one FMA per influence and lane for four rows; the sixteen
    /// lanes' registers are transposed once per batch.
    #[inline(always)]
    unsafe fn window_sums<T, I: BoneIndex, const ROWS: usize>(
        self,
        slots: &[Slot<I>],
        signed: Option<&[[f32; LANES]]>,
        lane0: usize,
        table: &[T],
        offsets: [usize; ROWS],
    ) -> [[__m512; 4]; ROWS] {
        const { assert!(ROWS <= 8) };
        debug_assert_eq!(lane0, 0, "one part per batch");
        assert_row_pairs::<T, ROWS>(&offsets);
        debug_assert!(signed.is_none_or(|s| s.len() == slots.len()));
        let mut sums = [[_mm512_setzero_ps(); 4]; ROWS];
        for g in 0..ROWS.div_ceil(4) {
            let first = offsets[4 * g];
            // The group's second pair of rows, if it has one: right after the first (one load)
            // or elsewhere in the record.
            let second = (4 * g + 2 < ROWS).then(|| offsets[4 * g + 2]);
            // SAFETY: the caller's contract, and the pairs of rows inside the record (asserted).
            let columns = unsafe { lane_sums(slots, signed, table, first, second) };
            for r in 4 * g..ROWS.min(4 * g + 4) {
                let at = 4 * (r - 4 * g);
                sums[r] = [columns[at], columns[at + 1], columns[at + 2], columns[at + 3]];
            }
        }
        sums
    }
}

/// [`Avx512::window_sums`] for one group of up to four rows: floats `first .. first + 8` and
/// (if given) `second .. second + 8` of each lane's record, summed with its weights (`signed`
/// if given, else the slots' own), as sixteen 16-lane component vectors (the floats in that
/// order; those of a missing second pair are zero).
///
/// # Safety
/// Every bone index of `slots` indexes `table`; both eight-float spans lie inside its records.
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn lane_sums<T, I: BoneIndex>(
    slots: &[Slot<I>],
    signed: Option<&[[f32; LANES]]>,
    table: &[T],
    first: usize,
    second: Option<usize>,
) -> [__m512; 16] {
    let mut lanes = [_mm512_setzero_ps(); LANES];
    for (s, slot) in slots.iter().enumerate() {
        let weights = signed.map_or(&slot.weights, |w| &w[s]);
        for (l, lane) in lanes.iter_mut().enumerate() {
            // SAFETY: the caller's contract.
            let rows = unsafe {
                let record = scalar_record(table, &slot.bones, l);
                match second {
                    Some(second) if second == first + 8 => _mm512_loadu_ps(record.add(first)),
                    Some(second) => join(_mm256_loadu_ps(record.add(first)), _mm256_loadu_ps(record.add(second))),
                    None => _mm512_zextps256_ps512(_mm256_loadu_ps(record.add(first))),
                }
            };
            *lane = _mm512_fmadd_ps(rows, _mm512_set1_ps(weights[l]), *lane);
        }
    }
    transpose_lanes(&lanes)
}

/// Sixteen lane vectors as sixteen 16-lane component vectors (a 16×16 transpose): the in-block
/// 4×4 transposes of each group of four lanes, then the 128-bit blocks gathered across them.
#[inline]
#[target_feature(enable = "avx512f")]
fn transpose_lanes(r: &[__m512; LANES]) -> [__m512; 16] {
    let mut u = [[_mm512_setzero_ps(); 4]; 4];
    for (g, group) in u.iter_mut().enumerate() {
        *group = transpose_blocks([r[4 * g], r[4 * g + 1], r[4 * g + 2], r[4 * g + 3]]);
    }
    let mut out = [_mm512_setzero_ps(); 16];
    for e in 0..4 {
        let lo01 = _mm512_shuffle_f32x4::<0x44>(u[0][e], u[1][e]);
        let hi01 = _mm512_shuffle_f32x4::<0xEE>(u[0][e], u[1][e]);
        let lo23 = _mm512_shuffle_f32x4::<0x44>(u[2][e], u[3][e]);
        let hi23 = _mm512_shuffle_f32x4::<0xEE>(u[2][e], u[3][e]);
        out[e] = _mm512_shuffle_f32x4::<0x88>(lo01, lo23);
        out[4 + e] = _mm512_shuffle_f32x4::<0xDD>(lo01, lo23);
        out[8 + e] = _mm512_shuffle_f32x4::<0x88>(hi01, hi23);
        out[12 + e] = _mm512_shuffle_f32x4::<0xDD>(hi01, hi23);
    }
    out
}

/// [`Avx512::load_columns4`]'s body: a function of its own, not a closure, so that the
/// intrinsics inline (a closure does not have the instruction sets of the function around it).
/// Row `k` holds the four floats of lanes `k`, `k + 4`, `k + 8` and `k + 12` (one per 128-bit
/// block), so that the in-block transposes leave the lanes in order.
///
/// # Safety
/// `bones` has sixteen entries, each indexing `table`; `offset + 4` floats lie inside
/// a record.
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn columns4<T, I: BoneIndex>(table: &[T], bones: &[I], offset: usize) -> [__m512; 4] {
    let bones: &[I; LANES] = bones[..LANES].try_into().expect("sixteen lanes");
    let mut rows = [_mm512_setzero_ps(); 4];
    for (k, row) in rows.iter_mut().enumerate() {
        // SAFETY: the caller's contract.
        unsafe {
            let at = |l: usize| scalar_record(table, bones, l).add(offset);
            let v = _mm512_castps128_ps512(_mm_loadu_ps(at(k)));
            let v = _mm512_insertf32x4::<1>(v, _mm_loadu_ps(at(k + 4)));
            let v = _mm512_insertf32x4::<2>(v, _mm_loadu_ps(at(k + 8)));
            *row = _mm512_insertf32x4::<3>(v, _mm_loadu_ps(at(k + 12)));
        }
    }
    transpose_blocks(rows)
}

//! LBS for a batch whose bones lie within sixteen consecutive indices: each lane's record is not
//! loaded whole per influence (`kept.rs`) but picked component by component from the window's
//! sixteen records, one `vpermps` a component, out of the call's moves stored by component
//! ([`MoveColumns`]). Each lane adds the same products in the same order as `kept.rs`'s LBS and
//! applies its sum with the same operations, so both give the same bits; the batches whose bones
//! spread wider take `kept.rs`'s way. Each batch's window is found once and kept with its
//! influences (`influences/bone_windows.rs`): found per call, its reduction across lanes held
//! every batch's loads back. On a Zen 4 the picks and the multiply-adds issue on overlapping pipes and
//! no lane's sums need gathering into coordinates at the end (docs/performance.md has the
//! figures).

use core::arch::x86_64::*;

use super::super::influences::{BoneIndex, Slot, LANES};
use super::super::pose::LinearBone;
use super::{load_points, store_points};

/// The floats of a move the sums use: three rows of four.
const COMPONENTS: usize = 12;

/// One call's bone moves (`spaces.rs`) by component: component `e` of bone `b` at
/// `e·stride + b`, each component's array followed by [`LANES`] zeros so that sixteen floats from
/// any bone are in bounds.
pub(in crate::skin) struct MoveColumns {
    floats: Vec<f32>,
    stride: usize,
}

impl MoveColumns {
    /// The moves by component, or `None` if one is not finite: a lane whose weight is zero may
    /// pick another bone of the window than its own (bone 0, for a vertex with fewer influences
    /// than its batch's), and zero times a finite component leaves a sum as zero times its own
    /// does (but for the sign of a zero sum, after a product smaller than any float).
    pub(in crate::skin) fn new(moves: &[LinearBone]) -> Option<Self> {
        let stride = moves.len() + LANES;
        let mut floats = vec![0.0f32; COMPONENTS * stride];
        let mut finite = true;
        // Bone by bone, each record's twelve floats to their columns (3.5 us for 720 bones on a
        // Zen 4, where column by column took 5.5).
        for (b, m) in moves.iter().enumerate() {
            for (e, x) in m.matrix.rows.iter().flat_map(|row| row.to_array()).enumerate() {
                floats[e * stride + b] = x;
                finite &= x.is_finite();
            }
        }
        finite.then_some(MoveColumns { floats, stride })
    }
}

/// A slot's sixteen bone indices as 32-bit lanes.
///
/// # Safety
/// The CPU must support AVX-512F.
#[inline]
#[target_feature(enable = "avx512f,avx2")]
unsafe fn bone_lanes<I: BoneIndex>(slot: &Slot<I>) -> __m512i {
    let p = slot.bones.as_ptr();
    // SAFETY: a slot has sixteen indices of one or two bytes.
    unsafe {
        if core::mem::size_of::<I>() == 1 {
            _mm512_cvtepu8_epi32(_mm_loadu_si128(p.cast()))
        } else {
            _mm512_cvtepu16_epi32(_mm256_loadu_si256(p.cast()))
        }
    }
}

/// LBS on one full batch of 16 vertices whose weighted bones are among bones
/// `start..start + 16` (the batch's bone window, `influences/bone_windows.rs`):
/// `co + (a/contrib)·Σ wᵢ·Dᵢ·co`, as `kept::linear_batch` computes it.
///
/// # Safety
/// The CPU must support AVX-512F, AVX2 and FMA; `start` and every bone index in `slots` must be
/// below the number of moves `columns` was made from, and every weighted one within the window.
#[target_feature(enable = "avx512f,avx2,fma")]
pub(in crate::skin) unsafe fn linear_batch(
    columns: &MoveColumns,
    start: u32,
    positions: &[[f32; 3]; LANES],
    out: &mut [[f32; 3]; LANES],
    slots: &[Slot<impl BoneIndex>],
    strength: Option<&[f32; LANES]>,
) {
    let first = start as usize;
    // The window's sixteen records, one vector a component; `first` is a bone, so the sixteen
    // floats from it lie within the component's array and its padding.
    let table: [__m512; COMPONENTS] = core::array::from_fn(|e| {
        debug_assert!(first + LANES <= columns.stride);
        // SAFETY: as above: e·stride + first + 16 ≤ 12·stride floats.
        unsafe { _mm512_loadu_ps(columns.floats.as_ptr().add(e * columns.stride + first)) }
    });
    let at_start = _mm512_set1_epi32(start as i32);
    let mut sums = [_mm512_setzero_ps(); COMPONENTS];
    let mut contrib = _mm512_setzero_ps();
    for slot in slots {
        // SAFETY: the CPU has AVX-512F; a slot has 16 weights.
        let (bones, w) = unsafe { (bone_lanes(slot), _mm512_loadu_ps(slot.weights.as_ptr())) };
        // A weightless lane may pick any of the window's records (its product adds nothing):
        // only the index's low four bits pick.
        let at = _mm512_sub_epi32(bones, at_start);
        for (sum, component) in sums.iter_mut().zip(&table) {
            *sum = _mm512_fmadd_ps(w, _mm512_permutexvar_ps(at, *component), *sum);
        }
        contrib = _mm512_add_ps(contrib, w);
    }
    // SAFETY: 16 points.
    let co = unsafe { load_points(positions) };
    let [x, y, z] = co;
    // Each row times the point as `kept.rs` sums it: (m0·x + m2·z) + (m1·y + t).
    let offset: [__m512; 3] = core::array::from_fn(|r| {
        let s = &sums[4 * r..4 * r + 4];
        _mm512_add_ps(
            _mm512_add_ps(_mm512_mul_ps(s[0], x), _mm512_mul_ps(s[2], z)),
            _mm512_add_ps(_mm512_mul_ps(s[1], y), s[3]),
        )
    });
    let a = match strength {
        // SAFETY: the mask has 16 lanes.
        Some(s) => unsafe { _mm512_loadu_ps(s.as_ptr()) },
        None => _mm512_set1_ps(1.0),
    };
    let valid = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(contrib, _mm512_set1_ps(super::super::MIN_TOTAL_WEIGHT));
    let f = _mm512_maskz_div_ps(valid, a, contrib);
    // Unordered too: a NaN factor moves its lane, as in the one body.
    let moving = _mm512_cmp_ps_mask::<_CMP_NEQ_UQ>(f, _mm512_setzero_ps());
    let moved = core::array::from_fn(|k| _mm512_mask3_fmadd_ps(f, offset[k], co[k], moving));
    // SAFETY: 16 points.
    unsafe { store_points(moved, out) };
}

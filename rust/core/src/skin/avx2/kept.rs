//! The hand-written AVX2 LBS, kept where it measured faster than the one body of `batch.rs`
//! (docs/performance.md): each lane sums its bones' moves by column ([`ColumnMove`], two vectors
//! a lane) and applies the sum to its own point where the lane lies, so neither the sums nor the
//! points are transposed into coordinate vectors (on a Zen 3 those transposes' shuffles, a third
//! of them one-a-cycle lane crossings, cost as much as the finish itself). It computes what the
//! one body computes, operation for operation, so that the copies give the same bits (the tests
//! check it): only the loads and shuffles differ.

use core::arch::x86_64::*;

use super::super::batch::total_weight;
use super::super::influences::{lane_record, BoneIndex, Slot, LANES};
use super::super::pose::ColumnMove;
use super::super::MIN_TOTAL_WEIGHT;
use super::Avx2;

/// Lanes summed at a time: two accumulators a lane, eight of AVX2's sixteen registers.
const GROUP: usize = 4;

/// LBS on one full batch of 16 vertices, in mesh space: `co + (a/contrib)·Σ wᵢ·Dᵢ·co` with each
/// bone's move `Dᵢ` by column (`spaces.rs`), lanes whose factor is 0 (strength 0, too little
/// weight) left bit-identical.
///
/// A lane's sum is two vectors, the columns `[c₀ | c₁]` and `[c₂ | c₃]`; times `[x | y]` and
/// `[z | 1]` and added they give `[c₀·x + c₂·z | c₁·y + c₃]`, whose halves add to the move of
/// the point: the one body's `(d₀·x + d₂·z) + (d₁·y + d₃)` for the three rows at once.
///
/// # Safety
/// The CPU must support AVX2 and FMA; every bone index in `slots` must index `moves`.
#[target_feature(enable = "avx2,fma")]
pub(in crate::skin) unsafe fn linear_batch<I: BoneIndex>(
    moves: &[ColumnMove],
    positions: &[[f32; 3]; LANES],
    out: &mut [[f32; 3]; LANES],
    slots: &[Slot<I>],
    strength: Option<&[f32; LANES]>,
) {
    const { assert!(core::mem::size_of::<ColumnMove>() == 64 && LANES == 4 * GROUP) };
    let (factor, mut still) = factors(slots, strength);
    let points = positions.as_ptr().cast::<f32>();
    let dst = out.as_mut_ptr().cast::<f32>();
    // Hidden from the compiler, which would otherwise make `[x | y]` with a slower lane-crossing
    // permute (measured).
    let xy = _mm256_castps_si256(opaque(_mm256_castsi256_ps(_mm256_setr_epi32(0, 0, 0, 0, 1, 1, 1, 1))));
    let one_high = _mm256_setr_ps(0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0);
    for group in 0..LANES / GROUP {
        let first = GROUP * group;
        // SAFETY: the caller's contract.
        let sums = unsafe { group_sums(slots, moves, first) };
        for (k, [c01, c23]) in sums.into_iter().enumerate() {
            let l = first + k;
            // The point `(x, y, z)` and one float more: the next point's, or for the last point
            // the float before it, moved behind.
            // SAFETY: floats 3l..3l + 4 of the 48 (44..48 for the last point).
            let co = unsafe {
                if l + 1 < LANES {
                    _mm_loadu_ps(points.add(3 * l))
                } else {
                    _mm_permute_ps::<0b00_11_10_01>(_mm_loadu_ps(points.add(3 * l - 1)))
                }
            };
            let p = _mm256_set_m128(co, co);
            let t = _mm256_mul_ps(c01, _mm256_permutevar_ps(p, xy));
            let z1 = _mm256_blend_ps::<0xF0>(_mm256_permute_ps::<0xAA>(p), one_high);
            let v = _mm256_add_ps(t, _mm256_mul_ps(c23, z1));
            let offset = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps::<1>(v));
            let moved = _mm_fmadd_ps(_mm_broadcast_ss(&factor[l]), offset, co);
            // SAFETY: point l's three floats and, for all but the last point, the next point's
            // first, which that point's own store overwrites after this one.
            unsafe {
                if l + 1 < LANES {
                    _mm_storeu_ps(dst.add(3 * l), moved);
                } else {
                    _mm_storel_epi64(dst.add(3 * l).cast(), _mm_castps_si128(moved));
                    _mm_store_ss(dst.add(3 * l + 2), _mm_movehl_ps(moved, moved));
                }
            }
        }
    }
    // The still lanes keep their points' bits.
    while still != 0 {
        let l = still.trailing_zeros() as usize;
        out[l] = positions[l];
        still &= still - 1;
    }
}

/// Each lane's factor `a/contrib` (0 without enough weight: the one body's), and the lanes it
/// leaves still (factor 0) as bits.
#[inline]
#[target_feature(enable = "avx2,fma")]
fn factors<I: BoneIndex>(slots: &[Slot<I>], strength: Option<&[f32; LANES]>) -> ([f32; LANES], u32) {
    // SAFETY: this function runs only where AVX2 and FMA are (its `target_feature`).
    let v = unsafe { Avx2::new() };
    let (mut factor, mut still) = ([0.0f32; LANES], 0u32);
    for half in 0..2 {
        let lanes = 8 * half..8 * half + 8;
        let contrib = total_weight(v, slots, lanes.start);
        let a = match strength {
            // SAFETY: eight of the mask's 16 lanes.
            Some(s) => unsafe { _mm256_loadu_ps(s[lanes.clone()].as_ptr()) },
            None => _mm256_set1_ps(1.0),
        };
        let valid = _mm256_cmp_ps::<_CMP_GT_OQ>(contrib, _mm256_set1_ps(MIN_TOTAL_WEIGHT));
        let f = _mm256_and_ps(valid, _mm256_div_ps(a, contrib));
        // SAFETY: eight of the 16 floats.
        unsafe { _mm256_storeu_ps(factor[lanes].as_mut_ptr(), f) };
        let zero = _mm256_cmp_ps::<_CMP_EQ_OQ>(f, _mm256_setzero_ps());
        still |= (_mm256_movemask_ps(zero) as u32) << (8 * half);
    }
    (factor, still)
}

/// `Σ wᵢ·Dᵢ` by column, `[c₀ | c₁]` and `[c₂ | c₃]`, of the lanes `first..first + GROUP`, one
/// fused multiply-add a vector and slot, in slot order. The group's four weights of a slot are
/// loaded once and spread with in-lane shuffles rather than broadcast from memory lane by lane:
/// the loads are what bound these sums (two vector loads a cycle on a Zen 3).
///
/// # Safety
/// Every bone index of those lanes of `slots` indexes `moves`.
#[inline]
#[target_feature(enable = "avx2,fma")]
unsafe fn group_sums<I: BoneIndex>(slots: &[Slot<I>], moves: &[ColumnMove], first: usize) -> [[__m256; 2]; GROUP] {
    let mut sums = [[_mm256_setzero_ps(); 2]; GROUP];
    for slot in slots {
        // SAFETY: four of a slot's 16 weights.
        let w = unsafe { _mm_loadu_ps(slot.weights[first..first + GROUP].as_ptr()) };
        // Hidden from the compiler, which would otherwise broadcast each weight from memory.
        let weights = opaque(_mm256_set_m128(w, w));
        for (k, [c01, c23]) in sums.iter_mut().enumerate() {
            let w = spread(weights, k);
            // SAFETY: the bone indexes `moves` (this function's contract); a ColumnMove is 16
            // floats.
            unsafe {
                let record = lane_record(moves, slot.bones[first + k]);
                *c01 = _mm256_fmadd_ps(_mm256_loadu_ps(record), w, *c01);
                *c23 = _mm256_fmadd_ps(_mm256_loadu_ps(record.add(8)), w, *c23);
            }
        }
    }
    sums
}

/// Float `k` of `v`'s low half, in every float (`v`'s halves are the same).
#[inline]
#[target_feature(enable = "avx2,fma")]
fn spread(v: __m256, k: usize) -> __m256 {
    match k {
        0 => _mm256_permute_ps::<0x00>(v),
        1 => _mm256_permute_ps::<0x55>(v),
        2 => _mm256_permute_ps::<0xAA>(v),
        _ => _mm256_permute_ps::<0xFF>(v),
    }
}

/// `v`, as a value the compiler cannot see into, so that it keeps the shuffles written.
#[inline]
#[target_feature(enable = "avx2,fma")]
fn opaque(mut v: __m256) -> __m256 {
    // SAFETY: an empty instruction string: reads and writes only the register.
    unsafe { core::arch::asm!("/* {0} */", inout(ymm_reg) v, options(pure, nomem, nostack, preserves_flags)) };
    v
}

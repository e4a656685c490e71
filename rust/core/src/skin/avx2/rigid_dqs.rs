//! The hand-written AVX2 DQS for rigid bones, kept where it measured faster than the one body of
//! `batch.rs` (docs/performance.md): the sign chains of a batch's two parts run side by side.
//!
//! In the one body each part of eight lanes sums its rotations with their signs and then
//! finishes, so the CPU runs one chain at a time: each slot's sign waits on the previous slot's
//! sum (a dot product, a comparison and a fused multiply-add in a row), and on a Zen 3 that
//! wait, more than the loads or the arithmetic, bounded the kernel. Here both parts' chains run in
//! one slot loop, the signed weights kept; the dual parts are summed after it, each lane pair's
//! records as they lie (no transpose per slot), and each part is finished as in the one body. The
//! same operations per lane in the same order as the one body, so the same bits (the tests
//! check it).

use core::arch::x86_64::*;

use super::super::batch::{add_signed, dual_quaternion, keep_masked, total_weight, VectorOps, DQ_DUAL, DQ_REAL};
use super::super::influences::{lane_record, BoneIndex, Slot, LANES};
use super::super::pose::DqBone;
use super::{transpose_halves, Avx2};

/// Lanes of a part (one AVX2 vector).
const PART: usize = 8;

/// DQS with rigid bones on one full batch, in mesh space (the spaces folded into `dq`), with
/// strength `strength`; `signed` holds a slot's signed weights between the chains and the dual
/// sums (one entry per slot).
///
/// # Safety
/// The CPU must support AVX2 and FMA; every bone index in `slots` must index `dq`.
#[target_feature(enable = "avx2,fma")]
pub(in crate::skin) unsafe fn dual_quaternion_batch<I: BoneIndex>(
    dq: &[DqBone],
    positions: &[[f32; 3]; LANES],
    out: &mut [[f32; 3]; LANES],
    slots: &[Slot<I>],
    strength: Option<&[f32; LANES]>,
    signed: &mut [[f32; LANES]],
) {
    const { assert!(LANES == 2 * PART) };
    assert_eq!(signed.len(), slots.len(), "a signed weight row per slot");
    // SAFETY: this function runs only where AVX2 and FMA are (its `target_feature`).
    let v = unsafe { Avx2::new() };
    let zero = _mm256_setzero_ps();
    // The rotations' sums with their signs, both parts in each slot (batch.rs's `rigid_sums`).
    let mut real = [[zero; 4]; 2];
    for (k, slot) in slots.iter().enumerate() {
        for (part, sum) in real.iter_mut().enumerate() {
            let lane0 = PART * part;
            // SAFETY: the caller's contract; the rotation is four floats of a DqBone.
            let q = unsafe { v.load_columns4(dq, &slot.bones[lane0..], DQ_REAL) };
            let ws = add_signed(v, k == 0, &q, v.load(&slot.weights[lane0..]), sum);
            v.store(ws, &mut signed[k][lane0..]);
        }
    }
    for (part, real) in real.into_iter().enumerate() {
        let lane0 = PART * part;
        // SAFETY: the caller's contract.
        let dual = unsafe { dual_sums(dq, slots, signed, lane0) };
        let contrib = total_weight(v, slots, lane0);
        let a = match strength {
            Some(s) => v.load(&s[lane0..]),
            None => v.splat(1.0),
        };
        let lanes = lane0..lane0 + PART;
        let p = v.load_points(&positions[lanes.clone()]);
        let r = dual_quaternion(v, real, dual, contrib, p, a);
        let r = if strength.is_some() { keep_masked(v, a, &positions[lanes.clone()], r) } else { r };
        v.store_points(r, &mut out[lanes]);
    }
}

/// `Σ ±wᵢ·dᵢ` of the dual parts of lanes `lane0..lane0 + 8`, by lane pair: lanes `l` and
/// `l + 4` share a register (low and high half), so each pair's two records are one load and
/// an insert, its signed weights one in-lane shuffle, and one transpose at the end gives the
/// components.
///
/// # Safety
/// Every bone index of those lanes of `slots` indexes `dq`.
#[inline]
#[target_feature(enable = "avx2,fma")]
unsafe fn dual_sums<I: BoneIndex>(
    dq: &[DqBone],
    slots: &[Slot<I>],
    signed: &[[f32; LANES]],
    lane0: usize,
) -> [__m256; 4] {
    // SAFETY: this function runs only where AVX2 and FMA are (its `target_feature`).
    let v = unsafe { Avx2::new() };
    let mut pairs = [_mm256_setzero_ps(); 4];
    for (slot, ws) in slots.iter().zip(signed) {
        let ws = v.load(&ws[lane0..]);
        for (l, pair) in pairs.iter_mut().enumerate() {
            let lane = lane0 + l;
            // SAFETY: the caller's contract; the dual part is four floats of a DqBone.
            let d = unsafe {
                let (lo, hi) = (lane_record(dq, slot.bones[lane]), lane_record(dq, slot.bones[lane + 4]));
                _mm256_insertf128_ps::<1>(
                    _mm256_castps128_ps256(_mm_loadu_ps(lo.add(DQ_DUAL))),
                    _mm_loadu_ps(hi.add(DQ_DUAL)),
                )
            };
            let w = match l {
                0 => _mm256_permute_ps::<0x00>(ws),
                1 => _mm256_permute_ps::<0x55>(ws),
                2 => _mm256_permute_ps::<0xAA>(ws),
                _ => _mm256_permute_ps::<0xFF>(ws),
            };
            *pair = _mm256_fmadd_ps(d, w, *pair);
        }
    }
    transpose_halves(v, pairs)
}

//! The baseline copy, compiled for the target's baseline instruction set and run where no SIMD
//! copy is (or where `DQSKIN_SIMD=baseline` asks for it): the one arithmetic body of `batch.rs`
//! with four lanes as plain arrays, which the compiler maps to the baseline's vector registers
//! (SSE2 on x86-64) where it can, a 16-vertex batch in four parts; and a hand-written LBS kept
//! where it measured faster ([`kept`]). Products are not fused: the baseline may have no FMA
//! instruction (in the x86-64 baseline a fused `mul_add` would be a slow library call).

use super::batch::VectorOps;
use super::influences::{lane_record, BoneIndex, Slot, LANES};

mod kept;

pub(super) use kept::linear_batch;

/// Four lanes.
pub(super) type F4 = [f32; 4];
/// A per-lane condition: all bits set where it holds.
pub(super) type Mask4 = [u32; 4];

const SIGN: u32 = 0x8000_0000;

/// The baseline copy's vector operations (every CPU has them).
#[derive(Clone, Copy)]
pub(super) struct Baseline;

#[inline(always)]
fn each(f: impl Fn(usize) -> f32) -> F4 {
    [f(0), f(1), f(2), f(3)]
}

#[inline(always)]
fn mask(f: impl Fn(usize) -> bool) -> Mask4 {
    [0, 1, 2, 3].map(|l| if f(l) { u32::MAX } else { 0 })
}

impl VectorOps for Baseline {
    const WIDTH: usize = 4;
    type F = F4;
    type Mask = Mask4;

    #[inline(always)]
    fn splat(self, x: f32) -> F4 {
        [x; 4]
    }

    #[inline(always)]
    fn load(self, a: &[f32]) -> F4 {
        [a[0], a[1], a[2], a[3]]
    }

    #[inline(always)]
    fn store(self, v: F4, a: &mut [f32]) {
        a[..4].copy_from_slice(&v);
    }

    #[inline(always)]
    fn add(self, a: F4, b: F4) -> F4 {
        each(|l| a[l] + b[l])
    }

    #[inline(always)]
    fn sub(self, a: F4, b: F4) -> F4 {
        each(|l| a[l] - b[l])
    }

    #[inline(always)]
    fn mul(self, a: F4, b: F4) -> F4 {
        each(|l| a[l] * b[l])
    }

    #[inline(always)]
    fn div(self, a: F4, b: F4) -> F4 {
        each(|l| a[l] / b[l])
    }

    #[inline(always)]
    fn mul_add(self, a: F4, b: F4, c: F4) -> F4 {
        each(|l| a[l] * b[l] + c[l])
    }

    #[inline(always)]
    fn neg_mul_add(self, a: F4, b: F4, c: F4) -> F4 {
        each(|l| c[l] - a[l] * b[l])
    }

    #[inline(always)]
    fn mul_sub(self, a: F4, b: F4, c: F4) -> F4 {
        each(|l| a[l] * b[l] - c[l])
    }

    #[inline(always)]
    fn lt(self, a: F4, b: F4) -> Mask4 {
        mask(|l| a[l] < b[l])
    }

    #[inline(always)]
    fn gt(self, a: F4, b: F4) -> Mask4 {
        mask(|l| a[l] > b[l])
    }

    #[inline(always)]
    fn eq(self, a: F4, b: F4) -> Mask4 {
        mask(|l| a[l] == b[l])
    }

    #[inline(always)]
    fn and(self, a: Mask4, b: Mask4) -> Mask4 {
        [0, 1, 2, 3].map(|l| a[l] & b[l])
    }

    #[inline(always)]
    fn select(self, m: Mask4, a: F4, b: F4) -> F4 {
        each(|l| f32::from_bits((a[l].to_bits() & m[l]) | (b[l].to_bits() & !m[l])))
    }

    #[inline(always)]
    fn neg_where(self, m: Mask4, a: F4) -> F4 {
        each(|l| f32::from_bits(a[l].to_bits() ^ (m[l] & SIGN)))
    }

    #[inline(always)]
    unsafe fn load_columns4<T, I: BoneIndex>(self, table: &[T], bones: &[I], offset: usize) -> [F4; 4] {
        debug_assert!(bones.len() >= 4 && offset + 4 <= core::mem::size_of::<T>() / 4);
        // SAFETY: the caller guarantees the records and the offset are in range.
        let rows: [*const f32; 4] = [0, 1, 2, 3].map(|l| unsafe { lane_record(table, bones[l]).add(offset) });
        // SAFETY: as above.
        [0, 1, 2, 3].map(|c| each(|l| unsafe { *rows[l].add(c) }))
    }

    #[inline(always)]
    fn load_points(self, points: &[[f32; 3]]) -> [F4; 3] {
        [0, 1, 2].map(|k| each(|l| points[l][k]))
    }

    #[inline(always)]
    fn store_points(self, p: [F4; 3], out: &mut [[f32; 3]]) {
        for (l, o) in out[..4].iter_mut().enumerate() {
            *o = [p[0][l], p[1][l], p[2][l]];
        }
    }

    /// Lane by lane: each lane's weight times the rows of its record (four floats, one vector
    /// operation), summed in slot order, and transposed once at the end.
    #[inline(always)]
    unsafe fn window_sums<T, I: BoneIndex, const ROWS: usize>(
        self,
        slots: &[Slot<I>],
        signed: Option<&[[f32; LANES]]>,
        lane0: usize,
        table: &[T],
        offsets: [usize; ROWS],
    ) -> [[F4; 4]; ROWS] {
        debug_assert!(offsets.iter().all(|&o| o + 4 <= core::mem::size_of::<T>() / 4));
        debug_assert!(signed.is_none_or(|s| s.len() == slots.len()));
        // rows[r][l]: row r of lane l; one lane at a time (its rows stay in registers; the
        // baseline has few), the slots read again from the cache for the next.
        let mut rows = [[[0.0f32; 4]; 4]; ROWS];
        for l in 0..4 {
            let lane = lane0 + l;
            let mut sums = [[0.0f32; 4]; ROWS];
            for (s, slot) in slots.iter().enumerate() {
                let w = signed.map_or(&slot.weights, |w| &w[s])[lane];
                // SAFETY: the caller's contract: the lane's bone indexes `table` and the rows
                // lie inside its record.
                let record = unsafe { lane_record(table, slot.bones[lane]) };
                for (sum, &offset) in sums.iter_mut().zip(&offsets) {
                    // SAFETY: as above.
                    let values = unsafe { *record.add(offset).cast::<[f32; 4]>() };
                    *sum = each(|c| w * values[c] + sum[c]);
                }
            }
            for (row, sum) in rows.iter_mut().zip(sums) {
                row[l] = sum;
            }
        }
        rows.map(|row| [0, 1, 2, 3].map(|c| each(|l| row[l][c])))
    }
}

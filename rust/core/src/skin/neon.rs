//! The batch kernels' vector operations for NEON (aarch64: Apple Silicon, Windows on ARM, Linux
//! ARM): four lanes per vector, so a 16-vertex batch runs as four parts.
//!
//! NEON is part of every aarch64 target, so its intrinsics need no run-time detection. Points
//! (de)interleave in one instruction (`ld3`/`st3`); bone records are loaded as rows and
//! transposed 4×4 (`trn1`/`trn2` on floats, then on pairs); the linear sums accumulate each
//! lane's record rows with the weight taken from its lane of the weight vector (`fmla` by
//! element), so they are transposed once per vertex instead of once per influence.

use core::arch::aarch64::*;

use super::batch::VectorOps;
use super::influences::{lane_record, BoneIndex, Slot, LANES};

/// Proof that the CPU has NEON (every aarch64 CPU does).
#[derive(Clone, Copy)]
pub(super) struct Neon {
    _baseline: (),
}

impl Neon {
    /// # Safety
    /// Always sound on aarch64 (NEON is part of the target); `unsafe` like the other sets'
    /// constructors.
    #[inline(always)]
    pub(super) unsafe fn new() -> Self {
        Neon { _baseline: () }
    }
}

/// Methods that are NEON instructions. The intrinsics are `#[target_feature(enable = "neon")]`
/// functions, which the batch kernels (compiled with that feature, where these inline) may call;
/// called from elsewhere they are still sound, since NEON is part of every aarch64 target.
macro_rules! instructions {
    ($($name:ident($($arg:ident: $t:ty),*) -> $out:ty = $body:expr;)*) => {$(
        #[inline(always)]
        fn $name(self, $($arg: $t),*) -> $out {
            // SAFETY: a `Neon` exists only on aarch64, whose CPUs all have NEON.
            unsafe { $body }
        }
    )*};
}

/// Rows to columns.
#[inline(always)]
fn transpose4(_: Neon, r: [float32x4_t; 4]) -> [float32x4_t; 4] {
    // SAFETY: as in `instructions!`.
    unsafe {
        let t0 = vtrn1q_f32(r[0], r[1]); // r0[0] r1[0] r0[2] r1[2]
        let t1 = vtrn2q_f32(r[0], r[1]); // r0[1] r1[1] r0[3] r1[3]
        let t2 = vtrn1q_f32(r[2], r[3]);
        let t3 = vtrn2q_f32(r[2], r[3]);
        let pairs = |a: float32x4_t, b: float32x4_t, high: bool| {
            let (a, b) = (vreinterpretq_f64_f32(a), vreinterpretq_f64_f32(b));
            vreinterpretq_f32_f64(if high { vtrn2q_f64(a, b) } else { vtrn1q_f64(a, b) })
        };
        [pairs(t0, t2, false), pairs(t1, t3, false), pairs(t0, t2, true), pairs(t1, t3, true)]
    }
}

type F = float32x4_t;
type M = uint32x4_t;

impl VectorOps for Neon {
    const WIDTH: usize = 4;
    type F = F;
    type Mask = M;

    instructions! {
        splat(x: f32) -> F = vdupq_n_f32(x);
        add(a: F, b: F) -> F = vaddq_f32(a, b);
        sub(a: F, b: F) -> F = vsubq_f32(a, b);
        mul(a: F, b: F) -> F = vmulq_f32(a, b);
        div(a: F, b: F) -> F = vdivq_f32(a, b);
        mul_add(a: F, b: F, c: F) -> F = vfmaq_f32(c, a, b);
        neg_mul_add(a: F, b: F, c: F) -> F = vfmsq_f32(c, a, b);
        mul_sub(a: F, b: F, c: F) -> F = vfmaq_f32(vnegq_f32(c), a, b);
        lt(a: F, b: F) -> M = vcltq_f32(a, b);
        gt(a: F, b: F) -> M = vcgtq_f32(a, b);
        eq(a: F, b: F) -> M = vceqq_f32(a, b);
        and(a: M, b: M) -> M = vandq_u32(a, b);
        select(m: M, a: F, b: F) -> F = vbslq_f32(m, a, b);
        neg_where(m: M, a: F) -> F = vreinterpretq_f32_u32(veorq_u32(vreinterpretq_u32_f32(a), vandq_u32(m, vdupq_n_u32(0x8000_0000))));
    }

    #[inline(always)]
    fn load(self, a: &[f32]) -> F {
        assert!(a.len() >= 4);
        // SAFETY: four floats (checked); NEON as in `instructions!`.
        unsafe { vld1q_f32(a.as_ptr()) }
    }

    #[inline(always)]
    fn store(self, v: F, a: &mut [f32]) {
        assert!(a.len() >= 4);
        // SAFETY: four floats (checked); NEON as in `instructions!`.
        unsafe { vst1q_f32(a.as_mut_ptr(), v) }
    }

    #[inline(always)]
    unsafe fn load_columns4<T, I: BoneIndex>(self, table: &[T], bones: &[I], offset: usize) -> [F; 4] {
        debug_assert!(bones.len() >= 4 && offset + 4 <= core::mem::size_of::<T>() / 4);
        let row = |l: usize| {
            // SAFETY: the caller guarantees the record and the offset are in range; NEON as in
            // `instructions!`.
            unsafe { vld1q_f32(lane_record(table, bones[l]).add(offset)) }
        };
        transpose4(self, [row(0), row(1), row(2), row(3)])
    }

    #[inline(always)]
    fn load_points(self, points: &[[f32; 3]]) -> [F; 3] {
        assert!(points.len() >= 4);
        // SAFETY: four points are 12 floats (checked); NEON as in `instructions!`.
        let p = unsafe { vld3q_f32(points.as_ptr() as *const f32) };
        [p.0, p.1, p.2]
    }

    #[inline(always)]
    fn store_points(self, [x, y, z]: [F; 3], out: &mut [[f32; 3]]) {
        assert!(out.len() >= 4);
        // SAFETY: four points are 12 floats (checked); NEON as in `instructions!`.
        unsafe { vst3q_f32(out.as_mut_ptr() as *mut f32, float32x4x3_t(x, y, z)) }
    }

    /// Accumulated per lane, each row's weight taken from its lane of the weight vector (`fmla`
    /// by element), and transposed once at the end.
    #[inline(always)]
    unsafe fn window_sums<T, I: BoneIndex, const ROWS: usize>(
        self,
        slots: &[Slot<I>],
        signed: Option<&[[f32; LANES]]>,
        lane0: usize,
        table: &[T],
        offsets: [usize; ROWS],
    ) -> [[F; 4]; ROWS] {
        debug_assert!(
            offsets.iter().all(|&r| r + 4 <= core::mem::size_of::<T>() / 4)
                && signed.is_none_or(|s| s.len() == slots.len())
        );
        let zero = self.splat(0.0);
        let mut acc = [[zero; ROWS]; 4];
        for (s, slot) in slots.iter().enumerate() {
            let w = self.load(&signed.map_or(&slot.weights, |w| &w[s])[lane0..]);
            let bones = &slot.bones[lane0..lane0 + 4];
            let row = |l: usize, r: usize| {
                // SAFETY: the caller's contract: the lane's bone indexes `table` and the window
                // lies inside its record; NEON as in `instructions!`.
                unsafe { vld1q_f32(lane_record(table, bones[l]).add(offsets[r])) }
            };
            for r in 0..ROWS {
                // SAFETY: NEON as in `instructions!`.
                unsafe {
                    acc[0][r] = vfmaq_laneq_f32::<0>(acc[0][r], row(0, r), w);
                    acc[1][r] = vfmaq_laneq_f32::<1>(acc[1][r], row(1, r), w);
                    acc[2][r] = vfmaq_laneq_f32::<2>(acc[2][r], row(2, r), w);
                    acc[3][r] = vfmaq_laneq_f32::<3>(acc[3][r], row(3, r), w);
                }
            }
        }
        let mut sums = [[zero; 4]; ROWS];
        for (r, sum) in sums.iter_mut().enumerate() {
            *sum = transpose4(self, [acc[0][r], acc[1][r], acc[2][r], acc[3][r]]);
        }
        sums
    }
}

//! The hot loop of the precompute: one vertex's similarity-weighted sums over one bone pair's
//! list of triangles, `Σ e·P` and `Σ e·P·c` with `e = exp(−(aⱼ·bₖ − aₖ·bⱼ)²/σ²)`.
//!
//! Written so that the compiler vectorizes it: [`WIDTH`] independent accumulators per sum (f64
//! addition is not associative, so it would not reorder one accumulator) and a branch-free
//! `exp`. Copies for AVX2+FMA, AVX-512 and NEON are chosen at run time like the skinning
//! kernels'.

use super::super::isa::{InstructionSet, Simd};

/// Entries per step, and the padding of every pair's list.
pub(super) const WIDTH: usize = 8;

/// One bone pair's triangles in structure-of-arrays form, padded to a multiple of [`WIDTH`] with
/// zero entries (`p = 0` adds nothing).
pub(super) struct PairList<'a> {
    pub bj: &'a [f64],
    pub bk: &'a [f64],
    /// `bⱼ·bₖ·A` (A the triangles' total area).
    pub p: &'a [f64],
    /// `bⱼ·bₖ·Σ A·c`, one array per axis.
    pub pc: [&'a [f64]; 3],
}

/// `(Σ e·P, Σ e·P·c)` over a pair's list for the vertex weights `(aj, ak)`, with
/// `e = exp(shift − (aj·bₖ − ak·bⱼ)²·inv_sigma2)`. `shift` is a common factor `exp(shift)` that
/// cancels in the centre (it keeps `e` from underflowing for tiny σ).
pub(super) fn pair_sums(simd: Simd, list: &PairList<'_>, aj: f64, ak: f64, inv_sigma2: f64, shift: f64) -> [f64; 4] {
    match simd.instruction_set() {
        InstructionSet::Baseline => sums(list, aj, ak, inv_sigma2, shift),
        // SAFETY: a `Simd` of this set exists only where AVX2 and FMA were detected.
        #[cfg(target_arch = "x86_64")]
        InstructionSet::Avx2Fma => unsafe { sums_avx2(list, aj, ak, inv_sigma2, shift) },
        // SAFETY: a `Simd` of this set exists only where AVX-512F, AVX2 and FMA were detected.
        #[cfg(target_arch = "x86_64")]
        InstructionSet::Avx512 => unsafe { sums_avx512(list, aj, ak, inv_sigma2, shift) },
        // SAFETY: every aarch64 CPU has NEON.
        #[cfg(target_arch = "aarch64")]
        InstructionSet::Neon => unsafe { sums_neon(list, aj, ak, inv_sigma2, shift) },
    }
}

/// The smallest `(aj·bₖ − ak·bⱼ)²` over a list (for the underflow shift).
pub(super) fn min_cross_squared(list: &PairList<'_>, aj: f64, ak: f64) -> f64 {
    let mut m = f64::INFINITY;
    for (bj, bk) in list.bj.iter().zip(list.bk) {
        let u = aj * bk - ak * bj;
        m = m.min(u * u);
    }
    m
}

/// The polynomial of [`exp_nonpositive`], highest degree first, for the SIMD copies.
const EXP_POLY: [f64; 10] =
    [1.0 / 362880.0, 1.0 / 40320.0, 1.0 / 5040.0, 1.0 / 720.0, 1.0 / 120.0, 1.0 / 24.0, 1.0 / 6.0, 1.0 / 2.0, 1.0, 1.0];
const LOG2_E: f64 = core::f64::consts::LOG2_E;
/// ln 2 in two parts (fdlibm's): `k·LN2_HI` is exact for the k used here.
const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
/// 1.5·2⁵²: adding it rounds to an integer kept in the low mantissa bits.
const ROUND: f64 = 6_755_399_441_055_744.0;
/// Added to the bits of `x·log₂e + ROUND` (whose low bits are k): `k + 1023` in the bits that the
/// shift by 52 moves into the exponent field (the high bits of ROUND shift out).
const EXPONENT_BIAS: i64 = 1023;
/// Below this `exp` returns `exp(MIN_EXPONENT)` ≈ 2.5e-308 instead of a smaller number:
/// arguments this low are only reached with the underflow shift, where the largest term is 1.
const MIN_EXPONENT: f64 = -708.0;

/// [`sums`] with AVX2+FMA: two 4-wide vectors per step, the same arithmetic.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn sums_avx2(list: &PairList<'_>, aj: f64, ak: f64, inv_sigma2: f64, shift: f64) -> [f64; 4] {
    use core::arch::x86_64::*;
    let (vaj, vak, vinv, vshift) =
        (_mm256_set1_pd(aj), _mm256_set1_pd(ak), _mm256_set1_pd(inv_sigma2), _mm256_set1_pd(shift));
    let exp = |x: __m256d| -> __m256d {
        let x = _mm256_min_pd(_mm256_max_pd(x, _mm256_set1_pd(MIN_EXPONENT)), _mm256_setzero_pd());
        let t = _mm256_fmadd_pd(x, _mm256_set1_pd(LOG2_E), _mm256_set1_pd(ROUND));
        let kf = _mm256_sub_pd(t, _mm256_set1_pd(ROUND));
        let r = _mm256_fnmadd_pd(kf, _mm256_set1_pd(LN2_LO), _mm256_fnmadd_pd(kf, _mm256_set1_pd(LN2_HI), x));
        let mut poly = _mm256_set1_pd(EXP_POLY[0]);
        for c in &EXP_POLY[1..] {
            poly = _mm256_fmadd_pd(poly, r, _mm256_set1_pd(*c));
        }
        // t's low mantissa bits hold k; adding the bias there and shifting gives 2ᵏ.
        let biased = _mm256_add_epi64(_mm256_castpd_si256(t), _mm256_set1_epi64x(EXPONENT_BIAS));
        _mm256_mul_pd(poly, _mm256_castsi256_pd(_mm256_slli_epi64::<52>(biased)))
    };
    let mut acc = [[_mm256_setzero_pd(); 2]; 4];
    let n = list.p.len();
    let mut i = 0;
    while i < n {
        for h in 0..2 {
            let at = i + 4 * h;
            // SAFETY: every array has `n` entries, a multiple of WIDTH = 8, and at + 4 ≤ n.
            let ld = |a: &[f64]| unsafe { _mm256_loadu_pd(a.as_ptr().add(at)) };
            let u = _mm256_fmsub_pd(vaj, ld(list.bk), _mm256_mul_pd(vak, ld(list.bj)));
            let e = exp(_mm256_fnmadd_pd(_mm256_mul_pd(u, u), vinv, vshift));
            acc[0][h] = _mm256_fmadd_pd(e, ld(list.p), acc[0][h]);
            acc[1][h] = _mm256_fmadd_pd(e, ld(list.pc[0]), acc[1][h]);
            acc[2][h] = _mm256_fmadd_pd(e, ld(list.pc[1]), acc[2][h]);
            acc[3][h] = _mm256_fmadd_pd(e, ld(list.pc[2]), acc[3][h]);
        }
        i += WIDTH;
    }
    acc.map(|[a, b]| {
        let mut lanes = [0.0f64; 8];
        // SAFETY: 8 doubles.
        unsafe {
            _mm256_storeu_pd(lanes.as_mut_ptr(), a);
            _mm256_storeu_pd(lanes.as_mut_ptr().add(4), b);
        }
        lanes.iter().sum()
    })
}

/// [`sums`] with AVX-512: one 8-wide vector per step, the same arithmetic.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn sums_avx512(list: &PairList<'_>, aj: f64, ak: f64, inv_sigma2: f64, shift: f64) -> [f64; 4] {
    use core::arch::x86_64::*;
    let (vaj, vak, vinv, vshift) =
        (_mm512_set1_pd(aj), _mm512_set1_pd(ak), _mm512_set1_pd(inv_sigma2), _mm512_set1_pd(shift));
    let mut acc = [_mm512_setzero_pd(); 4];
    let n = list.p.len();
    let mut i = 0;
    while i < n {
        // SAFETY: every array has `n` entries, a multiple of WIDTH = 8, and i + 8 ≤ n.
        let ld = |a: &[f64]| unsafe { _mm512_loadu_pd(a.as_ptr().add(i)) };
        let u = _mm512_fmsub_pd(vaj, ld(list.bk), _mm512_mul_pd(vak, ld(list.bj)));
        let x = _mm512_fnmadd_pd(_mm512_mul_pd(u, u), vinv, vshift);
        let x = _mm512_min_pd(_mm512_max_pd(x, _mm512_set1_pd(MIN_EXPONENT)), _mm512_setzero_pd());
        let t = _mm512_fmadd_pd(x, _mm512_set1_pd(LOG2_E), _mm512_set1_pd(ROUND));
        let kf = _mm512_sub_pd(t, _mm512_set1_pd(ROUND));
        let r = _mm512_fnmadd_pd(kf, _mm512_set1_pd(LN2_LO), _mm512_fnmadd_pd(kf, _mm512_set1_pd(LN2_HI), x));
        let mut poly = _mm512_set1_pd(EXP_POLY[0]);
        for c in &EXP_POLY[1..] {
            poly = _mm512_fmadd_pd(poly, r, _mm512_set1_pd(*c));
        }
        let biased = _mm512_add_epi64(_mm512_castpd_si512(t), _mm512_set1_epi64(EXPONENT_BIAS));
        let e = _mm512_mul_pd(poly, _mm512_castsi512_pd(_mm512_slli_epi64::<52>(biased)));
        acc[0] = _mm512_fmadd_pd(e, ld(list.p), acc[0]);
        acc[1] = _mm512_fmadd_pd(e, ld(list.pc[0]), acc[1]);
        acc[2] = _mm512_fmadd_pd(e, ld(list.pc[1]), acc[2]);
        acc[3] = _mm512_fmadd_pd(e, ld(list.pc[2]), acc[3]);
        i += WIDTH;
    }
    acc.map(|a| {
        let mut lanes = [0.0f64; 8];
        // SAFETY: 8 doubles.
        unsafe { _mm512_storeu_pd(lanes.as_mut_ptr(), a) };
        lanes.iter().sum()
    })
}

/// [`sums`] with NEON: four 2-wide vectors per step, the same arithmetic.
#[cfg(target_arch = "aarch64")]
#[target_feature(enable = "neon")]
unsafe fn sums_neon(list: &PairList<'_>, aj: f64, ak: f64, inv_sigma2: f64, shift: f64) -> [f64; 4] {
    use core::arch::aarch64::*;
    let (vaj, vak, vinv, vshift) = (vdupq_n_f64(aj), vdupq_n_f64(ak), vdupq_n_f64(inv_sigma2), vdupq_n_f64(shift));
    let exp = |x: float64x2_t| -> float64x2_t {
        let x = vminq_f64(vmaxq_f64(x, vdupq_n_f64(MIN_EXPONENT)), vdupq_n_f64(0.0));
        let t = vfmaq_f64(vdupq_n_f64(ROUND), x, vdupq_n_f64(LOG2_E));
        let kf = vsubq_f64(t, vdupq_n_f64(ROUND));
        let r = vfmsq_f64(vfmsq_f64(x, kf, vdupq_n_f64(LN2_HI)), kf, vdupq_n_f64(LN2_LO));
        let mut poly = vdupq_n_f64(EXP_POLY[0]);
        for c in &EXP_POLY[1..] {
            poly = vfmaq_f64(vdupq_n_f64(*c), poly, r);
        }
        // t's low mantissa bits hold k; adding the bias there and shifting gives 2ᵏ.
        let biased = vaddq_s64(vreinterpretq_s64_f64(t), vdupq_n_s64(EXPONENT_BIAS));
        vmulq_f64(poly, vreinterpretq_f64_s64(vshlq_n_s64::<52>(biased)))
    };
    let zero = vdupq_n_f64(0.0);
    let mut acc = [[zero; 4]; 4];
    let n = list.p.len();
    assert!(
        list.bj.len() == n && list.bk.len() == n && list.pc.iter().all(|c| c.len() == n) && n.is_multiple_of(WIDTH)
    );
    let mut i = 0;
    while i < n {
        for h in 0..4 {
            let at = i + 2 * h;
            // SAFETY: every array has `n` entries (checked), a multiple of WIDTH = 8, and at + 2 ≤ n.
            let ld = |a: &[f64]| unsafe { vld1q_f64(a.as_ptr().add(at)) };
            let u = vfmaq_f64(vnegq_f64(vmulq_f64(vak, ld(list.bj))), vaj, ld(list.bk));
            let e = exp(vfmsq_f64(vshift, vmulq_f64(u, u), vinv));
            acc[0][h] = vfmaq_f64(acc[0][h], e, ld(list.p));
            acc[1][h] = vfmaq_f64(acc[1][h], e, ld(list.pc[0]));
            acc[2][h] = vfmaq_f64(acc[2][h], e, ld(list.pc[1]));
            acc[3][h] = vfmaq_f64(acc[3][h], e, ld(list.pc[2]));
        }
        i += WIDTH;
    }
    acc.map(|a| {
        let mut lanes = [0.0f64; 8];
        for (h, v) in a.iter().enumerate() {
            // SAFETY: two doubles at 2·h < 8.
            unsafe { vst1q_f64(lanes.as_mut_ptr().add(2 * h), *v) };
        }
        lanes.iter().sum()
    })
}

/// The portable copy (lanes the compiler may vectorize).
fn sums(list: &PairList<'_>, aj: f64, ak: f64, inv_sigma2: f64, shift: f64) -> [f64; 4] {
    let mut acc = [[0.0f64; WIDTH]; 4];
    debug_assert!(list.p.len().is_multiple_of(WIDTH));
    let steps = list.p.len() / WIDTH;
    for s in 0..steps {
        let r = s * WIDTH..(s + 1) * WIDTH;
        let (bj, bk, p) = (&list.bj[r.clone()], &list.bk[r.clone()], &list.p[r.clone()]);
        let (cx, cy, cz) = (&list.pc[0][r.clone()], &list.pc[1][r.clone()], &list.pc[2][r]);
        for l in 0..WIDTH {
            let u = aj * bk[l] - ak * bj[l];
            let e = exp_nonpositive(shift - u * u * inv_sigma2);
            acc[0][l] += e * p[l];
            acc[1][l] += e * cx[l];
            acc[2][l] += e * cy[l];
            acc[3][l] += e * cz[l];
        }
    }
    acc.map(|a| a.iter().sum())
}

/// `exp(x)` for `x ≤ 0` (NaN-free inputs), branch-free, with a relative error below 1e-11
/// for `x ≥ −708` (and `exp(−708)` below that).
///
/// `x = k·ln 2 + r` with `|r| ≤ ln 2 / 2` (Cody–Waite: `ln 2` split in a part exact in k·hi and a
/// correction), `exp(r)` by its Taylor polynomial of degree 9 (relative remainder at most
/// `0.3466¹⁰/10!·e^0.3466 < 1e-11`, f64 rounding adds a few ulps), and `2ᵏ` built in the exponent
/// field. Why 1e-11 is enough: weights `wₜ` with relative errors `≤ δ` move a weighted mean of
/// centroids by at most `δ/(1−δ)·max|cₜ − p*|`, i.e. `≤ 1.0001·δ·(bbox diagonal)`.
#[inline(always)]
pub(super) fn exp_nonpositive(x: f64) -> f64 {
    let x = x.clamp(MIN_EXPONENT, 0.0);
    let t = x * LOG2_E + ROUND;
    let kf = t - ROUND;
    let r = (x - kf * LN2_HI) - kf * LN2_LO;
    let mut poly = EXP_POLY[0];
    for c in &EXP_POLY[1..] {
        poly = poly * r + c;
    }
    // k ∈ [−1022, 0] sits in t's low bits; k + 1023 shifted into the exponent field is 2ᵏ.
    let biased = (t.to_bits() as i64).wrapping_add(EXPONENT_BIAS) as u64;
    poly * f64::from_bits(biased << 52)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_matches_the_library_within_a_few_ulps() {
        let mut worst = 0.0f64;
        let mut x = 0.0f64;
        while x > -708.0 {
            {
                let got = exp_nonpositive(x);
                let want = x.exp();
                worst = worst.max(((got - want) / want).abs());
            }
            x -= 0.0137;
        }
        assert!(worst < 1e-11, "worst relative error {worst}");
        assert_eq!(exp_nonpositive(0.0), 1.0);
        assert!(exp_nonpositive(-1e300) <= (-708.0f64).exp());
    }
}

//! The fast path of the precompute: a bone pair's entries grouped in small cells of
//! `(bⱼ, bₖ)` space, each cell's sum replaced by a Taylor expansion with a certified remainder.
//!
//! For a vertex with weights `(aⱼ, aₖ)` an entry's term is `P·g(x)` (and `P·c·g(x)`) with
//! `g(x) = exp(−x²)`, `x = (aⱼ·bₖ − aₖ·bⱼ)/σ`. Inside a cell, with the expansion point
//! `(bⱼ₀, bₖ₀)`, `x = x₀ + δ`, `δ = sⱼ·Δbₖ − sₖ·Δbⱼ` (`s = a/σ`), and
//! `g(x₀ + δ) = Σ_{n<N} (−1)ⁿ·Hₙ(x₀)·g(x₀)·δⁿ/n! + R` (`Hₙ` the physicists' Hermite
//! polynomials, `g⁽ⁿ⁾ = (−1)ⁿ·Hₙ·g`). Expanding `δⁿ/n! = Σ_{m+l=n} (−sₖΔbⱼ)ᵐ/m!·(sⱼΔbₖ)ˡ/l!`,
//! the cell's sums need only its moments `Σ P·Δbⱼᵐ·Δbₖˡ` (and the same with `P·c`), computed
//! once: the cost per vertex is per cell, not per triangle.
//!
//! # The bound
//! Lagrange's remainder is `|R| ≤ max_ξ |Hₙ(ξ)|·g(ξ)·|δ|ᴺ/N!` over `ξ` between `x₀` and `x`;
//! Cramér's inequality `|Hₙ(ξ)| ≤ k·2^{n/2}·√(n!)·e^{ξ²/2}` (`k < 1.0865`) gives
//! `|R| ≤ k·(√2·|δ|)ᴺ/√(N!)·exp(−ξ_min²/2)`, with `|δ| ≤ sⱼ·hₖ + sₖ·hⱼ` (`h` the cell's
//! half-widths around its expansion point) and `ξ_min = max(0, |x₀| − |δ|)`. The expansion is
//! the same for `P` and `P·c`, so it amounts to replacing each triangle weight `wₜ = 2aⱼaₖ·P·g`
//! by some `w̃ₜ` with `|w̃ₜ − wₜ| ≤ 2aⱼaₖ·P·|R|`. With `E = Σ |w̃ₜ − wₜ|` and `D̃ = Σ w̃ₜ`,
//! since `Σ wₜ·(cₜ − p*) = 0`, the computed center `p̃ = Σ w̃ₜcₜ/D̃` satisfies
//! `p̃ − p* = Σ (w̃ₜ − wₜ)(cₜ − p*)/D̃`, so `|p̃ − p*| ≤ E/D̃ · max|cₜ − p*|`, and `cₜ`, `p*`
//! (a weighted mean of centroids) lie in the mesh's bounding box. A vertex keeps the fast
//! result only if its bound `E ≤ TOLERANCE·D̃`; otherwise it is summed exactly.

use super::super::isa::{InstructionSet, Simd};
use super::sums::exp_nonpositive;
use super::Entry;

/// Terms of the expansion (degree `ORDER − 1`); the remainder is of order `ORDER`.
pub(super) const ORDER: usize = 8;
/// Moments per cell: `Δbⱼᵐ·Δbₖˡ` for `m + l < ORDER`.
pub(super) const MOMENTS: usize = ORDER * (ORDER + 1) / 2;
/// `k·2^{N/2}/√(N!)` for `N = ORDER` (`k = 1.0865`, rounded up): 1.0865·16/√40320.
const REMAINDER: f64 = 1.0865 * 16.0 / 200.798_406_368_1;
/// A vertex's certified bound on `E/D̃`: its center moves by at most this × the bounding box
/// diagonal (plus the `exp` error, below 1e-11 relative, see `sums.rs`).
pub(super) const TOLERANCE: f64 = 1e-7;
/// Covers the relative error of `exp_nonpositive` (below 1e-11) in the bound.
const SLACK: f64 = 1.0 + 1e-9;
/// Cell side as a multiple of σ (0.25: on the creature the bound stays below 1e-8, so no vertex
/// falls back; 0.15 to 0.3 all run within 2× of the best).
pub(super) const CELL: f64 = 0.25;
/// Fewest entries for a cell to be expanded (smaller ones stay as entries).
pub(super) const MIN_CELL: usize = 16;

/// Cells per group (the SIMD width of the evaluation); a pair's cells are padded with empty
/// ones (zero mass and moments, which add nothing).
pub(super) const LANES: usize = 8;

/// [`LANES`] expanded cells in structure-of-arrays form.
#[derive(Clone)]
pub(super) struct CellGroup {
    /// Expansion points `(bⱼ₀, bₖ₀)`.
    b0: [[f64; LANES]; 2],
    /// Largest `|bⱼ − bⱼ₀|`, `|bₖ − bₖ₀|` over a cell's entries.
    half: [[f64; LANES]; 2],
    /// `Σ P` (all `P ≥ 0`).
    mass: [f64; LANES],
    /// `Σ (P, P·cₓ, P·c_y, P·c_z)·Δbⱼᵐ·Δbₖˡ`, ordered by `n = m + l`, then by `m`.
    moments: [[[f64; LANES]; 4]; MOMENTS],
}

impl CellGroup {
    fn empty() -> Self {
        Self {
            b0: [[0.0; LANES]; 2],
            half: [[0.0; LANES]; 2],
            mass: [0.0; LANES],
            moments: [[[0.0; LANES]; 4]; MOMENTS],
        }
    }
}

/// Splits a pair list into cells of side `CELL·σ`: those with at least [`MIN_CELL`] entries are
/// expanded (in groups of [`LANES`]), the entries of the others are returned as they are.
pub(super) fn build(entries: &[Entry], sigma: f64) -> (Vec<Entry>, Vec<CellGroup>) {
    let side = CELL * sigma;
    let mut keyed: Vec<((i64, i64), &Entry)> =
        entries.iter().map(|e| (((e.bj / side).floor() as i64, (e.bk / side).floor() as i64), e)).collect();
    keyed.sort_unstable_by_key(|k| k.0);
    let sorted: Vec<&Entry> = keyed.iter().map(|k| k.1).collect();
    let key = |e: &Entry| ((e.bj / side).floor() as i64, (e.bk / side).floor() as i64);
    let mut raw = Vec::new();
    let mut groups: Vec<CellGroup> = Vec::new();
    let mut count = 0;
    for group in sorted.chunk_by(|a, b| key(a) == key(b)) {
        if group.len() < MIN_CELL {
            raw.extend(group.iter().map(|e| **e));
            continue;
        }
        if count % LANES == 0 {
            groups.push(CellGroup::empty());
        }
        let (g, l) = (groups.last_mut().expect("pushed"), count % LANES);
        count += 1;
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for e in group {
            lo = [lo[0].min(e.bj), lo[1].min(e.bk)];
            hi = [hi[0].max(e.bj), hi[1].max(e.bk)];
        }
        let b0 = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
        g.b0[0][l] = b0[0];
        g.b0[1][l] = b0[1];
        for e in group {
            let d = [e.bj - b0[0], e.bk - b0[1]];
            g.half[0][l] = g.half[0][l].max(d[0].abs());
            g.half[1][l] = g.half[1][l].max(d[1].abs());
            g.mass[l] += e.p;
            let mut pj = [1.0; ORDER];
            let mut pk = [1.0; ORDER];
            for i in 1..ORDER {
                pj[i] = pj[i - 1] * d[0];
                pk[i] = pk[i - 1] * d[1];
            }
            let value = [e.p, e.pc[0], e.pc[1], e.pc[2]];
            let mut idx = 0;
            for n in 0..ORDER {
                for m in 0..=n {
                    let f = pj[m] * pk[n - m];
                    for c in 0..4 {
                        g.moments[idx][c][l] += f * value[c];
                    }
                    idx += 1;
                }
            }
        }
    }
    (raw, groups)
}

/// The expanded cells' `(Σ P·g, Σ P·c·g)` for vertex weights `(aj, ak)` and the bound on
/// `Σ P·|R|` (see the module's comment).
pub(super) fn cell_sums(simd: Simd, groups: &[CellGroup], aj: f64, ak: f64, inv_sigma: f64) -> ([f64; 4], f64) {
    match simd.instruction_set() {
        InstructionSet::Baseline => sums(groups, aj, ak, inv_sigma),
        // SAFETY: a `Simd` of this set exists only where AVX2 and FMA were detected.
        #[cfg(target_arch = "x86_64")]
        InstructionSet::Avx2Fma => unsafe { sums_avx2(groups, aj, ak, inv_sigma) },
        // SAFETY: a `Simd` of this set exists only where AVX-512F, AVX2 and FMA were detected.
        #[cfg(target_arch = "x86_64")]
        InstructionSet::Avx512 => unsafe { sums_avx512(groups, aj, ak, inv_sigma) },
        // SAFETY: every aarch64 CPU has NEON.
        #[cfg(target_arch = "aarch64")]
        InstructionSet::Neon => unsafe { sums_neon(groups, aj, ak, inv_sigma) },
    }
}

/// `γ = (−sₖ)ᵐ/m!·sⱼˡ/l!` in the moments' order.
#[inline(always)]
fn gamma(sj: f64, sk: f64) -> [f64; MOMENTS] {
    let mut pa = [1.0; ORDER];
    let mut pb = [1.0; ORDER];
    for i in 1..ORDER {
        pa[i] = pa[i - 1] * -sk / i as f64;
        pb[i] = pb[i - 1] * sj / i as f64;
    }
    let mut gamma = [0.0; MOMENTS];
    let mut idx = 0;
    for n in 0..ORDER {
        for m in 0..=n {
            gamma[idx] = pa[m] * pb[n - m];
            idx += 1;
        }
    }
    gamma
}

/// Per cell of a group, `q[n] = (−1)ⁿ·Hₙ(x₀)·g(x₀)` (`Hₙ₊₁ = 2x·Hₙ − 2n·Hₙ₋₁`), and the
/// remainder bound added to `bound`.
#[inline(always)]
fn hermite(g: &CellGroup, sj: f64, sk: f64, bound: &mut [f64; LANES]) -> [[f64; LANES]; ORDER] {
    let mut q = [[0.0f64; LANES]; ORDER];
    for l in 0..LANES {
        let x0 = sj * g.b0[1][l] - sk * g.b0[0][l];
        let g0 = exp_nonpositive(-x0 * x0);
        q[0][l] = g0;
        q[1][l] = -2.0 * x0 * g0;
        for n in 1..ORDER - 1 {
            q[n + 1][l] = -2.0 * x0 * q[n][l] - 2.0 * n as f64 * q[n - 1][l];
        }
        let delta = sj * g.half[1][l] + sk * g.half[0][l];
        let xi = (x0.abs() - delta).max(0.0);
        let mut power = 1.0;
        for _ in 0..ORDER {
            power *= delta;
        }
        bound[l] += SLACK * REMAINDER * power * exp_nonpositive(-0.5 * xi * xi) * g.mass[l];
    }
    q
}

/// [`sums`] with AVX2+FMA: the moments' loop in two 4-wide vectors per group.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn sums_avx2(groups: &[CellGroup], aj: f64, ak: f64, inv_sigma: f64) -> ([f64; 4], f64) {
    use core::arch::x86_64::*;
    let (sj, sk) = (aj * inv_sigma, ak * inv_sigma);
    let gamma = gamma(sj, sk);
    let mut acc = [[_mm256_setzero_pd(); 2]; 4];
    let mut bound = [0.0f64; LANES];
    for g in groups {
        let q = hermite(g, sj, sk, &mut bound);
        let mut idx = 0;
        for (n, qn) in q.iter().enumerate() {
            let qv = [_mm256_loadu_pd(qn.as_ptr()), _mm256_loadu_pd(qn.as_ptr().add(4))];
            for _ in 0..=n {
                let gv = _mm256_set1_pd(gamma[idx]);
                for h in 0..2 {
                    let f = _mm256_mul_pd(qv[h], gv);
                    for c in 0..4 {
                        let m = _mm256_loadu_pd(g.moments[idx][c].as_ptr().add(4 * h));
                        acc[c][h] = _mm256_fmadd_pd(f, m, acc[c][h]);
                    }
                }
                idx += 1;
            }
        }
    }
    let total = acc.map(|[a, b]| {
        let mut lanes = [0.0f64; 8];
        _mm256_storeu_pd(lanes.as_mut_ptr(), a);
        _mm256_storeu_pd(lanes.as_mut_ptr().add(4), b);
        lanes.iter().sum()
    });
    (total, bound.iter().sum())
}

/// [`sums`] with AVX-512: the moments' loop in one 8-wide vector per group.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn sums_avx512(groups: &[CellGroup], aj: f64, ak: f64, inv_sigma: f64) -> ([f64; 4], f64) {
    use core::arch::x86_64::*;
    let (sj, sk) = (aj * inv_sigma, ak * inv_sigma);
    let gamma = gamma(sj, sk);
    let mut acc = [_mm512_setzero_pd(); 4];
    let mut bound = [0.0f64; LANES];
    for g in groups {
        let q = hermite(g, sj, sk, &mut bound);
        let mut idx = 0;
        for (n, qn) in q.iter().enumerate() {
            let qv = _mm512_loadu_pd(qn.as_ptr());
            for _ in 0..=n {
                let f = _mm512_mul_pd(qv, _mm512_set1_pd(gamma[idx]));
                for c in 0..4 {
                    acc[c] = _mm512_fmadd_pd(f, _mm512_loadu_pd(g.moments[idx][c].as_ptr()), acc[c]);
                }
                idx += 1;
            }
        }
    }
    let total = acc.map(|a| {
        let mut lanes = [0.0f64; 8];
        _mm512_storeu_pd(lanes.as_mut_ptr(), a);
        lanes.iter().sum()
    });
    (total, bound.iter().sum())
}

/// [`sums`] with NEON: the moments' loop in four 2-wide vectors per group.
#[cfg(target_arch = "aarch64")]
#[target_feature(enable = "neon")]
unsafe fn sums_neon(groups: &[CellGroup], aj: f64, ak: f64, inv_sigma: f64) -> ([f64; 4], f64) {
    use core::arch::aarch64::*;
    let (sj, sk) = (aj * inv_sigma, ak * inv_sigma);
    let gamma = gamma(sj, sk);
    let mut acc = [[vdupq_n_f64(0.0); 4]; 4];
    let mut bound = [0.0f64; LANES];
    // SAFETY: every array read has LANES = 8 doubles, and 2·h + 2 ≤ 8.
    let ld = |a: &[f64; LANES], h: usize| unsafe { vld1q_f64(a.as_ptr().add(2 * h)) };
    for g in groups {
        let q = hermite(g, sj, sk, &mut bound);
        let mut idx = 0;
        for (n, qn) in q.iter().enumerate() {
            let qv = [ld(qn, 0), ld(qn, 1), ld(qn, 2), ld(qn, 3)];
            for _ in 0..=n {
                let gv = vdupq_n_f64(gamma[idx]);
                for h in 0..4 {
                    let f = vmulq_f64(qv[h], gv);
                    for c in 0..4 {
                        acc[c][h] = vfmaq_f64(acc[c][h], f, ld(&g.moments[idx][c], h));
                    }
                }
                idx += 1;
            }
        }
    }
    let total = acc.map(|a| {
        let mut lanes = [0.0f64; LANES];
        for (h, v) in a.iter().enumerate() {
            // SAFETY: two doubles at 2·h < 8.
            unsafe { vst1q_f64(lanes.as_mut_ptr().add(2 * h), *v) };
        }
        lanes.iter().sum()
    });
    (total, bound.iter().sum())
}

/// The portable copy of [`cell_sums`].
fn sums(groups: &[CellGroup], aj: f64, ak: f64, inv_sigma: f64) -> ([f64; 4], f64) {
    let (sj, sk) = (aj * inv_sigma, ak * inv_sigma);
    let gamma = gamma(sj, sk);
    let mut acc = [[0.0f64; LANES]; 4];
    let mut bound = [0.0f64; LANES];
    for g in groups {
        let q = hermite(g, sj, sk, &mut bound);
        let mut idx = 0;
        for (n, qn) in q.iter().enumerate() {
            for _ in 0..=n {
                for l in 0..LANES {
                    let f = qn[l] * gamma[idx];
                    for c in 0..4 {
                        acc[c][l] += f * g.moments[idx][c][l];
                    }
                }
                idx += 1;
            }
        }
    }
    (acc.map(|a| a.iter().sum()), bound.iter().sum())
}

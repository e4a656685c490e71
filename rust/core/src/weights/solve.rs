//! Conjugate gradients for a symmetric positive definite system with several right-hand sides
//! at once (one per bone), preconditioned by the diagonal. The columns share every pass over
//! the matrix; each has its own step and stops when its residual is small enough.
//!
//! The passes run on the thread pool in blocks of rows of a fixed size, and sums are added
//! block by block in order, so the result does not depend on the thread count.

use rayon::prelude::*;

use super::laplacian::Csr;

/// Rows per block of a parallel pass.
const BLOCK: usize = 1024;

/// `A·X` for `X` with `c` columns (row-major).
fn multiply(a: &Csr, x: &[f64], c: usize, out: &mut [f64]) {
    out.par_chunks_mut(BLOCK * c).enumerate().for_each(|(block, rows)| {
        let first = block * BLOCK;
        for (k, row) in rows.chunks_exact_mut(c).enumerate() {
            row.fill(0.0);
            for (j, v) in a.row(first + k) {
                for (o, xj) in row.iter_mut().zip(&x[j * c..(j + 1) * c]) {
                    *o += v * xj;
                }
            }
        }
    });
}

/// Per-column sums over the rows of `f(block's rows)`, added block by block in order.
fn column_sums(rows: usize, c: usize, f: impl Fn(std::ops::Range<usize>, &mut [f64]) + Sync) -> Vec<f64> {
    let blocks = rows.div_ceil(BLOCK);
    let partial: Vec<Vec<f64>> = (0..blocks)
        .into_par_iter()
        .map(|b| {
            let mut sums = vec![0.0; c];
            f(b * BLOCK..((b + 1) * BLOCK).min(rows), &mut sums);
            sums
        })
        .collect();
    add_in_order(partial, c)
}

/// The blocks' per-column sums added in block order.
fn add_in_order(partial: Vec<Vec<f64>>, c: usize) -> Vec<f64> {
    let mut out = vec![0.0; c];
    for sums in partial {
        for (o, s) in out.iter_mut().zip(sums) {
            *o += s;
        }
    }
    out
}

fn column_dots(a: &[f64], b: &[f64], c: usize) -> Vec<f64> {
    column_sums(a.len() / c, c, |range, sums| {
        let span = range.start * c..range.end * c;
        for (ra, rb) in a[span.clone()].chunks_exact(c).zip(b[span].chunks_exact(c)) {
            for k in 0..c {
                sums[k] += ra[k] * rb[k];
            }
        }
    })
}

/// Solves `A·X = B` (`c` columns, row-major) from the guess in `x`, until each column's residual
/// is at most `tolerance` times its right-hand side (a zero one: the largest one), or
/// `max_iterations`. Returns the iterations taken.
pub(crate) fn conjugate_gradients(
    a: &Csr,
    b: &[f64],
    x: &mut [f64],
    c: usize,
    tolerance: f64,
    max_iterations: usize,
) -> usize {
    let n = a.rows();
    if n == 0 || c == 0 {
        return 0;
    }
    let inverse_diagonal: Vec<f64> = (0..n)
        .map(|i| {
            let d = a.row(i).find(|&(j, _)| j == i).map_or(0.0, |(_, v)| v);
            if d > 0.0 {
                1.0 / d
            } else {
                1.0
            }
        })
        .collect();
    let mut r = vec![0.0; n * c];
    multiply(a, x, c, &mut r);
    for (ri, bi) in r.iter_mut().zip(b) {
        *ri = bi - *ri;
    }
    // Each column's residual relative to its right-hand side; a column whose right-hand side is
    // zero (its solution is zero) relative to the largest one's, else it would never be done.
    let norms = column_dots(b, b, c);
    let largest = norms.iter().copied().fold(0.0, f64::max);
    let goal: Vec<f64> = norms.iter().map(|&s| tolerance * tolerance * if s > 0.0 { s } else { largest }).collect();
    let mut z: Vec<f64> = r.iter().enumerate().map(|(i, ri)| ri * inverse_diagonal[i / c]).collect();
    let mut p = z.clone();
    let mut rz = column_dots(&r, &z, c);
    let mut q = vec![0.0; n * c];
    let mut active: Vec<bool> = column_dots(&r, &r, c).iter().zip(&goal).map(|(rr, g)| rr > g).collect();
    let mut iterations = 0;
    while iterations < max_iterations && active.iter().any(|&a| a) {
        iterations += 1;
        multiply(a, &p, c, &mut q);
        let pq = column_dots(&p, &q, c);
        let alpha: Vec<f64> = (0..c).map(|k| if active[k] && pq[k] > 0.0 { rz[k] / pq[k] } else { 0.0 }).collect();
        // x += α·p, r −= α·q, z = D⁻¹·r, with r·r and r·z, in one pass.
        let partial: Vec<Vec<f64>> = x
            .par_chunks_mut(BLOCK * c)
            .zip(r.par_chunks_mut(BLOCK * c))
            .zip(z.par_chunks_mut(BLOCK * c))
            .enumerate()
            .map(|(block, ((xs, rs), zs))| {
                let first = block * BLOCK;
                let mut sums = vec![0.0; 2 * c];
                for (row, ((xr, rr), zr)) in
                    xs.chunks_exact_mut(c).zip(rs.chunks_exact_mut(c)).zip(zs.chunks_exact_mut(c)).enumerate()
                {
                    let i = first + row;
                    let d = inverse_diagonal[i];
                    for k in 0..c {
                        xr[k] += alpha[k] * p[i * c + k];
                        let ri = rr[k] - alpha[k] * q[i * c + k];
                        rr[k] = ri;
                        let zi = ri * d;
                        zr[k] = zi;
                        sums[k] += ri * ri;
                        sums[c + k] += ri * zi;
                    }
                }
                sums
            })
            .collect();
        let sums = add_in_order(partial, 2 * c);
        let (rr, rz_next) = sums.split_at(c);
        for k in 0..c {
            if active[k] && (rr[k] <= goal[k] || !(pq[k] > 0.0)) {
                active[k] = false;
            }
        }
        let beta: Vec<f64> = (0..c).map(|k| if active[k] && rz[k] > 0.0 { rz_next[k] / rz[k] } else { 0.0 }).collect();
        p.par_chunks_mut(BLOCK * c).zip(z.par_chunks(BLOCK * c)).for_each(|(pb, zb)| {
            for (pr, zr) in pb.chunks_exact_mut(c).zip(zb.chunks_exact(c)) {
                for k in 0..c {
                    pr[k] = zr[k] + beta[k] * pr[k];
                }
            }
        });
        rz = rz_next.to_vec();
    }
    iterations
}

//! Conjugate gradients for a symmetric positive definite system with several right-hand sides
//! at once (one per bone), preconditioned by the diagonal. The columns share every pass over
//! the matrix; each has its own step and stops when its residual is small enough.

use super::laplacian::Csr;

/// `A·X` for `X` with `c` columns (row-major).
fn multiply(a: &Csr, x: &[f64], c: usize, out: &mut [f64]) {
    for i in 0..a.rows() {
        let row = &mut out[i * c..(i + 1) * c];
        row.fill(0.0);
        for (j, v) in a.row(i) {
            for (o, xj) in row.iter_mut().zip(&x[j * c..(j + 1) * c]) {
                *o += v * xj;
            }
        }
    }
}

fn column_dots(a: &[f64], b: &[f64], c: usize) -> Vec<f64> {
    let mut out = vec![0.0; c];
    for (ra, rb) in a.chunks_exact(c).zip(b.chunks_exact(c)) {
        for k in 0..c {
            out[k] += ra[k] * rb[k];
        }
    }
    out
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
    let precondition = |r: &[f64], z: &mut [f64]| {
        for (i, (zr, rr)) in z.chunks_exact_mut(c).zip(r.chunks_exact(c)).enumerate() {
            for (zk, rk) in zr.iter_mut().zip(rr) {
                *zk = rk * inverse_diagonal[i];
            }
        }
    };
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
    let mut z = vec![0.0; n * c];
    precondition(&r, &mut z);
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
        for i in 0..n {
            for k in 0..c {
                x[i * c + k] += alpha[k] * p[i * c + k];
                r[i * c + k] -= alpha[k] * q[i * c + k];
            }
        }
        let rr = column_dots(&r, &r, c);
        for k in 0..c {
            if active[k] && (rr[k] <= goal[k] || !(pq[k] > 0.0)) {
                active[k] = false;
            }
        }
        precondition(&r, &mut z);
        let rz_next = column_dots(&r, &z, c);
        let beta: Vec<f64> = (0..c).map(|k| if active[k] && rz[k] > 0.0 { rz_next[k] / rz[k] } else { 0.0 }).collect();
        for (pr, zr) in p.chunks_exact_mut(c).zip(z.chunks_exact(c)) {
            for k in 0..c {
                pr[k] = zr[k] + beta[k] * pr[k];
            }
        }
        rz = rz_next;
    }
    iterations
}

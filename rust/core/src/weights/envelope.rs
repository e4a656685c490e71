//! A direct solve of a sparse symmetric positive definite system with several right-hand
//! sides: the rows renumbered by reverse Cuthill–McKee, so that the nonzeros gather near the
//! diagonal, then a Cholesky factorization within each row's envelope (the columns from the
//! row's first nonzero to the diagonal, where all of the factor's fill lands).
//!
//! For the patches weight transfer fills in (a few thousand vertices of a surface) the
//! envelope is narrow and the factorization costs a fraction of the iterations conjugate
//! gradients take on the same system; `factor` refuses a system whose envelope would cost more
//! than a budget (or that is not positive definite), and the caller iterates instead.

use std::collections::VecDeque;

use super::laplacian::Csr;

/// The Cholesky factor of a renumbered system.
pub(crate) struct Envelope {
    /// `order[k]`: the original row at position `k`.
    order: Vec<u32>,
    /// Each position's first column in the envelope.
    first: Vec<u32>,
    /// Where each position's row of the factor starts in `values` (`first..=k`).
    start: Vec<usize>,
    values: Vec<f64>,
}

/// Reverse Cuthill–McKee: breadth-first from a vertex of least degree in each connected part,
/// neighbours by increasing degree, the whole order reversed.
fn reverse_cuthill_mckee(a: &Csr) -> Vec<u32> {
    let n = a.rows();
    let degree: Vec<usize> = (0..n).map(|i| a.row(i).filter(|&(j, _)| j != i).count()).collect();
    let mut by_degree: Vec<u32> = (0..n as u32).collect();
    by_degree.sort_by_key(|&i| (degree[i as usize], i));
    let mut placed = vec![false; n];
    let mut order = Vec::with_capacity(n);
    let mut queue = VecDeque::new();
    let mut next: Vec<u32> = Vec::new();
    for &seed in &by_degree {
        if placed[seed as usize] {
            continue;
        }
        placed[seed as usize] = true;
        queue.push_back(seed);
        while let Some(v) = queue.pop_front() {
            order.push(v);
            next.clear();
            next.extend(a.row(v as usize).map(|(j, _)| j as u32).filter(|&j| !placed[j as usize]));
            next.sort_by_key(|&j| (degree[j as usize], j));
            for &j in &next {
                placed[j as usize] = true;
                queue.push_back(j);
            }
        }
    }
    order.reverse();
    order
}

impl Envelope {
    /// The factor of `a` (symmetric), or None when its envelope holds more than `budget`
    /// multiply-adds' worth of work or `a` is not positive definite.
    pub fn factor(a: &Csr, budget: f64) -> Option<Envelope> {
        let n = a.rows();
        let order = reverse_cuthill_mckee(a);
        let mut position = vec![0u32; n];
        for (k, &i) in order.iter().enumerate() {
            position[i as usize] = k as u32;
        }
        let first: Vec<u32> = (0..n)
            .map(|k| {
                a.row(order[k] as usize)
                    .map(|(j, _)| position[j])
                    .filter(|&p| p as usize <= k)
                    .min()
                    .unwrap_or(k as u32)
            })
            .collect();
        let work: f64 = (0..n).map(|k| ((k - first[k] as usize) as f64).powi(2)).sum();
        if work > budget {
            return None;
        }
        let mut start = Vec::with_capacity(n + 1);
        let mut total = 0usize;
        for k in 0..n {
            start.push(total);
            total += k - first[k] as usize + 1;
        }
        start.push(total);
        let mut values = vec![0.0f64; total];
        for k in 0..n {
            for (j, v) in a.row(order[k] as usize) {
                let p = position[j] as usize;
                if p <= k {
                    values[start[k] + p - first[k] as usize] += v;
                }
            }
        }
        // Row by row: L[k][j] = (A[k][j] − Σ L[k][m]·L[j][m]) / L[j][j], m over both envelopes.
        for k in 0..n {
            let fk = first[k] as usize;
            for j in fk..=k {
                let fj = first[j] as usize;
                let from = fk.max(fj);
                let (row_k, row_j) = (start[k], start[j]);
                let mut sum = values[row_k + j - fk];
                for m in from..j {
                    sum -= values[row_k + m - fk] * values[row_j + m - fj];
                }
                if j < k {
                    values[row_k + j - fk] = sum / values[row_j + j - fj];
                } else {
                    if !(sum > 0.0) || !sum.is_finite() {
                        return None;
                    }
                    values[row_k + k - fk] = sum.sqrt();
                }
            }
        }
        Some(Envelope { order, first, start, values })
    }

    /// Solves for `b` (`c` columns, row-major by original row) into `x`.
    pub fn solve(&self, b: &[f64], x: &mut [f64], c: usize) {
        let n = self.order.len();
        let mut y = vec![0.0f64; n * c];
        for (k, &i) in self.order.iter().enumerate() {
            y[k * c..(k + 1) * c].copy_from_slice(&b[i as usize * c..(i as usize + 1) * c]);
        }
        // L·z = y, forward.
        for k in 0..n {
            let fk = self.first[k] as usize;
            let row = &self.values[self.start[k]..self.start[k + 1]];
            let (done, rest) = y.split_at_mut(k * c);
            let yk = &mut rest[..c];
            for (m, &l) in (fk..k).zip(row) {
                for (t, s) in yk.iter_mut().zip(&done[m * c..(m + 1) * c]) {
                    *t -= l * s;
                }
            }
            let d = row[k - fk];
            yk.iter_mut().for_each(|t| *t /= d);
        }
        // Lᵀ·w = z, backward: each row, once final, is taken out of the rows above it.
        for k in (0..n).rev() {
            let fk = self.first[k] as usize;
            let row = &self.values[self.start[k]..self.start[k + 1]];
            let d = row[k - fk];
            let (before, rest) = y.split_at_mut(k * c);
            let yk = &mut rest[..c];
            yk.iter_mut().for_each(|t| *t /= d);
            for (m, &l) in (fk..k).zip(row) {
                for (t, s) in before[m * c..(m + 1) * c].iter_mut().zip(yk.iter()) {
                    *t -= l * s;
                }
            }
        }
        for (k, &i) in self.order.iter().enumerate() {
            x[i as usize * c..(i as usize + 1) * c].copy_from_slice(&y[k * c..(k + 1) * c]);
        }
    }
}

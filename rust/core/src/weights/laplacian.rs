//! The energy that fills weights in: `Q = K + K·M⁻¹·K` (Abdrashitov et al. 2023), with `K` the
//! cotangent stiffness (`−L`: positive semi-definite, zero on constants) and `M` the lumped
//! (barycentric) vertex areas. Its rows for the unknown vertices split into the block among
//! the unknowns and the part that multiplies the known weights.

use glam::Vec3;

/// A sparse matrix by rows (columns sorted within a row).
#[derive(Clone, Debug, Default)]
pub(crate) struct Csr {
    pub offsets: Vec<u32>,
    pub columns: Vec<u32>,
    pub values: Vec<f64>,
}

impl Csr {
    pub fn row(&self, i: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let r = self.offsets[i] as usize..self.offsets[i + 1] as usize;
        self.columns[r.clone()].iter().map(|&c| c as usize).zip(self.values[r].iter().copied())
    }

    pub fn rows(&self) -> usize {
        self.offsets.len() - 1
    }

    /// From `(row, column, value)` triplets, repeated entries added.
    pub fn from_triplets(rows: usize, mut triplets: Vec<(u32, u32, f64)>) -> Csr {
        triplets.sort_unstable_by_key(|t| (t.0, t.1));
        let mut m = Csr { offsets: vec![0; rows + 1], columns: Vec::new(), values: Vec::new() };
        let mut last: Option<(u32, u32)> = None;
        for (r, c, v) in triplets {
            if last == Some((r, c)) {
                *m.values.last_mut().expect("an entry") += v;
                continue;
            }
            last = Some((r, c));
            m.columns.push(c);
            m.values.push(v);
            m.offsets[r as usize + 1] += 1;
        }
        for i in 0..rows {
            m.offsets[i + 1] += m.offsets[i];
        }
        m
    }
}

/// Cotangents beyond this (angles within about 0.06° of 0 or 180°) are clamped: a sliver
/// triangle would otherwise dominate its neighbours.
const MAX_COTANGENT: f64 = 1e3;

/// The cotangent stiffness `K` and the lumped areas `M` of a triangle mesh. Triangles of no
/// area add nothing; a vertex on none gets the smallest positive area of the others.
pub(crate) fn stiffness_and_mass(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> (Csr, Vec<f64>) {
    let n = positions.len();
    let mut triplets: Vec<(u32, u32, f64)> = Vec::with_capacity(triangles.len() * 9);
    let mut mass = vec![0.0f64; n];
    for t in triangles {
        let p = t.map(|i| Vec3::from_array(positions[i as usize]).as_dvec3());
        let double_area = (p[1] - p[0]).cross(p[2] - p[0]).length();
        if !(double_area > 0.0) || !double_area.is_finite() {
            continue;
        }
        for corner in 0..3 {
            let (i, j) = ((corner + 1) % 3, (corner + 2) % 3);
            let cot = ((p[i] - p[corner]).dot(p[j] - p[corner]) / double_area).clamp(-MAX_COTANGENT, MAX_COTANGENT);
            let half = 0.5 * cot;
            let (a, b) = (t[i], t[j]);
            triplets.push((a, b, -half));
            triplets.push((b, a, -half));
            triplets.push((a, a, half));
            triplets.push((b, b, half));
        }
        for &i in t {
            mass[i as usize] += double_area / 6.0;
        }
    }
    let smallest = mass.iter().copied().filter(|&m| m > 0.0).fold(f64::INFINITY, f64::min);
    let fill = if smallest.is_finite() { smallest } else { 1.0 };
    for m in &mut mass {
        if !(*m > 0.0) {
            *m = fill;
        }
    }
    (Csr::from_triplets(n, triplets), mass)
}

/// Row `i` of `Q = K + K·M⁻¹·K` added into `dense` (indexed by vertex); the columns it touches
/// are marked in `seen` and listed in `touched`, for the caller to read and clear.
pub(crate) fn q_row(k: &Csr, mass: &[f64], i: usize, dense: &mut [f64], seen: &mut [bool], touched: &mut Vec<u32>) {
    let mut add = |c: usize, v: f64| {
        if !seen[c] {
            seen[c] = true;
            touched.push(c as u32);
        }
        dense[c] += v;
    };
    for (j, kij) in k.row(i) {
        add(j, kij);
        let s = kij / mass[j];
        for (l, kjl) in k.row(j) {
            add(l, s * kjl);
        }
    }
}

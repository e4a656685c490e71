//! What an update after a weight change keeps for the next one: each weight vector's sums per
//! bone pair, so that a vertex the next stroke reaches computes again only the pairs whose lists
//! that stroke changed.
//!
//! A vertex's center is a ratio of totals, each a sum over its bone pairs (in the order of its
//! weight vector) of one value per pair. A pair's value depends only on the vertex's weights and
//! on the pair's list of triangles; a list that a stroke did not change gives the same value bit
//! for bit, so taking it from before and adding the values up in the same order gives the center
//! a full precompute gives, bit for bit. Values are kept per weight vector, and only for the
//! vectors some vertex has: a vector no vertex has any more could come back after a pair of its
//! changed, with values no longer true.

use std::collections::{HashMap, HashSet};

use super::super::isa::Simd;
use super::{cells, sums, PairIndex, WeightKey, WeightVectors};

/// One pair's part of a vertex's fast-path totals: `Σ e·P` and `Σ e·P·c` (raw entries plus
/// expanded cells) and the cells' error bound; `None` where the pair has no list.
type FastPart = Option<[f64; 5]>;
/// One pair's exact sums; `None` where the pair has no list.
type ExactPart = Option<[f64; 4]>;

/// One weight vector's per-pair values, in the order of its pairs.
pub(super) struct ClassSums {
    fast: Vec<FastPart>,
    /// Only where the vertex took the exact sums.
    exact: Option<Vec<ExactPart>>,
}

impl ClassSums {
    /// Nothing kept (an update that keeps nothing).
    pub(super) fn none() -> Self {
        Self { fast: Vec::new(), exact: None }
    }
}

/// The per-pair sums of the weight vectors an update computed or kept (see the module doc), for
/// the same positions, triangles and σ. Opaque: what the next update reuses.
#[derive(Default)]
pub struct CenterSums {
    sigma_bits: u32,
    classes: HashMap<WeightKey, ClassSums>,
}

impl CenterSums {
    pub(super) fn new(sigma: f32) -> Self {
        Self { sigma_bits: sigma.to_bits(), classes: HashMap::new() }
    }

    /// Whether these sums were computed with `sigma`.
    pub(super) fn is_for(&self, sigma: f32) -> bool {
        self.sigma_bits == sigma.to_bits()
    }

    /// The values of the weight vector `key`, if kept and of its number of pairs.
    pub(super) fn get(&self, key: &WeightKey, pairs: usize) -> Option<&ClassSums> {
        self.classes.get(key).filter(|c| c.fast.len() == pairs)
    }

    pub(super) fn take(&mut self, key: &WeightKey) -> Option<ClassSums> {
        self.classes.remove(key)
    }

    pub(super) fn insert(&mut self, key: WeightKey, sums: ClassSums) {
        self.classes.insert(key, sums);
    }

    /// How many weight vectors have values.
    pub fn len(&self) -> usize {
        self.classes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.classes.is_empty()
    }
}

/// A vertex's weight vector as a key.
pub(super) fn key_of(weights: &WeightVectors, v: usize) -> WeightKey {
    weights.of(v).iter().map(|&(b, w)| (b, w.to_bits())).collect()
}

/// The number of bone pairs of vertex `v`'s weight vector.
pub(super) fn pair_count(weights: &WeightVectors, v: usize) -> usize {
    let n = weights.of(v).len();
    n * n.saturating_sub(1) / 2
}

/// What computing one vertex's center gave.
pub(super) enum Outcome {
    /// Its center (if its denominator is positive), whether the fast path gave it, its values.
    Done(Option<[f64; 3]>, bool, ClassSums),
    /// It needs the exact sums of a pair whose list is not in the index (kept only on the fast
    /// path, and the fast path's bound no longer holds): compute it again with its lists.
    NeedsLists,
}

/// The center of vertex `v` as [`PairIndex::center`] computes it (the same operations in the
/// same order), taking the values of the pairs not in `changed` from `kept`. Only for an index
/// with the fast path (`index.fast`), whose exact sums need no underflow shift.
pub(super) fn center(
    index: &PairIndex,
    simd: Simd,
    weights: &WeightVectors,
    v: usize,
    inv_sigma2: f64,
    kept: Option<&ClassSums>,
    changed: &HashSet<(u32, u32)>,
) -> Outcome {
    debug_assert!(index.fast);
    let a = weights.of(v);
    let pairs: Vec<(u32, u32, f64, f64)> =
        (0..a.len()).flat_map(|x| a[x + 1..].iter().map(move |&(k, ak)| (a[x].0, k, a[x].1, ak))).collect();
    let reuse = |j: u32, k: u32| kept.filter(|_| !changed.contains(&(j, k)));
    let inv_sigma = inv_sigma2.sqrt();
    let mut fast = Vec::with_capacity(pairs.len());
    let mut total = [0.0f64; 4];
    let mut bound = 0.0;
    for (p, &(j, k, aj, ak)) in pairs.iter().enumerate() {
        let part = match reuse(j, k) {
            Some(c) => c.fast[p],
            None => index.ids.get(&(j, k)).map(|&id| {
                let s = sums::pair_sums(simd, &index.raw.list(id), aj, ak, inv_sigma2, 0.0);
                let (c, b) = cells::cell_sums(
                    simd,
                    &index.cells[index.cell_starts[id]..index.cell_starts[id + 1]],
                    aj,
                    ak,
                    inv_sigma,
                );
                [s[0] + c[0], s[1] + c[1], s[2] + c[2], s[3] + c[3], b]
            }),
        };
        fast.push(part);
        if let Some(x) = part {
            let f = 2.0 * aj * ak;
            for k in 0..4 {
                total[k] += f * x[k];
            }
            bound += f * x[4];
        }
    }
    if total[0] > 0.0 && bound <= index.tolerance * total[0] {
        let d = total[0];
        let c = [total[1] / d, total[2] / d, total[3] / d];
        if c.iter().all(|x| x.is_finite()) {
            return Outcome::Done(Some(c), true, ClassSums { fast, exact: None });
        }
    }
    let mut exact = Vec::with_capacity(pairs.len());
    let mut total = [0.0f64; 4];
    for (p, &(j, k, aj, ak)) in pairs.iter().enumerate() {
        let part = match (fast[p], reuse(j, k).and_then(|c| c.exact.as_ref())) {
            (None, _) => None, // no list
            (Some(_), Some(e)) => e[p],
            (Some(_), None) => match index.ids.get(&(j, k)) {
                Some(&id) => Some(sums::pair_sums(simd, &index.exact.list(id), aj, ak, inv_sigma2, 0.0)),
                None => return Outcome::NeedsLists,
            },
        };
        exact.push(part);
        if let Some(s) = part {
            let f = 2.0 * aj * ak;
            for k in 0..4 {
                total[k] += f * s[k];
            }
        }
    }
    let d = total[0];
    let c = (d > 0.0).then(|| [total[1] / d, total[2] / d, total[3] / d]).filter(|c| c.iter().all(|x| x.is_finite()));
    Outcome::Done(c, false, ClassSums { fast, exact: Some(exact) })
}

//! A vertex's center from its bone pairs' values, and what an update after a weight change
//! keeps of those values for the next one (each weight vector's values per bone pair), so that a
//! vertex the next stroke reaches computes again only the pairs whose lists that stroke changed.
//!
//! A vertex's center is a ratio of totals, each a sum over its bone pairs (in the order of its
//! weight vector) of one value per pair. A pair's value depends only on the vertex's weights and
//! on the pair's list of triangles; a list that a stroke did not change gives the same value bit
//! for bit, so taking it from before and adding the values up in the same order gives the center
//! a full precompute gives, bit for bit. Values are kept per weight vector, and only for the
//! vectors some vertex has: a vector no vertex has any more could come back after a pair of its
//! changed, with values no longer true.

use std::collections::{HashMap, HashSet};
use std::hash::Hasher;

use super::super::isa::Simd;
use super::{cells, sums, PairIndex, WeightKey, WeightVectors, SHIFT_THRESHOLD};

/// A fingerprint of `positions` and `triangles` (SipHash over their bits and counts): kept sums
/// hold only for the geometry they were computed on.
pub(super) fn geometry_of(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> u64 {
    let mut h = std::hash::DefaultHasher::new();
    h.write_usize(positions.len());
    for p in positions {
        for c in p {
            h.write_u32(c.to_bits());
        }
    }
    h.write_usize(triangles.len());
    for t in triangles {
        for &i in t {
            h.write_u32(i);
        }
    }
    h.finish()
}

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

/// The per-pair sums of the weight vectors an update computed or kept (see the module doc), for
/// the same positions, triangles and σ. Opaque: what the next update reuses.
#[derive(Default)]
pub struct CenterSums {
    sigma_bits: u32,
    /// [`geometry_of`] the positions and triangles they were computed on.
    geometry: u64,
    classes: HashMap<WeightKey, ClassSums>,
}

impl CenterSums {
    pub(super) fn new(sigma: f32, geometry: u64) -> Self {
        Self { sigma_bits: sigma.to_bits(), geometry, classes: HashMap::new() }
    }

    /// Whether these sums were computed with `sigma` on the geometry `geometry` (see
    /// [`geometry_of`]): a pair's value depends on both, so sums of another mesh that has the
    /// same weights (a copy with moved vertices, say) are not taken.
    pub(super) fn is_for(&self, sigma: f32, geometry: u64) -> bool {
        self.sigma_bits == sigma.to_bits() && self.geometry == geometry
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

    /// The bytes they hold on the heap (the values, the weight vectors as keys, the table),
    /// about: for memory accounting.
    pub fn heap_bytes(&self) -> usize {
        let table = self.classes.capacity() * (size_of::<WeightKey>() + size_of::<ClassSums>() + 1);
        let held: usize = self
            .classes
            .iter()
            .map(|(key, c)| {
                key.capacity() * size_of::<(u32, u64)>()
                    + c.fast.capacity() * size_of::<FastPart>()
                    + c.exact.as_ref().map_or(0, |e| e.capacity() * size_of::<ExactPart>())
            })
            .sum();
        table + held
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

/// The center of vertex `v`, if its denominator is positive: from the expanded cells if their
/// certified bound allows (see `cells.rs`; then also `true`), else from the exact sums over
/// every entry, with the values of the pairs not in `changed` taken from `kept` (given only
/// with the fast path, whose exact sums need no underflow shift). With `record`, the values
/// come back in the outcome (else it holds none, and nothing is allocated).
#[allow(clippy::too_many_arguments)] // a vertex of an index, and what is kept of it
pub(super) fn center(
    index: &PairIndex,
    simd: Simd,
    weights: &WeightVectors,
    v: usize,
    inv_sigma2: f64,
    kept: Option<&ClassSums>,
    changed: &HashSet<(u32, u32)>,
    record: bool,
) -> Outcome {
    debug_assert!(kept.is_none() || (index.fast && record));
    let a = weights.of(v);
    let pairs = || (0..a.len()).flat_map(move |x| a[x + 1..].iter().map(move |&(k, ak)| (a[x].0, k, a[x].1, ak)));
    let reuse = |j: u32, k: u32| kept.filter(|_| !changed.contains(&(j, k)));
    let mut fast = Vec::new();
    if index.fast {
        let inv_sigma = inv_sigma2.sqrt();
        let mut total = [0.0f64; 4];
        let mut bound = 0.0;
        for (p, (j, k, aj, ak)) in pairs().enumerate() {
            let part = match reuse(j, k) {
                Some(c) => c.fast[p],
                None => index.ids.get(&(j, k)).map(|&id| {
                    let s = sums::pair_sums(simd, &index.raw.list(id), aj, ak, inv_sigma2, 0.0);
                    let cells = &index.cells[index.cell_starts[id]..index.cell_starts[id + 1]];
                    let (c, b) = cells::cell_sums(simd, cells, aj, ak, inv_sigma);
                    [s[0] + c[0], s[1] + c[1], s[2] + c[2], s[3] + c[3], b]
                }),
            };
            if record {
                fast.push(part);
            }
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
    }
    // With exponents that could underflow (tiny σ, no fast path), factor out the largest
    // exp(−u²/σ²) so it becomes 1; the factor cancels in the ratio.
    let shift = if inv_sigma2 > SHIFT_THRESHOLD {
        let m = pairs()
            .filter_map(|(j, k, aj, ak)| {
                index.ids.get(&(j, k)).map(|&id| sums::min_cross_squared(&index.exact.list(id), aj, ak))
            })
            .fold(f64::INFINITY, f64::min);
        if m.is_finite() {
            m * inv_sigma2
        } else {
            0.0
        }
    } else {
        0.0
    };
    let mut exact = Vec::new();
    let mut total = [0.0f64; 4];
    for (p, (j, k, aj, ak)) in pairs().enumerate() {
        // (Without `record`, `fast` is empty: every pair's list is in the index, or it has none.)
        let part = match (fast.get(p), reuse(j, k).and_then(|c| c.exact.as_ref())) {
            (Some(None), _) => None, // no list
            (Some(Some(_)), Some(e)) => e[p],
            (listed, _) => match index.ids.get(&(j, k)) {
                Some(&id) => Some(sums::pair_sums(simd, &index.exact.list(id), aj, ak, inv_sigma2, shift)),
                // Listed, its fast value kept, its list not built: only its exact sums were missing.
                None if listed.is_some() => return Outcome::NeedsLists,
                None => None, // no list
            },
        };
        if record {
            exact.push(part);
        }
        if let Some(s) = part {
            let f = 2.0 * aj * ak;
            for k in 0..4 {
                total[k] += f * s[k];
            }
        }
    }
    let d = total[0];
    let c = (d > 0.0).then(|| [total[1] / d, total[2] / d, total[3] / d]).filter(|c| c.iter().all(|x| x.is_finite()));
    Outcome::Done(c, false, ClassSums { fast, exact: record.then_some(exact) })
}

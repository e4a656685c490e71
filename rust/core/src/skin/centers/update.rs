//! What a weight change reaches: the precompute after weights were painted computes again only
//! the vertices whose sums can have changed, and takes every other center from before.
//!
//! A vertex's center is a ratio of sums over the pair lists of its own bone pairs, and a pair
//! list holds only the triangles having both bones. A changed vertex changes the weight vectors
//! of the triangles around it, so it changes exactly the lists of the bone pairs those
//! triangles have (before or after). A vertex whose own weights did not change and none of whose
//! pairs is among those reads the same lists, entry for entry, as before: its center is the
//! same bit for bit (the lists are built in an order that does not depend on the other lists).

use std::collections::HashSet;

use super::WeightVectors;

/// The bone pairs `(j, k)`, `j < k`, whose pair lists a weight change from `before` to `after`
/// can have changed, and which vertices changed (their weight vectors differ bit for bit).
pub(super) struct Reach {
    pub(super) pairs: HashSet<(u32, u32)>,
    pub(super) changed: Vec<bool>,
}

impl Reach {
    pub(super) fn new(triangles: &[[u32; 3]], before: &WeightVectors, after: &WeightVectors) -> Self {
        let n = after.offsets.len() - 1;
        let same = |v: usize| {
            let (a, b) = (before.of(v), after.of(v));
            a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.0 == y.0 && x.1.to_bits() == y.1.to_bits())
        };
        let changed: Vec<bool> = (0..n).map(|v| !same(v)).collect();
        let mut pairs = HashSet::new();
        let mut bones: Vec<u32> = Vec::new();
        for t in triangles {
            if !t.iter().any(|&v| changed[v as usize]) {
                continue;
            }
            // Every pair of the bones the triangle has before or after (a superset of the pairs
            // of its weight vectors: computing a few more vertices again changes nothing).
            bones.clear();
            for &v in t {
                bones.extend(before.of(v as usize).iter().chain(after.of(v as usize)).map(|e| e.0));
            }
            bones.sort_unstable();
            bones.dedup();
            for (x, &j) in bones.iter().enumerate() {
                for &k in &bones[x + 1..] {
                    pairs.insert((j, k));
                }
            }
        }
        Self { pairs, changed }
    }

    /// Whether vertex `v` (with the weight vector `after.of(v)`) needs its center computed again.
    pub(super) fn reaches(&self, after: &WeightVectors, v: usize) -> bool {
        if self.changed[v] {
            return true;
        }
        let a = after.of(v);
        (0..a.len()).any(|x| a[x + 1..].iter().any(|&(k, _)| self.pairs.contains(&(a[x].0, k))))
    }
}

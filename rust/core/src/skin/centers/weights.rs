//! Each vertex's weight vector as the precompute reads it, and vertices grouped by it.

use std::collections::{HashMap, HashSet};

use super::super::{Influences, MIN_TOTAL_WEIGHT};

/// The bone pairs `(j, k)`, `j < k`, of the weight vectors of `vertices`.
pub(super) fn pairs_of(weights: &WeightVectors, vertices: impl Iterator<Item = usize>) -> HashSet<(u32, u32)> {
    let mut pairs = HashSet::new();
    for v in vertices {
        let a = weights.of(v);
        for (x, &(j, _)) in a.iter().enumerate() {
            pairs.extend(a[x + 1..].iter().map(|&(k, _)| (j, k)));
        }
    }
    pairs
}

/// Every vertex's weights, repeated bones added up, normalized to sum 1, sorted by bone, zero
/// weights dropped (empty for a vertex with total weight ≤ [`MIN_TOTAL_WEIGHT`]).
pub(crate) struct WeightVectors {
    pub(super) offsets: Vec<usize>,
    entries: Vec<(u32, f64)>,
}

impl WeightVectors {
    pub(crate) fn new(influences: &Influences) -> Self {
        let mut offsets = Vec::with_capacity(influences.vertex_count() + 1);
        let mut entries = Vec::with_capacity(influences.len());
        offsets.push(0);
        let mut list: Vec<(u32, f64)> = Vec::new();
        for v in 0..influences.vertex_count() {
            list.clear();
            list.extend(influences.of_vertex(v).filter(|i| i.weight > 0.0).map(|i| (i.bone, f64::from(i.weight))));
            add_up_repeated_bones(&mut list);
            let total: f64 = list.iter().map(|e| e.1).sum();
            if total > f64::from(MIN_TOTAL_WEIGHT) {
                entries.extend(list.iter().map(|&(b, w)| (b, w / total)));
            }
            offsets.push(entries.len());
        }
        Self { offsets, entries }
    }

    pub(crate) fn of(&self, v: usize) -> &[(u32, f64)] {
        &self.entries[self.offsets[v]..self.offsets[v + 1]]
    }
}

/// Vertices grouped by weight vector (bit for bit): only vertices with at least two bones get a
/// class, since the others have no center.
pub(super) struct VertexClasses {
    /// Per class, its first vertex (whose weights stand for all of them); classes ordered by
    /// their bones, so that consecutive ones read the same pair lists.
    pub(super) members: Vec<Member>,
    pub(super) of_vertex: Vec<Option<u32>>,
}

pub(super) struct Member {
    pub(super) first: usize,
}

impl VertexClasses {
    pub(super) fn new(weights: &WeightVectors) -> Self {
        let n = weights.offsets.len() - 1;
        let key = |v: usize| -> Vec<(u32, u64)> { weights.of(v).iter().map(|&(b, w)| (b, w.to_bits())).collect() };
        let mut ids: HashMap<Vec<(u32, u64)>, u32> = HashMap::new();
        let mut firsts = Vec::new();
        let mut of_vertex = vec![None; n];
        for (v, slot) in of_vertex.iter_mut().enumerate() {
            if weights.of(v).len() < 2 {
                continue;
            }
            let next = firsts.len() as u32;
            let id = *ids.entry(key(v)).or_insert_with(|| {
                firsts.push(v);
                next
            });
            *slot = Some(id);
        }
        // Order by bones; renumber.
        let mut order: Vec<u32> = (0..firsts.len() as u32).collect();
        order.sort_by(|&a, &b| {
            let (wa, wb) = (weights.of(firsts[a as usize]), weights.of(firsts[b as usize]));
            wa.iter().map(|e| e.0).cmp(wb.iter().map(|e| e.0))
        });
        let mut renumber = vec![0u32; order.len()];
        for (new, &old) in order.iter().enumerate() {
            renumber[old as usize] = new as u32;
        }
        for c in of_vertex.iter_mut().flatten() {
            *c = renumber[*c as usize];
        }
        let members = order.iter().map(|&c| Member { first: firsts[c as usize] }).collect();
        Self { members, of_vertex }
    }
}

/// A weight vector bit for bit: `(bone, weight bits)` sorted by bone.
pub(super) type WeightKey = Vec<(u32, u64)>;

/// Sorts `(bone, weight)` pairs by bone and adds up the weights of a bone listed more than once
/// (stable: equal bones keep their order, so the sums are the same on every run).
pub(super) fn add_up_repeated_bones(list: &mut Vec<(u32, f64)>) {
    list.sort_by_key(|e| e.0);
    list.dedup_by(|next, kept| {
        let same = next.0 == kept.0;
        if same {
            kept.1 += next.1;
        }
        same
    });
}

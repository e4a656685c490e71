//! A vertex's few `(bone, weight)` pairs: keeping the strongest, normalizing, and turning lists
//! into [`Influences`].

use crate::skin::Influences;

/// One `(bone, weight)` pair.
pub(crate) type Pair = (u32, f32);

/// Keeps the `k` strongest of `pairs` (ties broken by the lower bone index, so results do not
/// depend on the order pairs were found in), sorted strongest first.
pub(crate) fn keep_strongest(pairs: &mut Vec<Pair>, k: usize) {
    pairs.sort_unstable_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    pairs.truncate(k);
}

/// Adds the weights of repeated bones together (order of first appearance kept).
pub(crate) fn merge_repeated(pairs: &mut Vec<Pair>) {
    let mut out: Vec<Pair> = Vec::with_capacity(pairs.len());
    for &(b, w) in pairs.iter() {
        match out.iter_mut().find(|p| p.0 == b) {
            Some(p) => p.1 += w,
            None => out.push((b, w)),
        }
    }
    *pairs = out;
}

/// Drops non-positive (and non-finite) weights and scales the rest to sum 1. Returns false
/// (leaving `pairs` empty) when nothing is left.
pub(crate) fn normalize(pairs: &mut Vec<Pair>) -> bool {
    pairs.retain(|p| p.1 > 0.0 && p.1.is_finite());
    let total: f64 = pairs.iter().map(|p| f64::from(p.1)).sum();
    if !(total > 0.0) || !total.is_finite() {
        pairs.clear();
        return false;
    }
    for p in pairs.iter_mut() {
        p.1 = (f64::from(p.1) / total) as f32;
    }
    true
}

/// At most `k` bones, normalized: the strongest `k`, then scaled to sum 1.
pub(crate) fn limit_and_normalize(pairs: &mut Vec<Pair>, k: usize) -> bool {
    merge_repeated(pairs);
    keep_strongest(pairs, k);
    normalize(pairs)
}

/// CSR influences from one list per vertex (every list already limited and normalized).
pub(crate) fn to_influences(lists: &[Vec<Pair>], bone_count: usize) -> Influences {
    let mut offsets = Vec::with_capacity(lists.len() + 1);
    let total: usize = lists.iter().map(Vec::len).sum();
    let (mut bones, mut weights) = (Vec::with_capacity(total), Vec::with_capacity(total));
    offsets.push(0u32);
    for list in lists {
        for &(b, w) in list {
            bones.push(b);
            weights.push(w);
        }
        offsets.push(bones.len() as u32);
    }
    Influences::from_csr(&offsets, &bones, &weights, bone_count).expect("weights built here are valid influences")
}

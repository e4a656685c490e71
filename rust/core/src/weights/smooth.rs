//! Smoothing weights over the mesh: each pass moves every chosen vertex's weights half way to the
//! mean of its neighbours', then limits and normalizes them again.

use rayon::prelude::*;

use super::mesh::Neighbours;
use super::sparse::{self, Pair};

/// How far one pass moves a vertex toward its neighbours' mean.
const STEP: f32 = 0.5;

/// `passes` passes over the vertices where `chosen` is true (all when it is `None`).
pub(crate) fn smooth(
    lists: &mut Vec<Vec<Pair>>,
    neighbours: &Neighbours,
    passes: u32,
    k: usize,
    chosen: Option<&[bool]>,
) {
    for _ in 0..passes {
        let next: Vec<Vec<Pair>> = crate::pool::run(|| {
            (0..lists.len())
                .into_par_iter()
                .with_min_len(512)
                .map(|v| {
                    let around = neighbours.of(v);
                    if around.is_empty() || chosen.is_some_and(|c| !c[v]) {
                        return lists[v].clone();
                    }
                    let share = STEP / around.len() as f32;
                    let mut mixed: Vec<Pair> = lists[v].iter().map(|&(b, w)| (b, w * (1.0 - STEP))).collect();
                    for &u in around {
                        mixed.extend(lists[u as usize].iter().map(|&(b, w)| (b, w * share)));
                    }
                    if !sparse::limit_and_normalize(&mut mixed, k) {
                        return lists[v].clone();
                    }
                    mixed
                })
                .collect()
        });
        *lists = next;
    }
}

//! The pair index of the precompute: merged triangles listed under each pair of their bones.

use std::collections::{HashMap, HashSet};

use rayon::prelude::*;

use super::super::SkinError;
use super::sums::{PairList, WIDTH};
use super::weights::{add_up_repeated_bones, WeightKey, WeightVectors};
use super::{cells, SHIFT_THRESHOLD};

/// Merged triangles listed under each pair of their bones, in padded structure-of-arrays form,
/// and the same lists split into expanded cells and the remaining entries (the fast path).
pub(super) struct PairIndex {
    /// Pair `(j, k)`, `j < k` → its id in `exact`, `raw` and `cell_starts`.
    pub(super) ids: HashMap<(u32, u32), usize>,
    /// Every entry.
    pub(super) exact: Soa,
    /// The entries outside expanded cells.
    pub(super) raw: Soa,
    /// Pair id → its cells `cell_starts[id]..cell_starts[id + 1]`.
    pub(super) cell_starts: Vec<usize>,
    pub(super) cells: Vec<cells::CellGroup>,
    /// Whether the fast path may be tried (σ large enough not to need the underflow shift).
    pub(super) fast: bool,
    /// The fast path's tolerance on `E/D̃`.
    pub(super) tolerance: f64,
}

/// Entry lists in padded structure-of-arrays form: list `id` is `starts[id]..starts[id + 1]`.
pub(super) struct Soa {
    starts: Vec<usize>,
    bj: Vec<f64>,
    bk: Vec<f64>,
    p: Vec<f64>,
    pc: [Vec<f64>; 3],
}

impl Soa {
    fn new() -> Self {
        Self { starts: vec![0], bj: Vec::new(), bk: Vec::new(), p: Vec::new(), pc: Default::default() }
    }

    fn push(&mut self, list: &[Entry]) {
        let padding = Entry { bj: 0.0, bk: 0.0, p: 0.0, pc: [0.0; 3] };
        let padded = list.len().next_multiple_of(WIDTH);
        for e in list.iter().chain(std::iter::repeat_n(&padding, padded - list.len())) {
            self.bj.push(e.bj);
            self.bk.push(e.bk);
            self.p.push(e.p);
            for k in 0..3 {
                self.pc[k].push(e.pc[k]);
            }
        }
        self.starts.push(self.p.len());
    }

    pub(super) fn list(&self, id: usize) -> PairList<'_> {
        let r = self.starts[id]..self.starts[id + 1];
        PairList {
            bj: &self.bj[r.clone()],
            bk: &self.bk[r.clone()],
            p: &self.p[r.clone()],
            pc: [&self.pc[0][r.clone()], &self.pc[1][r.clone()], &self.pc[2][r]],
        }
    }
}

/// One pair-list entry before packing.
#[derive(Clone, Copy)]
pub(super) struct Entry {
    pub(super) bj: f64,
    pub(super) bk: f64,
    pub(super) p: f64,
    pub(super) pc: [f64; 3],
}

impl PairIndex {
    /// The index (of the pairs in `needed` only, if given), or `check`'s error between its stages.
    pub(super) fn new(
        positions: &[[f32; 3]],
        triangles: &[[u32; 3]],
        weights: &WeightVectors,
        sigma: f64,
        tolerance: Option<f64>,
        needed: Option<&HashSet<(u32, u32)>>,
        check: &mut dyn FnMut() -> Result<(), SkinError>,
    ) -> Result<Self, SkinError> {
        let wanted = |j: u32, k: u32| needed.is_none_or(|n| n.contains(&(j, k)));
        let inv_sigma2 = 1.0 / (sigma * sigma);
        // Per triangle (in parallel): its weight vector, area and area × centroid.
        let each: Vec<(WeightKey, f64, [f64; 3])> = crate::pool::run(|| {
            triangles
                .par_iter()
                .map_init(Vec::new, |mean: &mut Vec<(u32, f64)>, t| {
                    let [a, b, c] = t.map(|v| positions[v as usize].map(f64::from));
                    let (e1, e2) = (sub(b, a), sub(c, a));
                    let area = 0.5 * length(cross(e1, e2));
                    if !(area > 0.0) {
                        return None;
                    }
                    mean.clear();
                    for &v in t {
                        mean.extend_from_slice(weights.of(v as usize));
                    }
                    add_up_repeated_bones(mean);
                    if mean.len() < 2 {
                        return None;
                    }
                    // (A triangle of no wanted pair is in no list built: its whole weight
                    // vector's group is left out, so the others' sums keep their order.)
                    if needed.is_some()
                        && !(0..mean.len()).any(|x| mean[x + 1..].iter().any(|e| wanted(mean[x].0, e.0)))
                    {
                        return None;
                    }
                    let key: WeightKey = mean.iter().map(|&(bone, w)| (bone, (w / 3.0).to_bits())).collect();
                    let centroid = [(a[0] + b[0] + c[0]) / 3.0, (a[1] + b[1] + c[1]) / 3.0, (a[2] + b[2] + c[2]) / 3.0];
                    Some((key, area, centroid.map(|x| area * x)))
                })
                .flatten()
                .collect()
        });
        check()?;
        // Triangles merged by weight vector: Σ A and Σ A·c (a stable sort keeps the sums in
        // triangle order, so the result does not depend on the threads).
        let mut each = each;
        crate::pool::run(|| each.par_sort_by(|a, b| a.0.cmp(&b.0)));
        check()?;
        let merged: Vec<(WeightKey, (f64, [f64; 3]))> = each
            .chunk_by(|a, b| a.0 == b.0)
            .map(|group| {
                let mut sum = (0.0, [0.0; 3]);
                for (_, area, area_c) in group {
                    sum.0 += area;
                    for k in 0..3 {
                        sum.1[k] += area_c[k];
                    }
                }
                (group[0].0.clone(), sum)
            })
            .collect();
        drop(each);
        check()?;
        // Lists per bone pair.
        let mut ids: HashMap<(u32, u32), usize> = HashMap::new();
        let mut lists: Vec<Vec<Entry>> = Vec::new();
        for (key, (area, area_c)) in &merged {
            for (x, &(j, bj)) in key.iter().enumerate() {
                for &(k, bk) in &key[x + 1..] {
                    if !wanted(j, k) {
                        continue;
                    }
                    let (bj, bk) = (f64::from_bits(bj), f64::from_bits(bk));
                    let id = *ids.entry((j, k)).or_insert_with(|| {
                        lists.push(Vec::new());
                        lists.len() - 1
                    });
                    let w = bj * bk;
                    lists[id].push(Entry { bj, bk, p: w * area, pc: area_c.map(|x| w * x) });
                }
            }
        }
        drop(merged);
        check()?;
        // Equal (bⱼ, bₖ) in one list merged; padded to WIDTH; split into cells.
        let fast = tolerance.is_some() && inv_sigma2 <= SHIFT_THRESHOLD;
        let mut index = Self {
            ids,
            exact: Soa::new(),
            raw: Soa::new(),
            cell_starts: vec![0],
            cells: Vec::new(),
            fast,
            tolerance: tolerance.unwrap_or(0.0),
        };
        // Lists are independent: sorted, merged and split in parallel, then packed in order.
        let prepared: Vec<(Vec<Entry>, Vec<Entry>, Vec<cells::CellGroup>)> = crate::pool::run(|| {
            lists
                .into_par_iter()
                .map(|mut list| {
                    list.sort_unstable_by_key(|e| (e.bj.to_bits(), e.bk.to_bits()));
                    list.dedup_by(|next, kept| {
                        let same = next.bj.to_bits() == kept.bj.to_bits() && next.bk.to_bits() == kept.bk.to_bits();
                        if same {
                            kept.p += next.p;
                            for k in 0..3 {
                                kept.pc[k] += next.pc[k];
                            }
                        }
                        same
                    });
                    let (raw, cells) = if fast { cells::build(&list, sigma) } else { (Vec::new(), Vec::new()) };
                    (list, raw, cells)
                })
                .collect()
        });
        check()?;
        for (list, raw, cells) in prepared {
            index.exact.push(&list);
            index.raw.push(&raw);
            index.cells.extend(cells);
            index.cell_starts.push(index.cells.len());
        }
        Ok(index)
    }

    /// Work of vertex `v` on the fast path (entries, a group of cells counting as [`CELL_WORK`]);
    /// with `only`, of those of its pairs only (the others' values are kept).
    pub(super) fn work(&self, weights: &WeightVectors, v: usize, only: Option<&HashSet<(u32, u32)>>) -> usize {
        let a = weights.of(v);
        let pairs = (0..a.len()).flat_map(move |x| a[x + 1..].iter().map(move |&(k, _)| (a[x].0, k)));
        pairs
            .filter(|p| only.is_none_or(|o| o.contains(p)))
            .filter_map(|p| self.ids.get(&p).copied())
            .map(|id| {
                if self.fast {
                    self.raw.list(id).p.len() + CELL_WORK * (self.cell_starts[id + 1] - self.cell_starts[id])
                } else {
                    self.exact.list(id).p.len()
                }
            })
            .sum::<usize>()
            + 1
    }
}

/// Work of one group of expanded cells, in entries (measured: about 6 entries per cell).
pub(super) const CELL_WORK: usize = 48;

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn length(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

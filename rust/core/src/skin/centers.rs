//! Optimized centers of rotation (Le & Hodgins, "Real-time Skeletal Skinning with Optimized
//! Centers of Rotation", SIGGRAPH 2016): the per-vertex precompute on the rest mesh.
//!
//! Vertex `i` with weights `wᵢ` gets the center
//! `pᵢ* = Σₜ s(wᵢ, wₜ)·Aₜ·cₜ / Σₜ s(wᵢ, wₜ)·Aₜ` over the triangles `t` (area `Aₜ`, centroid
//! `cₜ`, weights `wₜ` the mean of its corners'), with the similarity
//! `s(a, b) = Σ_{j≠k} aⱼ·aₖ·bⱼ·bₖ·exp(−(aⱼ·bₖ − aₖ·bⱼ)²/σ²)`.
//!
//! Weight vectors are each vertex's influences with repeated bones added up, normalized to sum 1;
//! a vertex whose total weight is at most [`MIN_TOTAL_WEIGHT`] (which skinning leaves in place)
//! counts as having none. Where the denominator is 0 — fewer than two bones, or no triangle
//! sharing two of its bones — the vertex has no center and is skinned by LBS (its row holds its
//! own position, for which the per-frame formula is exactly LBS).
//!
//! # Algorithm
//! A term of `s` is non-zero only for bones `j ≠ k` both in `a` and `b`, so
//! `s(a, b) = Σ_{pairs j<k} 2·aⱼaₖ·bⱼbₖ·exp(…)`, and the two sums split into per-pair sums:
//! 1. vertices with equal weight vectors share a center (computed once);
//! 2. triangles with equal weight vectors are merged (their `A` and `A·c` added);
//! 3. every merged triangle is listed under each pair of its bones, with `bⱼ`, `bₖ`,
//!    `P = bⱼbₖ·A` and `P·c`; entries of a list with equal `(bⱼ, bₖ)` are merged again;
//! 4. a vertex visits only the lists of its own bone pairs (a triangle sharing fewer than two
//!    bones contributes 0 and is never visited), in parallel over unique weight vectors;
//! 5. the fast path (`cells.rs`): each list is also split into small cells of `(bⱼ, bₖ)`
//!    space; a cell with enough entries is summed through a Taylor expansion of the kernel about
//!    its middle, from moments computed once, so a vertex pays per cell instead of per triangle.
//!    Every vertex gets a certified bound on how far that moves its center; a vertex whose bound
//!    exceeds 1e-7 × the bounding box diagonal is summed exactly (as is every vertex when σ is so
//!    small that the exact sums need their underflow shift).
//!
//! Everything is accumulated in f64. Apart from the fast path's certified 1e-7, the only
//! approximation is a vectorizable `exp` with a relative error below 1e-11, which moves a
//! center (a weighted mean of centroids) by at most about 1e-11 × the bounding box diagonal
//! (see `sums.rs`). The tests check the result against the naive O(V·T) sum with the library
//! `exp`.

mod cells;
mod kept;
mod sums;
mod update;

use std::collections::{HashMap, HashSet};

use rayon::prelude::*;

use super::isa::Simd;
use super::{Influences, SkinError, MIN_TOTAL_WEIGHT};
pub use kept::CenterSums;
use kept::Outcome;
use sums::{PairList, WIDTH};
use update::Reach;

/// Above this `1/σ²` the exponents could underflow: the exact sums factor out the largest term
/// (see [`PairIndex::center`]) and the fast path is not used.
const SHIFT_THRESHOLD: f64 = 600.0;

/// The paper's default σ.
pub const DEFAULT_SIGMA: f32 = 0.1;

/// Per-vertex centers of rotation.
#[derive(Clone, Debug, PartialEq)]
pub struct Centers {
    /// One per vertex, in mesh space (the space of the rest positions); a vertex without a
    /// center holds its own position.
    pub centers: Vec<[f32; 3]>,
    /// Whether the vertex has a center (false: it is skinned exactly like LBS).
    pub has_center: Vec<bool>,
}

/// Computes the centers of rotation of a rest mesh: `positions` (one per vertex of
/// `influences`), `triangles` (vertex indices) and the similarity width `sigma`
/// ([`DEFAULT_SIGMA`] in the paper). Runs on the crate's thread pool.
pub fn centers_of_rotation(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    influences: &Influences,
    sigma: f32,
) -> Result<Centers, SkinError> {
    centers_of_rotation_with_progress(positions, triangles, influences, sigma, &mut |_, _| true)
}

/// [`centers_of_rotation`] that reports progress and can be cancelled: `progress(done, total)`
/// (in units of work, `done ≤ total`) is called on the calling thread before the work starts
/// and after every part of it (about a hundred parts on a large mesh); returning `false`
/// stops the computation with [`SkinError::Cancelled`].
pub fn centers_of_rotation_with_progress(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    influences: &Influences,
    sigma: f32,
    progress: &mut dyn FnMut(usize, usize) -> bool,
) -> Result<Centers, SkinError> {
    centers_of_rotation_interruptible(positions, triangles, influences, sigma, progress, &mut || false)
}

/// [`centers_of_rotation_with_progress`] that also asks `interrupted()` between the stages of
/// the setup, before the amount of work (and so `progress`'s total) is known: the setup takes
/// seconds on a mesh of half a million vertices. `true` stops the computation with
/// [`SkinError::Cancelled`] (the Python module checks for Ctrl-C there).
pub fn centers_of_rotation_interruptible(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    influences: &Influences,
    sigma: f32,
    progress: &mut dyn FnMut(usize, usize) -> bool,
    interrupted: &mut dyn FnMut() -> bool,
) -> Result<Centers, SkinError> {
    centers_counted(
        Simd::detect(),
        Some(cells::TOLERANCE),
        positions,
        triangles,
        influences,
        sigma,
        progress,
        interrupted,
    )
    .map(|(c, _)| c)
}

/// Centers computed before, for the same rest positions and triangles, with other weights:
/// [`centers_of_rotation_update`] computes again only what the new weights reach.
#[derive(Clone, Copy)]
pub struct PreviousCenters<'a> {
    /// The weights the centers were computed with.
    pub influences: &'a Influences,
    /// What [`centers_of_rotation`] returned for them.
    pub centers: &'a Centers,
}

/// [`centers_of_rotation_interruptible`] after a weight change (weights painted): given the
/// centers computed `previous`ly for the same `positions` and `triangles`, only the vertices
/// whose sums the change reaches are computed again (see `update.rs`); the result is the one a
/// full computation gives, bit for bit. The caller vouches that positions and triangles are
/// those of `previous`.
pub fn centers_of_rotation_update(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    influences: &Influences,
    sigma: f32,
    previous: PreviousCenters<'_>,
    progress: &mut dyn FnMut(usize, usize) -> bool,
    interrupted: &mut dyn FnMut() -> bool,
) -> Result<Centers, SkinError> {
    update(positions, triangles, influences, sigma, previous, None, false, progress, interrupted).map(|(c, _)| c)
}

/// [`centers_of_rotation_update`] for strokes that follow one another: `kept`, what the update
/// before returned with the centers it made (`previous`), lets a vertex the change reaches
/// compute again only the bone pairs whose lists the change altered (see `kept.rs`); the
/// centers are the same bit for bit. Returns what to keep for the next stroke (the values of
/// every vertex this update computed, and of the others from `kept`); sums made for another σ
/// are not used.
#[allow(clippy::too_many_arguments)] // the update's inputs and what the one before kept
pub fn centers_of_rotation_update_keeping(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    influences: &Influences,
    sigma: f32,
    previous: PreviousCenters<'_>,
    kept: Option<CenterSums>,
    progress: &mut dyn FnMut(usize, usize) -> bool,
    interrupted: &mut dyn FnMut() -> bool,
) -> Result<(Centers, CenterSums), SkinError> {
    update(positions, triangles, influences, sigma, previous, kept, true, progress, interrupted)
        .map(|(c, k)| (c, k.unwrap_or_else(|| CenterSums::new(sigma))))
}

/// An update on the copy of the inner loop this CPU runs, with the fast path.
#[allow(clippy::too_many_arguments)]
fn update(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    influences: &Influences,
    sigma: f32,
    previous: PreviousCenters<'_>,
    kept: Option<CenterSums>,
    keep: bool,
    progress: &mut dyn FnMut(usize, usize) -> bool,
    interrupted: &mut dyn FnMut() -> bool,
) -> Result<(Centers, Option<CenterSums>), SkinError> {
    check_previous(influences, previous)?;
    let simd = Simd::detect();
    let tolerance = Some(cells::TOLERANCE);
    centers_counted_since(
        simd,
        tolerance,
        positions,
        triangles,
        influences,
        sigma,
        Some(previous),
        kept,
        keep,
        progress,
        interrupted,
    )
    .map(|(c, _, k)| (c, k))
}

fn check_previous(influences: &Influences, previous: PreviousCenters<'_>) -> Result<(), SkinError> {
    let n = influences.vertex_count();
    if previous.influences.vertex_count() != n {
        return Err(SkinError::LengthMismatch {
            what: "previous influences",
            expected: n,
            got: previous.influences.vertex_count(),
        });
    }
    if previous.centers.centers.len() != n || previous.centers.has_center.len() != n {
        return Err(SkinError::LengthMismatch {
            what: "previous centers",
            expected: n,
            got: previous.centers.centers.len(),
        });
    }
    Ok(())
}

/// The precompute on a given compiled copy of the inner loop, with the fast path's tolerance on
/// `E/D̃` (see `cells.rs`; `None`: exact sums only), also returning how many distinct weight
/// vectors took the fast path. `interrupted` is asked between the setup's stages.
#[allow(clippy::too_many_arguments)] // the inputs, the two knobs tests turn, the two callbacks
pub(super) fn centers_counted(
    simd: Simd,
    tolerance: Option<f64>,
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    influences: &Influences,
    sigma: f32,
    progress: &mut dyn FnMut(usize, usize) -> bool,
    interrupted: &mut dyn FnMut() -> bool,
) -> Result<(Centers, usize), SkinError> {
    centers_counted_since(
        simd,
        tolerance,
        positions,
        triangles,
        influences,
        sigma,
        None,
        None,
        false,
        progress,
        interrupted,
    )
    .map(|(c, fast, _)| (c, fast))
}

/// [`centers_counted`], computing again only what a weight change since `previous` reaches,
/// taking the values of the pairs it did not change from `kept`; with `keep`, also returns what
/// the next update can take (where the fast path is on: see `kept.rs`).
#[allow(clippy::too_many_arguments)]
pub(super) fn centers_counted_since(
    simd: Simd,
    tolerance: Option<f64>,
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    influences: &Influences,
    sigma: f32,
    previous: Option<PreviousCenters<'_>>,
    kept: Option<CenterSums>,
    keep: bool,
    progress: &mut dyn FnMut(usize, usize) -> bool,
    interrupted: &mut dyn FnMut() -> bool,
) -> Result<(Centers, usize, Option<CenterSums>), SkinError> {
    let n = influences.vertex_count();
    if positions.len() != n {
        return Err(SkinError::LengthMismatch { what: "positions", expected: n, got: positions.len() });
    }
    if !(sigma > 0.0 && sigma.is_finite()) {
        return Err(SkinError::InvalidSigma(sigma));
    }
    if let Some(index) = positions.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(SkinError::NotFinite { what: "positions", index });
    }
    super::check_triangles(triangles, n)?;
    let mut check = || if interrupted() { Err(SkinError::Cancelled) } else { Ok(()) };
    check()?;
    let weights = WeightVectors::new(influences);
    check()?;
    let classes = VertexClasses::new(&weights);
    check()?;
    let inv_sigma2 = 1.0 / (f64::from(sigma) * f64::from(sigma));
    // Per-pair values are kept and reused only with the fast path (no underflow shift).
    let keep = keep && tolerance.is_some() && inv_sigma2 <= SHIFT_THRESHOLD;
    let kept = kept.filter(|k| keep && k.is_for(sigma));
    // The classes to compute: every one, or those a weight change since `previous` reaches.
    let reach = previous.map(|p| Reach::new(triangles, &WeightVectors::new(p.influences), &weights));
    let todo: Vec<usize> = match &reach {
        None => (0..classes.members.len()).collect(),
        Some(r) => (0..classes.members.len()).filter(|&c| r.reaches(&weights, classes.members[c].first)).collect(),
    };
    check()?;
    // The kept values of each class to compute whose own weights did not change.
    let reused: Vec<Option<&kept::ClassSums>> = match (&kept, &reach) {
        (Some(k), Some(r)) => todo
            .iter()
            .map(|&c| {
                let v = classes.members[c].first;
                (!r.changed[v]).then(|| k.get(&kept::key_of(&weights, v), kept::pair_count(&weights, v))).flatten()
            })
            .collect(),
        _ => vec![None; todo.len()],
    };
    let no_pairs = HashSet::new();
    let changed = reach.as_ref().map_or(&no_pairs, |r| &r.pairs);
    check()?;
    // After a weight change only the lists of the pairs the recomputed classes read are built
    // (each exactly as a full build makes it, so their centers are the same bit for bit): of a
    // class with kept values, only the pairs the change altered.
    let needed = reach.is_some().then(|| {
        let mut pairs = pairs_of(
            &weights,
            todo.iter().zip(&reused).filter(|(_, k)| k.is_none()).map(|(&c, _)| classes.members[c].first),
        );
        for (&c, _) in todo.iter().zip(&reused).filter(|(_, k)| k.is_some()) {
            let a = weights.of(classes.members[c].first);
            for (x, &(j, _)) in a.iter().enumerate() {
                pairs.extend(a[x + 1..].iter().map(|&(k, _)| (j, k)).filter(|p| changed.contains(p)));
            }
        }
        pairs
    });
    let index =
        PairIndex::new(positions, triangles, &weights, f64::from(sigma), tolerance, needed.as_ref(), &mut check)?;

    // Parts of roughly equal work, so progress advances evenly and cancelling is quick.
    let work: Vec<usize> = crate::pool::run(|| {
        todo.par_iter()
            .zip(&reused)
            .map(|(&c, k)| index.work(&weights, classes.members[c].first, k.map(|_| changed)))
            .collect()
    });
    check()?;
    let total: usize = work.iter().sum();
    let part_work = (total / 100).max(1 << 16);
    let mut parts = vec![0usize];
    let mut acc = 0;
    for (c, w) in work.iter().enumerate() {
        acc += w;
        if acc >= part_work {
            parts.push(c + 1);
            acc = 0;
        }
    }
    if *parts.last().unwrap_or(&0) != work.len() {
        parts.push(work.len());
    }

    if !progress(0, total) {
        return Err(SkinError::Cancelled);
    }
    let compute = |index: &PairIndex, t: usize, reuse: Option<&kept::ClassSums>| -> Outcome {
        kept::center(index, simd, &weights, classes.members[todo[t]].first, inv_sigma2, reuse, changed, keep)
    };
    let mut outcomes: Vec<Outcome> = (0..todo.len()).map(|_| Outcome::NeedsLists).collect();
    let mut done = 0;
    for part in parts.windows(2) {
        let range = part[0]..part[1];
        let one = |(t, out): (usize, &mut Outcome)| *out = compute(&index, t, reused[t]);
        let slots = &mut outcomes[range.clone()];
        let part_work: usize = work[range.clone()].iter().sum();
        if part_work < (1 << 14) {
            slots.iter_mut().enumerate().map(|(i, o)| (range.start + i, o)).for_each(one);
        } else {
            crate::pool::run(|| slots.par_iter_mut().enumerate().map(|(i, o)| (range.start + i, o)).for_each(one));
        }
        done += part_work;
        if !progress(done, total) {
            return Err(SkinError::Cancelled);
        }
    }
    // Classes that left the fast path where a kept pair has no exact sums: again, with every
    // list they read (rare: the fast path's bound holds for almost every vertex).
    let again: Vec<usize> = (0..todo.len()).filter(|&t| matches!(outcomes[t], Outcome::NeedsLists)).collect();
    if !again.is_empty() {
        check()?;
        let pairs = pairs_of(&weights, again.iter().map(|&t| classes.members[todo[t]].first));
        let index =
            PairIndex::new(positions, triangles, &weights, f64::from(sigma), tolerance, Some(&pairs), &mut check)?;
        let redone: Vec<Outcome> = crate::pool::run(|| again.par_iter().map(|&t| compute(&index, t, None)).collect());
        for (&t, o) in again.iter().zip(redone) {
            outcomes[t] = o;
        }
    }
    drop(reused);

    let mut centers = positions.to_vec();
    let mut has_center = vec![false; n];
    // Class → its slot in `todo` (the others keep the center from before).
    let mut slot = vec![usize::MAX; classes.members.len()];
    for (t, &c) in todo.iter().enumerate() {
        slot[c] = t;
    }
    for (v, class) in classes.of_vertex.iter().enumerate() {
        let Some(c) = class.map(|c| c as usize) else { continue };
        if slot[c] != usize::MAX {
            if let Outcome::Done(Some(center), _, _) = &outcomes[slot[c]] {
                centers[v] = center.map(|x| x as f32);
                has_center[v] = true;
            }
        } else if let Some(p) = previous {
            // Not reached: the vertex's weights and lists are as before, and so is its center.
            let first = classes.members[c].first;
            centers[v] = p.centers.centers[first];
            has_center[v] = p.centers.has_center[first];
        }
    }
    let fast = outcomes.iter().filter(|o| matches!(o, Outcome::Done(_, true, _))).count();
    // What the next update can take: the values of every current class, computed now or kept.
    let next = keep.then(|| {
        let mut kept = kept;
        let mut next = CenterSums::new(sigma);
        let mut outcomes: Vec<Option<Outcome>> = outcomes.into_iter().map(Some).collect();
        for (c, member) in classes.members.iter().enumerate() {
            let key = kept::key_of(&weights, member.first);
            let values = if slot[c] != usize::MAX {
                match outcomes[slot[c]].take() {
                    Some(Outcome::Done(_, _, values)) => Some(values),
                    _ => None,
                }
            } else {
                kept.as_mut().and_then(|k| k.take(&key))
            };
            if let Some(values) = values {
                next.insert(key, values);
            }
        }
        next
    });
    Ok((Centers { centers, has_center }, fast, next))
}

/// The bone pairs `(j, k)`, `j < k`, of the weight vectors of `vertices`.
fn pairs_of(weights: &WeightVectors, vertices: impl Iterator<Item = usize>) -> HashSet<(u32, u32)> {
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
    offsets: Vec<usize>,
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
struct VertexClasses {
    /// Per class, its first vertex (whose weights stand for all of them); classes ordered by
    /// their bones, so that consecutive ones read the same pair lists.
    members: Vec<Member>,
    of_vertex: Vec<Option<u32>>,
}

struct Member {
    first: usize,
}

impl VertexClasses {
    fn new(weights: &WeightVectors) -> Self {
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
type WeightKey = Vec<(u32, u64)>;

/// Merged triangles listed under each pair of their bones, in padded structure-of-arrays form,
/// and the same lists split into expanded cells and the remaining entries (the fast path).
struct PairIndex {
    /// Pair `(j, k)`, `j < k` → its id in `exact`, `raw` and `cell_starts`.
    ids: HashMap<(u32, u32), usize>,
    /// Every entry.
    exact: Soa,
    /// The entries outside expanded cells.
    raw: Soa,
    /// Pair id → its cells `cell_starts[id]..cell_starts[id + 1]`.
    cell_starts: Vec<usize>,
    cells: Vec<cells::CellGroup>,
    /// Whether the fast path may be tried (σ large enough not to need the underflow shift).
    fast: bool,
    /// The fast path's tolerance on `E/D̃`.
    tolerance: f64,
}

/// Entry lists in padded structure-of-arrays form: list `id` is `starts[id]..starts[id + 1]`.
struct Soa {
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

    fn list(&self, id: usize) -> PairList<'_> {
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
struct Entry {
    bj: f64,
    bk: f64,
    p: f64,
    pc: [f64; 3],
}

impl PairIndex {
    /// The index (of the pairs in `needed` only, if given), or `check`'s error between its stages.
    fn new(
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
    fn work(&self, weights: &WeightVectors, v: usize, only: Option<&HashSet<(u32, u32)>>) -> usize {
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
const CELL_WORK: usize = 48;

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn length(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

/// Sorts `(bone, weight)` pairs by bone and adds up the weights of a bone listed more than once
/// (stable: equal bones keep their order, so the sums are the same on every run).
fn add_up_repeated_bones(list: &mut Vec<(u32, f64)>) {
    list.sort_by_key(|e| e.0);
    list.dedup_by(|next, kept| {
        let same = next.0 == kept.0;
        if same {
            kept.1 += next.1;
        }
        same
    });
}

#[cfg(test)]
mod tests;

//! Optimized centers of rotation (Le & Hodgins, "Real-time Skeletal Skinning with Optimized
//! Centers of Rotation", SIGGRAPH 2016): the per-vertex precompute on the rest mesh.
//!
//! Vertex `i` with weights `wᵢ` gets the center
//! `pᵢ* = Σₜ s(wᵢ, wₜ)·Aₜ·cₜ / Σₜ s(wᵢ, wₜ)·Aₜ` over the triangles `t` (area `Aₜ`, centroid
//! `cₜ`, weights `wₜ` the mean of its corners'), with the similarity
//! `s(a, b) = Σ_{j≠k} aⱼ·aₖ·bⱼ·bₖ·exp(−(aⱼ·bₖ − aₖ·bⱼ)²/σ²)`.
//!
//! Weight vectors are each vertex's influences with repeated bones added up, normalized to sum 1;
//! a vertex whose total weight is at most [`MIN_TOTAL_WEIGHT`](super::MIN_TOTAL_WEIGHT) (which skinning leaves in place)
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
mod pair_index;
mod sums;
mod update;
mod weights;

use std::collections::HashSet;

use rayon::prelude::*;

use super::isa::Simd;
use super::{Influences, SkinError};
pub use kept::CenterSums;
use kept::Outcome;
use pair_index::{Entry, PairIndex};
use update::Reach;
pub(crate) use weights::WeightVectors;
use weights::{pairs_of, VertexClasses, WeightKey};

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
        .map(|(c, k)| (c, k.unwrap_or_else(|| CenterSums::new(sigma, kept::geometry_of(positions, triangles)))))
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

/// The errors the centers' computation would return on these inputs (lengths, σ, non-finite
/// positions, triangles out of range, `previous` of other vertices), found before any work: a
/// caller that runs the computation elsewhere (the Python module's `centers_of_rotation_job`) refuses bad
/// input at once.
pub fn check_centers_inputs(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    influences: &Influences,
    sigma: f32,
    previous: Option<PreviousCenters<'_>>,
) -> Result<(), SkinError> {
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
    match previous {
        Some(p) => check_previous(influences, p),
        None => Ok(()),
    }
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
    check_centers_inputs(positions, triangles, influences, sigma, previous)?;
    let n = influences.vertex_count();
    let mut check = || if interrupted() { Err(SkinError::Cancelled) } else { Ok(()) };
    check()?;
    let weights = WeightVectors::new(influences);
    check()?;
    let classes = VertexClasses::new(&weights);
    check()?;
    let inv_sigma2 = 1.0 / (f64::from(sigma) * f64::from(sigma));
    // Per-pair values are kept and reused only with the fast path (no underflow shift).
    let keep = keep && tolerance.is_some() && inv_sigma2 <= SHIFT_THRESHOLD;
    let geometry = if keep { kept::geometry_of(positions, triangles) } else { 0 };
    let kept = kept.filter(|k| keep && k.is_for(sigma, geometry));
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
        let mut next = CenterSums::new(sigma, geometry);
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

#[cfg(test)]
mod tests;

//! From distances to weights. A vertex's distance to a bone is the least, over the solid cells
//! around it (the eight whose centers surround it), of the cell's geodesic distance plus the
//! straight step from the cell's center to the vertex. Its weights follow the falloff of Dionne
//! & de Lasa: `w = 1 / ((1 − α)·d + α·d²)²`, with `d` divided by the mesh's bounding-box
//! diagonal (so weights do not depend on the mesh's scale) and `α` the falloff.
//!
//! Of the `K + 1` nearest bones the first `K` keep their weight less that of the `(K + 1)`-th:
//! a bone's weight then reaches zero exactly where it stops being among the `K` nearest, so the
//! limit to `K` bones leaves no seam.

use glam::Vec3;

use super::geodesic::{segment_distance, NearestBones};
use super::sparse::{self, Pair};
use super::voxels::Solid;

/// The least distance (in the mesh's units, over `diagonal`) below which every distance counts
/// as this one: a vertex on a bone's segment would otherwise take all of its weight.
const NEAREST: f32 = 1e-4;

/// The bones around grid point `g` with their distances in cells, from the eight cells whose
/// centers surround it, else the 27 around its own cell. Empty if no bone reaches any of them.
pub(crate) fn distances_at(solid: &Solid, nearest: &NearestBones, g: Vec3, out: &mut Vec<(u32, f32)>) {
    out.clear();
    let base = (g - Vec3::splat(0.5)).floor();
    visit(solid, nearest, g, base, 2, out);
    if out.is_empty() {
        visit(solid, nearest, g, g.floor() - Vec3::ONE, 3, out);
    }
}

fn visit(solid: &Solid, nearest: &NearestBones, g: Vec3, base: Vec3, span: i32, out: &mut Vec<(u32, f32)>) {
    for dz in 0..span {
        for dy in 0..span {
            for dx in 0..span {
                let center = base + Vec3::new(dx as f32, dy as f32, dz as f32) + Vec3::splat(0.5);
                let Some(cell) = solid.grid.cell_at(center) else { continue };
                let Some(id) = solid.id(cell) else { continue };
                let step = center.distance(g);
                for (bone, d) in nearest.of(id) {
                    let d = d + step;
                    match out.iter_mut().find(|p| p.0 == bone) {
                        Some(p) => p.1 = p.1.min(d),
                        None => out.push((bone, d)),
                    }
                }
            }
        }
    }
}

/// The `max_influences + 1` bones nearest to `p` in straight lines (for vertices no bone
/// reaches through the solid), with their distances.
pub(crate) fn straight_distances(p: Vec3, segments: &[(Vec3, Vec3)], count: usize) -> Vec<(u32, f32)> {
    let mut all: Vec<(u32, f32)> =
        segments.iter().enumerate().map(|(b, &(a, t))| (b as u32, segment_distance(p, a, t))).collect();
    all.sort_unstable_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    all.truncate(count);
    all
}

/// Weights from `(bone, distance)` pairs (`scale` turns a distance into a fraction of the
/// bounding-box diagonal): the falloff, the `(K + 1)`-th nearest taken off the `K` nearest,
/// normalized. Never empty when `distances` is not.
pub(crate) fn weights_from_distances(distances: &mut [(u32, f32)], scale: f32, falloff: f32, k: usize) -> Vec<Pair> {
    distances.sort_unstable_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    let weight = |d: f32| {
        let d = (d * scale).max(NEAREST);
        let s = (1.0 - falloff) * d + falloff * d * d;
        1.0 / (s * s)
    };
    let mut pairs: Vec<Pair> = distances.iter().take(k + 1).map(|&(b, d)| (b, weight(d))).collect();
    if pairs.len() > k {
        let floor = pairs[k].1;
        let mut lowered: Vec<Pair> = pairs[..k].iter().map(|&(b, w)| (b, w - floor)).collect();
        if sparse::normalize(&mut lowered) {
            return lowered;
        }
        // All of the K nearest tie with the next one: keep them equal.
        pairs.truncate(k);
    }
    sparse::normalize(&mut pairs);
    pairs
}

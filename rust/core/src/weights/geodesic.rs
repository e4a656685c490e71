//! Geodesic distances from bones through the solid: for every solid cell, its `k` nearest bones
//! and their distances, by shortest paths between the centers of 26-neighbouring solid cells
//! (steps of 1, √2, √3 cells).
//!
//! One Dijkstra search carries every bone at once, each cell keeping up to `k` labels (a bone and
//! its distance). This is exact for the `k` nearest: if bone `b` is among the `k` nearest of a
//! cell `v`, it is among the `k` nearest of every cell `u` on its shortest path to `v` (a bone
//! nearer to `u` than `b` would be nearer to `v` too), so stopping a bone at cells that already
//! hold `k` nearer ones loses nothing. The queue is a bucket queue of width one cell, the
//! shortest step: labels in one bucket cannot improve each other, so each bucket is settled in
//! order of distance after a sort, without a heap.
//!
//! Each bone starts from the solid cells whose centers lie within one cell of its segment, at
//! their distance from it. A bone that crosses no solid cell (outside the mesh, or inside an open
//! garment that has no inside) reaches the solid in straight lines first, at its distance (each
//! cell from the `k` such bones nearest to it), and the search carries it on from there; the
//! caller reports those bones. Where some bone starts inside the solid, outside bones reach only
//! the connected parts such bones start in: a loose part no bone is inside stays unreached.

use glam::Vec3;
use rayon::prelude::*;

use super::voxels::Solid;
use super::{Progress, WeightsError};

/// Bytes kept per solid cell for `k` labels (count, bones, distances).
pub(crate) fn bytes_per_cell(k: usize) -> usize {
    1 + k * (2 + 4)
}

/// The `k` nearest bones of every solid cell, nearest first.
pub(crate) struct NearestBones {
    pub k: usize,
    count: Vec<u8>,
    bones: Vec<u16>,
    dists: Vec<f32>,
}

impl NearestBones {
    /// The labels of solid cell `id`: `(bone, distance in cells)`, nearest first.
    #[inline]
    pub fn of(&self, id: u32) -> impl Iterator<Item = (u32, f32)> + '_ {
        let start = id as usize * self.k;
        let n = self.count[id as usize] as usize;
        (start..start + n).map(move |s| (u32::from(self.bones[s]), self.dists[s]))
    }

    #[inline]
    fn holds(&self, id: usize, bone: u16) -> bool {
        let start = id * self.k;
        self.bones[start..start + self.count[id] as usize].contains(&bone)
    }
}

#[derive(Clone, Copy)]
struct Label {
    dist: f32,
    id: u32,
    bone: u16,
}

/// Distance from point `p` to segment `a`–`b`.
#[inline]
pub(crate) fn segment_distance(p: Vec3, a: Vec3, b: Vec3) -> f32 {
    let ab = b - a;
    let len2 = ab.length_squared();
    let t = if len2 > 0.0 { ((p - a).dot(ab) / len2).clamp(0.0, 1.0) } else { 0.0 };
    (a + ab * t).distance(p)
}

/// The part of the segment `a`-`b` inside the box `lo`-`hi` (Liang-Barsky), or None.
pub(crate) fn clip_segment(a: Vec3, b: Vec3, lo: Vec3, hi: Vec3) -> Option<(Vec3, Vec3)> {
    let d = b - a;
    let (mut t0, mut t1) = (0.0f32, 1.0f32);
    for axis in 0..3 {
        let (p, q0, q1) = (d[axis], lo[axis] - a[axis], hi[axis] - a[axis]);
        if p == 0.0 {
            if q0 > 0.0 || q1 < 0.0 {
                return None;
            }
            continue;
        }
        let (mut near, mut far) = (q0 / p, q1 / p);
        if near > far {
            std::mem::swap(&mut near, &mut far);
        }
        t0 = t0.max(near);
        t1 = t1.min(far);
        if t0 > t1 || !t0.is_finite() || !t1.is_finite() {
            return None;
        }
    }
    Some((a + d * t0, a + d * t1))
}

/// The starting cells of each bone (segments in grid coordinates): `(cell id, bone, distance)`,
/// and the bones that cross no solid cell (they start from every solid cell, in straight lines).
fn seeds(solid: &Solid, segments: &[(Vec3, Vec3)], k: usize) -> (Vec<Label>, Vec<u32>) {
    let grid = &solid.grid;
    let per_bone: Vec<Vec<Label>> = crate::pool::run(|| {
        segments
            .par_iter()
            .enumerate()
            .map(|(bone, &(a, b))| {
                let mut found: Vec<Label> = Vec::new();
                // Only the part of the bone inside the grid can touch a solid cell (and a bone
                // far out, or huge, costs no more than one across the grid).
                let [nx, ny, nz] = grid.dims;
                let Some((a, b)) =
                    clip_segment(a, b, Vec3::splat(-1.0), Vec3::new(nx as f32, ny as f32, nz as f32) + 1.0)
                else {
                    return found;
                };
                let steps = ((b - a).length() * 2.0).ceil().max(1.0) as usize;
                for s in 0..=steps {
                    let p = a + (b - a) * (s as f32 / steps as f32);
                    let c = p.floor();
                    for dz in -1..=1 {
                        for dy in -1..=1 {
                            for dx in -1..=1 {
                                let q = c + Vec3::new(dx as f32, dy as f32, dz as f32) + Vec3::splat(0.5);
                                let Some(cell) = grid.cell_at(q) else { continue };
                                let Some(id) = solid.id(cell) else { continue };
                                let dist = segment_distance(q, a, b);
                                if dist <= 1.0 {
                                    found.push(Label { dist, id, bone: bone as u16 });
                                }
                            }
                        }
                    }
                }
                found.sort_unstable_by_key(|l| l.id);
                found.dedup_by_key(|l| l.id);
                found
            })
            .collect()
    });
    let mut all = Vec::new();
    let mut outside = Vec::new();
    for (bone, found) in per_bone.into_iter().enumerate() {
        if found.is_empty() {
            outside.push(bone as u32);
        }
        all.extend(found);
    }
    if !outside.is_empty() {
        let reach = reached_parts(solid, &all);
        all.extend(straight_seeds(solid, segments, &outside, k, reach.as_deref()));
    }
    (all, outside)
}

/// Which solid cells lie in a connected part of the solid (26-neighbours, the search's steps)
/// that some bone starts inside, or None when no bone starts inside any part (every bone is
/// outside: an open garment alone). Outside bones reach only those parts in straight lines: a
/// loose part away from every inside bone (an eye) stays unreached, so its vertices take their
/// nearest bones among all bones, not the outside bones alone.
fn reached_parts(solid: &Solid, inside: &[Label]) -> Option<Vec<bool>> {
    if inside.is_empty() {
        return None;
    }
    let [nx, ny, _] = solid.grid.dims;
    let mut reached = vec![false; solid.len()];
    let mut stack: Vec<u32> = Vec::new();
    for l in inside {
        if !reached[l.id as usize] {
            reached[l.id as usize] = true;
            stack.push(l.id);
        }
    }
    while let Some(id) = stack.pop() {
        let cell = solid.cells[id as usize] as isize;
        for dz in -1isize..=1 {
            for dy in -1isize..=1 {
                for dx in -1isize..=1 {
                    let step = dx + nx as isize * (dy + ny as isize * dz);
                    // Solid cells lie inside the grid's empty border, so every neighbour exists.
                    let Some(next) = solid.id((cell + step) as usize) else { continue };
                    if !reached[next as usize] {
                        reached[next as usize] = true;
                        stack.push(next);
                    }
                }
            }
        }
    }
    Some(reached)
}

/// Seeds of the bones that cross no solid cell: each solid cell gets the `k` of them nearest in a
/// straight line. That loses nothing: a path through the solid is never shorter than the straight
/// line, so a bone that `k` others beat in a straight line at a cell cannot be among its `k`
/// nearest by any path.
fn straight_seeds(
    solid: &Solid,
    segments: &[(Vec3, Vec3)],
    outside: &[u32],
    k: usize,
    parts: Option<&[bool]>,
) -> Vec<Label> {
    let grid = &solid.grid;
    crate::pool::run(|| {
        solid
            .cells
            .par_iter()
            .enumerate()
            .with_min_len(1024)
            .filter(|(id, _)| parts.is_none_or(|reached| reached[*id]))
            .flat_map_iter(|(id, &cell)| {
                let c = grid.center(cell as usize);
                let mut near: Vec<Label> = outside
                    .iter()
                    .map(|&b| {
                        let (a, t) = segments[b as usize];
                        Label { dist: segment_distance(c, a, t), id: id as u32, bone: b as u16 }
                    })
                    .collect();
                if near.len() > k {
                    near.select_nth_unstable_by(k - 1, |x, y| x.dist.total_cmp(&y.dist).then(x.bone.cmp(&y.bone)));
                    near.truncate(k);
                }
                near
            })
            .collect()
    })
}

/// The `k` nearest bones of every solid cell by geodesic distance (in cells). Returns them and
/// the bones that started outside the solid.
pub(crate) fn nearest_bones(
    solid: &Solid,
    segments: &[(Vec3, Vec3)],
    k: usize,
    progress: Progress<'_>,
) -> Result<(NearestBones, Vec<u32>), WeightsError> {
    let n = solid.len();
    let mut out = NearestBones { k, count: vec![0; n], bones: vec![0; n * k], dists: vec![0.0; n * k] };
    let (start, snapped) = seeds(solid, segments, k);
    let grid = &solid.grid;
    let [nx, ny, _] = grid.dims;
    let mut steps: Vec<(isize, f32)> = Vec::with_capacity(26);
    for dz in -1isize..=1 {
        for dy in -1isize..=1 {
            for dx in -1isize..=1 {
                let moved = dx.abs() + dy.abs() + dz.abs();
                if moved > 0 {
                    steps.push((dx + nx as isize * (dy + ny as isize * dz), (moved as f32).sqrt()));
                }
            }
        }
    }
    let mut buckets: Vec<Vec<Label>> = Vec::new();
    let push = |buckets: &mut Vec<Vec<Label>>, l: Label| {
        let b = l.dist as usize;
        if b >= buckets.len() {
            buckets.resize_with(b + 1, Vec::new);
        }
        buckets[b].push(l);
    };
    for l in start {
        push(&mut buckets, l);
    }
    let total = n * k;
    let mut settled = 0usize;
    let mut current = 0usize;
    while current < buckets.len() {
        // Taken (not swapped): a settled bucket's memory is freed, not kept in its slot.
        let mut batch = std::mem::take(&mut buckets[current]);
        batch.sort_unstable_by(|a, b| a.dist.total_cmp(&b.dist).then(a.bone.cmp(&b.bone)).then(a.id.cmp(&b.id)));
        for &l in &batch {
            let id = l.id as usize;
            let held = out.count[id] as usize;
            if held == k || out.holds(id, l.bone) {
                continue;
            }
            out.bones[id * k + held] = l.bone;
            out.dists[id * k + held] = l.dist;
            out.count[id] += 1;
            settled += 1;
            let cell = solid.cells[id] as isize;
            for &(step, length) in &steps {
                // Solid cells lie inside the grid's empty border, so every neighbour exists.
                let Some(next) = solid.id((cell + step) as usize) else { continue };
                let next_usize = next as usize;
                if out.count[next_usize] as usize == k || out.holds(next_usize, l.bone) {
                    continue;
                }
                push(&mut buckets, Label { dist: l.dist + length, id: next, bone: l.bone });
            }
        }
        current += 1;
        if current.is_multiple_of(32) && !progress(settled, total) {
            return Err(WeightsError::Cancelled);
        }
    }
    Ok((out, snapped))
}

//! Automatic weights: the pipeline of geodesic voxel binding (see the module's documentation).

use glam::Vec3;
use rayon::prelude::*;

use super::falloff::{distances_at, straight_distances, weights_from_distances};
use super::geodesic::{bytes_per_cell, nearest_bones};
use super::mesh::{diagonal, Neighbours};
use super::sparse::{self, Pair};
use super::voxels::{grid_bytes, Grid, Solid};
use super::{
    check_points, check_range, check_triangles, mirror, smooth, Progress, WeightsError, DEFAULT_RESOLUTION,
    MAX_RESOLUTION, MAX_WEIGHT_BONES, MAX_WEIGHT_INFLUENCES, MEMORY_BUDGET, MIN_RESOLUTION,
};
use crate::skin::Influences;

/// A bone as a segment from head to tail, in the space of the mesh's positions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bone {
    pub head: [f32; 3],
    pub tail: [f32; 3],
}

/// How automatic weights are computed.
#[derive(Clone, Debug, PartialEq)]
pub struct AutoOptions {
    /// Voxels along the longest side of the mesh's bounding box
    /// ([`MIN_RESOLUTION`]..=[`MAX_RESOLUTION`]).
    pub resolution: usize,
    /// `α` of the falloff `1 / ((1 − α)·d + α·d²)²`, in `[0, 1]`: higher, the weights fall off
    /// faster away from each bone.
    pub falloff: f32,
    /// The most bones per vertex (1..=[`MAX_WEIGHT_INFLUENCES`]).
    pub max_influences: usize,
    /// Smoothing passes over the mesh (0: none).
    pub smoothing: u32,
    /// Mirror across X = 0 with this map from each bone to its mirrored namesake
    /// ([`super::mirror_bone_map`]).
    pub mirror: Option<Vec<u32>>,
}

impl Default for AutoOptions {
    fn default() -> Self {
        AutoOptions { resolution: DEFAULT_RESOLUTION, falloff: 0.2, max_influences: 4, smoothing: 0, mirror: None }
    }
}

/// Automatic weights and what the caller should be told about them.
#[derive(Clone, Debug)]
pub struct AutoWeights {
    /// At most `max_influences` bones per vertex, weights summing to one, for every vertex.
    pub influences: Influences,
    /// Vertices no bone reached through the solid, weighted to their nearest bones instead.
    pub unreached: usize,
    /// Bones that cross no solid voxel (outside the mesh): they reach it in straight lines.
    pub outside_bones: Vec<u32>,
    /// The voxel grid's size and how many of its voxels are solid.
    pub grid: [usize; 3],
    pub solid_voxels: usize,
}

/// Progress units per stage: voxelizing, the geodesic search (its share), the vertices.
const STAGES: usize = 100;

/// Automatic weights of a rest mesh (`positions`, `triangles`) for `bones` (same space).
pub fn automatic_weights(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    bones: &[Bone],
    options: &AutoOptions,
    progress: Progress<'_>,
) -> Result<AutoWeights, WeightsError> {
    check_points("positions", positions)?;
    check_triangles("triangles", triangles, positions.len())?;
    let b = bones.len();
    if b == 0 {
        return Err(WeightsError::NoBones);
    }
    if b > MAX_WEIGHT_BONES {
        return Err(WeightsError::TooManyBones { count: b });
    }
    if let Some(i) = bones.iter().position(|b| !b.head.iter().chain(&b.tail).all(|c| c.is_finite())) {
        return Err(WeightsError::NotFinite { what: "bones", index: i });
    }
    check_range("resolution", options.resolution as f64, MIN_RESOLUTION as f64, MAX_RESOLUTION as f64)?;
    check_range("falloff", f64::from(options.falloff), 0.0, 1.0)?;
    check_range("max_influences", options.max_influences as f64, 1.0, MAX_WEIGHT_INFLUENCES as f64)?;
    check_range("smoothing", f64::from(options.smoothing), 0.0, 1000.0)?;
    if let Some(map) = &options.mirror {
        if map.len() != b {
            return Err(WeightsError::LengthMismatch { what: "mirror", expected: b, got: map.len() });
        }
        if let Some(&m) = map.iter().find(|&&m| m as usize >= b) {
            return Err(WeightsError::OutOfRange {
                what: "mirror bone",
                value: f64::from(m),
                min: 0.0,
                max: (b - 1) as f64,
            });
        }
    }
    let k = options.max_influences;
    let labels = k + 1;
    let grid = Grid::around(positions, options.resolution);
    let dims = grid.dims;
    // The grid's bitsets must fit before voxelizing; the labels once the solid is known.
    let fixed = grid_bytes(grid.cell_count());
    if fixed > MEMORY_BUDGET {
        return Err(WeightsError::TooMuchMemory { resolution: options.resolution, needed: fixed });
    }
    if !progress(0, 3 * STAGES) {
        return Err(WeightsError::Cancelled);
    }
    let solid = crate::pool::run(|| Solid::build(grid, positions, triangles));
    let needed = fixed + solid.len() * (4 + bytes_per_cell(labels) + QUEUE_BYTES_PER_CELL);
    if needed > MEMORY_BUDGET {
        return Err(WeightsError::TooMuchMemory { resolution: options.resolution, needed });
    }
    if !progress(STAGES, 3 * STAGES) {
        return Err(WeightsError::Cancelled);
    }
    let grid = solid.grid.clone();
    let segments: Vec<(Vec3, Vec3)> = bones
        .iter()
        .map(|b| (grid.to_grid(Vec3::from_array(b.head)), grid.to_grid(Vec3::from_array(b.tail))))
        .collect();
    let mut search_progress = |done: usize, total: usize| progress(STAGES + done * STAGES / total.max(1), 3 * STAGES);
    let (nearest, outside_bones) = nearest_bones(&solid, &segments, labels, &mut search_progress)?;
    let diag = diagonal(positions);
    // Distances in cells to fractions of the diagonal.
    let scale = if diag > 0.0 { grid.cell / diag } else { 1.0 };
    let falloff = options.falloff;
    let results: Vec<(Vec<Pair>, bool)> = crate::pool::run(|| {
        positions
            .par_iter()
            .with_min_len(1024)
            .map_init(Vec::new, |scratch, p| {
                let p = Vec3::from_array(*p);
                distances_at(&solid, &nearest, grid.to_grid(p), scratch);
                if scratch.is_empty() {
                    let mut straight = straight_distances(grid.to_grid(p), &segments, labels);
                    return (weights_from_distances(&mut straight, scale, falloff, k), true);
                }
                (weights_from_distances(scratch, scale, falloff, k), false)
            })
            .collect()
    });
    drop(nearest);
    let unreached = results.iter().filter(|r| r.1).count();
    let mut lists: Vec<Vec<Pair>> = results.into_iter().map(|r| r.0).collect();
    if !progress(2 * STAGES, 3 * STAGES) {
        return Err(WeightsError::Cancelled);
    }
    if options.smoothing > 0 {
        let neighbours = Neighbours::of_triangles(positions.len(), triangles);
        smooth::smooth(&mut lists, &neighbours, options.smoothing, k, None);
    }
    if let Some(map) = &options.mirror {
        mirror::mirror(&mut lists, positions, map, MIRROR_TOLERANCE * diag, k);
    }
    for list in &mut lists {
        sparse::keep_strongest(list, k);
    }
    if !progress(3 * STAGES, 3 * STAGES) {
        return Err(WeightsError::Cancelled);
    }
    Ok(AutoWeights {
        influences: sparse::to_influences(&lists, b),
        unreached,
        outside_bones,
        grid: dims,
        solid_voxels: solid.len(),
    })
}

/// What the search's queue may hold per solid voxel at most, counted in the memory budget: a
/// label is 12 bytes and each voxel's labels are pushed by a few of its 26 neighbours before
/// they settle.
const QUEUE_BYTES_PER_CELL: usize = 64;

/// How far (a fraction of the bounding-box diagonal) a vertex's mirror image may be from the
/// vertex standing for it.
const MIRROR_TOLERANCE: f32 = 1e-3;

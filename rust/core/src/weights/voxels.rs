//! The solid voxelization of a rest mesh: a grid of cubic cells over its bounding box, the cells
//! its triangles touch (a triangle–box overlap test by separating axes, Akenine-Möller 2001),
//! and the cells a flood fill from outside cannot reach. Surface and enclosed cells together are
//! the *solid* through which geodesic distances run. Nothing needs the mesh to be closed, single
//! or free of intersections: an open sheet is its surface cells, intersecting closed parts are
//! one solid, and a hole smaller than a cell is sealed by the surface cells around it.
//!
//! Solid cells are numbered densely (a rank over the solid bitset), so per-cell data costs
//! memory for the solid only, not for the whole grid.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};

use glam::Vec3;
use rayon::prelude::*;

/// Empty cells around the mesh on every side, so the flood fill starts outside it.
const PAD: usize = 2;

/// A grid of cubic cells: cell `(x, y, z)` spans `origin + cell·[x, x+1] × ...`.
#[derive(Clone, Debug)]
pub(crate) struct Grid {
    pub origin: Vec3,
    pub cell: f32,
    pub dims: [usize; 3],
}

impl Grid {
    /// The grid whose longest side of the points' bounding box spans `resolution` cells.
    pub fn around(points: &[[f32; 3]], resolution: usize) -> Grid {
        let (lo, hi) = bounds(points);
        let extent = hi - lo;
        let longest = extent.max_element();
        // A point or a degenerate box still gets a usable cell size.
        let cell = if longest > 0.0 { longest / resolution as f32 } else { 1.0 };
        let dims = [0, 1, 2].map(|a| ((extent[a] / cell).ceil() as usize).max(1) + 2 * PAD);
        Grid { origin: lo - Vec3::splat(PAD as f32 * cell), cell, dims }
    }

    pub fn cell_count(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    /// Grid coordinates of a point (cell `(x, y, z)` spans `[x, x+1]` in each).
    #[inline]
    pub fn to_grid(&self, p: Vec3) -> Vec3 {
        (p - self.origin) / self.cell
    }

    #[inline]
    pub fn index(&self, x: usize, y: usize, z: usize) -> usize {
        x + self.dims[0] * (y + self.dims[1] * z)
    }

    #[inline]
    pub fn coords(&self, i: usize) -> [usize; 3] {
        let x = i % self.dims[0];
        let yz = i / self.dims[0];
        [x, yz % self.dims[1], yz / self.dims[1]]
    }

    /// The center of a cell in grid coordinates.
    #[inline]
    pub fn center(&self, i: usize) -> Vec3 {
        let [x, y, z] = self.coords(i);
        Vec3::new(x as f32 + 0.5, y as f32 + 0.5, z as f32 + 0.5)
    }

    /// The cell containing grid point `g`, if inside the grid.
    #[inline]
    pub fn cell_at(&self, g: Vec3) -> Option<usize> {
        let c = g.floor();
        if c.min_element() < 0.0 {
            return None;
        }
        let [x, y, z] = [c.x as usize, c.y as usize, c.z as usize];
        (x < self.dims[0] && y < self.dims[1] && z < self.dims[2]).then(|| self.index(x, y, z))
    }
}

pub(crate) fn bounds(points: &[[f32; 3]]) -> (Vec3, Vec3) {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for p in points {
        let p = Vec3::from_array(*p);
        lo = lo.min(p);
        hi = hi.max(p);
    }
    if points.is_empty() {
        (Vec3::ZERO, Vec3::ZERO)
    } else {
        (lo, hi)
    }
}

/// Bytes of the grid's bitsets (surface, outside and the solid rank) for a cell count.
pub(crate) fn grid_bytes(cells: usize) -> usize {
    let words = cells.div_ceil(64);
    words * (8 + 8 + 8 + 4)
}

/// The solid cells of a mesh on a grid, densely numbered.
pub(crate) struct Solid {
    pub grid: Grid,
    /// Bit per cell: inside the solid.
    bits: Vec<u64>,
    /// Solid cells before each 64-cell word.
    rank: Vec<u32>,
    /// Grid index of each solid cell, in grid order.
    pub cells: Vec<u32>,
}

impl Solid {
    /// Voxelizes `triangles` of `positions` on `grid`.
    pub fn build(grid: Grid, positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Solid {
        let surface = surface_cells(&grid, positions, triangles);
        let bits = enclosed(&grid, &surface);
        drop(surface);
        let mut rank = Vec::with_capacity(bits.len());
        let mut count = 0u32;
        for w in &bits {
            rank.push(count);
            count += w.count_ones();
        }
        let mut cells = Vec::with_capacity(count as usize);
        for (wi, &w) in bits.iter().enumerate() {
            let mut w = w;
            while w != 0 {
                let b = w.trailing_zeros() as usize;
                cells.push((wi * 64 + b) as u32);
                w &= w - 1;
            }
        }
        Solid { grid, bits, rank, cells }
    }

    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// The solid number of grid cell `i`, if it is solid.
    #[inline]
    pub fn id(&self, i: usize) -> Option<u32> {
        let (w, b) = (i / 64, i % 64);
        let word = self.bits[w];
        if word >> b & 1 == 0 {
            return None;
        }
        Some(self.rank[w] + (word & ((1u64 << b) - 1)).count_ones())
    }
}

/// Cells that some triangle touches, as a bitset over the grid.
fn surface_cells(grid: &Grid, positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Vec<u64> {
    let bits: Vec<AtomicU64> = (0..grid.cell_count().div_ceil(64)).map(|_| AtomicU64::new(0)).collect();
    let set = |i: usize| {
        bits[i / 64].fetch_or(1 << (i % 64), Ordering::Relaxed);
    };
    triangles.par_iter().with_min_len(256).for_each(|t| {
        let v = t.map(|i| grid.to_grid(Vec3::from_array(positions[i as usize])));
        let lo = v[0].min(v[1]).min(v[2]).floor().max(Vec3::ZERO);
        let hi = v[0].max(v[1]).max(v[2]).floor();
        let top = [grid.dims[0] - 1, grid.dims[1] - 1, grid.dims[2] - 1];
        let (x0, y0, z0) = (lo.x as usize, lo.y as usize, lo.z as usize);
        let (x1, y1, z1) = ((hi.x as usize).min(top[0]), (hi.y as usize).min(top[1]), (hi.z as usize).min(top[2]));
        if x0 == x1 && y0 == y1 && z0 == z1 {
            set(grid.index(x0, y0, z0));
            return;
        }
        for z in z0..=z1 {
            for y in y0..=y1 {
                for x in x0..=x1 {
                    let center = Vec3::new(x as f32 + 0.5, y as f32 + 0.5, z as f32 + 0.5);
                    if triangle_touches_box(v, center, 0.5) {
                        set(grid.index(x, y, z));
                    }
                }
            }
        }
    });
    bits.into_iter().map(AtomicU64::into_inner).collect()
}

/// Everything a 6-connected flood fill from the grid's border cannot reach through non-surface
/// cells (surface cells included), as a bitset.
fn enclosed(grid: &Grid, surface: &[u64]) -> Vec<u64> {
    let [nx, ny, nz] = grid.dims;
    let n = grid.cell_count();
    let mut outside = vec![0u64; surface.len()];
    let is = |bits: &[u64], i: usize| bits[i / 64] >> (i % 64) & 1 == 1;
    let mut queue: VecDeque<u32> = VecDeque::new();
    // The border cells are empty (the grid has PAD empty cells around the mesh): seed with one.
    outside[0] |= 1;
    queue.push_back(0);
    let steps: [isize; 6] = [1, -1, nx as isize, -(nx as isize), (nx * ny) as isize, -((nx * ny) as isize)];
    while let Some(i) = queue.pop_front() {
        let i = i as usize;
        let [x, y, z] = grid.coords(i);
        let open = [x + 1 < nx, x > 0, y + 1 < ny, y > 0, z + 1 < nz, z > 0];
        for (k, &step) in steps.iter().enumerate() {
            if !open[k] {
                continue;
            }
            let j = (i as isize + step) as usize;
            if !is(&outside, j) && !is(surface, j) {
                outside[j / 64] |= 1 << (j % 64);
                queue.push_back(j as u32);
            }
        }
    }
    let mut solid: Vec<u64> = outside.iter().map(|w| !w).collect();
    // Bits past the last cell are not cells.
    if !n.is_multiple_of(64) {
        let last = solid.len() - 1;
        solid[last] &= (1u64 << (n % 64)) - 1;
    }
    solid
}

/// Whether triangle `v` (grid coordinates) touches the axis-aligned box at `center` with
/// half-size `h`: the 13 separating axes of the triangle–box overlap test.
pub(crate) fn triangle_touches_box(v: [Vec3; 3], center: Vec3, h: f32) -> bool {
    // A little slack so that a triangle lying exactly on a cell face marks both cells.
    let h = h * (1.0 + 1e-4);
    let v = v.map(|p| p - center);
    let e = [v[1] - v[0], v[2] - v[1], v[0] - v[2]];
    // The box's own axes.
    for a in 0..3 {
        let lo = v[0][a].min(v[1][a]).min(v[2][a]);
        let hi = v[0][a].max(v[1][a]).max(v[2][a]);
        if lo > h || hi < -h {
            return false;
        }
    }
    // The triangle's plane.
    let normal = e[0].cross(e[1]);
    let d = normal.dot(v[0]);
    let r = h * normal.abs().element_sum();
    if d.abs() > r {
        return false;
    }
    // Cross products of the box axes and the edges.
    for edge in e {
        for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
            let a = axis.cross(edge);
            if a == Vec3::ZERO {
                continue;
            }
            let p = [a.dot(v[0]), a.dot(v[1]), a.dot(v[2])];
            let lo = p[0].min(p[1]).min(p[2]);
            let hi = p[0].max(p[1]).max(p[2]);
            let r = h * a.abs().element_sum();
            if lo > r || hi < -r {
                return false;
            }
        }
    }
    true
}

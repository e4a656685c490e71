//! What the weighting needs of a triangle mesh: vertex neighbours, area-weighted vertex normals,
//! connected parts and the bounding-box diagonal.

use glam::Vec3;

use super::voxels::bounds;

/// Each vertex's neighbours along triangle edges (CSR, sorted, no repeats).
pub(crate) struct Neighbours {
    pub offsets: Vec<u32>,
    pub list: Vec<u32>,
}

impl Neighbours {
    pub fn of_triangles(vertex_count: usize, triangles: &[[u32; 3]]) -> Neighbours {
        let mut pairs: Vec<(u32, u32)> = Vec::with_capacity(triangles.len() * 6);
        for t in triangles {
            for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                if a != b {
                    pairs.push((a, b));
                    pairs.push((b, a));
                }
            }
        }
        pairs.sort_unstable();
        pairs.dedup();
        let mut offsets = vec![0u32; vertex_count + 1];
        for &(a, _) in &pairs {
            offsets[a as usize + 1] += 1;
        }
        for v in 0..vertex_count {
            offsets[v + 1] += offsets[v];
        }
        Neighbours { offsets, list: pairs.into_iter().map(|p| p.1).collect() }
    }

    #[inline]
    pub fn of(&self, v: usize) -> &[u32] {
        &self.list[self.offsets[v] as usize..self.offsets[v + 1] as usize]
    }
}

/// Area-weighted vertex normals (unit length; zero for a vertex on no triangle of any area).
pub(crate) fn vertex_normals(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Vec<Vec3> {
    let mut normals = vec![Vec3::ZERO; positions.len()];
    for t in triangles {
        let [a, b, c] = t.map(|i| Vec3::from_array(positions[i as usize]));
        let n = (b - a).cross(c - a);
        for &i in t {
            normals[i as usize] += n;
        }
    }
    for n in &mut normals {
        *n = n.normalize_or_zero();
    }
    normals
}

/// The connected part of each vertex (through triangle edges), numbered from 0, and the count.
pub(crate) fn parts(vertex_count: usize, neighbours: &Neighbours) -> (Vec<u32>, usize) {
    let mut part = vec![u32::MAX; vertex_count];
    let mut count = 0u32;
    let mut stack = Vec::new();
    for start in 0..vertex_count {
        if part[start] != u32::MAX {
            continue;
        }
        part[start] = count;
        stack.push(start as u32);
        while let Some(v) = stack.pop() {
            for &u in neighbours.of(v as usize) {
                if part[u as usize] == u32::MAX {
                    part[u as usize] = count;
                    stack.push(u);
                }
            }
        }
        count += 1;
    }
    (part, count as usize)
}

/// The length of the bounding box's diagonal (0 for no points).
pub(crate) fn diagonal(points: &[[f32; 3]]) -> f32 {
    let (lo, hi) = bounds(points);
    (hi - lo).length()
}

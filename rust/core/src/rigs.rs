//! Small procedural rigs for demos, tests and benchmarks.

use glam::{Mat4, Quat, Vec3};

use crate::skin::{Influences, SkinError};

/// A closed cylinder along +Y driven by two bones that meet in the middle, the classic test of
/// the "candy wrapper" collapse: twisting the upper bone makes linear blend skinning pinch the
/// middle to a point, while dual quaternion skinning keeps the cross-section.
#[derive(Clone, Debug)]
pub struct TwistCylinder {
    /// Rest positions: `rings × segments` side vertices, ring by ring from y = 0, then the
    /// bottom and top cap centres.
    pub positions: Vec<[f32; 3]>,
    /// Triangles, counter-clockwise seen from outside (a closed, consistently oriented surface).
    pub triangles: Vec<[u32; 3]>,
    pub influences: Influences,
    /// Rest matrices of the two bones (`Bone.matrix_local`): the lower at the origin, the upper
    /// at half height, both pointing along +Y.
    pub rest: [Mat4; 2],
    pub rings: usize,
    pub segments: usize,
    pub length: f32,
    pub radius: f32,
}

/// Size limits of [`TwistCylinder`] (16M vertices: about 1 GB with its influences).
pub const MAX_RINGS: usize = 1 << 20;
pub const MAX_SEGMENTS: usize = 1 << 20;
pub const MAX_VERTICES: usize = 1 << 24;

impl TwistCylinder {
    /// `rings ≥ 2` rings of `segments ≥ 3` vertices. Weights blend linearly from the lower bone
    /// to the upper one over the middle `blend_zone` fraction of the length.
    pub fn new(
        rings: usize,
        segments: usize,
        length: f32,
        radius: f32,
        blend_zone: f32,
    ) -> Result<Self, SkinError> {
        let bad = |msg: &str| Err(SkinError::InvalidInfluences(msg.to_string()));
        if rings < 2 || segments < 3 {
            return bad("a cylinder needs at least 2 rings of 3 segments");
        }
        if rings > MAX_RINGS || segments > MAX_SEGMENTS || rings * segments > MAX_VERTICES {
            return Err(SkinError::InvalidInfluences(format!(
                "rings × segments = {rings} × {segments} is too large (at most {MAX_RINGS} rings, {MAX_SEGMENTS} segments, {MAX_VERTICES} vertices)"
            )));
        }
        if !(length > 0.0 && radius > 0.0 && length.is_finite() && radius.is_finite()) {
            return bad("length and radius must be positive and finite");
        }
        let blend_zone = blend_zone.clamp(1e-3, 1.0);
        let mut positions = Vec::with_capacity(rings * segments + 2);
        let mut lists = Vec::with_capacity(rings * segments + 2);
        let weights_at = |y: f32| {
            let u = ((y / length - 0.5) / blend_zone + 0.5).clamp(0.0, 1.0);
            let mut list = Vec::new();
            if u < 1.0 {
                list.push((0u32, 1.0 - u));
            }
            if u > 0.0 {
                list.push((1u32, u));
            }
            list
        };
        for r in 0..rings {
            let y = length * r as f32 / (rings - 1) as f32;
            for s in 0..segments {
                let phi = core::f32::consts::TAU * s as f32 / segments as f32;
                positions.push([radius * phi.cos(), y, -radius * phi.sin()]);
                lists.push(weights_at(y));
            }
        }
        let bottom = positions.len() as u32;
        positions.push([0.0, 0.0, 0.0]);
        lists.push(weights_at(0.0));
        let top = bottom + 1;
        positions.push([0.0, length, 0.0]);
        lists.push(weights_at(length));

        let idx = |r: usize, s: usize| (r * segments + s % segments) as u32;
        let mut triangles = Vec::with_capacity(2 * segments * rings);
        for r in 0..rings - 1 {
            for s in 0..segments {
                let (a, b, c, d) = (idx(r, s), idx(r, s + 1), idx(r + 1, s + 1), idx(r + 1, s));
                triangles.push([a, b, c]);
                triangles.push([a, c, d]);
            }
        }
        for s in 0..segments {
            triangles.push([bottom, idx(0, s + 1), idx(0, s)]);
            triangles.push([top, idx(rings - 1, s), idx(rings - 1, s + 1)]);
        }
        let influences = Influences::from_lists(&lists, 2)?;
        let rest = [Mat4::IDENTITY, Mat4::from_translation(Vec3::new(0.0, 0.5 * length, 0.0))];
        Ok(Self { positions, triangles, influences, rest, rings, segments, length, radius })
    }

    /// Deform matrices (posed × rest⁻¹) for the upper bone twisted by `angle` radians about its
    /// own Y axis (the cylinder's axis); the lower bone stays at rest.
    pub fn twist(&self, angle: f32) -> [Mat4; 2] {
        let posed = self.rest[1] * Mat4::from_quat(Quat::from_rotation_y(angle));
        [Mat4::IDENTITY, posed * self.rest[1].inverse()]
    }

    /// Indices of the side vertices of ring `r` (0 at the bottom).
    pub fn ring(&self, r: usize) -> core::ops::Range<usize> {
        r * self.segments..(r + 1) * self.segments
    }
}

/// Enclosed volume of a closed, consistently oriented triangle mesh (divergence theorem);
/// positive for outward-facing triangles. Triangles with out-of-range indices are skipped.
pub fn mesh_volume(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> f64 {
    let p = |i: u32| positions.get(i as usize).map(|v| [v[0] as f64, v[1] as f64, v[2] as f64]);
    let mut six_v = 0.0f64;
    for t in triangles {
        let (Some(a), Some(b), Some(c)) = (p(t[0]), p(t[1]), p(t[2])) else { continue };
        // a · (b × c)
        six_v += a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
            + a[2] * (b[0] * c[1] - b[1] * c[0]);
    }
    six_v / 6.0
}

/// Area of a planar polygon given by its vertices in order (the length of the vector area).
pub fn polygon_area(points: &[[f32; 3]]) -> f64 {
    let mut sum = [0.0f64; 3];
    let n = points.len();
    for i in 0..n {
        let a = points[i].map(f64::from);
        let b = points[(i + 1) % n].map(f64::from);
        sum[0] += a[1] * b[2] - a[2] * b[1];
        sum[1] += a[2] * b[0] - a[0] * b[2];
        sum[2] += a[0] * b[1] - a[1] * b[0];
    }
    0.5 * (sum[0] * sum[0] + sum[1] * sum[1] + sum[2] * sum[2]).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cylinder_is_closed_and_has_the_expected_volume() {
        let c = TwistCylinder::new(16, 64, 4.0, 0.5, 0.5).unwrap();
        let v = mesh_volume(&c.positions, &c.triangles);
        // Inscribed 64-gon prism: (n/2)·r²·sin(2π/n)·L.
        let expected = 32.0 * 0.25 * (core::f64::consts::TAU / 64.0).sin() * 4.0;
        assert!((v - expected).abs() < 1e-4 * expected, "{v} vs {expected}");
        let ring: Vec<_> = c.ring(8).map(|i| c.positions[i]).collect();
        let area = polygon_area(&ring);
        assert!((area - expected / 4.0).abs() < 1e-4);
        // Every edge is shared by exactly two triangles, in opposite directions.
        let mut edges = std::collections::HashMap::new();
        for t in &c.triangles {
            for k in 0..3 {
                *edges.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        assert!(edges.iter().all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1)));
    }

    #[test]
    fn weights_ramp_across_the_middle() {
        let c = TwistCylinder::new(11, 8, 10.0, 1.0, 0.4).unwrap();
        let weight_of_upper = |r: usize| {
            let v = c.ring(r).start;
            c.influences.of_vertex(v).iter().find(|i| i.bone == 1).map_or(0.0, |i| i.weight)
        };
        assert_eq!(weight_of_upper(0), 0.0);
        assert!((weight_of_upper(5) - 0.5).abs() < 1e-6);
        assert_eq!(weight_of_upper(10), 1.0);
        assert!(TwistCylinder::new(1, 8, 1.0, 1.0, 0.5).is_err());
    }
}

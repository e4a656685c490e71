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
    pub fn new(rings: usize, segments: usize, length: f32, radius: f32, blend_zone: f32) -> Result<Self, SkinError> {
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
/// positive for outward-facing triangles. A triangle naming a vertex beyond `positions` is an
/// error.
pub fn mesh_volume(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Result<f64, SkinError> {
    crate::skin::check_triangles(triangles, positions.len())?;
    let p = |i: u32| positions[i as usize].map(f64::from);
    let mut six_v = 0.0f64;
    for t in triangles {
        let (a, b, c) = (p(t[0]), p(t[1]), p(t[2]));
        // a · (b × c)
        six_v += a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
            + a[2] * (b[0] * c[1] - b[1] * c[0]);
    }
    Ok(six_v / 6.0)
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

/// A branching creature for benchmarks and tests of skinning on a realistic mesh: a spine, a
/// neck and head, a tail and four legs (40 bones), each chain skinned as a tube around its
/// bones. Every vertex has four influences with weights that vary smoothly along the tube and a
/// little around it, as painted weights on a subdivided mesh do, so nearly every vertex has a
/// weight vector of its own. The neck, tail and legs blend into the spine bone they hang from.
#[derive(Clone, Debug)]
pub struct Creature {
    pub positions: Vec<[f32; 3]>,
    /// Triangles of the tubes' sides (open tubes).
    pub triangles: Vec<[u32; 3]>,
    pub influences: Influences,
    /// Rest matrices (`Bone.matrix_local`): head at the translation, Y along the bone.
    pub rest: Vec<Mat4>,
    /// Parent bone of each bone (`None` for the root).
    pub parents: Vec<Option<usize>>,
}

/// One chain of the creature: joints from the first bone's head to the last bone's tail, the
/// tube radius at both ends, and the spine bone it hangs from.
struct Chain {
    joints: Vec<Vec3>,
    radius: (f32, f32),
    attached_to: Option<usize>,
}

/// Most vertices a [`Creature`] may have (about 1 GB with its influences and triangles).
pub const MAX_CREATURE_VERTICES: usize = 1 << 24;

impl Creature {
    /// A creature of about `vertices` vertices (at least a few thousand: every tube keeps at
    /// least 8 segments and 4 rings per bone).
    pub fn new(vertices: usize) -> Result<Self, SkinError> {
        if vertices > MAX_CREATURE_VERTICES {
            return Err(SkinError::InvalidInfluences(format!(
                "a creature of {vertices} vertices is too large (at most {MAX_CREATURE_VERTICES})"
            )));
        }
        let line = |from: Vec3, to: Vec3, bones: usize, bow: Vec3| -> Vec<Vec3> {
            (0..=bones)
                .map(|i| {
                    let t = i as f32 / bones as f32;
                    from.lerp(to, t) + bow * (4.0 * t * (1.0 - t))
                })
                .collect()
        };
        let mut chains = vec![Chain {
            joints: line(Vec3::new(0.0, 1.0, -1.2), Vec3::new(0.0, 1.0, 1.2), 8, Vec3::new(0.0, 0.1, 0.0)),
            radius: (0.3, 0.32),
            attached_to: None,
        }];
        chains.push(Chain {
            joints: line(Vec3::new(0.0, 1.05, 1.2), Vec3::new(0.0, 1.8, 1.9), 6, Vec3::new(0.0, 0.1, -0.1)),
            radius: (0.16, 0.12),
            attached_to: Some(7),
        });
        chains.push(Chain {
            joints: line(Vec3::new(0.0, 1.0, -1.2), Vec3::new(0.0, 0.8, -2.6), 6, Vec3::new(0.2, 0.2, 0.0)),
            radius: (0.1, 0.03),
            attached_to: Some(0),
        });
        for (x, z, spine) in [(0.25f32, 0.9f32, 6usize), (-0.25, 0.9, 6), (0.25, -0.9, 1), (-0.25, -0.9, 1)] {
            chains.push(Chain {
                joints: line(Vec3::new(x, 0.85, z), Vec3::new(1.4 * x, 0.0, z + 0.1), 5, Vec3::new(0.0, 0.0, 0.15)),
                radius: (0.11, 0.06),
                attached_to: Some(spine),
            });
        }
        // Tube spacing so the total is about `vertices`.
        let surface: f32 =
            chains.iter().map(|c| chain_length(&c.joints) * core::f32::consts::PI * (c.radius.0 + c.radius.1)).sum();
        let h = (surface / vertices.max(1) as f32).sqrt();

        let mut rest = Vec::new();
        let mut parents = Vec::new();
        let mut positions = Vec::new();
        let mut triangles = Vec::new();
        let mut lists: Vec<Vec<(u32, f32)>> = Vec::new();
        for chain in &chains {
            let first = rest.len();
            let bones = chain.joints.len() - 1;
            for b in 0..bones {
                rest.push(bone_matrix(chain.joints[b], chain.joints[b + 1]));
                parents.push(if b == 0 { chain.attached_to } else { Some(first + b - 1) });
            }
            let length = chain_length(&chain.joints);
            let rings = ((length / h).round() as usize).max(4 * bones) + 1;
            let mean_radius = 0.5 * (chain.radius.0 + chain.radius.1);
            let segments = ((core::f32::consts::TAU * mean_radius / h).round() as usize).max(8);
            if positions.len() + rings * segments > MAX_CREATURE_VERTICES {
                return Err(SkinError::InvalidInfluences("the creature would be too large".into()));
            }
            // Bone k of the weighting chain covers arc length [k, k+1]·(bone length); the bone it
            // hangs from comes first, centred half a bone before the tube starts.
            let bone_length = length / bones as f32;
            let mut weighting: Vec<(u32, f32)> =
                (0..bones).map(|b| ((first + b) as u32, (b as f32 + 0.5) * bone_length)).collect();
            if let Some(p) = chain.attached_to {
                weighting.insert(0, (p as u32, -0.5 * bone_length));
            }
            let base = positions.len() as u32;
            for r in 0..rings {
                let s = length * r as f32 / (rings - 1) as f32;
                let (centre, tangent) = point_on(&chain.joints, s);
                let (u, v) = perpendiculars(tangent);
                let radius = chain.radius.0 + (chain.radius.1 - chain.radius.0) * s / length;
                for k in 0..segments {
                    let phi = core::f32::consts::TAU * k as f32 / segments as f32;
                    let p = centre + radius * (phi.cos() * u + phi.sin() * v);
                    positions.push(p.to_array());
                    // Painted weights drift a little around the tube.
                    let s_painted =
                        s + 0.12 * bone_length * (2.0 * phi).sin() + 0.05 * bone_length * (3.0 * phi + s).cos();
                    lists.push(four_nearest(&weighting, s_painted, bone_length));
                }
            }
            for r in 0..rings - 1 {
                for k in 0..segments {
                    let at = |r: usize, k: usize| base + (r * segments + k % segments) as u32;
                    let (a, b, c, d) = (at(r, k), at(r, k + 1), at(r + 1, k + 1), at(r + 1, k));
                    triangles.push([a, b, c]);
                    triangles.push([a, c, d]);
                }
            }
        }
        let influences = Influences::from_lists(&lists, rest.len())?;
        Ok(Self { positions, triangles, influences, rest, parents })
    }

    /// Deform matrices (posed × rest⁻¹) with every bone bent by `bend` radians about its own
    /// X axis and twisted by `twist` about its own Y axis, relative to its parent.
    pub fn pose(&self, bend: f32, twist: f32) -> Vec<Mat4> {
        let local = Mat4::from_quat(Quat::from_rotation_y(twist) * Quat::from_rotation_x(bend));
        let mut posed: Vec<Mat4> = Vec::with_capacity(self.rest.len());
        for (b, rest) in self.rest.iter().enumerate() {
            // Parents come before their children.
            let parent_motion = self.parents[b].map_or(Mat4::IDENTITY, |p| posed[p] * self.rest[p].inverse());
            posed.push(parent_motion * *rest * local);
        }
        posed.iter().zip(&self.rest).map(|(p, r)| *p * r.inverse()).collect()
    }
}

fn chain_length(joints: &[Vec3]) -> f32 {
    joints.windows(2).map(|w| (w[1] - w[0]).length()).sum()
}

/// The point at arc length `s` along a polyline and the direction there.
fn point_on(joints: &[Vec3], s: f32) -> (Vec3, Vec3) {
    let mut left = s;
    for w in joints.windows(2) {
        let d = w[1] - w[0];
        let l = d.length();
        if left <= l {
            return (w[0] + d * (left / l), d / l);
        }
        left -= l;
    }
    let n = joints.len();
    let d = (joints[n - 1] - joints[n - 2]).normalize();
    (joints[n - 1], d)
}

fn perpendiculars(t: Vec3) -> (Vec3, Vec3) {
    let helper = if t.x.abs() < 0.9 { Vec3::X } else { Vec3::Z };
    let u = t.cross(helper).normalize();
    (u, t.cross(u))
}

/// A bone from `head` to `tail`: Y along it, translation at the head.
fn bone_matrix(head: Vec3, tail: Vec3) -> Mat4 {
    let y = (tail - head).normalize();
    let (x, z) = perpendiculars(y);
    // Right-handed: x × y = z.
    let z = if x.cross(y).dot(z) < 0.0 { -z } else { z };
    Mat4::from_cols(x.extend(0.0), y.extend(0.0), z.extend(0.0), head.extend(1.0))
}

/// The four bones nearest to arc length `s` weighted by a Gaussian of the distance to their
/// middles, normalized.
fn four_nearest(weighting: &[(u32, f32)], s: f32, bone_length: f32) -> Vec<(u32, f32)> {
    let mut w: Vec<(u32, f32)> = weighting
        .iter()
        .map(|&(b, mid)| {
            let d = (s - mid) / (0.75 * bone_length);
            (b, (-d * d).exp())
        })
        .collect();
    w.sort_by(|a, b| b.1.total_cmp(&a.1));
    w.truncate(4);
    let total: f32 = w.iter().map(|e| e.1).sum();
    w.iter().map(|&(b, x)| (b, x / total)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cylinder_is_closed_and_has_the_expected_volume() {
        let c = TwistCylinder::new(16, 64, 4.0, 0.5, 0.5).unwrap();
        let v = mesh_volume(&c.positions, &c.triangles).unwrap();
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
        let mut bad = c.triangles.clone();
        bad[5][2] = c.positions.len() as u32;
        let e = mesh_volume(&c.positions, &bad).unwrap_err();
        assert_eq!(
            e,
            SkinError::InvalidTriangle { index: 5, vertex: c.positions.len() as u32, vertex_count: c.positions.len() }
        );
    }

    #[test]
    fn weights_ramp_across_the_middle() {
        let c = TwistCylinder::new(11, 8, 10.0, 1.0, 0.4).unwrap();
        let weight_of_upper = |r: usize| {
            let v = c.ring(r).start;
            c.influences.of_vertex(v).find(|i| i.bone == 1).map_or(0.0, |i| i.weight)
        };
        assert_eq!(weight_of_upper(0), 0.0);
        assert!((weight_of_upper(5) - 0.5).abs() < 1e-6);
        assert_eq!(weight_of_upper(10), 1.0);
        assert!(TwistCylinder::new(1, 8, 1.0, 1.0, 0.5).is_err());
    }

    #[test]
    fn creature_has_about_the_asked_size_and_four_smooth_influences() {
        let c = Creature::new(20_000).unwrap();
        let n = c.positions.len();
        assert!((16_000..=26_000).contains(&n), "{n} vertices");
        assert_eq!(c.rest.len(), 40);
        assert!(c.triangles.len() > n * 19 / 10);
        assert!((0..n).all(|v| c.influences.of_vertex(v).len() == 4));
        // Nearly every vertex has its own weights.
        let unique: std::collections::HashSet<Vec<u32>> =
            (0..n).map(|v| c.influences.of_vertex(v).map(|i| i.weight.to_bits()).collect()).collect();
        assert!(unique.len() > n * 8 / 10, "{} unique of {n}", unique.len());
        // Rest pose: identity deforms; parents precede children.
        assert!(c.pose(0.0, 0.0).iter().all(|m| m.abs_diff_eq(Mat4::IDENTITY, 1e-5)));
        assert!(c.parents.iter().enumerate().all(|(b, p)| p.is_none_or(|p| p < b)));
    }
}

//! Bone envelopes, as Blender's Armature modifier uses them (`armature_deform.cc`): a vertex
//! without vertex groups mapped to a deforming bone is bound to every bone whose envelope
//! reaches it, and bones with "Multiply Vertex Group by Envelope" scale their group weights by
//! the envelope. Both depend on the vertex's current position, so they are evaluated per frame
//! into *effective influences* that the kernels then use as usual.

use glam::{Mat4, Vec3};
use rayon::prelude::*;

use super::{Influences, SkinError};

/// One bone's envelope, in armature space at rest (`Bone.head_local`, `Bone.tail_local`,
/// `head_radius`, `tail_radius`, `envelope_distance`, `envelope_weight`,
/// `use_envelope_multiply`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Envelope {
    pub head: Vec3,
    pub tail: Vec3,
    pub head_radius: f32,
    pub tail_radius: f32,
    pub distance: f32,
    pub weight: f32,
    pub multiply_groups: bool,
}

/// Blender's `distfactor_to_bone`: 1 inside the radius (interpolated along the bone), falling
/// off quadratically to 0 over `distance` outside it.
pub fn distance_factor(co: Vec3, head: Vec3, tail: Vec3, head_radius: f32, tail_radius: f32, distance: f32) -> f32 {
    let delta = tail - head;
    let l = delta.length();
    let dir = if l != 0.0 { delta / l } else { delta };
    let p = co - head;
    let a = dir.dot(p);
    let (dist_sq, rad) = if a < 0.0 {
        (head.distance_squared(co), head_radius)
    } else if a > l {
        (tail.distance_squared(co), tail_radius)
    } else {
        let rad = if l != 0.0 {
            let f = a / l;
            f * tail_radius + (1.0 - f) * head_radius
        } else {
            head_radius
        };
        (p.length_squared() - a * a, rad)
    };
    if dist_sq < rad * rad {
        return 1.0;
    }
    let outer = (rad + distance) * (rad + distance);
    if distance == 0.0 || dist_sq >= outer {
        return 0.0;
    }
    let d = dist_sq.sqrt() - rad;
    1.0 - d * d / (distance * distance)
}

impl Influences {
    /// The influences Blender's Armature modifier uses this frame. `self` holds the vertex-group
    /// influences (every group mapped to a deforming bone, zero weights included, in stored
    /// order); `envelopes` has one entry per bone, in the order Blender visits pose bones;
    /// `positions` are the coordinates that reach the modifier, taken to armature space by
    /// `premat`.
    ///
    /// Per vertex: with `use_vertex_groups` and at least one group, its groups (weights scaled
    /// by the envelope for bones that multiply); otherwise, with `use_envelopes`, every bone
    /// whose envelope reaches it, weighted by envelope factor × envelope weight.
    pub fn with_envelopes(
        &self,
        positions: &[[f32; 3]],
        premat: Option<Mat4>,
        envelopes: &[Envelope],
        use_vertex_groups: bool,
        use_envelopes: bool,
    ) -> Result<Influences, SkinError> {
        let n = self.vertex_count();
        if positions.len() != n {
            return Err(SkinError::LengthMismatch { what: "positions", expected: n, got: positions.len() });
        }
        if envelopes.len() != self.bone_count() {
            return Err(SkinError::LengthMismatch {
                what: "envelopes (one per bone)",
                expected: self.bone_count(),
                got: envelopes.len(),
            });
        }
        if let Some(i) = envelopes.iter().position(|e| {
            !(e.head.is_finite()
                && e.tail.is_finite()
                && [e.head_radius, e.tail_radius, e.distance, e.weight].iter().all(|v| v.is_finite()))
        }) {
            return Err(SkinError::InvalidInfluences(format!("envelope of bone {i} has a NaN or infinite value")));
        }
        if let Some(m) = premat {
            if let Some(problem) = super::pose::affine_problem(&m) {
                return Err(SkinError::InvalidSpaceMatrix { what: "premat", problem });
            }
        }
        let any_multiply = envelopes.iter().any(|e| e.multiply_groups);
        let lists: Vec<Vec<(u32, f32)>> = crate::pool::run(|| {
            (0..n)
                .into_par_iter()
                .map(|v| {
                    let own = self.of_vertex(v);
                    let co = || {
                        let p = Vec3::from_array(positions[v]);
                        premat.map_or(p, |m| m.transform_point3(p))
                    };
                    if use_vertex_groups && !own.is_empty() {
                        if !any_multiply {
                            return own.iter().map(|i| (i.bone, i.weight)).collect();
                        }
                        let co = co();
                        own.iter()
                            .map(|i| {
                                let e = &envelopes[i.bone as usize];
                                let w = if e.multiply_groups {
                                    i.weight
                                        * distance_factor(co, e.head, e.tail, e.head_radius, e.tail_radius, e.distance)
                                } else {
                                    i.weight
                                };
                                (i.bone, w)
                            })
                            .collect()
                    } else if use_envelopes {
                        let co = co();
                        envelopes
                            .iter()
                            .enumerate()
                            .filter_map(|(b, e)| {
                                let f = distance_factor(co, e.head, e.tail, e.head_radius, e.tail_radius, e.distance);
                                let w = f * e.weight;
                                (f > 0.0 && w > 0.0).then_some((b as u32, w))
                            })
                            .collect()
                    } else {
                        Vec::new()
                    }
                })
                .collect()
        });
        Influences::from_lists(&lists, self.bone_count())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(head: Vec3, tail: Vec3) -> Envelope {
        Envelope { head, tail, head_radius: 0.1, tail_radius: 0.2, distance: 0.25, weight: 1.0, multiply_groups: false }
    }

    #[test]
    fn distance_factor_follows_blender() {
        let (h, t) = (Vec3::ZERO, Vec3::new(0.0, 1.0, 0.0));
        // Inside the interpolated radius: 1.
        assert_eq!(distance_factor(Vec3::new(0.14, 0.5, 0.0), h, t, 0.1, 0.2, 0.25), 1.0);
        // Beyond radius + distance: 0; distance 0 outside the radius: 0.
        assert_eq!(distance_factor(Vec3::new(0.5, 0.5, 0.0), h, t, 0.1, 0.2, 0.25), 0.0);
        assert_eq!(distance_factor(Vec3::new(0.2, 0.5, 0.0), h, t, 0.1, 0.2, 0.0), 0.0);
        // In the fall-off: 1 − (d − r)²/dist² with r = 0.15 at the middle.
        let f = distance_factor(Vec3::new(0.25, 0.5, 0.0), h, t, 0.1, 0.2, 0.25);
        assert!((f - (1.0 - 0.1f32 * 0.1 / 0.0625)).abs() < 1e-6, "{f}");
        // Past the head and the tail: spheres with their own radii.
        let f = distance_factor(Vec3::new(0.0, -0.2, 0.0), h, t, 0.1, 0.2, 0.25);
        assert!((f - (1.0 - 0.1f32 * 0.1 / 0.0625)).abs() < 1e-6, "{f}");
        assert_eq!(distance_factor(Vec3::new(0.0, 1.15, 0.0), h, t, 0.1, 0.2, 0.25), 1.0);
    }

    #[test]
    fn groups_win_and_envelopes_fill_in() {
        let envelopes = [env(Vec3::ZERO, Vec3::Y), env(Vec3::Y, Vec3::new(0.0, 2.0, 0.0))];
        // Vertex 0 has a group; vertex 1 has none and sits inside both envelopes' fall-off.
        let groups = Influences::from_lists(&[vec![(1, 0.7)], vec![]], 2).unwrap();
        let positions = [[0.0, 0.5, 0.0], [0.0, 1.0, 0.25]];
        let e = groups.with_envelopes(&positions, None, &envelopes, true, true).unwrap();
        assert_eq!(e.of_vertex(0).len(), 1);
        assert_eq!((e.of_vertex(0)[0].bone, e.of_vertex(0)[0].weight), (1, 0.7));
        let bones: Vec<u32> = e.of_vertex(1).iter().map(|i| i.bone).collect();
        assert_eq!(bones, [0, 1], "envelopes in bone order");
        // Without envelopes, vertex 1 has nothing; without groups, vertex 0 uses envelopes.
        assert!(groups.with_envelopes(&positions, None, &envelopes, true, false).unwrap().of_vertex(1).is_empty());
        let only_env = groups.with_envelopes(&positions, None, &envelopes, false, true).unwrap();
        assert_eq!(only_env.of_vertex(0)[0].bone, 0);
        assert_eq!(only_env.of_vertex(0)[0].weight, 1.0);
    }

    #[test]
    fn multiply_scales_group_weights_by_the_envelope_only() {
        let mut envelopes = [env(Vec3::ZERO, Vec3::Y)];
        envelopes[0].multiply_groups = true;
        envelopes[0].weight = 0.3; // not applied to group weights, as in Blender
        let groups = Influences::from_lists(&[vec![(0, 0.8)], vec![(0, 0.8)]], 1).unwrap();
        let positions = [[0.0, 0.5, 0.0], [0.25, 0.5, 0.0]];
        let e = groups.with_envelopes(&positions, None, &envelopes, true, false).unwrap();
        assert_eq!(e.of_vertex(0)[0].weight, 0.8);
        let f = distance_factor(Vec3::new(0.25, 0.5, 0.0), Vec3::ZERO, Vec3::Y, 0.1, 0.2, 0.25);
        assert!((e.of_vertex(1)[0].weight - 0.8 * f).abs() < 1e-7);
        // premat moves the vertices before measuring.
        let shifted = groups
            .with_envelopes(&positions, Some(Mat4::from_translation(Vec3::new(5.0, 0.0, 0.0))), &envelopes, true, false)
            .unwrap();
        assert_eq!(shifted.of_vertex(0)[0].weight, 0.0);
    }

    #[test]
    fn bad_envelope_inputs_are_named() {
        let groups = Influences::from_lists(&[vec![]], 1).unwrap();
        let e = [env(Vec3::ZERO, Vec3::Y)];
        assert!(matches!(
            groups.with_envelopes(&[], None, &e, true, true),
            Err(SkinError::LengthMismatch { what: "positions", .. })
        ));
        assert!(matches!(
            groups.with_envelopes(&[[0.0; 3]], None, &[], true, true),
            Err(SkinError::LengthMismatch { what: "envelopes (one per bone)", .. })
        ));
        let mut nan = e;
        nan[0].distance = f32::NAN;
        assert!(groups.with_envelopes(&[[0.0; 3]], None, &nan, true, true).is_err());
    }
}

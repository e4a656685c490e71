//! Bone envelopes, as Blender's Armature modifier uses them (`armature_deform.cc`): a vertex
//! without vertex groups mapped to a deforming bone is bound to every bone whose envelope
//! reaches it, and bones with "Multiply Vertex Group by Envelope" scale their group weights by
//! the envelope. Both depend on the vertex's current position, so they are evaluated per frame
//! into *effective influences* that the kernels then use as usual. B-Bones are resolved there
//! too: each influence of a B-Bone becomes two, on the segment joints around the vertex.

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

/// A B-Bone for [`Influences::effective`]: its segment joints are bones `first ..= first +
/// segments` of the expanded bone list, and its rest matrix's inverse takes armature-space points
/// into the bone's space, whose Y axis runs from head (0) to tail (`length`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BBone<'a> {
    pub first: u32,
    pub segments: u32,
    pub inverse_rest: Mat4,
    pub length: f32,
    /// Per-vertex `(index, blend)` computed elsewhere (Blender's Curved mapping, which needs
    /// its runtime data), used where the index is not negative; the straight mapping otherwise.
    pub mapped: Option<(&'a [i32], &'a [f32])>,
}

impl BBone<'_> {
    /// Blender's straight mapping (`find_bbone_segment_index_straight`): the first segment joint
    /// affecting `co` (armature space) and the blend toward the next one.
    pub fn segment(&self, co: Vec3) -> (u32, f32) {
        let y = self.inverse_rest.transform_point3(co).y;
        let head_tail = (y / self.length).clamp(0.0, 1.0);
        let pre = head_tail * self.segments as f32;
        let index = (pre.floor() as i64).clamp(0, i64::from(self.segments) - 1);
        let blend = (pre - index as f32).clamp(0.0, 1.0);
        (index as u32, blend)
    }
}

/// What besides vertex groups decides this frame's influences.
#[derive(Clone, Copy, Debug, Default)]
pub struct Effective<'a> {
    /// One envelope per bone, or `None` when no bone uses envelopes.
    pub envelopes: Option<&'a [Envelope]>,
    pub use_vertex_groups: bool,
    pub use_envelopes: bool,
    /// One entry per bone (`None` for ordinary bones), or empty when there are no B-Bones.
    pub bbones: &'a [Option<BBone<'a>>],
    /// Size of the expanded bone list (bones, then every B-Bone's segment joints).
    pub expanded_bone_count: usize,
}

/// The deform and rest matrices of a B-Bone's `N + 1` segment joints for [`Pose::new`], from
/// the bone's channel matrix (`matrix_channel`), rest matrix (`matrix_local`) and the joints'
/// pose and rest matrices in bone space (`PoseBone.bbone_segment_matrix(i, rest=False/True)`),
/// as Blender's `BKE_pchan_bbone_segments_cache_compute` builds them:
/// `deform_a = channel·rest·P_a·R_a⁻¹·rest⁻¹`, basis `normalize(rest·R_a)`.
///
/// [`Pose::new`]: super::Pose::new
pub fn bbone_segment_matrices(channel: Mat4, rest: Mat4, pose: &[Mat4], rest_joints: &[Mat4]) -> Vec<(Mat4, Mat4)> {
    let rest_inverse = rest.inverse();
    pose.iter()
        .zip(rest_joints)
        .map(|(p, r)| {
            let deform = channel * rest * *p * r.inverse() * rest_inverse;
            let mut basis = rest * *r;
            for axis in [&mut basis.x_axis, &mut basis.y_axis, &mut basis.z_axis] {
                let len = axis.truncate().length();
                if len != 0.0 {
                    *axis /= len;
                }
            }
            (deform, basis)
        })
        .collect()
}

impl Influences {
    /// The influences Blender's Armature modifier uses this frame. `self` holds the vertex-group
    /// influences (every group mapped to a deforming bone, zero weights included, in stored
    /// order); `positions` are the coordinates that reach the modifier, taken to armature space
    /// by `premat`.
    ///
    /// Per vertex: with `use_vertex_groups` and at least one group, its groups (weights scaled
    /// by the envelope for bones that multiply); otherwise, with `use_envelopes`, every bone
    /// whose envelope reaches it, weighted by envelope factor × envelope weight. Then each
    /// influence of a B-Bone becomes two, on the segment joints around the vertex, weighted by
    /// `1 − blend` and `blend`. Bone indices of the result run over the expanded bone list.
    pub fn effective(
        &self,
        positions: &[[f32; 3]],
        premat: Option<Mat4>,
        what: &Effective<'_>,
    ) -> Result<Influences, SkinError> {
        let n = self.vertex_count();
        let bones = self.bone_count();
        if positions.len() != n {
            return Err(SkinError::LengthMismatch { what: "positions", expected: n, got: positions.len() });
        }
        if let Some(envelopes) = what.envelopes {
            if envelopes.len() != bones {
                return Err(SkinError::LengthMismatch { what: "envelopes (one per bone)", expected: bones, got: envelopes.len() });
            }
            if let Some(i) = envelopes.iter().position(|e| {
                !(e.head.is_finite()
                    && e.tail.is_finite()
                    && [e.head_radius, e.tail_radius, e.distance, e.weight].iter().all(|v| v.is_finite()))
            }) {
                return Err(SkinError::InvalidInfluences(format!("envelope of bone {i} has a NaN or infinite value")));
            }
        }
        if !what.bbones.is_empty() && what.bbones.len() != bones {
            return Err(SkinError::LengthMismatch { what: "B-Bones (one entry per bone)", expected: bones, got: what.bbones.len() });
        }
        for (b, bb) in what.bbones.iter().enumerate() {
            if let Some(bb) = bb {
                let last = bb.first as usize + bb.segments as usize;
                let mapped_ok = bb.mapped.is_none_or(|(i, f)| i.len() == n && f.len() == n);
                if bb.segments < 2
                    || last >= what.expanded_bone_count
                    || !(bb.length > 0.0)
                    || !bb.inverse_rest.is_finite()
                    || !mapped_ok
                {
                    return Err(SkinError::InvalidInfluences(format!(
                        "B-Bone {b}: needs at least 2 segments, a positive length, a finite rest matrix, joints inside the {} expanded bones and one mapped segment per vertex",
                        what.expanded_bone_count
                    )));
                }
            }
        }
        if what.expanded_bone_count < bones {
            return Err(SkinError::InvalidInfluences("the expanded bone list is shorter than the bone list".into()));
        }
        if let Some(m) = premat {
            if let Some(problem) = super::pose::affine_problem(&m) {
                return Err(SkinError::InvalidSpaceMatrix { what: "premat", problem });
            }
        }
        let multiply = what.envelopes.is_some_and(|e| e.iter().any(|e| e.multiply_groups));
        let lists: Vec<Vec<(u32, f32)>> = crate::pool::run(|| {
            (0..n)
                .into_par_iter()
                .map(|v| {
                    let co = || {
                        let p = Vec3::from_array(positions[v]);
                        premat.map_or(p, |m| m.transform_point3(p))
                    };
                    let own = self.of_vertex(v);
                    let mut list: Vec<(u32, f32)> = if what.use_vertex_groups && !own.is_empty() {
                        match (multiply, what.envelopes) {
                            (true, Some(envelopes)) => {
                                let co = co();
                                own.iter()
                                    .map(|i| {
                                        let e = &envelopes[i.bone as usize];
                                        let f = if e.multiply_groups {
                                            distance_factor(co, e.head, e.tail, e.head_radius, e.tail_radius, e.distance)
                                        } else {
                                            1.0
                                        };
                                        (i.bone, i.weight * f)
                                    })
                                    .collect()
                            }
                            _ => own.iter().map(|i| (i.bone, i.weight)).collect(),
                        }
                    } else if let (true, Some(envelopes)) = (what.use_envelopes, what.envelopes) {
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
                    };
                    if !what.bbones.is_empty() && list.iter().any(|(b, _)| what.bbones[*b as usize].is_some()) {
                        let co = co();
                        list = list
                            .into_iter()
                            .flat_map(|(b, w)| match what.bbones[b as usize] {
                                Some(bb) => {
                                    let (index, blend) = match bb.mapped {
                                        Some((i, f)) if i[v] >= 0 => {
                                            ((i[v] as u32).min(bb.segments - 1), f[v].clamp(0.0, 1.0))
                                        }
                                        _ => bb.segment(co),
                                    };
                                    let j = bb.first + index;
                                    vec![(j, w * (1.0 - blend)), (j + 1, w * blend)]
                                }
                                None => vec![(b, w)],
                            })
                            .collect();
                    }
                    list
                })
                .collect()
        });
        Influences::from_lists(&lists, what.expanded_bone_count)
    }

    /// [`Self::effective`] with envelopes and no B-Bones.
    pub fn with_envelopes(
        &self,
        positions: &[[f32; 3]],
        premat: Option<Mat4>,
        envelopes: &[Envelope],
        use_vertex_groups: bool,
        use_envelopes: bool,
    ) -> Result<Influences, SkinError> {
        let what = Effective {
            envelopes: Some(envelopes),
            use_vertex_groups,
            use_envelopes,
            bbones: &[],
            expanded_bone_count: self.bone_count(),
        };
        self.effective(positions, premat, &what)
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

#[cfg(test)]
mod bbone_tests {
    use super::*;

    #[test]
    fn straight_mapping_follows_blender() {
        let bb = BBone { first: 5, segments: 4, inverse_rest: Mat4::IDENTITY, length: 2.0, mapped: None };
        assert_eq!(bb.segment(Vec3::new(0.0, -1.0, 0.0)), (0, 0.0));
        assert_eq!(bb.segment(Vec3::new(0.0, 0.75, 0.0)), (1, 0.5));
        assert_eq!(bb.segment(Vec3::new(0.3, 2.0, 9.0)), (3, 1.0));
        assert_eq!(bb.segment(Vec3::new(0.0, 5.0, 0.0)), (3, 1.0));
    }

    #[test]
    fn b_bone_influences_split_over_two_joints() {
        let groups = Influences::from_lists(&[vec![(0, 0.6), (1, 0.4)]], 2).unwrap();
        let bbones = [None, Some(BBone { first: 2, segments: 3, inverse_rest: Mat4::IDENTITY, length: 3.0, mapped: None })];
        let what = Effective { envelopes: None, use_vertex_groups: true, use_envelopes: false, bbones: &bbones, expanded_bone_count: 6 };
        let e = groups.effective(&[[0.0, 1.25, 0.0]], None, &what).unwrap();
        let got: Vec<(u32, f32)> = e.of_vertex(0).iter().map(|i| (i.bone, i.weight)).collect();
        assert_eq!(got, vec![(0, 0.6), (3, 0.4 * 0.75), (4, 0.4 * 0.25)]);
        assert_eq!(e.bone_count(), 6);
        let bad = [None, Some(BBone { first: 4, segments: 3, inverse_rest: Mat4::IDENTITY, length: 3.0, mapped: None })];
        let what = Effective { bbones: &bad, ..what };
        assert!(groups.effective(&[[0.0; 3]], None, &what).is_err());
        // A mapping computed elsewhere wins where given.
        let (index, blend) = ([2i32], [0.5f32]);
        let mapped = [None, Some(BBone { first: 2, segments: 3, inverse_rest: Mat4::IDENTITY, length: 3.0, mapped: Some((&index, &blend)) })];
        let what = Effective { bbones: &mapped, ..what };
        let e = groups.effective(&[[0.0, 1.25, 0.0]], None, &what).unwrap();
        let got: Vec<(u32, f32)> = e.of_vertex(0).iter().map(|i| (i.bone, i.weight)).collect();
        assert_eq!(got, vec![(0, 0.6), (4, 0.4 * 0.5), (5, 0.4 * 0.5)]);
    }

    #[test]
    fn segment_matrices_match_blenders_formula() {
        let channel = Mat4::from_rotation_z(0.4);
        let rest = Mat4::from_translation(Vec3::new(0.0, 1.0, 0.0)) * Mat4::from_rotation_x(0.3);
        let pose = [Mat4::IDENTITY, Mat4::from_translation(Vec3::Y) * Mat4::from_rotation_z(0.2)];
        let rest_joints = [Mat4::IDENTITY, Mat4::from_translation(Vec3::Y) * Mat4::from_scale(Vec3::splat(1.0))];
        let m = bbone_segment_matrices(channel, rest, &pose, &rest_joints);
        assert!(m[0].0.abs_diff_eq(channel, 1e-6));
        assert!(m[1].1.abs_diff_eq(rest * rest_joints[1], 1e-6));
    }
}

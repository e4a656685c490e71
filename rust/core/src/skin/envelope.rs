//! Bone envelopes, as Blender's Armature modifier uses them (`armature_deform.cc`): a vertex
//! without vertex groups mapped to a deforming bone is bound to every bone whose envelope
//! reaches it, and bones with "Multiply Vertex Group by Envelope" scale their group weights by
//! the envelope. Both depend on the vertex's current position, so they are evaluated per frame
//! into *effective influences* that the kernels then use as usual. B-Bones are resolved there
//! too: each influence of a B-Bone becomes two, on the segment joints around the vertex.

use glam::{Mat4, Vec3};
use rayon::prelude::*;

use super::{BBone, Influence, Influences, SkinError};

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
                return Err(SkinError::LengthMismatch {
                    what: "envelopes (one per bone)",
                    expected: bones,
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
        }
        if !what.bbones.is_empty() && what.bbones.len() != bones {
            return Err(SkinError::LengthMismatch {
                what: "B-Bones (one entry per bone)",
                expected: bones,
                got: what.bbones.len(),
            });
        }
        if what.expanded_bone_count < bones {
            return Err(SkinError::InvalidInfluences("the expanded bone list is shorter than the bone list".into()));
        }
        for (b, bb) in what.bbones.iter().enumerate() {
            if let Some(problem) = bb.as_ref().and_then(|bb| bb.problem(n, what.expanded_bone_count)) {
                return Err(SkinError::InvalidInfluences(format!("B-Bone {b}: {problem}")));
            }
        }
        if let Some(m) = premat {
            if let Some(problem) = super::pose::affine_problem(&m) {
                return Err(SkinError::InvalidSpaceMatrix { what: "premat", problem });
            }
        }
        // Vertices in chunks, each writing its pairs into flat arrays (no list per vertex), then
        // joined in order.
        const CHUNK: usize = 2048;
        let parts: Vec<(Vec<u32>, Vec<Influence>)> = crate::pool::run(|| {
            (0..n.div_ceil(CHUNK))
                .into_par_iter()
                .map(|c| {
                    let range = c * CHUNK..n.min((c + 1) * CHUNK);
                    let mut counts = Vec::with_capacity(range.len());
                    let mut pairs = Vec::with_capacity(range.len() * 2 * self.max_per_vertex().max(1));
                    for v in range {
                        let before = pairs.len();
                        self.effective_vertex(v, positions[v], premat, what, &mut pairs);
                        counts.push((pairs.len() - before) as u32);
                    }
                    (counts, pairs)
                })
                .collect()
        });
        let total: usize = parts.iter().map(|p| p.1.len()).sum();
        if u32::try_from(total).is_err() {
            return Err(SkinError::InvalidInfluences("more than 2^32-1 influences".into()));
        }
        let mut offsets = Vec::with_capacity(n + 1);
        let (mut bones_out, mut weights) = (Vec::with_capacity(total), Vec::with_capacity(total));
        offsets.push(0u32);
        for (counts, pairs) in &parts {
            for &k in counts {
                offsets.push(offsets.last().unwrap() + k);
            }
            bones_out.extend(pairs.iter().map(|p| p.bone));
            weights.extend(pairs.iter().map(|p| p.weight));
        }
        Influences::from_csr(&offsets, &bones_out, &weights, what.expanded_bone_count)
    }

    /// Appends vertex `v`'s pairs for [`Self::effective`] (inputs already checked).
    fn effective_vertex(
        &self,
        v: usize,
        position: [f32; 3],
        premat: Option<Mat4>,
        what: &Effective<'_>,
        out: &mut Vec<Influence>,
    ) {
        let co = {
            let p = Vec3::from_array(position);
            premat.map_or(p, |m| m.transform_point3(p))
        };
        // Each influence of a B-Bone becomes two, on the joints around the vertex.
        let mut push = |bone: u32, weight: f32| match what.bbones.get(bone as usize).copied().flatten() {
            Some(bb) => {
                let (index, blend) = bb.segment(v, co);
                let j = bb.first + index;
                out.push(Influence { bone: j, weight: weight * (1.0 - blend) });
                out.push(Influence { bone: j + 1, weight: weight * blend });
            }
            None => out.push(Influence { bone, weight }),
        };
        let own = self.of_vertex(v);
        if what.use_vertex_groups && own.len() > 0 {
            for i in own {
                let factor = match what.envelopes.map(|e| &e[i.bone as usize]) {
                    Some(e) if e.multiply_groups => {
                        distance_factor(co, e.head, e.tail, e.head_radius, e.tail_radius, e.distance)
                    }
                    _ => 1.0,
                };
                push(i.bone, i.weight * factor);
            }
        } else if let (true, Some(envelopes)) = (what.use_envelopes, what.envelopes) {
            for (b, e) in envelopes.iter().enumerate() {
                let f = distance_factor(co, e.head, e.tail, e.head_radius, e.tail_radius, e.distance);
                let w = f * e.weight;
                if f > 0.0 && w > 0.0 {
                    push(b as u32, w);
                }
            }
        }
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
        assert_eq!((e.of_vertex(0).next().unwrap().bone, e.of_vertex(0).next().unwrap().weight), (1, 0.7));
        let bones: Vec<u32> = e.of_vertex(1).map(|i| i.bone).collect();
        assert_eq!(bones, [0, 1], "envelopes in bone order");
        // Without envelopes, vertex 1 has nothing; without groups, vertex 0 uses envelopes.
        assert!(groups.with_envelopes(&positions, None, &envelopes, true, false).unwrap().of_vertex(1).len() == 0);
        let only_env = groups.with_envelopes(&positions, None, &envelopes, false, true).unwrap();
        assert_eq!(only_env.of_vertex(0).next().unwrap().bone, 0);
        assert_eq!(only_env.of_vertex(0).next().unwrap().weight, 1.0);
    }

    #[test]
    fn multiply_scales_group_weights_by_the_envelope_only() {
        let mut envelopes = [env(Vec3::ZERO, Vec3::Y)];
        envelopes[0].multiply_groups = true;
        envelopes[0].weight = 0.3; // not applied to group weights, as in Blender
        let groups = Influences::from_lists(&[vec![(0, 0.8)], vec![(0, 0.8)]], 1).unwrap();
        let positions = [[0.0, 0.5, 0.0], [0.25, 0.5, 0.0]];
        let e = groups.with_envelopes(&positions, None, &envelopes, true, false).unwrap();
        assert_eq!(e.of_vertex(0).next().unwrap().weight, 0.8);
        let f = distance_factor(Vec3::new(0.25, 0.5, 0.0), Vec3::ZERO, Vec3::Y, 0.1, 0.2, 0.25);
        assert!((e.of_vertex(1).next().unwrap().weight - 0.8 * f).abs() < 1e-7);
        // premat moves the vertices before measuring.
        let shifted = groups
            .with_envelopes(&positions, Some(Mat4::from_translation(Vec3::new(5.0, 0.0, 0.0))), &envelopes, true, false)
            .unwrap();
        assert_eq!(shifted.of_vertex(0).next().unwrap().weight, 0.0);
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

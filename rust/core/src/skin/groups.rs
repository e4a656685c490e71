//! From a mesh's vertex groups (as Blender stores them) to the inputs of the Armature
//! modifier: bone influences, the mask group's weights, and the mesh ↔ armature spaces.

use glam::Mat4;

use super::{Influences, SkinError};

/// A mesh's vertex-group weights in CSR form, in stored order: vertex `v` has the pairs
/// `(groups[i], weights[i])` for `i` in `offsets[v]..offsets[v+1]`.
#[derive(Clone, Copy, Debug)]
pub struct DeformGroups<'a> {
    pub offsets: &'a [u32],
    pub groups: &'a [u32],
    pub weights: &'a [f32],
}

impl DeformGroups<'_> {
    fn check(&self) -> Result<usize, SkinError> {
        let bad = |m: String| Err(SkinError::InvalidInfluences(m));
        if self.offsets.is_empty() || self.offsets[0] != 0 {
            return bad("vertex group offsets must start at 0 and have one entry per vertex plus one".into());
        }
        if self.groups.len() != self.weights.len() || *self.offsets.last().unwrap() as usize != self.groups.len() {
            return bad(format!(
                "vertex group offsets end at {} but there are {} groups and {} weights",
                self.offsets.last().unwrap(),
                self.groups.len(),
                self.weights.len()
            ));
        }
        if let Some(v) = self.offsets.windows(2).position(|w| w[1] < w[0]) {
            return bad(format!("vertex group offsets decrease at vertex {v}"));
        }
        Ok(self.offsets.len() - 1)
    }
}

impl Influences {
    /// The influences Blender's Armature modifier takes from vertex groups: each pair whose
    /// group maps to a bone (`group_to_bone[group]`, `None` for groups without a deforming bone
    /// and for groups beyond the table) becomes an influence of that bone, in stored order.
    /// Zero weights are kept (a vertex with any mapped group never falls back to envelopes).
    /// Negative or non-finite weights, which Blender's tools never store, are refused.
    pub fn from_deform_groups(
        groups: DeformGroups<'_>,
        group_to_bone: &[Option<u32>],
        bone_count: usize,
    ) -> Result<Self, SkinError> {
        let vertices = groups.check()?;
        let mut offsets = Vec::with_capacity(vertices + 1);
        let mut bones = Vec::with_capacity(groups.groups.len());
        let mut weights = Vec::with_capacity(groups.groups.len());
        offsets.push(0u32);
        for v in 0..vertices {
            for i in groups.offsets[v] as usize..groups.offsets[v + 1] as usize {
                if let Some(Some(bone)) = group_to_bone.get(groups.groups[i] as usize) {
                    bones.push(*bone);
                    weights.push(groups.weights[i]);
                }
            }
            offsets.push(bones.len() as u32);
        }
        Influences::from_csr(&offsets, &bones, &weights, bone_count)
    }
}

/// Each vertex's weight in `group` (0 where it is not in the group), as Blender's
/// `BKE_defvert_find_weight` finds it: the first pair with that group.
pub fn deform_group_weights(groups: DeformGroups<'_>, group: u32) -> Result<Vec<f32>, SkinError> {
    let vertices = groups.check()?;
    Ok((0..vertices)
        .map(|v| {
            let range = groups.offsets[v] as usize..groups.offsets[v + 1] as usize;
            groups.groups[range.clone()]
                .iter()
                .position(|&g| g == group)
                .map_or(0.0, |k| groups.weights[range.start + k])
        })
        .collect())
}

/// `(premat, postmat)` of the Armature modifier: `postmat = inverse(object world) · armature
/// world` and `premat = inverse(postmat)`, computed in single precision with a double inverse as
/// Blender does (the direct product differs from it by about 1e-5).
pub fn armature_spaces(object_world: Mat4, armature_world: Mat4) -> (Mat4, Mat4) {
    let postmat = object_world.inverse() * armature_world;
    (postmat.inverse(), postmat)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn csr(lists: &[Vec<(u32, f32)>]) -> (Vec<u32>, Vec<u32>, Vec<f32>) {
        let mut o = vec![0u32];
        let (mut g, mut w) = (vec![], vec![]);
        for l in lists {
            for &(a, b) in l {
                g.push(a);
                w.push(b);
            }
            o.push(g.len() as u32);
        }
        (o, g, w)
    }

    #[test]
    fn groups_map_to_bones_in_stored_order() {
        let (o, g, w) = csr(&[vec![(3, 0.5), (0, 0.25), (1, 0.0)], vec![], vec![(2, 1.0), (9, 0.3)]]);
        let dg = DeformGroups { offsets: &o, groups: &g, weights: &w };
        // Group 0 -> bone 1, group 1 -> bone 0, group 2 has no bone, group 3 -> bone 2.
        let map = [Some(1), Some(0), None, Some(2)];
        let inf = Influences::from_deform_groups(dg, &map, 3).unwrap();
        assert_eq!(inf.offsets(), [0, 3, 3, 3]);
        let pairs: Vec<(u32, f32)> = inf.entries().iter().map(|e| (e.bone, e.weight)).collect();
        assert_eq!(pairs, vec![(2, 0.5), (1, 0.25), (0, 0.0)]);
        assert_eq!(deform_group_weights(dg, 0).unwrap(), vec![0.25, 0.0, 0.0]);
        assert_eq!(deform_group_weights(dg, 9).unwrap(), vec![0.0, 0.0, 0.3]);
    }

    #[test]
    fn first_pair_of_a_group_wins() {
        let (o, g, w) = csr(&[vec![(4, 0.2), (4, 0.9)]]);
        let dg = DeformGroups { offsets: &o, groups: &g, weights: &w };
        assert_eq!(deform_group_weights(dg, 4).unwrap(), vec![0.2]);
    }

    #[test]
    fn broken_csr_and_weights_are_refused() {
        let dg = DeformGroups { offsets: &[0, 2], groups: &[0], weights: &[1.0] };
        assert!(Influences::from_deform_groups(dg, &[Some(0)], 1).is_err());
        let dg = DeformGroups { offsets: &[0, 1], groups: &[0], weights: &[f32::NAN] };
        assert!(Influences::from_deform_groups(dg, &[Some(0)], 1).is_err());
        let dg = DeformGroups { offsets: &[0, 2, 1], groups: &[0, 0], weights: &[1.0, 1.0] };
        assert!(deform_group_weights(dg, 0).is_err());
        let dg = DeformGroups { offsets: &[], groups: &[], weights: &[] };
        assert!(deform_group_weights(dg, 0).is_err());
    }

    #[test]
    fn spaces_invert_each_other() {
        let ob = Mat4::from_scale_rotation_translation(
            glam::Vec3::new(1.0, 2.0, 0.5),
            glam::Quat::from_rotation_z(0.3),
            glam::Vec3::new(1.0, -2.0, 3.0),
        );
        let arm = Mat4::from_rotation_translation(glam::Quat::from_rotation_x(1.1), glam::Vec3::new(0.0, 4.0, 0.0));
        let (pre, post) = armature_spaces(ob, arm);
        assert!((pre * post).abs_diff_eq(Mat4::IDENTITY, 1e-5));
        assert!((ob * post).abs_diff_eq(arm, 1e-5));
    }
}

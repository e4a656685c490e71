//! An armature's pose as Blender's Armature modifier deforms with it: every pose channel's
//! channel matrix, its bone's rest data (deform flag, envelope, B-Bone settings) and, for bones
//! that deform as B-Bones, Blender's own runtime B-Bone cache. From that, everything skinning
//! needs for a frame: the expanded deform and rest matrices (bones, then each B-Bone's joints),
//! the envelopes, the B-Bones' segment mappings, and signatures that tell what changed.

use glam::Mat4;

use super::bbone::{bbone_joint_starts, joint_rest, BBone, Mapping, SegmentBoundary};
use super::{Effective, Envelope, Influences, SkinError};
use crate::digest::Digest;

/// Blender's runtime B-Bone cache of one pose channel (`bPoseChannel_Runtime`), for a bone of
/// `N` segments.
#[derive(Clone, Debug, PartialEq)]
pub struct BBoneCache {
    /// The inverse rest matrix (`bbone_deform_mats[0]`), which the Straight mapping uses.
    pub inverse_rest: Mat4,
    /// The joints' deform matrices in armature space (`bbone_deform_mats[1..]`, `N + 1`).
    pub deform: Vec<Mat4>,
    /// The joints' rest matrices in bone space (`bbone_rest_mats`, `N + 1`).
    pub rest_joints: Vec<Mat4>,
    /// The Curved mapping's boundary planes (`bbone_segment_boundaries`, `N + 1`); empty for
    /// the Straight mapping (Blender keeps them only for the Curved one).
    pub boundaries: Vec<SegmentBoundary>,
    /// `bbone_arc_length_reciprocal` (used with `boundaries`).
    pub arc_length_reciprocal: f32,
}

/// One pose channel with its bone. For a bone that does not deform only `deform` matters
/// (nothing deforms with it, and the Armature modifier looks up no vertex group's bone among
/// them): [`ArmaturePose`] keeps nothing else of it.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseChannel {
    pub name: String,
    /// The bone deforms (`BONE_NO_DEFORM` unset).
    pub deform: bool,
    /// Posed times inverse rest, armature space (`chan_mat`, `PoseBone.matrix_channel`).
    pub channel: Mat4,
    /// Rest matrix in armature space (`arm_mat`, `Bone.matrix_local`).
    pub rest: Mat4,
    pub length: f32,
    /// The bone's envelope (rest head and tail, radii, distance, weight, multiply flag).
    pub envelope: Envelope,
    /// `Bone.segments` and whether its mapping mode is Curved, as set (the cache may lag).
    pub segments: u32,
    pub curved: bool,
    /// The B-Bone cache, exactly when Blender deforms with it: more than one segment and a cache
    /// computed for that many.
    pub bbone: Option<BBoneCache>,
}

/// The pose of an armature's channels, in `pose.bones` order; its *bones* are the deforming
/// channels, in that order. Only the bones are kept whole: of the other channels, only that they
/// do not deform (a generated Rigify rig has 546 such channels to 160 bones).
#[derive(Clone, Debug)]
pub struct ArmaturePose {
    /// Every channel's deform flag, in `pose.bones` order.
    deforms: Vec<bool>,
    /// The deforming channels, in order.
    bones: Vec<PoseChannel>,
    /// Each bone's index in `pose.bones`.
    indices: Vec<usize>,
    /// First joint of each bone's B-Bone in the expanded bone list.
    starts: Vec<Option<u32>>,
    expanded: usize,
    binding_signature: u64,
    pose_signature: u64,
}

impl ArmaturePose {
    /// From every channel, in `pose.bones` order (see [`ArmaturePose::from_bones`]).
    pub fn new(channels: Vec<PoseChannel>) -> Result<Self, SkinError> {
        let deforms = channels.iter().map(|c| c.deform).collect();
        Self::from_bones(deforms, channels.into_iter().filter(|c| c.deform).collect())
    }

    /// From every channel's deform flag (`deforms`, in `pose.bones` order) and the deforming
    /// channels alone (`bones`, in that order), as the memory reader gives them. Checks that they
    /// agree, that every matrix and envelope is finite and every B-Bone cache has one entry per
    /// joint (`segments + 1`, the deform matrices and the Curved boundaries alike).
    pub fn from_bones(deforms: Vec<bool>, bones: Vec<PoseChannel>) -> Result<Self, SkinError> {
        let indices: Vec<usize> = deforms.iter().enumerate().filter(|(_, &d)| d).map(|(i, _)| i).collect();
        if indices.len() != bones.len() || bones.iter().any(|c| !c.deform) {
            return Err(SkinError::InvalidInfluences(format!(
                "{} deforming pose channels, but {} bones given (of which {} deform)",
                indices.len(),
                bones.len(),
                bones.iter().filter(|c| c.deform).count()
            )));
        }
        for (&i, c) in indices.iter().zip(&bones) {
            let bad = |problem: String| {
                Err(SkinError::InvalidInfluences(format!("pose channel {i} ({}): {problem}", c.name)))
            };
            let e = &c.envelope;
            let finite = c.channel.is_finite()
                && c.rest.is_finite()
                && c.length.is_finite()
                && e.head.is_finite()
                && e.tail.is_finite()
                && [e.head_radius, e.tail_radius, e.distance, e.weight].iter().all(|v| v.is_finite());
            if !finite {
                return bad("a matrix, length or envelope value is NaN or infinite".into());
            }
            if let Some(b) = &c.bbone {
                let joints = c.segments as usize + 1;
                if c.segments < 2 || b.deform.len() != joints || b.rest_joints.len() != joints {
                    return bad(format!(
                        "a B-Bone of {} segments needs {joints} joints, got {} and {}",
                        c.segments,
                        b.deform.len(),
                        b.rest_joints.len()
                    ));
                }
                if !(b.boundaries.is_empty() || b.boundaries.len() == joints) {
                    return bad(format!("the Curved mapping needs {joints} boundaries, got {}", b.boundaries.len()));
                }
                let all_finite = b.inverse_rest.is_finite()
                    && b.arc_length_reciprocal.is_finite()
                    && b.deform.iter().chain(&b.rest_joints).all(Mat4::is_finite);
                if !all_finite {
                    return bad("a B-Bone matrix is NaN or infinite".into());
                }
            }
        }
        let segments: Vec<u32> = bones.iter().map(|c| c.bbone.as_ref().map_or(1, |_| c.segments)).collect();
        let (starts, expanded) = bbone_joint_starts(&segments);
        let mut pose = Self { deforms, bones, indices, starts, expanded, binding_signature: 0, pose_signature: 0 };
        pose.binding_signature = pose.binding_digest();
        pose.pose_signature = pose.pose_digest();
        Ok(pose)
    }

    /// Every channel's deform flag, in `pose.bones` order.
    pub fn deform_flags(&self) -> &[bool] {
        &self.deforms
    }

    /// The deforming channels' indices in `pose.bones`.
    pub fn bone_indices(&self) -> &[usize] {
        &self.indices
    }

    /// The deforming channels, in order: the bones influences refer to.
    pub fn bones(&self) -> impl ExactSizeIterator<Item = &PoseChannel> + '_ {
        self.bones.iter()
    }

    pub fn bone_count(&self) -> usize {
        self.bones.len()
    }

    /// Length of the expanded bone list: the bones, then every B-Bone's joints.
    pub fn expanded_bone_count(&self) -> usize {
        self.expanded
    }

    /// Each bone's segment count as it deforms: `N` for a B-Bone, 1 otherwise.
    pub fn segments(&self) -> Vec<u32> {
        self.bones().map(|c| if c.bbone.is_some() { c.segments } else { 1 }).collect()
    }

    /// The expanded deform matrices: each bone's channel matrix, then each B-Bone's joints'
    /// deform matrices (Blender's own, from its cache).
    pub fn deform_matrices(&self) -> Vec<Mat4> {
        let mut out: Vec<Mat4> = self.bones().map(|c| c.channel).collect();
        out.extend(self.bones().filter_map(|c| c.bbone.as_ref()).flat_map(|b| b.deform.iter().copied()));
        out
    }

    /// The expanded rest matrices: each bone's rest matrix, then each B-Bone joint's orthonormal
    /// rest basis `normalize(rest·R)`, as Blender computes the joints' dual quaternions.
    pub fn rest_matrices(&self) -> Vec<Mat4> {
        let mut out: Vec<Mat4> = self.bones().map(|c| c.rest).collect();
        for c in self.bones() {
            if let Some(b) = &c.bbone {
                out.extend(b.rest_joints.iter().map(|r| joint_rest(c.rest, *r)));
            }
        }
        out
    }

    /// The bones' envelopes.
    pub fn envelopes(&self) -> Vec<Envelope> {
        self.bones().map(|c| c.envelope).collect()
    }

    /// The bones' B-Bones (`None` for the others) with Blender's mapping: Curved where the cache
    /// has boundaries, Straight otherwise.
    pub fn bbones(&self) -> Vec<Option<BBone<'_>>> {
        self.bones()
            .zip(&self.starts)
            .map(|(c, start)| {
                let (b, first) = (c.bbone.as_ref()?, (*start)?);
                let mapping = if b.boundaries.is_empty() {
                    Mapping::Straight
                } else {
                    Mapping::Curved { boundaries: &b.boundaries, arc_length_reciprocal: b.arc_length_reciprocal }
                };
                Some(BBone { first, segments: c.segments, inverse_rest: b.inverse_rest, length: c.length, mapping })
            })
            .collect()
    }

    /// This frame's influences for vertex-group influences `groups` over this pose's bones
    /// (see [`Influences::effective`]).
    pub fn effective(
        &self,
        groups: &Influences,
        positions: &[[f32; 3]],
        premat: Option<Mat4>,
        use_vertex_groups: bool,
        use_envelopes: bool,
    ) -> Result<Influences, SkinError> {
        if groups.bone_count() != self.bone_count() {
            return Err(SkinError::LengthMismatch {
                what: "pose bones (the deforming bones the influences refer to)",
                expected: groups.bone_count(),
                got: self.bone_count(),
            });
        }
        let envelopes = self.envelopes();
        let bbones = self.bbones();
        let what = Effective {
            envelopes: Some(&envelopes),
            use_vertex_groups,
            use_envelopes,
            bbones: &bbones,
            expanded_bone_count: self.expanded,
        };
        groups.effective(positions, premat, &what)
    }

    /// A 64-bit digest of everything the influences depend on besides the vertices: the
    /// channels' order and deform flags, the deforming bones' names, rest matrices, lengths,
    /// envelopes, B-Bone settings and rest shapes (cache included). Equal digests: the same
    /// influences.
    pub fn binding_signature(&self) -> u64 {
        self.binding_signature
    }

    /// A 64-bit digest of the pose: the expanded deform matrices (equal digests: the same
    /// deformation for the same binding).
    pub fn pose_signature(&self) -> u64 {
        self.pose_signature
    }

    fn binding_digest(&self) -> u64 {
        let mut h = Digest::default();
        h.word(self.deforms.len() as u64);
        let mut bones = self.bones.iter();
        for &deform in &self.deforms {
            h.word(u64::from(deform));
            let Some(c) = deform.then(|| bones.next()).flatten() else {
                continue;
            };
            h.bytes(c.name.as_bytes());
            h.matrix(&c.rest);
            let e = &c.envelope;
            h.floats(&[c.length, e.head_radius, e.tail_radius, e.distance, e.weight]);
            h.floats(&e.head.to_array());
            h.floats(&e.tail.to_array());
            h.word(u64::from(e.multiply_groups) | u64::from(c.curved) << 1 | u64::from(c.segments) << 2);
            match &c.bbone {
                None => h.word(0),
                Some(b) => {
                    h.word(b.rest_joints.len() as u64);
                    h.matrix(&b.inverse_rest);
                    b.rest_joints.iter().for_each(|m| h.matrix(m));
                    h.word(b.boundaries.len() as u64);
                    for s in &b.boundaries {
                        h.floats(&s.point.to_array());
                        h.floats(&s.normal.to_array());
                        h.floats(&[s.offset, s.depth_scale]);
                    }
                    h.floats(&[b.arc_length_reciprocal]);
                }
            }
        }
        h.finish()
    }

    fn pose_digest(&self) -> u64 {
        let mut h = Digest::default();
        for c in self.bones() {
            h.matrix(&c.channel);
            if let Some(b) = &c.bbone {
                b.deform.iter().for_each(|m| h.matrix(m));
            }
        }
        h.finish()
    }
}

#[cfg(test)]
mod tests;

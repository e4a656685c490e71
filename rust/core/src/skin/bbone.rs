//! B-Bones as Blender's Armature modifier deforms with them (`armature.cc`, `armature_deform.cc`):
//! a B-Bone of `N` segments deforms through its `N + 1` segment joints; a vertex is mapped to the
//! joint pair around it (Straight or Curved mapping) and its weight split between the two.
//!
//! Joints live in an *expanded bone list*: the bones first, then each B-Bone's joints in bone
//! order ([`bbone_joint_starts`]), so that the kernels see every joint as one more bone.

use glam::{Mat4, Vec3};

/// Blender's `MAX_BBONE_SUBDIV`: the most segments a B-Bone has.
pub const MAX_BBONE_SEGMENTS: u32 = 32;

/// One plane between B-Bone segments for the Curved mapping, in armature space at rest
/// (`bPoseChannel_BBoneSegmentBoundary`): through the rest joint `point`, normal to the curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SegmentBoundary {
    pub point: Vec3,
    pub normal: Vec3,
    /// `point · normal`.
    pub offset: f32,
    /// The smoothing band's inverse width at BSP depth `i` for the boundary at index `i` (Blender
    /// keeps this per-depth value in the boundaries' padding); only the first
    /// [`bsp_depth`]`(segments)` boundaries have one (Blender leaves the others uninitialized).
    pub depth_scale: f32,
}

/// How deep the Curved mapping's binary search goes for `segments` segments: Blender's
/// `ceil(log2(segments + 2))` (two virtual end segments), in integers.
pub fn bsp_depth(segments: u32) -> usize {
    let n = segments + 2;
    ((n - 1).ilog2() + 1) as usize
}

/// Whether the boundaries of a B-Bone (one per joint) are usable: finite, with a finite
/// `depth_scale` where the search reads one.
fn boundaries_finite(boundaries: &[SegmentBoundary]) -> bool {
    let depth = bsp_depth(boundaries.len().saturating_sub(1) as u32);
    boundaries.iter().enumerate().all(|(i, b)| {
        b.point.is_finite() && b.normal.is_finite() && b.offset.is_finite() && (i >= depth || b.depth_scale.is_finite())
    })
}

/// How a B-Bone maps vertices to segments.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Mapping<'a> {
    /// Blender's Straight mapping: by the position along the rest bone's Y axis.
    Straight,
    /// Blender's Curved mapping: a binary search over the `segments + 1` boundary planes,
    /// smoothed near them; `arc_length_reciprocal` is the inverse length of the rest joints'
    /// polyline (`bbone_arc_length_reciprocal`).
    Curved { boundaries: &'a [SegmentBoundary], arc_length_reciprocal: f32 },
    /// Per-vertex `(index, blend)` computed elsewhere (`PoseBone.bbone_segment_index`); a
    /// negative index falls back to the Straight mapping for that vertex.
    Given { index: &'a [i32], blend: &'a [f32] },
}

/// A B-Bone for [`Influences::effective`]: its segment joints are bones `first ..= first +
/// segments` of the expanded bone list; `inverse_rest` takes armature-space points into the
/// bone's rest space, whose Y axis runs from head (0) to tail (`length`).
///
/// [`Influences::effective`]: super::Influences::effective
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BBone<'a> {
    pub first: u32,
    pub segments: u32,
    pub inverse_rest: Mat4,
    pub length: f32,
    pub mapping: Mapping<'a>,
}

impl BBone<'_> {
    /// Blender's Straight mapping (`find_bbone_segment_index_straight`): the first segment joint
    /// affecting `co` (armature space) and the blend toward the next one. The bone-space Y is
    /// summed in Blender's order, so the result is Blender's to the bit.
    pub fn straight_segment(&self, co: Vec3) -> (u32, f32) {
        let m = &self.inverse_rest;
        let y = m.x_axis.y * co.x + m.y_axis.y * co.y + m.z_axis.y * co.z + m.w_axis.y;
        clamp_segment_index(self.segments, y / self.length)
    }

    /// The segment of vertex `v` at `co` (armature space) with this bone's mapping.
    pub fn segment(&self, v: usize, co: Vec3) -> (u32, f32) {
        match self.mapping {
            Mapping::Straight => self.straight_segment(co),
            Mapping::Curved { boundaries, arc_length_reciprocal } => {
                curved_segment(boundaries, arc_length_reciprocal, co)
            }
            Mapping::Given { index, blend } if index[v] >= 0 => {
                ((index[v] as u32).min(self.segments - 1), blend[v].clamp(0.0, 1.0))
            }
            Mapping::Given { .. } => self.straight_segment(co),
        }
    }

    /// Why this B-Bone cannot be used with `vertices` vertices and `expanded` bones, if it cannot.
    pub(crate) fn problem(&self, vertices: usize, expanded: usize) -> Option<String> {
        let last = self.first as usize + self.segments as usize;
        if self.segments < 2 || last >= expanded {
            return Some(format!("needs at least 2 segments and its joints inside the {expanded} expanded bones"));
        }
        if !(self.length > 0.0) || !self.length.is_finite() || !self.inverse_rest.is_finite() {
            return Some("needs a positive length and a finite rest matrix".into());
        }
        match self.mapping {
            Mapping::Straight => None,
            Mapping::Curved { boundaries, arc_length_reciprocal } => {
                let ok = self.segments <= MAX_BBONE_SEGMENTS
                    && boundaries.len() == self.segments as usize + 1
                    && boundaries_finite(boundaries)
                    && arc_length_reciprocal.is_finite();
                (!ok).then(|| {
                    format!(
                        "the Curved mapping needs at most {MAX_BBONE_SEGMENTS} segments and one finite boundary per joint ({} for {} segments, got {})",
                        self.segments + 1,
                        self.segments,
                        boundaries.len()
                    )
                })
            }
            Mapping::Given { index, blend } => (index.len() != vertices || blend.len() != vertices)
                .then(|| "needs one mapped segment per vertex".into()),
        }
    }
}

/// Blender's `BKE_pchan_bbone_deform_clamp_segment_index`: `head_tail` (0 at the head, 1 at the
/// tail) to the first of the two joints and the blend toward the second.
fn clamp_segment_index(segments: u32, head_tail: f32) -> (u32, f32) {
    let pre_blend = head_tail.clamp(0.0, 1.0) * segments as f32;
    let index = (pre_blend.floor() as i64).clamp(0, i64::from(segments) - 1);
    let blend = (pre_blend - index as f32).clamp(0.0, 1.0);
    (index as u32, blend)
}

/// `dot(co, normal) − offset`, summed in Blender's order.
#[inline]
fn signed_distance(b: &SegmentBoundary, co: Vec3) -> f32 {
    co.x * b.normal.x + co.y * b.normal.y + co.z * b.normal.z - b.offset
}

/// Blender's `find_bbone_segment_index_curved` (PR #110758), operation for operation in single
/// precision: a BSP binary search over the boundary planes down to one segment, linear
/// interpolation between its two planes, then smoothing with the planes up the search stack.
/// `boundaries` has `segments + 1` entries, `segments ≤ MAX_BBONE_SEGMENTS`.
pub fn curved_segment(boundaries: &[SegmentBoundary], arc_length_reciprocal: f32, co: Vec3) -> (u32, f32) {
    const STACK: usize = MAX_BBONE_SEGMENTS as usize + 1;
    let segments = boundaries.len() as i32 - 1;
    debug_assert!((1..=MAX_BBONE_SEGMENTS as i32).contains(&segments));
    let mut distance = [0.0f32; STACK];
    let mut stack = [0usize; STACK];
    let mut depth = 0;
    let (mut start, mut end, mut bias) = (-1i32, segments + 1, 0);
    while end - start > 1 {
        // Non-negative (start ≥ −1, end ≥ start + 2), so the division truncates as in C.
        let mid = (start + end + bias) / 2;
        let d = signed_distance(&boundaries[mid as usize], co);
        stack[depth] = mid as usize;
        depth += 1;
        distance[mid as usize] = d;
        if d < 0.0 {
            end = mid;
            // Odd splits lean toward the previous one, for a more symmetrical boundary at the ends.
            bias = 1;
        } else {
            start = mid;
            bias = 0;
        }
    }
    let segment_size = 1.0 / segments as f32;
    let mut head_tail = if end <= 0 {
        0.0
    } else if start >= segments {
        1.0
    } else {
        let d1 = distance[start as usize].abs();
        let d2 = distance[end as usize].abs();
        let t = d1 / (d1 + d2);
        segment_size * (start as f32 + t)
    };
    // Pull the mapped position toward each boundary up the stack, where the mapping's slope
    // exceeds the ideal one; Blender's tuning constants.
    const SLOPE_TUNE: f32 = 3.0;
    const DISTANCE_TUNE: f32 = 7.0;
    for i in (0..depth).rev() {
        let index = stack[i];
        let boundary_pos = index as f32 * segment_size;
        let point_dist = distance[index] * arc_length_reciprocal;
        let point_dist_abs = point_dist.abs();
        let mapped_dist = (head_tail - boundary_pos).abs();
        let slope_gap = mapped_dist - point_dist_abs;
        if slope_gap <= 0.0 {
            continue;
        }
        // Indexed by depth, not by boundary (see `SegmentBoundary::depth_scale`).
        let dist_coeff = 1.0 - point_dist_abs * boundaries[i].depth_scale;
        if dist_coeff <= 0.0 {
            continue;
        }
        let scaled_gap = slope_gap * SLOPE_TUNE;
        let slope_coeff = scaled_gap / (scaled_gap + point_dist_abs);
        let dist_coeff_smooth = dist_coeff * dist_coeff * (DISTANCE_TUNE + 1.0) / (DISTANCE_TUNE * dist_coeff + 1.0);
        let target_pos = boundary_pos + point_dist;
        let fac = slope_coeff * dist_coeff_smooth;
        // Blender's `interpf(target, origin, fac)`.
        head_tail = fac * target_pos + (1.0 - fac) * head_tail;
    }
    clamp_segment_index(segments as u32, head_tail)
}

/// Where the B-Bones' joints go in the expanded bone list: for each bone its first joint's index
/// (`None` for bones with fewer than 2 segments), and the expanded list's length. Bones come
/// first, then each B-Bone's `segments + 1` joints in bone order.
pub fn bbone_joint_starts(segments: &[u32]) -> (Vec<Option<u32>>, usize) {
    let mut next = segments.len();
    let starts = segments
        .iter()
        .map(|&n| {
            (n > 1).then(|| {
                let first = next as u32;
                next += n as usize + 1;
                first
            })
        })
        .collect();
    (starts, next)
}

/// The B-Bones of bones with `segments`, `rest` matrices and `lengths` (one each per bone), all
/// with the Straight mapping except the bones in `given` (`(bone, index, blend)`, see
/// [`Mapping::Given`]); with the expanded bone list's length.
pub fn bbones_from_rest<'a>(
    segments: &[u32],
    rest: &[Mat4],
    lengths: &[f32],
    given: &[(usize, &'a [i32], &'a [f32])],
) -> (Vec<Option<BBone<'a>>>, usize) {
    let (starts, expanded) = bbone_joint_starts(segments);
    let bbones = starts
        .iter()
        .enumerate()
        .map(|(i, start)| {
            start.map(|first| BBone {
                first,
                segments: segments[i],
                inverse_rest: rest[i].inverse(),
                length: lengths[i],
                mapping: given
                    .iter()
                    .find(|g| g.0 == i)
                    .map_or(Mapping::Straight, |&(_, index, blend)| Mapping::Given { index, blend }),
            })
        })
        .collect();
    (bbones, expanded)
}

/// Blender's `normalize_m4`: each of the three axis columns divided by its length (multiplied by
/// the reciprocal, as `normalize_v3` does), a zero axis left at zero.
pub(crate) fn normalize_axes(mut m: Mat4) -> Mat4 {
    for axis in [&mut m.x_axis, &mut m.y_axis, &mut m.z_axis] {
        let d = axis.x * axis.x + axis.y * axis.y + axis.z * axis.z;
        let (x, y, z) = if d > 1.0e-35 {
            let inv = 1.0 / d.sqrt();
            (axis.x * inv, axis.y * inv, axis.z * inv)
        } else {
            (0.0, 0.0, 0.0)
        };
        (axis.x, axis.y, axis.z) = (x, y, z);
    }
    m
}

/// A B-Bone joint's deform and rest matrices for [`Pose::new`], as Blender's
/// `BKE_pchan_bbone_segments_cache_compute` builds them from the bone's channel matrix
/// (`matrix_channel`), rest matrix (`matrix_local`) and the joint's pose and rest matrices in
/// bone space (`bbone_pose_mats`, `bbone_rest_mats`): `deform = channel·rest·P·R⁻¹·rest⁻¹`, and
/// the orthonormal rest basis `normalize(rest·R)` that dual quaternion skinning uses.
///
/// [`Pose::new`]: super::Pose::new
pub fn bbone_segment_matrices(channel: Mat4, rest: Mat4, pose: &[Mat4], rest_joints: &[Mat4]) -> Vec<(Mat4, Mat4)> {
    let rest_inverse = rest.inverse();
    pose.iter()
        .zip(rest_joints)
        .map(|(p, r)| (channel * rest * *p * r.inverse() * rest_inverse, joint_rest(rest, *r)))
        .collect()
}

/// A joint's orthonormal rest basis in armature space, `normalize(rest·R)` (see
/// [`bbone_segment_matrices`]).
pub(crate) fn joint_rest(rest: Mat4, rest_joint: Mat4) -> Mat4 {
    normalize_axes(rest * rest_joint)
}

#[cfg(test)]
mod tests;

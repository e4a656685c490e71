//! Reading an armature object's pose out of Blender's memory: what the Armature modifier
//! deforms with.
//!
//! `Object.pose` points to a `bPose` whose `chanbase` lists the `bPoseChannel`s in `pose.bones`
//! order. Each channel has its `name`, `chan_mat` (posed times inverse rest) and its `Bone` (up to
//! Blender 5.1 the channel's `bone` pointer; from 5.2 the channel keeps an index into the
//! armature's runtime bone array instead, so the bone of the same name is found in the tree of
//! `Object.data`'s `bArmature.bonebase`), with the rest data (`arm_mat`, `length`, `flag`, the envelope's `arm_head`,
//! `arm_tail`, `rad_head`, `rad_tail`, `dist`, `weight`, and `segments`,
//! `bbone_mapping_mode`), and embeds a `bPoseChannel_Runtime` with Blender's B-Bone cache:
//! `bbone_segments`, `bbone_rest_mats` (`1 + N` `Mat4`), `bbone_deform_mats` (`2 + N`),
//! `bbone_segment_boundaries` (`1 + N`, Curved mapping only) and `bbone_arc_length_reciprocal`.
//! A bone deforms as a B-Bone exactly when `segments > 1` and the cache was computed for that
//! many segments (`armature_deform.cc`); then the cache is read too.

use dqskin_core::glam::{Mat4, Vec3};
use dqskin_core::skin::{bsp_depth, BBoneCache, Envelope, PoseChannel, SegmentBoundary, MAX_BBONE_SEGMENTS};

use std::collections::HashMap;

use crate::memory::{name_bytes, read, ReadError};
use crate::sdna::{DnaError, Sdna};

mod prefetch;
pub use prefetch::ReadHints;

/// `eObjectType::OB_ARMATURE`, unchanged since Blender 2.5.
const OB_ARMATURE: i16 = 25;
/// `eBone_Flag` bits.
const BONE_MULT_VG_ENV: i32 = 1 << 11;
const BONE_NO_DEFORM: i32 = 1 << 12;
/// `eBone_BBoneMappingMode::BBONE_MAPPING_CURVED`.
const BBONE_MAPPING_CURVED: u8 = 1;
/// `struct Mat4 { float mat[4][4]; }` (a Blender math type the SDNA lists without a size).
const MAT4_SIZE: usize = 64;
/// Sanity bound on the channel count the caller may ask for.
pub const MAX_CHANNELS: usize = 1 << 20;

/// How a pose channel leads to its bone.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum BoneLink {
    /// `bPoseChannel.bone` (Blender 4.2-5.1).
    Pointer { chan_bone: usize },
    /// The bone of the channel's name in the armature's bone tree: `Object.data` →
    /// `bArmature.bonebase`, each bone's `next` and `childbase` (Blender 5.2+).
    ByName { object_data: usize, bonebase_first: usize, bone_next: usize, childbase_first: usize },
}

/// Byte offsets of everything [`read_pose`] touches, from an [`Sdna`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PoseLayout {
    object_type: usize,
    object_pose: usize,
    chanbase_first: usize,
    chan_next: usize,
    chan_name: usize,
    name_size: usize,
    bone_link: BoneLink,
    chan_mat: usize,
    runtime_segments: usize,
    runtime_arc_length_reciprocal: usize,
    runtime_rest_mats: usize,
    runtime_deform_mats: usize,
    runtime_boundaries: usize,
    bone_name: usize,
    bone_name_size: usize,
    bone_flag: usize,
    bone_head: usize,
    bone_tail: usize,
    bone_arm_mat: usize,
    bone_dist: usize,
    bone_weight: usize,
    bone_length: usize,
    bone_rad_head: usize,
    bone_rad_tail: usize,
    bone_segments: usize,
    bone_mapping_mode: usize,
    boundary_size: usize,
    boundary_point: usize,
    boundary_normal: usize,
    boundary_offset: usize,
    boundary_depth_scale: usize,
}

impl PoseLayout {
    /// The layout of this Blender's poses, checked for the field sizes the reader assumes.
    pub fn new(sdna: &Sdna) -> Result<Self, DnaError> {
        let float = |s: &str, name: &str| sdna.number(s, &[name], 4);
        let vec3 = |s: &str, name: &str| sdna.number(s, &[name], 12);
        let mat4 = |s: &str, name: &str| sdna.number(s, &[name], MAT4_SIZE);
        let chanbase = sdna.embedded("bPose", &["chanbase"], "ListBase")?;
        let runtime = sdna.embedded("bPoseChannel", &["runtime"], "bPoseChannel_Runtime")?;
        let rt = |name: &str| sdna.pointer("bPoseChannel_Runtime", &[name]).map(|o| runtime + o);
        let (chan_name, name_size) = sdna.chars("bPoseChannel", "name")?;
        let (bone_name, bone_name_size) = sdna.chars("Bone", "name")?;
        let first = sdna.pointer("ListBase", &["first"])?;
        let bone_link = match sdna.pointer("bPoseChannel", &["bone"]) {
            Ok(chan_bone) => BoneLink::Pointer { chan_bone },
            Err(DnaError::NoField { .. }) => BoneLink::ByName {
                object_data: sdna.pointer("Object", &["data"])?,
                bonebase_first: sdna.embedded("bArmature", &["bonebase"], "ListBase")? + first,
                bone_next: sdna.pointer("Bone", &["next"])?,
                childbase_first: sdna.embedded("Bone", &["childbase"], "ListBase")? + first,
            },
            Err(e) => return Err(e),
        };
        Ok(Self {
            object_type: sdna.number("Object", &["type"], 2)?,
            object_pose: sdna.pointer("Object", &["pose"])?,
            chanbase_first: chanbase + first,
            chan_next: sdna.pointer("bPoseChannel", &["next"])?,
            chan_name,
            name_size,
            bone_link,
            chan_mat: mat4("bPoseChannel", "chan_mat")?,
            runtime_segments: runtime + sdna.number("bPoseChannel_Runtime", &["bbone_segments"], 4)?,
            runtime_arc_length_reciprocal: runtime + float("bPoseChannel_Runtime", "bbone_arc_length_reciprocal")?,
            runtime_rest_mats: rt("bbone_rest_mats")?,
            runtime_deform_mats: rt("bbone_deform_mats")?,
            runtime_boundaries: rt("bbone_segment_boundaries")?,
            bone_name,
            bone_name_size,
            bone_flag: sdna.number("Bone", &["flag"], 4)?,
            bone_head: vec3("Bone", "arm_head")?,
            bone_tail: vec3("Bone", "arm_tail")?,
            bone_arm_mat: mat4("Bone", "arm_mat")?,
            bone_dist: float("Bone", "dist")?,
            bone_weight: float("Bone", "weight")?,
            bone_length: float("Bone", "length")?,
            bone_rad_head: float("Bone", "rad_head")?,
            bone_rad_tail: float("Bone", "rad_tail")?,
            bone_segments: sdna.number("Bone", &["segments"], 2)?,
            bone_mapping_mode: sdna.number("Bone", &["bbone_mapping_mode"], 1)?,
            boundary_size: sdna.struct_size("bPoseChannel_BBoneSegmentBoundary")?,
            boundary_point: vec3("bPoseChannel_BBoneSegmentBoundary", "point")?,
            boundary_normal: vec3("bPoseChannel_BBoneSegmentBoundary", "plane_normal")?,
            boundary_offset: float("bPoseChannel_BBoneSegmentBoundary", "plane_offset")?,
            boundary_depth_scale: float("bPoseChannel_BBoneSegmentBoundary", "depth_scale")?,
        })
    }
}

/// What [`read_pose`] reads of an armature's pose channels (the parts of
/// `dqskin_core::skin::ArmaturePose::from_bones`).
#[derive(Clone, Debug, PartialEq)]
pub struct PoseRead {
    /// Every channel's deform flag, in `pose.bones` order.
    pub deforms: Vec<bool>,
    /// The deforming channels, in that order, each with its bone and B-Bone cache.
    pub bones: Vec<PoseChannel>,
}

/// Reads the pose channels of the armature `Object` at `object` (`bpy.types.Object.as_pointer()`),
/// which must have exactly `expected_channels` channels (`len(object.pose.bones)`).
///
/// # Safety
/// `object` must be the address of a live `Object` of the Blender whose SDNA built `layout`, not
/// changed by another thread during the call: Python handlers and operators run while nothing
/// else touches it; inside a depsgraph evaluation (a driver), only once every operation that
/// writes the object's pose, bones and B-Bone caches has run in that evaluation (the driver
/// ordered after them), since Blender's other threads then only read them. The object type, the channel count and every B-Bone segment count are
/// checked before anything they lead to is followed, so a mismatched layout is reported rather
/// than followed far.
///
/// `hints` are where the last read of this armature went (empty for none): they are prefetched
/// first, and replaced by where this read goes ([`ReadHints`]).
pub unsafe fn read_pose(
    layout: &PoseLayout,
    object: usize,
    expected_channels: usize,
    hints: &mut ReadHints,
) -> Result<PoseRead, ReadError> {
    // SAFETY: for all reads below, offsets come from the SDNA of this Blender and the object is
    // live (caller); the pose, channels, bones and B-Bone arrays are reached through pointers
    // read from it, each non-null, and the arrays' lengths come from segment counts checked
    // against Blender's maximum and against each other.
    unsafe {
        let pose = pose_of(layout, object, expected_channels)?;
        hints.prefetch(layout);
        hints.clear();
        let bones_by_name = match layout.bone_link {
            BoneLink::Pointer { .. } => None,
            BoneLink::ByName { object_data, .. } => {
                Some(bones_by_name(layout, read(object + object_data), expected_channels)?)
            }
        };
        // (Room for the bones of most rigs at once: a bone is a few hundred bytes, moved at each
        // growth of the vector.)
        let bones = Vec::with_capacity(expected_channels.min(256));
        let mut found = PoseRead { deforms: Vec::with_capacity(expected_channels), bones };
        each_channel(layout, pose, expected_channels, |chan| {
            let bone = match (&bones_by_name, layout.bone_link) {
                (None, BoneLink::Pointer { chan_bone }) => read(chan + chan_bone),
                (Some(map), _) => map.get(name_bytes(chan + layout.chan_name, layout.name_size)).copied().unwrap_or(0),
                (None, BoneLink::ByName { .. }) => unreachable!("the map is built for this link"),
            };
            let channel = read_channel(layout, chan, bone)?;
            hints.visited(chan, bone, channel.is_some());
            found.deforms.push(channel.is_some());
            found.bones.extend(channel);
            Ok(())
        })?;
        Ok(found)
    }
}

/// The `bPose` of the armature object at `object`, checked: not null, an armature, with a pose,
/// and a plausible `expected_channels`.
///
/// # Safety
/// As [`read_pose`].
unsafe fn pose_of(layout: &PoseLayout, object: usize, expected_channels: usize) -> Result<usize, ReadError> {
    if object == 0 {
        return Err(ReadError::Null);
    }
    if expected_channels > MAX_CHANNELS {
        return Err(ReadError::Implausible("channel count"));
    }
    // SAFETY: the caller's (see `read_pose`).
    unsafe {
        if read::<i16>(object + layout.object_type) != OB_ARMATURE {
            return Err(ReadError::NotAnArmature("the object is of another type"));
        }
        let pose: usize = read(object + layout.object_pose);
        if pose == 0 {
            return Err(ReadError::NotAnArmature("the object has no pose"));
        }
        Ok(pose)
    }
}

/// Calls `each` with the address of every channel of `pose`, in order; exactly
/// `expected_channels` of them, or an error (the walk stops at the first one too many).
///
/// # Safety
/// As [`read_pose`]; `pose` from [`pose_of`].
unsafe fn each_channel(
    layout: &PoseLayout,
    pose: usize,
    expected_channels: usize,
    mut each: impl FnMut(usize) -> Result<(), ReadError>,
) -> Result<(), ReadError> {
    let mut found = 0;
    // SAFETY: the caller's (see `read_pose`).
    unsafe {
        let mut chan: usize = read(pose + layout.chanbase_first);
        while chan != 0 {
            if found == expected_channels {
                return Err(ReadError::ChannelCount { expected: expected_channels, found: expected_channels + 1 });
            }
            each(chan)?;
            found += 1;
            chan = read(chan + layout.chan_next);
        }
    }
    if found != expected_channels {
        return Err(ReadError::ChannelCount { expected: expected_channels, found });
    }
    Ok(())
}

/// The channel matrices (`bPoseChannel.chan_mat`, what `PoseBone.matrix_channel` gives) of
/// every channel of the armature object at `object`, in `pose.bones` order: what the Armature modifier deforms vertex groups with, without the rest of
/// [`read_pose`] (a crowd's characters read only these every frame).
///
/// # Safety
/// As [`read_pose`]. The walk stops after `expected_channels` channels (at most
/// [`MAX_CHANNELS`]): another count is an error, so a corrupt list is refused rather than
/// followed.
pub unsafe fn read_channel_matrices(
    layout: &PoseLayout,
    object: usize,
    expected_channels: usize,
    hints: &mut ReadHints,
) -> Result<Vec<Mat4>, ReadError> {
    // SAFETY: as in `read_pose`: offsets from this Blender's SDNA, a live armature object
    // (checked by its type), channels reached through its pose's list.
    unsafe {
        let pose = pose_of(layout, object, expected_channels)?;
        hints.prefetch(layout);
        hints.clear();
        let mut matrices = Vec::with_capacity(expected_channels);
        each_channel(layout, pose, expected_channels, |chan| {
            hints.visited(chan, 0, true);
            matrices.push(read_mat4(chan + layout.chan_mat));
            Ok(())
        })?;
        Ok(matrices)
    }
}

/// The bones of the armature at `armature` (a `bArmature`) by name: its bone tree walked depth
/// first, at most `limit` bones (a pose has one channel per bone).
///
/// # Safety
/// As [`read_pose`]; `armature` is read from the live object.
unsafe fn bones_by_name<'a>(
    layout: &PoseLayout,
    armature: usize,
    limit: usize,
) -> Result<HashMap<&'a [u8], usize>, ReadError> {
    let BoneLink::ByName { bonebase_first, bone_next, childbase_first, .. } = layout.bone_link else {
        unreachable!("only for the by-name link")
    };
    if armature == 0 {
        return Err(ReadError::NotAnArmature("the object has no armature data"));
    }
    let mut map = HashMap::with_capacity(limit);
    // SAFETY: see `read_pose`; the walk stops after `limit` bones, so a corrupt tree is refused
    // rather than followed forever.
    unsafe {
        let mut pending: Vec<usize> = vec![read(armature + bonebase_first)];
        while let Some(mut bone) = pending.pop() {
            while bone != 0 {
                if map.len() == limit {
                    // More bones than channels: the count the caller gave is not this pose's.
                    return Err(ReadError::ChannelCount { expected: limit, found: limit + 1 });
                }
                map.insert(name_bytes(bone + layout.bone_name, layout.bone_name_size), bone);
                pending.push(read(bone + childbase_first));
                bone = read(bone + bone_next);
            }
        }
    }
    Ok(map)
}

/// One `bPoseChannel` and its `Bone` at `bone`; None for a bone that does not deform (nothing
/// deforms with it, or looks it up by name: a rig has many more of them than of deforming
/// ones, Rigify's 546 of 706, so only its flag is read).
///
/// # Safety
/// As [`read_pose`], for the channel at `chan`; `bone` is its bone's address or 0.
unsafe fn read_channel(layout: &PoseLayout, chan: usize, bone: usize) -> Result<Option<PoseChannel>, ReadError> {
    // SAFETY: see `read_pose`.
    unsafe {
        if bone == 0 {
            return Err(ReadError::Implausible("pose channel without a bone"));
        }
        let flag: i32 = read(bone + layout.bone_flag);
        if flag & BONE_NO_DEFORM != 0 {
            return Ok(None);
        }
        let name = name_bytes(chan + layout.chan_name, layout.name_size);
        if name != name_bytes(bone + layout.bone_name, layout.bone_name_size) {
            return Err(ReadError::Implausible("pose channel named unlike its bone"));
        }
        let name = String::from_utf8_lossy(name).into_owned();
        let segments: i16 = read(bone + layout.bone_segments);
        let cache_segments: i32 = read(chan + layout.runtime_segments);
        if !(0..=MAX_BBONE_SEGMENTS as i16).contains(&segments)
            || !(0..=MAX_BBONE_SEGMENTS as i32).contains(&cache_segments)
        {
            return Err(ReadError::Implausible("B-Bone segment count"));
        }
        let segments = segments as u32;
        let bbone = if segments > 1 && cache_segments as u32 == segments {
            Some(read_bbone_cache(layout, chan, segments as usize)?)
        } else {
            None
        };
        Ok(Some(PoseChannel {
            name,
            deform: true,
            channel: read_mat4(chan + layout.chan_mat),
            rest: read_mat4(bone + layout.bone_arm_mat),
            length: read(bone + layout.bone_length),
            envelope: Envelope {
                head: read_vec3(bone + layout.bone_head),
                tail: read_vec3(bone + layout.bone_tail),
                head_radius: read(bone + layout.bone_rad_head),
                tail_radius: read(bone + layout.bone_rad_tail),
                distance: read(bone + layout.bone_dist),
                weight: read(bone + layout.bone_weight),
                multiply_groups: flag & BONE_MULT_VG_ENV != 0,
            },
            segments,
            curved: read::<u8>(bone + layout.bone_mapping_mode) == BBONE_MAPPING_CURVED,
            bbone,
        }))
    }
}

/// The runtime B-Bone cache of the channel at `chan`, computed for `segments` segments.
///
/// # Safety
/// As [`read_pose`]; `segments` is the cache's own segment count (the arrays' allocation size).
unsafe fn read_bbone_cache(layout: &PoseLayout, chan: usize, segments: usize) -> Result<BBoneCache, ReadError> {
    // SAFETY: see `read_pose`; Blender allocates `1 + segments` rest matrices and boundaries and
    // `2 + segments` deform matrices for the cache's segment count.
    unsafe {
        let rest: usize = read(chan + layout.runtime_rest_mats);
        let deform: usize = read(chan + layout.runtime_deform_mats);
        if rest == 0 || deform == 0 {
            return Err(ReadError::Implausible("B-Bone cache without matrices"));
        }
        let mats = |base: usize, range: core::ops::Range<usize>| -> Vec<Mat4> {
            range.map(|i| read_mat4(base + i * MAT4_SIZE)).collect()
        };
        let boundaries: usize = read(chan + layout.runtime_boundaries);
        let boundaries = if boundaries == 0 {
            Vec::new()
        } else {
            // Blender sets `depth_scale` only down to the search depth; the rest is whatever the
            // allocation held, so it is not read (and cannot change a signature).
            let depth = bsp_depth(segments as u32);
            (0..=segments)
                .map(|i| {
                    let b = boundaries + i * layout.boundary_size;
                    SegmentBoundary {
                        point: read_vec3(b + layout.boundary_point),
                        normal: read_vec3(b + layout.boundary_normal),
                        offset: read(b + layout.boundary_offset),
                        depth_scale: if i < depth { read(b + layout.boundary_depth_scale) } else { 0.0 },
                    }
                })
                .collect()
        };
        Ok(BBoneCache {
            inverse_rest: read_mat4(deform),
            deform: mats(deform, 1..segments + 2),
            rest_joints: mats(rest, 0..segments + 1),
            boundaries,
            arc_length_reciprocal: read(chan + layout.runtime_arc_length_reciprocal),
        })
    }
}

/// A `float[4][4]` (Blender's column-major `mat[column][row]`, glam's order).
unsafe fn read_mat4(address: usize) -> Mat4 {
    // SAFETY: the caller's (see `read`).
    Mat4::from_cols_array(&unsafe { read::<[f32; 16]>(address) })
}

unsafe fn read_vec3(address: usize) -> Vec3 {
    // SAFETY: the caller's (see `read`).
    Vec3::from_array(unsafe { read::<[f32; 3]>(address) })
}

#[cfg(test)]
mod tests;

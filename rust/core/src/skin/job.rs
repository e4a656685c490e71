//! One skinning call's inputs as the kernels read them: the job types every copy of the kernels
//! and the dispatcher (`kernels.rs`) share, so that no copy imports anything from the dispatcher.

use super::{Influences, Pose};
use glam::Mat4;

/// The methods as const-generic codes for the kernels (one compiled body per method).
pub(super) const LINEAR: u8 = 0;
pub(super) const DUAL_QUATERNION: u8 = 1;
pub(super) const BLEND: u8 = 2;
pub(super) const CENTERS: u8 = 3;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    Linear,
    DualQuaternion,
    Blend,
    CentersOfRotation,
}

/// One skinning call's inputs, as the kernels read them.
///
/// The kernels read bone records without bounds checks (see [`bone`]); what makes that sound
/// is carried by this type: [`Job::new`] checks that the influences and the pose fit together
/// (every bone index of the influences, validated against their bone count when they were
/// built, indexes every table of the pose the method reads), and those fields are private.
/// The other inputs are read through checked slices.
pub(crate) struct Job<'a> {
    kind: Kind,
    influences: &'a Influences,
    pose: &'a Pose,
    pub positions: &'a [[f32; 3]],
    pub premat: Option<Mat4>,
    pub postmat: Option<Mat4>,
    pub mask: Option<&'a [f32]>,
    pub blend_amount: Option<&'a [f32]>,
    pub blend_factor: f32,
    /// One center per vertex (mesh space) for [`Kind::CentersOfRotation`].
    pub centers: Option<&'a [[f32; 3]]>,
}

impl<'a> Job<'a> {
    /// The method.
    pub(crate) fn kind(&self) -> Kind {
        self.kind
    }

    /// The influences (read-only: they were checked against the pose).
    pub(crate) fn influences(&self) -> &'a Influences {
        self.influences
    }

    /// The pose (read-only: it was checked against the influences).
    pub(crate) fn pose(&self) -> &'a Pose {
        self.pose
    }

    /// A job without options (set the public fields for them).
    ///
    /// # Panics
    /// If the pose does not have one bone per bone index of the influences, or a method other
    /// than LBS is asked for without the pose's rest data, or `positions` does not have one
    /// point per vertex. [`super::skin`] checks these first and reports what is wrong.
    pub(crate) fn new(kind: Kind, positions: &'a [[f32; 3]], influences: &'a Influences, pose: &'a Pose) -> Self {
        assert_eq!(pose.bone_count(), influences.bone_count(), "the pose must have one bone per bone index");
        assert!(kind == Kind::Linear || pose.has_dual_quaternions(), "this method needs the rest matrices");
        assert!(kind != Kind::CentersOfRotation || pose.has_centers(), "this method needs the centers tables");
        assert_eq!(positions.len(), influences.vertex_count(), "one position per vertex");
        Job {
            kind,
            influences,
            pose,
            positions,
            premat: None,
            postmat: None,
            mask: None,
            blend_amount: None,
            blend_factor: 0.0,
            centers: None,
        }
    }
}

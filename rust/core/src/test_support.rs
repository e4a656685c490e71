//! Random transforms for property tests.

use glam::{Quat, Vec3};
use proptest::prelude::*;

use crate::DualQuat;

/// A unit quaternion from a uniformly random axis and an angle in `[0, max_angle]`.
pub fn rotation(max_angle: f32) -> impl Strategy<Value = Quat> {
    (-1.0f32..1.0, 0.0f32..core::f32::consts::TAU, 0.0f32..=max_angle).prop_map(|(z, phi, angle)| {
        let r = (1.0 - z * z).max(0.0).sqrt();
        let axis = Vec3::new(r * phi.cos(), r * phi.sin(), z);
        Quat::from_axis_angle(axis, angle)
    })
}

pub fn translation(extent: f32) -> impl Strategy<Value = Vec3> {
    (-extent..extent, -extent..extent, -extent..extent).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

/// A unit dual quaternion with rotation up to `max_angle` and translation within `extent`,
/// with a random sign (both signs are the same transform).
pub fn rigid(max_angle: f32, extent: f32) -> impl Strategy<Value = DualQuat> {
    (rotation(max_angle), translation(extent), any::<bool>()).prop_map(|(q, t, neg)| {
        let d = DualQuat::from_rotation_translation(q, t);
        if neg {
            -d
        } else {
            d
        }
    })
}

/// Any rigid transform (rotation up to 180°, translation within 10).
pub fn any_rigid() -> impl Strategy<Value = DualQuat> {
    rigid(core::f32::consts::PI, 10.0)
}

/// Whether two unit dual quaternions are the same transform (either sign) within `tol`.
pub fn same_transform(a: &DualQuat, b: &DualQuat, tol: f32) -> bool {
    let d1 = (*a - *b).tangent_length();
    let d2 = (*a + *b).tangent_length();
    d1.min(d2) <= tol
}

/// Rotation angle in radians of the relative transform `a*·b` (in `[0, π]`).
pub fn rotation_angle_between(a: &DualQuat, b: &DualQuat) -> f32 {
    (a.conjugate() * *b).shortest().to_screw().angle
}

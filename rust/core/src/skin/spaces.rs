//! The modifier's spaces folded into the bones' records, once per call, so that the kernels map
//! no point into armature space and back: each bone's move of a mesh-space point
//! `Dᵢ = postmat·Mᵢ·premat − I` (LBS on the copies with fused multiply-adds) or its matrix
//! `postmat·Mᵢ·premat` (the baseline's LBS, Blend's); and, for rigid spaces, each bone's dual
//! quaternion and centers record likewise ([`fold_rigid_spaces`], [`fold_rigid_centers`]).
//!
//! LBS is `co' = postmat·(p + f·Σ wᵢ·(Mᵢ·p − p))` with `p = premat·co` and `f = a/Σ wᵢ`; since
//! every term is an affine map of `co`, that is `co + f·Σ wᵢ·Dᵢ·co` exactly when `postmat·premat`
//! is the identity, as it is for Blender's spaces (`premat` is `postmat`'s inverse). Spaces that
//! do not undo each other are not folded: the kernels apply them as they are.

use glam::{Affine3A, DMat3, DMat4, Mat3A, Mat4, Quat, Vec3, Vec4};

use super::pose::{AffineRows, CorRigidBone, DqBone, LinearBone, Pose};

/// How far `postmat·premat` may be from the identity, relative to the matrices' translations,
/// for the spaces to count as each other's inverse: well above the single-precision inverse's
/// round-off for a well-conditioned space (about 1e-7), well below the exactness tests' bar
/// (1e-5 of a mesh's size).
const INVERSE_TOLERANCE: f64 = 1e-6;

/// What each folded record holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Fold {
    /// `postmat·Mᵢ·premat`: a matrix of mesh space, for the kernels' usual LBS.
    Matrices,
    /// `postmat·Mᵢ·premat − I`: the bone's move of a mesh-space point.
    Moves,
}

/// Each bone's record as `fold` says, or `None` when the spaces are not each other's inverse. A
/// missing space is the identity.
pub(crate) fn fold_spaces(
    pose: &Pose,
    premat: Option<Mat4>,
    postmat: Option<Mat4>,
    fold: Fold,
) -> Option<Vec<LinearBone>> {
    let (pre, post) = (premat.unwrap_or(Mat4::IDENTITY), postmat.unwrap_or(Mat4::IDENTITY));
    if !undo_each_other(&pre.as_dmat4(), &post.as_dmat4()) {
        return None;
    }
    // Single precision, SIMD: a Rigify character has 720 bones to fold every frame.
    let (pre, post) = (Affine3A::from_mat4(pre), Affine3A::from_mat4(post));
    let records = pose
        .linear
        .iter()
        .map(|bone| {
            let mut d = post * bone.matrix.to_affine() * pre;
            if fold == Fold::Moves {
                d.matrix3 -= Mat3A::IDENTITY;
            }
            LinearBone { matrix: AffineRows::from_mat4(&Mat4::from(d)), padding: [0.0; 4] }
        })
        .collect();
    Some(records)
}

/// Each bone's dual quaternion with rigid spaces folded in: the rotation `q_post·qᵢ·q_pre` and
/// the translation of `postmat·Mᵢ·premat`; or `None` when `premat` is not a rotation and a
/// translation (a scale or shear does not pass through the blend), or the spaces do not undo each
/// other. A common rigid change of space leaves dual quaternion blending unchanged (the sign
/// choices compare rotations by dot products, which it keeps), so DQS in mesh space gives what
/// DQS in armature space gives. For poses without scale (their `dq` table).
pub(crate) fn fold_rigid_spaces(pose: &Pose, premat: Option<Mat4>, postmat: Option<Mat4>) -> Option<Vec<DqBone>> {
    let records = rigid_folds(pose, premat, postmat)?
        .map(|(q, t)| {
            let dual = Quat::from_xyzw(0.5 * t.x, 0.5 * t.y, 0.5 * t.z, 0.0) * q;
            DqBone { real: Vec4::from(q), dual: Vec4::from(dual) }
        })
        .collect();
    Some(records)
}

/// [`fold_rigid_spaces`] for the rigid centers' records (the rotation and half the
/// translation): centers of rotation move with the points, so the same change of space passes
/// through them.
pub(crate) fn fold_rigid_centers(
    pose: &Pose,
    premat: Option<Mat4>,
    postmat: Option<Mat4>,
) -> Option<Vec<CorRigidBone>> {
    let records = rigid_folds(pose, premat, postmat)?
        .map(|(q, t)| CorRigidBone { real: Vec4::from(q), half_translation: (0.5 * t).extend(0.0) })
        .collect();
    Some(records)
}

/// Each bone's rotation `q_post·qᵢ·q_pre` and the translation of `postmat·Mᵢ·premat`, when the
/// spaces are rigid and undo each other.
fn rigid_folds<'a>(
    pose: &'a Pose,
    premat: Option<Mat4>,
    postmat: Option<Mat4>,
) -> Option<impl Iterator<Item = (Quat, Vec3)> + 'a> {
    let (pre, post) = (premat.unwrap_or(Mat4::IDENTITY), postmat.unwrap_or(Mat4::IDENTITY));
    if !is_rigid(&pre.as_dmat4()) || !undo_each_other(&pre.as_dmat4(), &post.as_dmat4()) {
        return None;
    }
    let (pre, post) = (Affine3A::from_mat4(pre), Affine3A::from_mat4(post));
    let (q_pre, q_post) = (Quat::from_mat3a(&pre.matrix3).normalize(), Quat::from_mat3a(&post.matrix3).normalize());
    Some(pose.dq.iter().zip(&pose.linear).map(move |(bone, matrix)| {
        let q = q_post * Quat::from_vec4(bone.real) * q_pre;
        (q, Vec3::from((post * matrix.matrix.to_affine() * pre).translation))
    }))
}

/// Whether `m`'s linear part is a rotation (orthonormal columns, no reflection) to
/// [`INVERSE_TOLERANCE`].
fn is_rigid(m: &DMat4) -> bool {
    let r = DMat3::from_mat4(*m);
    (r.transpose() * r).abs_diff_eq(DMat3::IDENTITY, INVERSE_TOLERANCE) && r.determinant() > 0.0
}

/// Whether `post·pre` is the identity to [`INVERSE_TOLERANCE`].
fn undo_each_other(pre: &DMat4, post: &DMat4) -> bool {
    let product = *post * *pre;
    let reach = 1.0 + pre.w_axis.truncate().abs().max_element() + post.w_axis.truncate().abs().max_element();
    let linear_ok = DMat3::from_mat4(product).abs_diff_eq(DMat3::IDENTITY, INVERSE_TOLERANCE);
    let translation_ok = product.w_axis.truncate().abs().max_element() <= INVERSE_TOLERANCE * reach;
    linear_ok && translation_ok
}

#[cfg(test)]
mod tests {
    use glam::{Quat, Vec3, Vec4};

    use super::*;

    fn pose() -> Pose {
        let deform = [
            Mat4::from_scale_rotation_translation(Vec3::new(1.0, 1.3, 1.0), Quat::from_rotation_y(0.7), Vec3::X),
            Mat4::from_rotation_z(-0.4),
        ];
        Pose::new(&deform, None).unwrap()
    }

    #[test]
    fn blenders_spaces_fold_into_each_bones_matrix_and_move() {
        let postmat = Mat4::from_scale_rotation_translation(
            Vec3::splat(0.5),
            Quat::from_rotation_x(0.3),
            Vec3::new(100.0, -2.0, 3.0),
        );
        let premat = postmat.inverse();
        let moves = fold_spaces(&pose(), Some(premat), Some(postmat), Fold::Moves).expect("inverse spaces fold");
        let co = Vec3::new(0.25, -1.5, 2.0);
        for (bone, moved) in pose().linear.iter().zip(&moves) {
            let through = bone.matrix.transform_point(premat.transform_point3(co).extend(1.0));
            let want = postmat.transform_point3(through) - co;
            let got = moved.matrix.transform_point(co.extend(1.0));
            assert!((got - want).length() < 1e-4, "{got} vs {want}");
            assert_eq!(moved.padding, [0.0; 4]);
        }
        let identity = fold_spaces(&pose(), None, None, Fold::Moves).unwrap();
        let matrices = fold_spaces(&pose(), Some(premat), Some(postmat), Fold::Matrices).unwrap();
        for (m, d) in matrices.iter().zip(&moves) {
            for r in 0..3 {
                let unit = Vec4::from_array(core::array::from_fn(|c| if c == r { 1.0 } else { 0.0 }));
                assert!((m.matrix.rows[r] - unit - d.matrix.rows[r]).abs().max_element() < 1e-6);
            }
        }
        assert_eq!(identity[1].matrix.rows[2], Vec4::new(0.0, 0.0, 0.0, 0.0));
    }

    #[test]
    fn spaces_that_do_not_undo_each_other_are_not_folded() {
        let pre = Mat4::from_translation(Vec3::new(0.0, 0.0, 10.0));
        let post = Mat4::from_translation(Vec3::Z);
        assert!(fold_spaces(&pose(), Some(pre), Some(post), Fold::Matrices).is_none());
        assert!(fold_spaces(&pose(), Some(Mat4::from_rotation_x(1e-3)), None, Fold::Moves).is_none());
        assert!(fold_spaces(&pose(), None, Some(Mat4::from_scale(Vec3::splat(1.0 + 1e-5))), Fold::Matrices).is_none());
    }
}

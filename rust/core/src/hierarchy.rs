//! Forward kinematics of a bone hierarchy with dual quaternions (Kenwright, "A Beginners Guide to
//! Dual-Quaternions", §9): each bone's global transform is its parent's global transform times
//! its own local one, `globalᵢ = global_parent(i) · localᵢ`, renormalized at every level so that
//! float error cannot accumulate into non-rigid transforms along long chains.

use crate::dual_quat::DualQuat;

/// Why a hierarchy is invalid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HierarchyError {
    /// `parents` and `locals` have different lengths.
    LengthMismatch { parents: usize, locals: usize },
    /// A parent index is neither a root marker (negative) nor a valid bone index.
    ParentOutOfRange { bone: usize, parent: i64 },
    /// Following parents from this bone comes back to it.
    Cycle { bone: usize },
    /// A local transform has a zero or non-finite real part.
    NotATransform { bone: usize },
}

impl core::fmt::Display for HierarchyError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            HierarchyError::LengthMismatch { parents, locals } => {
                write!(f, "{parents} parents but {locals} local transforms: there must be one parent per bone")
            }
            HierarchyError::ParentOutOfRange { bone, parent } => {
                write!(f, "bone {bone} has parent {parent}, which is not a bone index (use -1 for a root)")
            }
            HierarchyError::Cycle { bone } => write!(f, "bone {bone} is its own ancestor (the parents form a cycle)"),
            HierarchyError::NotATransform { bone } => {
                write!(f, "local transform of bone {bone} has a zero or non-finite real part")
            }
        }
    }
}

impl std::error::Error for HierarchyError {}

/// Global transforms from local ones. `parents[i]` is the index of bone `i`'s parent, or any
/// negative number for a root. Bones may come in any order; a parent need not precede its
/// children.
pub fn forward_kinematics(parents: &[i64], locals: &[DualQuat]) -> Result<Vec<DualQuat>, HierarchyError> {
    let n = parents.len();
    if n != locals.len() {
        return Err(HierarchyError::LengthMismatch { parents: n, locals: locals.len() });
    }
    for (bone, &parent) in parents.iter().enumerate() {
        if parent >= n as i64 {
            return Err(HierarchyError::ParentOutOfRange { bone, parent });
        }
        if locals[bone].try_normalize().is_none() {
            return Err(HierarchyError::NotATransform { bone });
        }
    }
    // 0 = not visited, 1 = on the current path, 2 = done.
    let mut state = vec![0u8; n];
    let mut globals = vec![DualQuat::IDENTITY; n];
    let mut path = Vec::new();
    for start in 0..n {
        // Walk up to the first resolved ancestor, then resolve the path top-down.
        let mut bone = start;
        while state[bone] == 0 {
            state[bone] = 1;
            path.push(bone);
            match usize::try_from(parents[bone]) {
                Ok(parent) => bone = parent,
                Err(_) => break,
            }
        }
        if state[bone] == 1 && parents[bone] >= 0 {
            return Err(HierarchyError::Cycle { bone });
        }
        while let Some(b) = path.pop() {
            let local = locals[b].normalize_or_identity();
            globals[b] = match usize::try_from(parents[b]) {
                Ok(parent) => (globals[parent] * local).normalize_or_identity(),
                Err(_) => local,
            };
            state[b] = 2;
        }
    }
    Ok(globals)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat4, Quat, Vec3};

    fn local(angle: f32, t: Vec3) -> DualQuat {
        DualQuat::from_rotation_translation(Quat::from_rotation_z(angle), t)
    }

    #[test]
    fn matches_matrix_products_in_any_bone_order() {
        // Chain 2 -> 0 -> 3, and 1 a separate root; listed children first on purpose.
        let parents = [2i64, -1, -1, 0];
        let locals = [
            local(0.3, Vec3::new(1.0, 0.0, 0.0)),
            local(-0.7, Vec3::new(0.0, 2.0, 0.0)),
            local(1.1, Vec3::new(0.0, 0.0, 3.0)),
            local(0.5, Vec3::new(0.5, 0.5, 0.0)),
        ];
        let globals = forward_kinematics(&parents, &locals).unwrap();
        let m = |i: usize| locals[i].to_mat4();
        let expected: [Mat4; 4] = [m(2) * m(0), m(1), m(2), m(2) * m(0) * m(3)];
        for (g, e) in globals.iter().zip(expected) {
            assert!(g.to_mat4().abs_diff_eq(e, 1e-5), "{:?} vs {:?}", g.to_mat4(), e);
        }
    }

    #[test]
    fn long_chain_stays_rigid() {
        let n = 10_000;
        let parents: Vec<i64> = (0..n as i64).map(|i| i - 1).collect();
        let locals = vec![local(0.001, Vec3::new(0.001, 0.0, 0.0)); n];
        let globals = forward_kinematics(&parents, &locals).unwrap();
        assert!(globals.iter().all(|g| g.is_unit(1e-5)));
        // 10,000 turns of 0.001 rad about Z: 10 rad in all.
        let expected = Quat::from_rotation_z(10.0);
        assert!(globals[n - 1].real.dot(expected).abs() > 1.0 - 1e-4);
    }

    #[test]
    fn rejects_bad_hierarchies() {
        let l = [DualQuat::IDENTITY; 3];
        assert_eq!(forward_kinematics(&[-1, 5, 0], &l), Err(HierarchyError::ParentOutOfRange { bone: 1, parent: 5 }));
        assert!(matches!(forward_kinematics(&[1, 2, 0], &l), Err(HierarchyError::Cycle { .. })));
        assert!(matches!(forward_kinematics(&[-1, 1, 0], &l), Err(HierarchyError::Cycle { bone: 1 })));
        assert_eq!(forward_kinematics(&[-1, 0], &l), Err(HierarchyError::LengthMismatch { parents: 2, locals: 3 }));
        assert_eq!(
            forward_kinematics(&[-1, 0, 1], &[DualQuat::IDENTITY, DualQuat::ZERO, DualQuat::IDENTITY]),
            Err(HierarchyError::NotATransform { bone: 1 })
        );
    }
}

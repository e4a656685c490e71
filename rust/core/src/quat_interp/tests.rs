use super::*;
use crate::test_support::rotation;
use core::f32::consts::PI;
use proptest::collection::vec;
use proptest::prelude::*;

/// Angular velocity (rad per unit parameter) between two nearby rotations `dt` apart.
fn angular_velocity(a: Quat, b: Quat, dt: f32) -> Vec3 {
    let rel = a.conjugate() * b;
    let rel = if rel.w < 0.0 { -rel } else { rel };
    let l = quat_log(rel);
    Vec3::new(l.x, l.y, l.z) * (2.0 / dt)
}

/// Rotation angle from `a` to `b`, from the relative quaternion with atan2 (acos of the dot
/// product loses precision in f32 for small angles).
fn angle_between(a: Quat, b: Quat) -> f32 {
    let r = a.conjugate() * b;
    2.0 * Vec3::new(r.x, r.y, r.z).length().atan2(r.w.abs())
}

proptest! {
    #[test]
    fn slerp_hits_end_points_and_takes_the_short_arc(p in rotation(PI), q in rotation(PI), neg in any::<bool>()) {
        let q = if neg { -q } else { q };
        prop_assert!(slerp(p, q, 0.0).dot(p).abs() > 1.0 - 1e-6);
        prop_assert!(slerp(p, q, 1.0).dot(q).abs() > 1.0 - 1e-5);
        let total = angle_between(p, q);
        prop_assert!(total <= PI + 1e-5);
        let mid = slerp(p, q, 0.5);
        prop_assert!((angle_between(p, mid) - total / 2.0).abs() < 1e-3);
    }

    #[test]
    fn slerp_has_constant_angular_speed(p in rotation(PI), q in rotation(PI)) {
        let total = angle_between(p, q);
        prop_assume!(total > 0.05);
        let steps = 20;
        for i in 0..steps {
            let (t0, t1) = (i as f32 / steps as f32, (i + 1) as f32 / steps as f32);
            let step = angle_between(slerp(p, q, t0), slerp(p, q, t1));
            prop_assert!((step - total / steps as f32).abs() < 2e-4, "step {i}: {step} vs {}", total / steps as f32);
        }
    }

    #[test]
    fn squad_passes_through_every_key(keys in vec(rotation(PI), 2..8)) {
        let s = Squad::new(&keys);
        for (i, k) in keys.iter().enumerate() {
            prop_assert!(s.evaluate(i as f32).dot(*k).abs() > 1.0 - 1e-5);
        }
    }

    #[test]
    fn squad_is_c1_at_the_keys(keys in vec(rotation(2.0), 3..7)) {
        // Neighbouring keys well apart and not half a turn apart, so velocities are well defined.
        for w in keys.windows(2) {
            let a = angle_between(w[0], w[1]);
            prop_assume!(a > 0.2 && a < 2.5);
        }
        let s = Squad::new(&keys);
        let dt = 1e-3;
        for i in 1..keys.len() - 1 {
            let u = i as f32;
            let left = angular_velocity(s.evaluate(u - dt), s.evaluate(u), dt);
            let right = angular_velocity(s.evaluate(u), s.evaluate(u + dt), dt);
            let scale = left.length().max(right.length()).max(1.0);
            prop_assert!((left - right).length() < 2e-2 * scale, "key {i}: {left} vs {right}");
        }
    }
}

#[test]
fn a_chain_of_slerps_is_not_c1_but_squad_is() {
    // The C1 test above must be able to fail: the same measure on a piecewise Slerp shows a jump.
    let keys = [Quat::IDENTITY, Quat::from_rotation_x(1.0), Quat::from_rotation_x(1.0) * Quat::from_rotation_y(1.0)];
    let dt = 1e-3;
    let chain = |u: f32| if u <= 1.0 { slerp(keys[0], keys[1], u) } else { slerp(keys[1], keys[2], u - 1.0) };
    let jump = (angular_velocity(chain(1.0 - dt), chain(1.0), dt) - angular_velocity(chain(1.0), chain(1.0 + dt), dt))
        .length();
    assert!(jump > 1.0, "slerp chain jump {jump}");
    let s = Squad::new(&keys);
    let jump = (angular_velocity(s.evaluate(1.0 - dt), s.evaluate(1.0), dt)
        - angular_velocity(s.evaluate(1.0), s.evaluate(1.0 + dt), dt))
    .length();
    assert!(jump < 2e-2, "squad jump {jump}");
}

#[test]
fn squad_control_points_follow_the_report() {
    // sᵢ = qᵢ·exp(−(log(qᵢ*qᵢ₊₁) + log(qᵢ*qᵢ₋₁))/4): for keys on one great circle through
    // evenly spaced angles the control points are the keys themselves.
    let keys: Vec<_> = (0..4).map(|i| Quat::from_rotation_z(0.5 * i as f32)).collect();
    let s = Squad::new(&keys);
    for (c, k) in s.control_points().iter().zip(&keys) {
        assert!(c.dot(*k).abs() > 1.0 - 1e-6);
    }
    // And then Squad reduces to Slerp.
    for u in [0.25f32, 1.5, 2.75] {
        assert!(s.evaluate(u).dot(Quat::from_rotation_z(0.5 * u)).abs() > 1.0 - 1e-6);
    }
}

#[test]
fn keys_with_flipped_signs_are_made_continuous() {
    let mut keys: Vec<_> = (0..6).map(|i| Quat::from_rotation_y(0.4 * i as f32)).collect();
    keys[2] = -keys[2];
    keys[3] = -keys[3];
    keys[5] = -keys[5];
    let flipped = make_signs_continuous(&mut keys);
    assert_eq!(flipped, 3);
    assert!(keys.windows(2).all(|w| w[0].dot(w[1]) >= 0.0));
    // Squad through them turns monotonically the short way.
    let s = Squad::new(&keys);
    let mut last = 0.0;
    for i in 1..=50 {
        let angle = 2.0 * s.evaluate(i as f32 / 10.0).w.clamp(-1.0, 1.0).acos();
        assert!(angle >= last - 1e-4);
        last = angle;
    }
}

#[test]
fn squad_handles_degenerate_key_lists() {
    assert_eq!(Squad::new(&[]).evaluate(0.5), Quat::IDENTITY);
    let one = Quat::from_rotation_x(0.3);
    assert!(Squad::new(&[one]).evaluate(7.0).dot(one) > 1.0 - 1e-6);
    let s = Squad::new(&[Quat::IDENTITY, one]);
    assert!(s.evaluate(f32::NAN).is_finite());
    assert!(s.evaluate(-3.0).dot(Quat::IDENTITY) > 1.0 - 1e-6);
    assert!(s.evaluate(9.0).dot(one) > 1.0 - 1e-6);
}

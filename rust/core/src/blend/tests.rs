use super::*;
use crate::test_support::*;
use core::f32::consts::PI;
use glam::{Quat, Vec3};
use proptest::collection::vec;
use proptest::prelude::*;

/// The DIB precision used in these tests.
const PRECISION: f32 = 1e-5;
/// f32 round-off of a tangent-space mean of a few transforms within 5 units (log/exp of unit
/// dual quaternions are accurate to a few ulps of their magnitude, ~5·1.2e-7 each).
const ROUND_OFF: f32 = 5e-6;

fn weights(n: usize) -> impl Strategy<Value = Vec<f32>> {
    vec(0.05f32..1.0, n)
}

proptest! {
    #[test]
    fn sclerp_hits_its_end_points(p in any_rigid(), q in any_rigid()) {
        prop_assert!(same_transform(&sclerp(&p, &q, 0.0), &p, 1e-5));
        prop_assert!(same_transform(&sclerp(&p, &q, 1.0), &q, 2e-4));
    }

    #[test]
    fn sclerp_is_a_constant_speed_shortest_path_screw(p in any_rigid(), q in any_rigid(), t in 0.0f32..1.0) {
        // Relative to p, the motion is q' = p*·q on the shortest path: angle ≤ π ...
        let whole = (p.conjugate() * q).shortest().to_screw();
        prop_assert!(whole.angle <= PI + 1e-5);
        prop_assume!(whole.angle > 1e-2 && whole.angle < PI - 1e-2);
        // ... and at t it is the same screw with t·angle and t·pitch (constant speed, fixed axis).
        let part = (p.conjugate() * sclerp(&p, &q, t)).to_screw();
        prop_assert!((part.angle - t * whole.angle).abs() < 2e-4, "{} vs {}", part.angle, t * whole.angle);
        prop_assert!((part.pitch - t * whole.pitch).abs() < 2e-3 * (1.0 + whole.pitch.abs()));
        if t > 0.05 {
            prop_assert!(part.axis.abs_diff_eq(whole.axis, 1e-3));
            prop_assert!(part.moment.abs_diff_eq(whole.moment, 2e-2 * (1.0 + whole.moment.length())));
        }
    }

    #[test]
    fn sclerp_is_bi_invariant(p in any_rigid(), q in any_rigid(), r in any_rigid(), t in 0.0f32..1.0) {
        prop_assume!(rotation_angle_between(&p, &q) < PI - 1e-2);
        let base = sclerp(&p, &q, t);
        prop_assert!(same_transform(&sclerp(&(r * p), &(r * q), t), &(r * base), 5e-4));
        prop_assert!(same_transform(&sclerp(&(p * r), &(q * r), t), &(base * r), 5e-4));
    }

    #[test]
    fn dlb_is_bi_invariant(qs in vec(any_rigid(), 2..6), r in any_rigid(), seed in weights(6)) {
        let w = &seed[..qs.len()];
        let base = dlb(&qs, w).unwrap();
        let left: Vec<_> = qs.iter().map(|q| r * *q).collect();
        let right: Vec<_> = qs.iter().map(|q| *q * r).collect();
        prop_assert!(same_transform(&dlb(&left, w).unwrap(), &(r * base), 2e-4));
        prop_assert!(same_transform(&dlb(&right, w).unwrap(), &(base * r), 2e-4));
    }

    #[test]
    fn dlb_ignores_input_signs_and_order(qs in vec(any_rigid(), 2..6), seed in weights(6)) {
        let w = &seed[..qs.len()];
        let base = dlb(&qs, w).unwrap();
        let flipped: Vec<_> = qs.iter().enumerate().map(|(i, q)| if i % 2 == 0 { -*q } else { *q }).collect();
        prop_assert!(same_transform(&dlb(&flipped, w).unwrap(), &base, 1e-5));
        let (mut rq, mut rw) = (qs.clone(), w.to_vec());
        rq.reverse();
        rw.reverse();
        prop_assert!(same_transform(&dlb(&rq, &rw).unwrap(), &base, 1e-4));
    }

    #[test]
    fn dlb_stays_within_the_papers_bounds_of_sclerp(p in any_rigid(), q in any_rigid(), t in 0.0f32..1.0) {
        // Kavan et al.: rotation angles differ by less than 8.15°, translation along the common
        // screw axis by less than 15% of the translation of p*·q.
        let rel = (p.conjugate() * q).shortest().to_screw();
        let a = (p.conjugate() * dlb(&[p, q], &[1.0 - t, t]).unwrap()).shortest().to_screw();
        let b = (p.conjugate() * sclerp(&p, &q, t)).shortest().to_screw();
        prop_assert!((a.angle - b.angle).abs().to_degrees() < 8.15, "{}°", (a.angle - b.angle).abs().to_degrees());
        prop_assert!((a.pitch - b.pitch).abs() <= 0.15 * rel.pitch.abs() + 1e-4);
    }

    #[test]
    fn dib_equals_sclerp_for_two_transforms_after_one_update(p in any_rigid(), q in any_rigid(), t in 0.0f32..1.0) {
        prop_assume!(rotation_angle_between(&p, &q) < PI - 1e-2);
        let r = dib(&[p, q], &[1.0 - t, t], PRECISION, 20).unwrap();
        prop_assert!(r.converged);
        prop_assert!(r.iterations <= 1, "{} iterations", r.iterations);
        prop_assert!(same_transform(&r.blend, &sclerp(&p, &q, t), 5e-4));
    }

    #[test]
    fn dib_result_is_a_fixed_point(qs in vec(rigid(PI / 2.0, 5.0), 3..7), seed in weights(7)) {
        let w = &seed[..qs.len()];
        let r = dib(&qs, w, PRECISION, 50).unwrap();
        prop_assert!(r.converged, "residual {} after {} iterations", r.residual, r.iterations);
        // Recomputed independently (f32 weights, our own normalization), the tangent-space mean
        // at the result is zero to the precision, plus f32 round-off in the logarithms.
        let total: f32 = w.iter().sum();
        let units: Vec<_> = qs.iter().map(|q| q.normalize_or_identity()).collect();
        let normalized: Vec<_> = w.iter().map(|x| x / total).collect();
        let mean = tangent_mean(&r.blend, &units, &normalized).tangent_length();
        prop_assert!(mean < PRECISION + ROUND_OFF, "tangent mean {mean}");
    }

    #[test]
    fn dib_is_bi_invariant(qs in vec(rigid(PI / 2.0, 5.0), 3..6), r in any_rigid(), seed in weights(6)) {
        let w = &seed[..qs.len()];
        let base = dib(&qs, w, PRECISION, 50).unwrap().blend;
        let left: Vec<_> = qs.iter().map(|q| r * *q).collect();
        let right: Vec<_> = qs.iter().map(|q| *q * r).collect();
        prop_assert!(same_transform(&dib(&left, w, PRECISION, 50).unwrap().blend, &(r * base), 5e-4));
        prop_assert!(same_transform(&dib(&right, w, PRECISION, 50).unwrap().blend, &(base * r), 5e-4));
    }
}

#[test]
fn sclerp_at_exactly_half_a_turn_is_finite_and_rigid() {
    let p = DualQuat::from_translation(Vec3::new(1.0, 0.0, 0.0));
    let q = DualQuat::from_rotation_translation(Quat::from_rotation_z(PI), Vec3::new(0.0, 2.0, 0.0));
    for t in [0.0, 0.25, 0.5, 0.75, 1.0] {
        let r = sclerp(&p, &q, t);
        assert!(r.is_finite() && r.is_unit(1e-5), "t={t}: {r:?}");
        let angle = (p.conjugate() * r).shortest().to_screw().angle;
        assert!((angle - t * PI).abs() < 1e-4, "t={t}: angle {angle}");
    }
    // Both inputs exactly opposite in sign (the same transform): stays put.
    let r = sclerp(&q, &-q, 0.5);
    assert!(same_transform(&r, &q, 1e-6));
}

#[test]
fn dlb_of_one_transform_is_that_transform() {
    let q = DualQuat::from_rotation_translation(Quat::from_rotation_y(1.0), Vec3::ONE);
    assert!(same_transform(&dlb(&[q], &[3.0]).unwrap(), &q, 1e-6));
    let r = dib(&[q], &[1.0], 1e-6, 10).unwrap();
    assert_eq!(r.iterations, 0);
    assert!(same_transform(&r.blend, &q, 1e-6));
}

#[test]
fn bad_blend_inputs_are_named() {
    let q = DualQuat::IDENTITY;
    assert_eq!(dlb(&[], &[]), Err(BlendError::Empty));
    assert_eq!(dlb(&[q, q], &[1.0]), Err(BlendError::LengthMismatch { transforms: 2, weights: 1 }));
    assert_eq!(dlb(&[q, q], &[1.0, -0.5]), Err(BlendError::InvalidWeight { index: 1 }));
    assert_eq!(dlb(&[q, q], &[f32::NAN, 1.0]), Err(BlendError::InvalidWeight { index: 0 }));
    assert_eq!(dlb(&[q, q], &[0.0, 0.0]), Err(BlendError::ZeroWeightSum));
    assert_eq!(dlb(&[q, DualQuat::ZERO], &[1.0, 1.0]), Err(BlendError::NotATransform { index: 1 }));
    assert_eq!(dib(&[q, DualQuat::ZERO], &[1.0, 1.0], 1e-6, 5).unwrap_err(), BlendError::NotATransform { index: 1 });
}

#[test]
fn dib_reports_non_convergence_at_the_iteration_cap() {
    let qs: Vec<_> = (0..5)
        .map(|i| {
            DualQuat::from_rotation_translation(Quat::from_rotation_z(0.7 * i as f32), Vec3::new(i as f32, 0.0, 1.0))
        })
        .collect();
    let r = dib(&qs, &[1.0; 5], 0.0, 3).unwrap();
    assert_eq!(r.iterations, 3);
    assert!(!r.converged);
    assert!(r.blend.is_unit(1e-5));
}

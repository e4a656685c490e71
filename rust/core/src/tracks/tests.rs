use super::*;
use core::f32::consts::PI;
use glam::Vec3;

fn keys_on_a_zigzag() -> (Vec<f32>, Vec<Quat>) {
    let times = vec![0.0, 10.0, 16.0, 30.0, 36.0];
    let keys = vec![
        Quat::IDENTITY,
        Quat::from_rotation_x(1.2),
        Quat::from_rotation_x(1.2) * Quat::from_rotation_y(1.4),
        Quat::from_rotation_z(-0.8) * Quat::from_rotation_y(0.6),
        Quat::from_rotation_z(0.9),
    ];
    (times, keys)
}

fn angular_velocity(a: Quat, b: Quat, dt: f32) -> Vec3 {
    let r = a.conjugate() * b;
    let r = if r.w < 0.0 { -r } else { r };
    let l = quat_log(r);
    Vec3::new(l.x, l.y, l.z) * (2.0 / dt)
}

#[test]
fn slerp_track_hits_keys_and_has_constant_speed_per_segment() {
    let (times, keys) = keys_on_a_zigzag();
    let track = RotationTrack::new(&times, &keys).unwrap();
    for (t, k) in times.iter().zip(&keys) {
        assert!(track.slerp(*t).dot(*k).abs() > 1.0 - 1e-6);
    }
    let samples: Vec<Quat> = (0..=100).map(|i| track.slerp(10.0 + 6.0 * i as f32 / 100.0)).collect();
    let speeds = angular_speeds(&samples);
    let mean = speeds.iter().sum::<f32>() / speeds.len() as f32;
    assert!(speeds.iter().all(|s| (s - mean).abs() < 1e-4), "{speeds:?}");
}

#[test]
fn squad_track_passes_through_keys_and_is_c1_in_time_with_uneven_keys() {
    let (times, keys) = keys_on_a_zigzag();
    let track = RotationTrack::new(&times, &keys).unwrap();
    for (t, k) in times.iter().zip(&keys) {
        assert!(track.squad(*t).dot(*k).abs() > 1.0 - 1e-6);
    }
    // One-sided angular velocities at each inner key, Richardson-extrapolated (2·v(h) − v(2h))
    // to remove the first-order error of one-sided differences (acceleration jumps at keys).
    let dt = 2e-2;
    let one_sided = |f: &dyn Fn(f32) -> Quat, t: f32, sign: f32| {
        let v =
            |h: f32| if sign < 0.0 { angular_velocity(f(t - h), f(t), h) } else { angular_velocity(f(t), f(t + h), h) };
        v(dt) * 2.0 - v(2.0 * dt)
    };
    for &t in &times[1..times.len() - 1] {
        let f = |x: f32| track.squad(x);
        let (left, right) = (one_sided(&f, t, -1.0), one_sided(&f, t, 1.0));
        // Tolerance: f32 round-off in the finite differences (~1e-5 rad over 0.02 frames).
        assert!((left - right).length() < 1e-3 * left.length().max(0.1), "t={t}: {left} vs {right}");
    }
    // Shoemake's control points (made for even spacing) are not C¹ in time here: the test can fail.
    let uniform = crate::quat_interp::Squad::new(&keys);
    let at = |t: f32| {
        let (i, h) = locate(&times, t);
        uniform.segment(i, h)
    };
    let t = times[1];
    let jump = (one_sided(&at, t, -1.0) - one_sided(&at, t, 1.0)).length();
    assert!(jump > 1e-2, "{jump}");
}

#[test]
fn screw_track_is_piecewise_sclerp() {
    let times = [0.0, 4.0, 10.0];
    let keys = [
        DualQuat::IDENTITY,
        DualQuat::from_rotation_translation(Quat::from_rotation_z(PI / 2.0), Vec3::new(1.0, 0.0, 2.0)),
        DualQuat::from_rotation_translation(Quat::from_rotation_x(1.0), Vec3::new(0.0, 3.0, 0.0)),
    ];
    let mid = screw_track(&times, &keys, 7.0).unwrap();
    let want = sclerp(&keys[1], &keys[2], 0.5);
    assert!((mid - want).tangent_length() < 1e-5);
    assert!((screw_track(&times, &keys, -5.0).unwrap() - keys[0]).tangent_length() < 1e-6);
    assert!(screw_track(&times, &keys[..2], 1.0).is_err());
    assert!(screw_track(&[0.0, 0.0], &keys[..2], 1.0).is_err());
}

#[test]
fn spring_keeps_the_keys_and_beats_squad_on_curvature() {
    let (times, keys) = keys_on_a_zigzag();
    let settings = SpringSettings { step: 1.0, levels: 3, iterations: 600, key_weight: 1.2 };
    let samples = spring(&times, &keys, &settings).unwrap();
    assert_eq!(samples.len(), 37);
    let track = RotationTrack::new(&times, &keys).unwrap();
    for (t, k) in times.iter().zip(track.keys()) {
        assert!(samples[*t as usize].dot(*k).abs() > 1.0 - 1e-6, "key at {t}");
    }
    let squad: Vec<Quat> = (0..=36).map(|f| track.squad(f as f32)).collect();
    let slerp: Vec<Quat> = (0..=36).map(|f| track.slerp(f as f32)).collect();
    let (e_spring, e_squad, e_slerp) = (curvature_energy(&samples), curvature_energy(&squad), curvature_energy(&slerp));
    assert!(e_spring < e_squad, "spring {e_spring} vs squad {e_squad}");
    assert!(e_squad < e_slerp, "squad {e_squad} vs slerp {e_slerp}");
    assert!(samples.iter().all(|q| (q.length() - 1.0).abs() < 1e-5));
}

#[test]
fn spring_rejects_keys_off_the_grid_and_bad_settings() {
    let (times, keys) = keys_on_a_zigzag();
    let off = SpringSettings { step: 4.0, ..SpringSettings::default() };
    assert!(matches!(spring(&times, &keys, &off), Err(TrackError::Times(_))));
    let bad = SpringSettings { levels: 0, ..SpringSettings::default() };
    assert!(matches!(spring(&times, &keys, &bad), Err(TrackError::Settings(_))));
    assert!(matches!(RotationTrack::new(&[0.0, 1.0], &[Quat::IDENTITY]), Err(TrackError::Shape(_))));
    assert!(matches!(RotationTrack::new(&[1.0, 0.0], &[Quat::IDENTITY; 2]), Err(TrackError::Times(_))));
    let zero = Quat::from_xyzw(0.0, 0.0, 0.0, 0.0);
    assert!(matches!(RotationTrack::new(&[0.0, 1.0], &[Quat::IDENTITY, zero]), Err(TrackError::Key(_))));
}

#[test]
fn cleanup_removes_every_sign_flip() {
    let mut keys: Vec<Quat> = (0..20).map(|i| Quat::from_rotation_y(0.3 * i as f32)).collect();
    for i in [3, 4, 9, 15] {
        keys[i] = -keys[i];
    }
    let times: Vec<f32> = (0..20).map(|i| i as f32).collect();
    let track = RotationTrack::new(&times, &keys).unwrap();
    assert_eq!(track.flipped, 4); // every negated key is flipped back, once
    assert!(track.keys().windows(2).all(|w| w[0].dot(w[1]) >= 0.0));
}

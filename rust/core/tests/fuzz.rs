//! Fuzzing the crate's public functions with arbitrary inputs (NaN, infinities, huge and tiny
//! numbers, inconsistent lengths and indices): every call returns a value or an error, never
//! panics and never hangs. `make test` fixes the seed (PROPTEST_RNG_SEED); a plain `cargo test`
//! draws new cases.

use dqskin_core::glam::{Mat4, Quat, Vec3};
use dqskin_core::shape_keys::{self, KeyBlock};
use dqskin_core::tracks::{self, RotationTrack, SpringSettings};
use dqskin_core::{
    armature_spaces, centers_of_rotation, centers_of_rotation_with_progress, deform_group_weights, dib, dlb,
    forward_kinematics, make_signs_continuous, sclerp, skin, skin_many, DeformGroups, DualQuat, Influences, ManyJob,
    Method, Pose, SkinOptions, Squad,
};
use proptest::prelude::*;

fn num() -> impl Strategy<Value = f32> {
    prop_oneof![
        6 => -10.0f32..10.0,
        1 => Just(f32::NAN),
        1 => Just(f32::INFINITY),
        1 => Just(-f32::INFINITY),
        1 => Just(f32::MAX),
        1 => Just(f32::MIN_POSITIVE),
        1 => Just(0.0f32),
        1 => Just(-0.0f32),
        1 => Just(1e30f32),
    ]
}

fn mat() -> impl Strategy<Value = Mat4> {
    prop_oneof![
        3 => (prop::array::uniform4(num()), prop::array::uniform3(-5.0f32..5.0)).prop_map(|(q, t)| {
            let q = Quat::from_xyzw(q[0], q[1], q[2], q[3]);
            Mat4::from_rotation_translation(if q.is_finite() && q.length() > 1e-3 { q.normalize() } else { Quat::IDENTITY }, Vec3::from(t))
        }),
        1 => prop::array::uniform16(num()).prop_map(|a| Mat4::from_cols_array(&a)),
        1 => (0.0f32..3.0).prop_map(|s| Mat4::from_scale(Vec3::new(s, 1.0, 0.5))),
    ]
}

fn dq() -> impl Strategy<Value = DualQuat> {
    prop::array::uniform8(num()).prop_map(DualQuat::from_array_wxyz)
}

fn quat() -> impl Strategy<Value = Quat> {
    prop::array::uniform4(num()).prop_map(|a| Quat::from_xyzw(a[0], a[1], a[2], a[3]))
}

fn csr() -> impl Strategy<Value = (Vec<u32>, Vec<u32>, Vec<f32>, usize)> {
    (0usize..12, 0usize..6).prop_flat_map(|(v, bones)| {
        (
            prop::collection::vec(0u32..8, v),
            prop::collection::vec(0u32..(bones as u32 + 2), 0..40),
            prop::collection::vec(num(), 0..40),
            Just(bones),
        )
            .prop_map(|(counts, b, w, bones)| {
                let mut offsets = vec![0u32];
                for c in counts {
                    offsets.push(offsets.last().unwrap() + c);
                }
                (offsets, b, w, bones)
            })
    })
}

proptest! {
    // 256 cases by default; PROPTEST_CASES=N for a long local run.
    #![proptest_config(ProptestConfig::default())]

    #[test]
    fn influences_and_skin_never_panic(
        (offsets, bones, weights, bone_count) in csr(),
        deform in prop::collection::vec(mat(), 0..6),
        rest in prop::collection::vec(mat(), 0..6),
        positions in prop::collection::vec(prop::array::uniform3(num()), 0..12),
        mask in prop::option::of(prop::collection::vec(num(), 0..12)),
        pre in prop::option::of(mat()),
        method in 0u8..4,
        factor in num(),
        centers in prop::collection::vec(prop::array::uniform3(num()), 0..12),
    ) {
        if let Ok(inf) = Influences::from_csr(&offsets, &bones, &weights, bone_count) {
            let with_rest = if rest.len() == deform.len() { Some(rest.as_slice()) } else { None };
            if let Ok(pose) = Pose::new(&deform, with_rest) {
                let mut out = vec![[9.0f32; 3]; positions.len()];
                let before = out.clone();
                let m = match method {
                    0 => Method::Linear,
                    1 => Method::DualQuaternion,
                    2 => Method::Blend { amount: mask.as_deref(), factor },
                    _ => Method::CentersOfRotation { centers: &centers },
                };
                let options = SkinOptions { premat: pre, postmat: pre.map(|p| p.inverse()), mask: mask.as_deref() };
                if skin(m, &positions, &inf, &pose, &options, &mut out).is_err() {
                    prop_assert_eq!(out, before);
                }
            }
            let mut out = vec![[0.0f32; 3]; positions.len()];
            let mut jobs = vec![ManyJob { method: Method::Linear, positions: &positions, influences: &inf, deform: &deform, rest: None, options: SkinOptions::default(), out: &mut out }];
            let _ = skin_many(&mut jobs);
        }
    }

    #[test]
    fn centers_of_rotation_never_panic(
        (offsets, bones, weights, bone_count) in csr(),
        positions in prop::collection::vec(prop::array::uniform3(num()), 0..12),
        triangles in prop::collection::vec(prop::array::uniform3(0u32..14), 0..20),
        sigma in num(),
        stop_after in 0usize..3,
    ) {
        if let Ok(inf) = Influences::from_csr(&offsets, &bones, &weights, bone_count) {
            if let Ok(c) = centers_of_rotation(&positions, &triangles, &inf, sigma) {
                prop_assert_eq!(c.centers.len(), positions.len());
                prop_assert!(c.centers.iter().zip(&c.has_center).all(|(p, h)| !h || p.iter().all(|x| x.is_finite())));
            }
            let mut calls = 0;
            let _ = centers_of_rotation_with_progress(&positions, &triangles, &inf, sigma, &mut |_, _| {
                calls += 1;
                calls <= stop_after
            });
        }
    }

    #[test]
    fn groups_and_shape_keys_never_panic(
        (offsets, groups, weights, bone_count) in csr(),
        map in prop::collection::vec(prop::option::of(0u32..6), 0..8),
        group in 0u32..10,
        keys in prop::collection::vec((prop::collection::vec(prop::array::uniform3(num()), 0..5), 0usize..5, num(), any::<bool>(), prop::option::of(prop::collection::vec(num(), 0..5))), 0..5),
        reference in 0usize..6,
        shown in 0usize..6,
        n in 0usize..5,
    ) {
        let dg = DeformGroups { offsets: &offsets, groups: &groups, weights: &weights };
        let _ = Influences::from_deform_groups(dg, &map, bone_count);
        let _ = deform_group_weights(dg, group);
        let blocks: Vec<KeyBlock<'_>> = keys.iter().map(|(d, r, v, m, w)| KeyBlock { data: d, relative_to: *r, value: *v, muted: *m, weights: w.as_deref() }).collect();
        let mut out = vec![[0.0f32; 3]; n];
        let _ = shape_keys::mix_relative(&blocks, reference, &mut out);
        let _ = shape_keys::mix_locked(&blocks, reference, shown, &mut out);
    }

    #[test]
    fn blending_and_dual_quaternions_never_panic(
        qs in prop::collection::vec(dq(), 0..5),
        ws in prop::collection::vec(num(), 0..5),
        t in num(),
        precision in num(),
        iterations in 0u32..50,
        m in mat(),
        a in mat(),
    ) {
        let _ = dlb(&qs, &ws);
        let _ = dib(&qs, &ws, precision, iterations);
        for q in &qs {
            let _ = (q.log(), q.exp(), q.powf(t), q.to_screw(), q.inverse(), q.try_normalize(), q.shortest(), q.to_mat4());
            let _ = DualQuat::try_from_mat4(&m, 1e-5);
            if let Some(p) = qs.first() {
                let _ = sclerp(p, q, t);
            }
        }
        let _ = armature_spaces(m, a);
        let _ = Pose::new(&[m], Some(&[a]));
    }

    #[test]
    fn tracks_and_hierarchies_never_panic(
        times in prop::collection::vec(num(), 0..6),
        keys in prop::collection::vec(quat(), 0..6),
        dqs in prop::collection::vec(dq(), 0..6),
        at in num(),
        step in num(),
        parents in prop::collection::vec(-2i64..7, 0..6),
    ) {
        if let Ok(track) = RotationTrack::new(&times, &keys) {
            let _ = (track.slerp(at), track.squad(at));
        }
        let _ = tracks::screw_track(&times, &dqs, at);
        let settings = SpringSettings { step, levels: 2, iterations: 3, key_weight: 1.2 };
        let _ = tracks::spring(&times, &keys, &settings);
        let _ = tracks::angular_speeds(&keys);
        let _ = tracks::curvature_energy(&keys);
        let mut k = keys.clone();
        let _ = make_signs_continuous(&mut k);
        if !keys.is_empty() && keys.iter().all(|q| q.is_finite() && q.length_squared() > 0.0) {
            let _ = Squad::new(&keys).evaluate(at);
        }
        let _ = forward_kinematics(&parents, &dqs);
    }
}

use glam::{DVec3, Mat4, Vec3};
use proptest::prelude::*;

use super::*;
use crate::Influences;

fn straight(first: u32, segments: u32, length: f32) -> BBone<'static> {
    BBone { first, segments, inverse_rest: Mat4::IDENTITY, length, mapping: Mapping::Straight }
}

#[test]
fn straight_mapping_follows_blender() {
    let bb = straight(5, 4, 2.0);
    assert_eq!(bb.straight_segment(Vec3::new(0.0, -1.0, 0.0)), (0, 0.0));
    assert_eq!(bb.straight_segment(Vec3::new(0.0, 0.75, 0.0)), (1, 0.5));
    assert_eq!(bb.straight_segment(Vec3::new(0.3, 2.0, 9.0)), (3, 1.0));
    assert_eq!(bb.straight_segment(Vec3::new(0.0, 5.0, 0.0)), (3, 1.0));
    // The rest matrix's inverse decides "along the bone".
    let moved = BBone { inverse_rest: Mat4::from_translation(Vec3::new(0.0, -1.0, 0.0)), ..bb };
    assert_eq!(moved.straight_segment(Vec3::new(0.0, 1.75, 0.0)), (1, 0.5));
}

#[test]
fn b_bone_influences_split_over_two_joints() {
    let groups = Influences::from_lists(&[vec![(0, 0.6), (1, 0.4)]], 2).unwrap();
    let bbones = [None, Some(straight(2, 3, 3.0))];
    let what = crate::Effective {
        envelopes: None,
        use_vertex_groups: true,
        use_envelopes: false,
        bbones: &bbones,
        expanded_bone_count: 6,
    };
    let e = groups.effective(&[[0.0, 1.25, 0.0]], None, &what).unwrap();
    let got: Vec<(u32, f32)> = e.of_vertex(0).map(|i| (i.bone, i.weight)).collect();
    assert_eq!(got, vec![(0, 0.6), (3, 0.4 * 0.75), (4, 0.4 * 0.25)]);
    assert_eq!(e.bone_count(), 6);
    let bad = [None, Some(straight(4, 3, 3.0))];
    let what_bad = crate::Effective { bbones: &bad, ..what };
    assert!(groups.effective(&[[0.0; 3]], None, &what_bad).is_err());
    // A mapping computed elsewhere wins where given; a negative index falls back to Straight.
    for (index, expected) in
        [(2i32, vec![(0, 0.6), (4, 0.4 * 0.5), (5, 0.4 * 0.5)]), (-1, vec![(0, 0.6), (3, 0.4 * 0.75), (4, 0.4 * 0.25)])]
    {
        let (index, blend) = ([index], [0.5f32]);
        let mapped =
            [None, Some(BBone { mapping: Mapping::Given { index: &index, blend: &blend }, ..straight(2, 3, 3.0) })];
        let what = crate::Effective { bbones: &mapped, ..what };
        let e = groups.effective(&[[0.0, 1.25, 0.0]], None, &what).unwrap();
        let got: Vec<(u32, f32)> = e.of_vertex(0).map(|i| (i.bone, i.weight)).collect();
        assert_eq!(got, expected);
    }
}

#[test]
fn joints_follow_the_bones_in_order() {
    assert_eq!(bbone_joint_starts(&[1, 4, 0, 2, 1]), (vec![None, Some(5), None, Some(10), None], 13));
    assert_eq!(bbone_joint_starts(&[]), (vec![], 0));
    let rest = [Mat4::IDENTITY, Mat4::from_translation(Vec3::Y)];
    let (index, blend) = ([0i32], [0.0f32]);
    let (bbones, expanded) = bbones_from_rest(&[3, 2], &rest, &[1.0, 2.0], &[(1, &index, &blend)]);
    assert_eq!(expanded, 2 + 4 + 3);
    assert_eq!(bbones[0].unwrap().mapping, Mapping::Straight);
    let second = bbones[1].unwrap();
    assert_eq!((second.first, second.segments, second.length), (6, 2, 2.0));
    assert!(second.inverse_rest.abs_diff_eq(Mat4::from_translation(-Vec3::Y), 1e-7));
    assert!(matches!(second.mapping, Mapping::Given { .. }));
}

#[test]
fn segment_matrices_match_blenders_formula() {
    let channel = Mat4::from_rotation_z(0.4);
    let rest = Mat4::from_translation(Vec3::new(0.0, 1.0, 0.0)) * Mat4::from_rotation_x(0.3);
    let pose = [Mat4::IDENTITY, Mat4::from_translation(Vec3::Y) * Mat4::from_rotation_z(0.2)];
    let rest_joints = [Mat4::IDENTITY, Mat4::from_translation(Vec3::Y) * Mat4::from_scale(Vec3::new(2.0, 1.0, 0.5))];
    let m = bbone_segment_matrices(channel, rest, &pose, &rest_joints);
    assert!(m[0].0.abs_diff_eq(channel, 1e-6));
    // The rest basis is rest·R with unit axes.
    let basis = m[1].1;
    for axis in [basis.x_axis, basis.y_axis, basis.z_axis] {
        assert!((axis.truncate().length() - 1.0).abs() < 1e-6);
    }
    assert!(basis.x_axis.truncate().abs_diff_eq((rest * rest_joints[1]).x_axis.truncate() / 2.0, 1e-6));
    assert_eq!(basis.w_axis, (rest * rest_joints[1]).w_axis);
    assert_eq!(normalize_axes(Mat4::ZERO), Mat4::ZERO);
}

// -- the Curved mapping ----------------------------------------------------------------------

/// A B-Bone's rest joints along a cubic Bézier (points and unit tangents), in armature space.
fn bezier_joints(controls: [DVec3; 4], segments: usize) -> Vec<(DVec3, DVec3)> {
    let [p0, p1, p2, p3] = controls;
    (0..=segments)
        .map(|i| {
            let t = i as f64 / segments as f64;
            let u = 1.0 - t;
            let point = p0 * (u * u * u) + p1 * (3.0 * u * u * t) + p2 * (3.0 * u * t * t) + p3 * (t * t * t);
            let tangent = (p1 - p0) * (3.0 * u * u) + (p2 - p1) * (6.0 * u * t) + (p3 - p2) * (3.0 * t * t);
            (point, tangent.normalize())
        })
        .collect()
}

/// Blender's `compute_bbone_segment_boundaries` in double precision, rounded to single at the end.
fn boundaries_of(joints: &[(DVec3, DVec3)]) -> (Vec<SegmentBoundary>, f32) {
    let segments = joints.len() - 1;
    let arc: f64 = joints.windows(2).map(|w| w[0].0.distance(w[1].0)).sum();
    let bsp_depth = ((segments + 2) as f64).log2().ceil() as usize;
    assert_eq!(bsp_depth, super::bsp_depth(segments as u32));
    let straight_length = joints[0].0.distance(joints[segments].0);
    let max_depth_scale = segments as f64 * (straight_length / arc) * 0.222;
    let scale_factor = max_depth_scale.max(1.0).powf(1.0 / (bsp_depth as f64 - 1.0));
    let mut depth_scale = vec![0.0; segments + 1];
    depth_scale[0] = segments as f64 / max_depth_scale;
    for i in 1..bsp_depth {
        depth_scale[i] = depth_scale[i - 1] * scale_factor;
    }
    let boundaries = joints
        .iter()
        .zip(&depth_scale)
        .map(|((p, n), &d)| SegmentBoundary {
            point: p.as_vec3(),
            normal: n.as_vec3(),
            offset: p.dot(*n) as f32,
            depth_scale: d as f32,
        })
        .collect();
    (boundaries, (1.0 / arc) as f32)
}

/// The Curved mapping written plainly in double precision: binary search with a stack of visited
/// planes, interpolation inside the segment found, then smoothing up the stack. Returns the
/// head-to-tail position before it is split into index and blend.
fn reference_head_tail(boundaries: &[SegmentBoundary], arc_length_reciprocal: f32, co: Vec3) -> f64 {
    let n = boundaries.len() as i64 - 1;
    let co = co.as_dvec3();
    let distance = |i: i64| {
        let b = &boundaries[i as usize];
        co.dot(b.normal.as_dvec3()) - b.offset as f64
    };
    let mut visited: Vec<(i64, f64)> = Vec::new();
    let (mut lo, mut hi, mut lean) = (-1i64, n + 1, 0);
    while hi - lo > 1 {
        let mid = (lo + hi + lean) / 2;
        let d = distance(mid);
        visited.push((mid, d));
        if d < 0.0 {
            (hi, lean) = (mid, 1);
        } else {
            (lo, lean) = (mid, 0);
        }
    }
    let size = 1.0 / n as f64;
    let dist_of = |i: i64| visited.iter().find(|v| v.0 == i).unwrap().1;
    let mut pos = if hi <= 0 {
        0.0
    } else if lo >= n {
        1.0
    } else {
        let (a, b) = (dist_of(lo).abs(), dist_of(hi).abs());
        size * (lo as f64 + a / (a + b))
    };
    for (depth, &(plane, d)) in visited.iter().enumerate().rev() {
        let at = plane as f64 * size;
        let ideal = d * arc_length_reciprocal as f64;
        let gap = (pos - at).abs() - ideal.abs();
        let near = 1.0 - ideal.abs() * boundaries[depth].depth_scale as f64;
        if gap <= 0.0 || near <= 0.0 {
            continue;
        }
        let slope = 3.0 * gap / (3.0 * gap + ideal.abs());
        let smooth = near * near * 8.0 / (7.0 * near + 1.0);
        let f = slope * smooth;
        pos = f * (at + ideal) + (1.0 - f) * pos;
    }
    pos
}

fn head_tail_of((index, blend): (u32, f32), segments: u32) -> f64 {
    (index as f64 + blend as f64) / segments as f64
}

fn curved_bone(bend: f64) -> [DVec3; 4] {
    [DVec3::ZERO, DVec3::new(bend, 0.7, 0.0), DVec3::new(-0.5 * bend, 1.4, 0.3 * bend), DVec3::new(0.2, 2.0, 0.1)]
}

proptest! {
    #[test]
    fn curved_mapping_matches_a_plain_reference(
        segments in 2usize..=32,
        bend in -1.5f64..1.5,
        x in -1.5f32..1.5, y in -0.8f32..2.8, z in -1.0f32..1.0,
    ) {
        let (boundaries, reciprocal) = boundaries_of(&bezier_joints(curved_bone(bend), segments));
        let co = Vec3::new(x, y, z);
        let got = head_tail_of(curved_segment(&boundaries, reciprocal, co), segments as u32);
        let want = reference_head_tail(&boundaries, reciprocal, co).clamp(0.0, 1.0);
        prop_assert!((got - want).abs() < 2e-5, "{got} vs {want}");
    }

    #[test]
    fn curved_mapping_of_a_straight_bone_is_the_straight_mapping(
        segments in 2u32..=32,
        x in -0.5f32..0.5, y in -0.5f32..2.5, z in -0.5f32..0.5,
    ) {
        let joints = bezier_joints([DVec3::ZERO, DVec3::new(0.0, 2.0 / 3.0, 0.0), DVec3::new(0.0, 4.0 / 3.0, 0.0), DVec3::new(0.0, 2.0, 0.0)], segments as usize);
        let (boundaries, reciprocal) = boundaries_of(&joints);
        let co = Vec3::new(x, y, z);
        let curved = head_tail_of(curved_segment(&boundaries, reciprocal, co), segments);
        let straight = head_tail_of(straight(0, segments, 2.0).straight_segment(co), segments);
        prop_assert!((curved - straight).abs() < 1e-5, "{curved} vs {straight}");
    }
}

#[test]
fn curved_mapping_runs_along_the_curve() {
    let segments = 8;
    let joints = bezier_joints(curved_bone(1.2), segments);
    let (boundaries, reciprocal) = boundaries_of(&joints);
    // The joints themselves map close to their own positions (the smoothing moves them a
    // little), the ends past them to 0 and 1.
    for (i, (p, _)) in joints.iter().enumerate() {
        let got = head_tail_of(curved_segment(&boundaries, reciprocal, p.as_vec3()), segments as u32);
        assert!((got - i as f64 / segments as f64).abs() < 0.1 / segments as f64, "joint {i}: {got}");
    }
    let before = joints[0].0 - joints[0].1;
    let after = joints[segments].0 + joints[segments].1;
    assert_eq!(curved_segment(&boundaries, reciprocal, before.as_vec3()), (0, 0.0));
    assert_eq!(curved_segment(&boundaries, reciprocal, after.as_vec3()), (segments as u32 - 1, 1.0));
    // Points along the curve map monotonically.
    let curve = bezier_joints(curved_bone(1.2), 200);
    let mapped: Vec<f64> = curve
        .iter()
        .map(|(p, _)| head_tail_of(curved_segment(&boundaries, reciprocal, p.as_vec3()), segments as u32))
        .collect();
    assert!(mapped.windows(2).all(|w| w[1] >= w[0] - 1e-6), "{mapped:?}");
    // Off the curve it differs from the straight mapping: the planes follow the curve.
    let straight_bone = straight(0, segments as u32, 2.0);
    let differs = curve.iter().any(|(p, _)| {
        let off = (*p + DVec3::new(0.4, 0.0, 0.0)).as_vec3();
        let c = head_tail_of(curved_segment(&boundaries, reciprocal, off), segments as u32);
        (c - head_tail_of(straight_bone.straight_segment(off), segments as u32)).abs() > 0.02
    });
    assert!(differs);
}

#[test]
fn bad_b_bones_are_refused_with_a_reason() {
    let (boundaries, reciprocal) = boundaries_of(&bezier_joints(curved_bone(0.5), 4));
    let good = BBone {
        mapping: Mapping::Curved { boundaries: &boundaries, arc_length_reciprocal: reciprocal },
        ..straight(1, 4, 2.0)
    };
    assert_eq!(good.problem(3, 6), None);
    let short =
        BBone { mapping: Mapping::Curved { boundaries: &boundaries[..4], arc_length_reciprocal: reciprocal }, ..good };
    assert!(short.problem(3, 6).unwrap().contains("one finite boundary per joint"));
    // Blender leaves the depth scales past the search depth uninitialized: they are not read.
    let mut padding = boundaries.clone();
    assert_eq!(bsp_depth(4), 3);
    padding[3].depth_scale = f32::NAN;
    padding[4].depth_scale = f32::INFINITY;
    assert_eq!(
        BBone { mapping: Mapping::Curved { boundaries: &padding, arc_length_reciprocal: reciprocal }, ..good }
            .problem(3, 6),
        None
    );
    padding[2].depth_scale = f32::NAN;
    assert!(BBone { mapping: Mapping::Curved { boundaries: &padding, arc_length_reciprocal: reciprocal }, ..good }
        .problem(3, 6)
        .is_some());
    let mut nan = boundaries.clone();
    nan[2].normal.x = f32::NAN;
    let nan = BBone { mapping: Mapping::Curved { boundaries: &nan, arc_length_reciprocal: reciprocal }, ..good };
    assert!(nan.problem(3, 6).is_some());
    assert!(BBone { first: 2, ..good }.problem(3, 6).is_some(), "joints past the expanded list");
    assert!(BBone { length: 0.0, ..good }.problem(3, 6).is_some());
    assert!(BBone { segments: 1, ..good }.problem(3, 6).is_some());
    let (index, blend) = ([0i32; 2], [0.0f32; 2]);
    assert!(BBone { mapping: Mapping::Given { index: &index, blend: &blend }, ..good }.problem(3, 6).is_some());
}

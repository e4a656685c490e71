use glam::{Mat4, Quat, Vec3};

use super::*;

fn envelope(head: Vec3, tail: Vec3) -> Envelope {
    Envelope { head, tail, head_radius: 0.1, tail_radius: 0.2, distance: 0.3, weight: 1.0, multiply_groups: false }
}

/// A plain bone along +Y from `head`, rotated by `angle` about Z in the pose.
fn plain(name: &str, head: Vec3, angle: f32) -> PoseChannel {
    let rest = Mat4::from_translation(head);
    PoseChannel {
        name: name.into(),
        deform: true,
        channel: Mat4::from_rotation_translation(Quat::from_rotation_z(angle), Vec3::ZERO),
        rest,
        length: 1.0,
        envelope: envelope(head, head + Vec3::Y),
        segments: 1,
        curved: false,
        bbone: None,
    }
}

/// `plain` as a B-Bone of `segments` segments, with a cache whose joints are spaced along Y.
fn bbone(name: &str, head: Vec3, segments: u32, curved: bool) -> PoseChannel {
    let mut c = plain(name, head, 0.3);
    let joints = segments as usize + 1;
    let rest_joints: Vec<Mat4> = (0..joints)
        .map(|a| {
            Mat4::from_translation(Vec3::new(0.0, a as f32 / segments as f32, 0.0))
                * Mat4::from_scale(Vec3::new(1.5, 1.0, 0.5))
        })
        .collect();
    let deform: Vec<Mat4> = (0..joints).map(|a| Mat4::from_rotation_x(0.1 * a as f32)).collect();
    let boundaries = if curved {
        (0..joints)
            .map(|a| {
                let point = head + Vec3::new(0.0, a as f32 / segments as f32, 0.0);
                SegmentBoundary { point, normal: Vec3::Y, offset: point.y, depth_scale: 1.0 }
            })
            .collect()
    } else {
        Vec::new()
    };
    c.segments = segments;
    c.curved = curved;
    c.bbone = Some(BBoneCache {
        inverse_rest: c.rest.inverse(),
        deform,
        rest_joints,
        boundaries,
        arc_length_reciprocal: 1.0,
    });
    c
}

fn sample_channels() -> Vec<PoseChannel> {
    let mut hidden = plain("Helper", Vec3::ZERO, 0.0);
    hidden.deform = false;
    vec![
        plain("Root", Vec3::ZERO, 0.2),
        hidden,
        bbone("Spine", Vec3::Y, 3, false),
        bbone("Neck", 2.0 * Vec3::Y, 2, true),
    ]
}

fn sample() -> ArmaturePose {
    ArmaturePose::new(sample_channels()).unwrap()
}

#[test]
fn the_bones_alone_with_every_channels_flag_make_the_same_pose() {
    let channels = sample_channels();
    let deforms: Vec<bool> = channels.iter().map(|c| c.deform).collect();
    let bones: Vec<PoseChannel> = channels.iter().filter(|c| c.deform).cloned().collect();
    let (whole, parts) = (sample(), ArmaturePose::from_bones(deforms.clone(), bones.clone()).unwrap());
    assert_eq!(parts.deform_flags(), &[true, false, true, true]);
    assert_eq!(parts.bone_indices(), whole.bone_indices());
    assert_eq!(parts.binding_signature(), whole.binding_signature());
    assert_eq!(parts.pose_signature(), whole.pose_signature());
    assert_eq!(parts.deform_matrices(), whole.deform_matrices());
    // Flags and bones that disagree are refused.
    assert!(ArmaturePose::from_bones(deforms[..3].to_vec(), bones.clone()).is_err());
    assert!(ArmaturePose::from_bones(vec![true, false, false, true], bones.clone()).is_err());
    let mut not_deforming = bones;
    not_deforming[0].deform = false;
    assert!(ArmaturePose::from_bones(deforms, not_deforming).is_err());
}

#[test]
fn bones_are_the_deforming_channels_and_joints_follow_them() {
    let pose = sample();
    let channels = sample_channels();
    assert_eq!(pose.bone_indices(), &[0, 2, 3]);
    assert_eq!(pose.bone_count(), 3);
    assert_eq!(pose.segments(), vec![1, 3, 2]);
    assert_eq!(pose.expanded_bone_count(), 3 + 4 + 3);
    let deform = pose.deform_matrices();
    assert_eq!(deform.len(), 10);
    assert_eq!(deform[0], channels[0].channel);
    assert_eq!(deform[2], channels[3].channel);
    let spine = channels[2].bbone.as_ref().unwrap();
    assert_eq!(&deform[3..7], &spine.deform[..]);
    assert_eq!(&deform[7..10], &channels[3].bbone.as_ref().unwrap().deform[..]);
    let rest = pose.rest_matrices();
    assert_eq!(rest.len(), 10);
    assert_eq!(rest[1], channels[2].rest);
    // A joint's rest basis: the bone's rest times the joint's, with unit axes.
    let want = channels[2].rest * spine.rest_joints[1];
    assert!(rest[4].x_axis.abs_diff_eq(want.x_axis / 1.5, 1e-6));
    assert!(rest[4].z_axis.abs_diff_eq(want.z_axis / 0.5, 1e-6));
    assert_eq!(rest[4].w_axis, want.w_axis);
    let bbones = pose.bbones();
    assert!(bbones[0].is_none());
    let (s, n) = (bbones[1].unwrap(), bbones[2].unwrap());
    assert_eq!((s.first, s.segments, s.mapping), (3, 3, Mapping::Straight));
    assert_eq!((n.first, n.segments), (7, 2));
    assert!(matches!(n.mapping, Mapping::Curved { boundaries, .. } if boundaries.len() == 3));
}

#[test]
fn effective_influences_use_the_pose_bones() {
    let pose = sample();
    // Vertex 0 on the Spine B-Bone halfway along its second segment; vertex 1 on Root; vertex 2
    // has no group and lies in the Root envelope; vertex 3 on the Curved Neck at 3/4.
    let groups = Influences::from_lists(&[vec![(1, 1.0)], vec![(0, 0.5)], vec![], vec![(2, 1.0)]], 3).unwrap();
    let positions = [[0.0, 1.5, 0.0], [0.0, 0.5, 0.0], [0.05, 0.5, 0.0], [0.0, 2.75, 0.0]];
    let e = pose.effective(&groups, &positions, None, true, true).unwrap();
    assert_eq!(e.bone_count(), 10);
    let pairs = |v: usize| -> Vec<(u32, f32)> { e.of_vertex(v).map(|i| (i.bone, i.weight)).collect() };
    let (index, blend) = pose.bbones()[1].unwrap().straight_segment(Vec3::new(0.0, 1.5, 0.0));
    assert_eq!((index, blend), (1, 0.5));
    assert_eq!(pairs(0), vec![(4, 0.5), (5, 0.5)]);
    assert_eq!(pairs(1), vec![(0, 0.5)]);
    assert_eq!(pairs(2), vec![(0, 1.0)]);
    let p3 = pairs(3);
    assert_eq!((p3[0].0, p3[1].0), (8, 9));
    assert!((p3[1].1 - 0.5).abs() < 1e-5, "{p3:?}");
    // Without envelopes vertex 2 has nothing; the bone counts must agree.
    assert!(pose.effective(&groups, &positions, None, true, false).unwrap().of_vertex(2).len() == 0);
    let wrong = Influences::from_lists(&[vec![]], 4).unwrap();
    assert!(matches!(pose.effective(&wrong, &[[0.0; 3]], None, true, true), Err(SkinError::LengthMismatch { .. })));
}

#[test]
fn signatures_follow_what_they_cover() {
    let base = sample();
    let binding = base.binding_signature();
    let posed = base.pose_signature();
    assert_eq!(sample().binding_signature(), binding);
    assert_eq!(sample().pose_signature(), posed);
    let with = |f: &dyn Fn(&mut Vec<PoseChannel>)| {
        let mut channels = sample_channels();
        f(&mut channels);
        let p = ArmaturePose::new(channels).unwrap();
        (p.binding_signature() != binding, p.pose_signature() != posed)
    };
    // The pose: the channel matrices and the joints' deform matrices, and nothing else.
    assert_eq!(with(&|c| c[0].channel.w_axis.x += 1e-6), (false, true));
    assert_eq!(with(&|c| c[2].bbone.as_mut().unwrap().deform[2].x_axis.y = 0.25), (false, true));
    assert_eq!(with(&|c| c[1].channel = Mat4::from_rotation_y(1.0)), (false, false), "not a deforming bone");
    // The binding: the deforming bones' names, the order, the flags and the rest data.
    assert_eq!(with(&|c| c[0].name = "Root.001".into()), (true, false));
    assert_eq!(with(&|c| c[1].name = "Other".into()), (false, false), "not a deforming bone");
    assert!(with(&|c| c.swap(0, 2)).0);
    assert!(with(&|c| c[1].deform = true).0);
    assert_eq!(with(&|c| c[0].rest.w_axis.z = 0.5), (true, false));
    assert_eq!(with(&|c| c[0].length = 2.0), (true, false));
    assert_eq!(with(&|c| c[0].envelope.tail_radius = 0.5), (true, false));
    assert_eq!(with(&|c| c[0].envelope.multiply_groups = true), (true, false));
    assert_eq!(with(&|c| c[2].curved = true), (true, false));
    assert_eq!(with(&|c| c[2].bbone.as_mut().unwrap().rest_joints[1].w_axis.y = 0.4), (true, false));
    assert_eq!(with(&|c| c[3].bbone.as_mut().unwrap().boundaries[1].depth_scale = 2.0), (true, false));
    assert_eq!(with(&|c| c[3].bbone.as_mut().unwrap().arc_length_reciprocal = 0.5), (true, false));
    // A B-Bone whose cache lags behind its segment count deforms as a plain bone.
    let lagging = with(&|c| {
        c[2].segments = 5;
        c[2].bbone = None;
    });
    assert!(lagging.0);
}

#[test]
fn inconsistent_channels_are_refused() {
    let mut channels = sample_channels();
    channels[2].bbone.as_mut().unwrap().deform.pop();
    let e = ArmaturePose::new(channels).unwrap_err().to_string();
    assert!(e.contains("pose channel 2 (Spine)") && e.contains("needs 4 joints"), "{e}");
    let mut channels = sample_channels();
    channels[3].bbone.as_mut().unwrap().boundaries.pop();
    assert!(ArmaturePose::new(channels).unwrap_err().to_string().contains("boundaries"));
    let mut channels = sample_channels();
    channels[0].channel.x_axis.x = f32::NAN;
    assert!(ArmaturePose::new(channels).unwrap_err().to_string().contains("NaN"));
    let mut channels = sample_channels();
    channels[2].bbone.as_mut().unwrap().rest_joints[0].w_axis.x = f32::INFINITY;
    assert!(ArmaturePose::new(channels).is_err());
    let mut channels = sample_channels();
    channels[2].segments = 1;
    assert!(ArmaturePose::new(channels).is_err());
}

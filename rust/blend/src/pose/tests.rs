use super::*;
use crate::test_dna::Dna;

/// An SDNA with the structs the reader needs, in the shape Blender's have (other fields left
/// out or folded into padding); `by_name`: as from Blender 5.2, without `bPoseChannel.bone`.
fn pose_sdna(by_name: bool) -> Sdna {
    let mut dna = Dna::new();
    dna.opaque("Mat4", 0);
    dna.strukt("ListBase", &[("void", "*first"), ("void", "*last")]);
    dna.strukt(
        "Object",
        &[("char", "_pad0[8]"), ("short", "type"), ("char", "_pad1[6]"), ("bPose", "*pose"), ("ID", "*data")],
    );
    dna.strukt("bArmature", &[("char", "_pad[8]"), ("ListBase", "bonebase")]);
    dna.strukt(
        "bPoseChannel_BBoneSegmentBoundary",
        &[("float", "point[3]"), ("float", "plane_normal[3]"), ("float", "plane_offset"), ("float", "depth_scale")],
    );
    dna.strukt(
        "bPoseChannel_Runtime",
        &[
            ("int", "bbone_segments"),
            ("float", "bbone_arc_length_reciprocal"),
            ("Mat4", "*bbone_rest_mats"),
            ("Mat4", "*bbone_pose_mats"),
            ("Mat4", "*bbone_deform_mats"),
            ("bPoseChannel_BBoneSegmentBoundary", "*bbone_segment_boundaries"),
        ],
    );
    let bone = if by_name { "*_bone_index_elsewhere" } else { "*bone" };
    dna.strukt(
        "bPoseChannel",
        &[
            ("void", "*next"),
            ("void", "*prev"),
            ("char", "name[64]"),
            ("Bone", bone),
            ("float", "chan_mat[4][4]"),
            ("bPoseChannel_Runtime", "runtime"),
        ],
    );
    dna.strukt(
        "Bone",
        &[
            ("Bone", "*next"),
            ("ListBase", "childbase"),
            ("char", "name[64]"),
            ("int", "flag"),
            ("float", "arm_head[3]"),
            ("float", "arm_tail[3]"),
            ("float", "arm_mat[4][4]"),
            ("float", "dist"),
            ("float", "weight"),
            ("float", "length"),
            ("float", "rad_head"),
            ("float", "rad_tail"),
            ("short", "segments"),
            ("char", "bbone_mapping_mode"),
            ("char", "_pad[1]"),
            ("char", "_pad2[4]"),
        ],
    );
    dna.strukt("bPose", &[("char", "_pad[8]"), ("ListBase", "chanbase")]);
    Sdna::parse(&dna.bytes()).unwrap()
}

#[repr(C)]
struct FakeObject {
    pad0: [u8; 8],
    ty: i16,
    pad1: [u8; 6],
    pose: *const FakePose,
    data: *const FakeArmature,
}
#[repr(C)]
struct FakeArmature {
    pad: [u8; 8],
    first: *const FakeBone,
    last: *const FakeBone,
}
#[repr(C)]
struct FakePose {
    pad: [u8; 8],
    first: *const FakeChannel,
    last: *const FakeChannel,
}
#[repr(C)]
#[derive(Clone, Copy)]
struct FakeBoundary {
    point: [f32; 3],
    normal: [f32; 3],
    offset: f32,
    depth_scale: f32,
}
#[repr(C)]
struct FakeRuntime {
    segments: i32,
    arc_length_reciprocal: f32,
    rest: *const [f32; 16],
    pose: *const [f32; 16],
    deform: *const [f32; 16],
    boundaries: *const FakeBoundary,
}
#[repr(C)]
struct FakeChannel {
    next: *const FakeChannel,
    prev: *const FakeChannel,
    name: [u8; 64],
    bone: *const FakeBone,
    chan_mat: [f32; 16],
    runtime: FakeRuntime,
}
#[repr(C)]
struct FakeBone {
    next: *const FakeBone,
    child_first: *const FakeBone,
    child_last: *const FakeBone,
    name: [u8; 64],
    flag: i32,
    head: [f32; 3],
    tail: [f32; 3],
    arm_mat: [f32; 16],
    dist: f32,
    weight: f32,
    length: f32,
    rad_head: f32,
    rad_tail: f32,
    segments: i16,
    mapping: u8,
    pad: [u8; 5],
}

fn name(s: &str) -> [u8; 64] {
    let mut n = [0u8; 64];
    n[..s.len()].copy_from_slice(s.as_bytes());
    n
}

fn matrix(seed: f32) -> [f32; 16] {
    core::array::from_fn(|i| seed + i as f32)
}

fn bone(n: &str, flag: i32, segments: i16, mapping: u8) -> FakeBone {
    FakeBone {
        next: core::ptr::null(),
        child_first: core::ptr::null(),
        child_last: core::ptr::null(),
        name: name(n),
        flag,
        head: [1.0, 2.0, 3.0],
        tail: [1.0, 4.0, 3.0],
        arm_mat: matrix(100.0),
        dist: 0.25,
        weight: 0.75,
        length: 2.0,
        rad_head: 0.1,
        rad_tail: 0.05,
        segments,
        mapping,
        pad: [0; 5],
    }
}

fn channel(n: &str, bone: &FakeBone, seed: f32) -> FakeChannel {
    FakeChannel {
        next: core::ptr::null(),
        prev: core::ptr::null(),
        name: name(n),
        bone,
        chan_mat: matrix(seed),
        runtime: FakeRuntime {
            segments: 0,
            arc_length_reciprocal: 0.0,
            rest: core::ptr::null(),
            pose: core::ptr::null(),
            deform: core::ptr::null(),
            boundaries: core::ptr::null(),
        },
    }
}

/// A two-channel pose: `Root` (plain, no deform, multiplies its groups) and `Spine` (its child, a
/// 3-segment Curved B-Bone with its cache). Everything the pointers lead to is in the returned box.
struct Fixture {
    object: FakeObject,
    _pose: Box<FakePose>,
    armature: Box<FakeArmature>,
    channels: Vec<FakeChannel>,
    bones: Vec<FakeBone>,
    rest: Vec<[f32; 16]>,
    deform: Vec<[f32; 16]>,
    boundaries: Vec<FakeBoundary>,
}

fn fixture() -> Box<Fixture> {
    let mut f = Box::new(Fixture {
        object: FakeObject {
            pad0: [0; 8],
            ty: OB_ARMATURE,
            pad1: [0; 6],
            pose: core::ptr::null(),
            data: core::ptr::null(),
        },
        _pose: Box::new(FakePose { pad: [0; 8], first: core::ptr::null(), last: core::ptr::null() }),
        armature: Box::new(FakeArmature { pad: [0; 8], first: core::ptr::null(), last: core::ptr::null() }),
        channels: Vec::new(),
        bones: vec![bone("Root", BONE_NO_DEFORM | BONE_MULT_VG_ENV, 1, 0), bone("Spine", 0, 3, BBONE_MAPPING_CURVED)],
        rest: (0..4).map(|i| matrix(10.0 * i as f32)).collect(),
        deform: (0..5).map(|i| matrix(-10.0 * i as f32)).collect(),
        // Blender initializes depth_scale down to the search depth only (3 for 3 segments).
        boundaries: (0..4)
            .map(|i| FakeBoundary {
                point: [0.0, i as f32, 0.0],
                normal: [0.0, 1.0, 0.0],
                offset: i as f32,
                depth_scale: if i < 3 { 0.5 } else { f32::NAN },
            })
            .collect(),
    });
    f.channels = vec![channel("Root", &f.bones[0], 1.0), channel("Spine", &f.bones[1], 2.0)];
    let next: *const FakeChannel = &f.channels[1];
    f.channels[0].next = next;
    let rt = &mut f.channels[1].runtime;
    rt.segments = 3;
    rt.arc_length_reciprocal = 1.0 / 3.0;
    rt.rest = f.rest.as_ptr();
    rt.deform = f.deform.as_ptr();
    rt.boundaries = f.boundaries.as_ptr();
    f._pose.first = &f.channels[0];
    f._pose.last = &f.channels[1];
    f.object.pose = &*f._pose;
    // The bone tree: Root with its child Spine.
    let spine: *const FakeBone = &f.bones[1];
    f.bones[0].child_first = spine;
    f.bones[0].child_last = spine;
    f.armature.first = &f.bones[0];
    f.armature.last = &f.bones[0];
    f.object.data = &*f.armature;
    f
}

/// Reads `f` three times: without hints, with those of that read, and with those of a read of
/// another fixture since freed (stale addresses): the hints never change what is read.
fn read_with(f: &Fixture, expected: usize, by_name: bool) -> Result<PoseRead, ReadError> {
    let layout = PoseLayout::new(&pose_sdna(by_name)).unwrap();
    let read = |f: &Fixture, hints: &mut ReadHints| unsafe {
        read_pose(&layout, &f.object as *const _ as usize, expected, hints)
    };
    let mut hints = ReadHints::default();
    let first = read(f, &mut hints);
    assert_eq!(read(f, &mut hints), first);
    let mut stale = ReadHints::default();
    let _ = read(&fixture(), &mut stale);
    assert_eq!(read(f, &mut stale), first);
    first
}

/// Reads through both links (the bone pointer and the bone of the same name), which must agree.
fn read_fixture(f: &Fixture, expected: usize) -> Result<PoseRead, ReadError> {
    let by_pointer = read_with(f, expected, false);
    let by_name = read_with(f, expected, true);
    if by_pointer.is_ok() || by_name.is_ok() {
        assert_eq!(by_pointer, by_name);
    }
    by_pointer
}

#[test]
fn layout_matches_the_c_structs() {
    assert_eq!(core::mem::size_of::<FakeChannel>(), 192);
    assert_eq!(core::mem::size_of::<FakeBone>(), 208);
    let layout = PoseLayout::new(&pose_sdna(false)).unwrap();
    assert_eq!(layout.bone_link, BoneLink::Pointer { chan_bone: 80 });
    let by_name = PoseLayout::new(&pose_sdna(true)).unwrap();
    assert_eq!(
        by_name.bone_link,
        BoneLink::ByName { object_data: 24, bonebase_first: 8, bone_next: 0, childbase_first: 8 }
    );
    assert_eq!(layout.object_pose, 16);
    assert_eq!(layout.chanbase_first, 8);
    assert_eq!(layout.chan_mat, 88);
    assert_eq!(layout.runtime_segments, 152);
    assert_eq!(layout.runtime_boundaries, 152 + 32);
    assert_eq!(layout.bone_segments, 200);
    assert_eq!(layout.boundary_size, 32);
}

#[test]
fn reads_channels_bones_and_the_b_bone_cache() {
    let f = fixture();
    let got = read_fixture(&f, 2).unwrap();
    // A bone that does not deform: its flag only (nothing deforms with it or looks it up by name).
    assert_eq!(got.deforms, [false, true]);
    assert_eq!(got.bones.len(), 1);
    let spine = &got.bones[0];
    assert_eq!(spine.name, "Spine");
    assert!(spine.deform && !spine.envelope.multiply_groups);
    assert_eq!(spine.channel, Mat4::from_cols_array(&matrix(2.0)));
    assert_eq!(spine.rest, Mat4::from_cols_array(&matrix(100.0)));
    assert_eq!(spine.rest.w_axis.x, 112.0, "Blender's mat[3] is the translation column");
    let e = &spine.envelope;
    assert_eq!((e.head, e.tail), (Vec3::new(1.0, 2.0, 3.0), Vec3::new(1.0, 4.0, 3.0)));
    assert_eq!((e.head_radius, e.tail_radius, e.distance, e.weight, spine.length), (0.1, 0.05, 0.25, 0.75, 2.0));
    assert_eq!((spine.segments, spine.curved), (3, true));
    // Multiply Vertex Group by Envelope on a deforming bone.
    let mut f = fixture();
    f.bones[0].flag = BONE_MULT_VG_ENV;
    let both = read_fixture(&f, 2).unwrap();
    assert_eq!(both.deforms, [true, true]);
    let root = &both.bones[0];
    assert!(root.deform && root.envelope.multiply_groups);
    assert_eq!(root.channel, Mat4::from_cols_array(&matrix(1.0)));
    assert_eq!((root.segments, root.curved, root.bbone.is_none()), (1, false, true));
    let cache = spine.bbone.as_ref().unwrap();
    assert_eq!(cache.inverse_rest, Mat4::from_cols_array(&matrix(0.0)));
    assert_eq!(cache.deform.len(), 4);
    assert_eq!(cache.deform[3], Mat4::from_cols_array(&matrix(-40.0)));
    assert_eq!(cache.rest_joints.len(), 4);
    assert_eq!(cache.rest_joints[2], Mat4::from_cols_array(&matrix(20.0)));
    assert_eq!(cache.boundaries.len(), 4);
    assert_eq!(cache.boundaries[3].point, Vec3::new(0.0, 3.0, 0.0));
    assert_eq!((cache.boundaries[2].offset, cache.boundaries[2].depth_scale), (2.0, 0.5));
    assert_eq!(
        (cache.boundaries[3].offset, cache.boundaries[3].depth_scale),
        (3.0, 0.0),
        "uninitialized padding is not read"
    );
    assert_eq!(cache.arc_length_reciprocal, 1.0 / 3.0);
}

#[test]
fn the_cache_is_read_only_where_blender_deforms_with_it() {
    // A cache for another segment count (the bone changed, the pose was not evaluated yet).
    let mut f = fixture();
    f.channels[1].runtime.segments = 2;
    assert!(read_fixture(&f, 2).unwrap().bones[0].bbone.is_none());
    // The Straight mapping keeps no boundaries.
    let mut f = fixture();
    f.channels[1].runtime.boundaries = core::ptr::null();
    let spine = read_fixture(&f, 2).unwrap().bones.remove(0);
    assert!(spine.bbone.unwrap().boundaries.is_empty());
}

#[test]
fn channel_matrices_alone_are_every_channels_in_order() {
    let f = fixture();
    let layout = PoseLayout::new(&pose_sdna(false)).unwrap();
    let object = &f.object as *const _ as usize;
    let got = unsafe { read_channel_matrices(&layout, object, 2, &mut ReadHints::default()) }.unwrap();
    let want = [matrix(1.0), matrix(2.0)].map(|m| Mat4::from_cols_array(&m));
    assert_eq!(got, want, "the non-deforming channel too");
    assert_eq!(got[1], read_fixture(&f, 2).unwrap().bones[0].channel);
    assert_eq!(
        unsafe { read_channel_matrices(&layout, object, 1, &mut ReadHints::default()) },
        Err(ReadError::ChannelCount { expected: 1, found: 2 })
    );
    assert_eq!(
        unsafe { read_channel_matrices(&layout, object, 3, &mut ReadHints::default()) },
        Err(ReadError::ChannelCount { expected: 3, found: 2 })
    );
    assert_eq!(
        unsafe { read_channel_matrices(&layout, object, MAX_CHANNELS + 1, &mut ReadHints::default()) },
        Err(ReadError::Implausible("channel count"))
    );
    assert_eq!(unsafe { read_channel_matrices(&layout, 0, 2, &mut ReadHints::default()) }, Err(ReadError::Null));
    let mut f = fixture();
    f.object.ty = 1;
    let object = &f.object as *const _ as usize;
    assert!(matches!(
        unsafe { read_channel_matrices(&layout, object, 2, &mut ReadHints::default()) },
        Err(ReadError::NotAnArmature(_))
    ));
    f.object.ty = OB_ARMATURE;
    f.object.pose = core::ptr::null();
    assert!(matches!(
        unsafe { read_channel_matrices(&layout, object, 2, &mut ReadHints::default()) },
        Err(ReadError::NotAnArmature(_))
    ));
}

#[test]
fn wrong_objects_and_counts_are_refused() {
    let f = fixture();
    assert_eq!(read_fixture(&f, 1), Err(ReadError::ChannelCount { expected: 1, found: 2 }));
    assert_eq!(read_fixture(&f, 3), Err(ReadError::ChannelCount { expected: 3, found: 2 }));
    assert_eq!(read_fixture(&f, MAX_CHANNELS + 1), Err(ReadError::Implausible("channel count")));
    let layout = PoseLayout::new(&pose_sdna(false)).unwrap();
    assert_eq!(unsafe { read_pose(&layout, 0, 2, &mut ReadHints::default()) }, Err(ReadError::Null));
    let mut f = fixture();
    f.object.ty = 1;
    assert!(matches!(read_fixture(&f, 2), Err(ReadError::NotAnArmature(_))));
    let mut f = fixture();
    f.object.pose = core::ptr::null();
    assert!(matches!(read_fixture(&f, 2), Err(ReadError::NotAnArmature(_))));
}

#[test]
fn implausible_memory_is_refused() {
    type Spoil = fn(&mut Fixture);
    let cases: [(&str, Spoil); 4] = [
        ("B-Bone segment count", |f| f.bones[1].segments = 33),
        ("B-Bone segment count", |f| f.channels[1].runtime.segments = -1),
        ("B-Bone cache without matrices", |f| f.channels[1].runtime.rest = core::ptr::null()),
        ("B-Bone cache without matrices", |f| f.channels[1].runtime.deform = core::ptr::null()),
    ];
    for (what, spoil) in cases {
        let mut f = fixture();
        spoil(&mut f);
        assert_eq!(read_fixture(&f, 2), Err(ReadError::Implausible(what)));
    }
    // A bone pointer that is null, or leads to a bone of another name.
    let mut f = fixture();
    f.channels[0].bone = core::ptr::null();
    assert_eq!(read_with(&f, 2, false), Err(ReadError::Implausible("pose channel without a bone")));
    let mut f = fixture();
    f.channels[0].bone = &f.bones[1];
    assert_eq!(read_with(&f, 2, false), Err(ReadError::Implausible("pose channel named unlike its bone")));
    // No bone of the channel's name, more bones than channels, or no armature data.
    let mut f = fixture();
    f.bones[1].name = name("Other");
    assert_eq!(read_with(&f, 2, true), Err(ReadError::Implausible("pose channel without a bone")));
    let f = fixture();
    assert_eq!(read_with(&f, 1, true), Err(ReadError::ChannelCount { expected: 1, found: 2 }));
    let mut f = fixture();
    f.object.data = core::ptr::null();
    assert!(matches!(read_with(&f, 2, true), Err(ReadError::NotAnArmature(_))));
}

#[test]
fn layouts_without_a_field_are_refused() {
    let mut dna = Dna::new();
    dna.strukt("ListBase", &[("void", "*first"), ("void", "*last")]);
    dna.strukt("Object", &[("char", "_pad0[8]"), ("short", "type"), ("char", "_pad1[6]")]);
    let e = PoseLayout::new(&Sdna::parse(&dna.bytes()).unwrap()).unwrap_err();
    assert!(matches!(e, DnaError::NoStruct(_) | DnaError::NoField { .. }), "{e}");
    // Without the bone pointer, the by-name link needs Object.data and the bone tree.
    let mut dna = Dna::new();
    dna.strukt("ListBase", &[("void", "*first"), ("void", "*last")]);
    dna.strukt("Object", &[("char", "_pad0[8]"), ("short", "type"), ("char", "_pad1[6]"), ("bPose", "*pose")]);
    dna.strukt("bPose", &[("char", "_pad[8]"), ("ListBase", "chanbase")]);
    dna.strukt("bPoseChannel_Runtime", &[("int", "bbone_segments")]);
    dna.strukt("bPoseChannel", &[("void", "*next"), ("char", "name[64]"), ("bPoseChannel_Runtime", "runtime")]);
    dna.strukt("Bone", &[("char", "name[64]")]);
    let e = PoseLayout::new(&Sdna::parse(&dna.bytes()).unwrap()).unwrap_err();
    assert!(matches!(e, DnaError::NoStruct(_) | DnaError::NoField { .. }), "{e}");
}

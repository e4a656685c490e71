use super::*;
use crate::test_dna::Dna;
use core::ptr::null;

/// An SDNA with the structs the reader needs, in the shape Blender's have (other fields left
/// out or folded into padding); `system`: as from Blender 5.2, whose modifiers have system
/// properties (where a Geometry Nodes modifier's inputs went).
fn state_sdna(system: bool) -> Sdna {
    let mut dna = Dna::new();
    dna.strukt("ListBase", &[("void", "*first"), ("void", "*last")]);
    dna.strukt("ID", &[("char", "name[66]"), ("char", "_pad[6]"), ("IDProperty", "*properties")]);
    dna.strukt(
        "Object",
        &[
            ("ID", "id"),
            ("short", "type"),
            ("char", "_pad[2]"),
            ("int", "mode"),
            ("void", "*data"),
            ("ListBase", "modifiers"),
        ],
    );
    dna.strukt(
        "ModifierData",
        &[
            ("ModifierData", "*next"),
            ("ModifierData", "*prev"),
            ("int", "type"),
            ("int", "mode"),
            ("short", "flag"),
            ("char", "_pad[2]"),
            ("int", "persistent_uid"),
            ("char", "name[64]"),
            if system { ("IDProperty", "*system_properties") } else { ("char", "_pad3[8]") },
        ],
    );
    dna.strukt("NodesModifierSettings", &[("IDProperty", "*properties")]);
    dna.strukt(
        "NodesModifierData",
        &[("ModifierData", "modifier"), ("bNodeTree", "*node_group"), ("NodesModifierSettings", "settings")],
    );
    dna.strukt(
        "ArmatureModifierData",
        &[
            ("ModifierData", "modifier"),
            ("short", "deformflag"),
            ("short", "multi"),
            ("char", "_pad2[4]"),
            ("Object", "*object"),
            ("char", "defgrp_name[64]"),
        ],
    );
    dna.strukt("IDPropertyData", &[("void", "*pointer"), ("ListBase", "group"), ("int", "val"), ("int", "val2")]);
    dna.strukt(
        "IDProperty",
        &[
            ("IDProperty", "*next"),
            ("IDProperty", "*prev"),
            ("char", "type"),
            ("char", "subtype"),
            ("short", "flag"),
            ("char", "name[64]"),
            ("char", "_pad0[4]"),
            ("IDPropertyData", "data"),
            ("int", "len"),
            ("int", "totallen"),
        ],
    );
    dna.strukt("Mesh", &[("ID", "id"), ("ListBase", "vertex_group_names")]);
    dna.strukt("bDeformGroup", &[("bDeformGroup", "*next"), ("bDeformGroup", "*prev"), ("char", "name[64]")]);
    Sdna::parse(&dna.bytes()).unwrap()
}

#[repr(C)]
struct FakeId {
    name: [u8; 66],
    pad: [u8; 6],
    properties: *const FakeProperty,
}
#[repr(C)]
struct FakeObject {
    id: FakeId,
    ty: i16,
    pad: [u8; 2],
    mode: i32,
    data: *const FakeMesh,
    first: *const FakeModifier,
    last: *const FakeModifier,
}
#[repr(C)]
struct FakeModifier {
    next: *const FakeModifier,
    prev: *const FakeModifier,
    ty: i32,
    mode: i32,
    flag: i16,
    pad: [u8; 2],
    uid: i32,
    name: [u8; 64],
    system: *const FakeProperty,
}
#[repr(C)]
struct FakeNodes {
    modifier: FakeModifier,
    group: *const FakeId,
    properties: *const FakeProperty,
}
#[repr(C)]
struct FakeArmatureModifier {
    modifier: FakeModifier,
    deformflag: i16,
    multi: i16,
    pad: [u8; 4],
    object: *const FakeObject,
    group: [u8; 64],
}
#[repr(C)]
struct FakeProperty {
    next: *const FakeProperty,
    prev: *const FakeProperty,
    ty: u8,
    subtype: u8,
    flag: i16,
    name: [u8; 64],
    pad: [u8; 4],
    pointer: *const u8,
    first: *const FakeProperty,
    last: *const FakeProperty,
    val: i32,
    val2: i32,
    len: i32,
    totallen: i32,
}
#[repr(C)]
struct FakeMesh {
    id: FakeId,
    first: *const FakeGroup,
    last: *const FakeGroup,
}
#[repr(C)]
struct FakeGroup {
    next: *const FakeGroup,
    prev: *const FakeGroup,
    name: [u8; 64],
}

fn name<const N: usize>(s: &str) -> [u8; N] {
    let mut n = [0u8; N];
    n[..s.len()].copy_from_slice(s.as_bytes());
    n
}

fn id(s: &str) -> FakeId {
    FakeId { name: name(s), pad: [0; 6], properties: null() }
}

fn modifier(ty: i32, n: &str, uid: i32) -> FakeModifier {
    FakeModifier { next: null(), prev: null(), ty, mode: 3, flag: 0, pad: [0; 2], uid, name: name(n), system: null() }
}

fn property(ty: u8, n: &str) -> FakeProperty {
    FakeProperty {
        next: null(),
        prev: null(),
        ty,
        subtype: 0,
        flag: 0,
        name: name(n),
        pad: [0; 4],
        pointer: null(),
        first: null(),
        last: null(),
        val: 0,
        val2: 0,
        len: 0,
        totallen: 0,
    }
}

/// A mesh object with DQ Skin (a Geometry Nodes modifier), its companion Armature modifier and
/// a Mesh Cache modifier, two vertex groups, and the armature both point to.
struct Fixture {
    object: FakeObject,
    armature: Box<FakeObject>,
    mesh: Box<FakeMesh>,
    groups: Box<[FakeGroup; 2]>,
    nodes: Box<FakeNodes>,
    companion: Box<FakeArmatureModifier>,
    cache: Box<FakeModifier>,
    node_group: Box<FakeId>,
    other_group: Box<FakeId>,
    /// The inputs: Armature (ID), Method (int), Blend Factor (float), Companion (string), a
    /// group with a double and a boolean array inside.
    inputs: Box<FakeProperty>,
    input: Box<[FakeProperty; 5]>,
    inner: Box<[FakeProperty; 2]>,
    companion_text: Box<[u8; 16]>,
    flags: Box<[u8; 3]>,
}

fn fixture() -> Box<Fixture> {
    let mut f = Box::new(Fixture {
        object: FakeObject {
            id: id("OBBody"),
            ty: OB_MESH,
            pad: [0; 2],
            mode: 0,
            data: null(),
            first: null(),
            last: null(),
        },
        armature: Box::new(FakeObject {
            id: id("OBRig"),
            ty: 25,
            pad: [0; 2],
            mode: 0,
            data: null(),
            first: null(),
            last: null(),
        }),
        mesh: Box::new(FakeMesh { id: id("MEBody"), first: null(), last: null() }),
        groups: Box::new([
            FakeGroup { next: null(), prev: null(), name: name("Spine") },
            FakeGroup { next: null(), prev: null(), name: name("Head") },
        ]),
        nodes: Box::new(FakeNodes {
            modifier: modifier(MODIFIER_NODES, "DQ Skin", 11),
            group: null(),
            properties: null(),
        }),
        companion: Box::new(FakeArmatureModifier {
            modifier: modifier(MODIFIER_ARMATURE, "Armature", 12),
            deformflag: 1,
            multi: 0,
            pad: [0; 4],
            object: null(),
            group: name(""),
        }),
        cache: Box::new(modifier(46, "Mesh Cache", 13)),
        node_group: Box::new(id("NTDQ Skin")),
        other_group: Box::new(id("NTOther")),
        inputs: Box::new(property(IDP_GROUP, "")),
        input: Box::new([
            property(IDP_ID, "Socket_0"),
            property(IDP_INT, "Socket_1"),
            property(IDP_FLOAT, "Socket_2"),
            property(IDP_STRING, "Socket_3"),
            property(IDP_GROUP, "Nested"),
        ]),
        inner: Box::new([property(IDP_DOUBLE, "Double"), property(IDP_ARRAY, "Flags")]),
        companion_text: Box::new(name("{\"name\": \"A\"}")),
        flags: Box::new([1, 0, 1]),
    });
    let groups: *const FakeGroup = &f.groups[0];
    f.groups[0].next = &f.groups[1];
    f.mesh.first = groups;
    f.mesh.last = &f.groups[1];
    f.object.data = &*f.mesh;
    // The stack: DQ Skin, its companion, a Mesh Cache.
    let (nodes, companion, cache): (*const FakeModifier, *const FakeModifier, *const FakeModifier) =
        (&f.nodes.modifier, &f.companion.modifier, &*f.cache);
    f.nodes.modifier.next = companion;
    f.companion.modifier.next = cache;
    f.object.first = nodes;
    f.object.last = cache;
    f.companion.object = &*f.armature;
    // The inputs.
    f.input[0].pointer = (&*f.armature as *const FakeObject).cast();
    f.input[1].val = 2;
    f.input[2].val = 0.5f32.to_bits() as i32;
    f.input[3].pointer = f.companion_text.as_ptr();
    f.input[3].len = 14;
    let double = 0.25f64.to_bits();
    (f.inner[0].val, f.inner[0].val2) = (double as i32, (double >> 32) as i32);
    f.inner[1].subtype = IDP_BOOLEAN;
    f.inner[1].pointer = f.flags.as_ptr();
    f.inner[1].len = 3;
    f.inner[0].next = &f.inner[1];
    let inner: *const FakeProperty = &f.inner[0];
    f.input[4].first = inner;
    f.input[4].last = &f.inner[1];
    for i in 0..4 {
        let next: *const FakeProperty = &f.input[i + 1];
        f.input[i].next = next;
    }
    f.inputs.first = &f.input[0];
    f.inputs.last = &f.input[4];
    f.nodes.properties = &*f.inputs;
    f.nodes.group = &*f.node_group;
    f
}

fn layout() -> ObjectStateLayout {
    ObjectStateLayout::new(&state_sdna(false)).unwrap()
}

fn state(f: &Fixture) -> Result<Vec<u8>, ReadError> {
    state_with(f, &layout())
}

/// Reads `f` three times: without hints, with those of that read, and with those of a read of
/// another fixture since freed (stale addresses): the hints never change what is read.
fn state_with(f: &Fixture, layout: &ObjectStateLayout) -> Result<Vec<u8>, ReadError> {
    let read = |f: &Fixture, hints: &mut StateHints| {
        let mut out = vec![1, 2, 3]; // (cleared by the read)
        unsafe { read_object_state(layout, &f.object as *const FakeObject as usize, &mut out, hints) }.map(|()| out)
    };
    let mut hints = StateHints::default();
    let first = read(f, &mut hints);
    assert_eq!(read(f, &mut hints), first);
    let mut stale = StateHints::default();
    let _ = read(&fixture(), &mut stale);
    assert_eq!(read(f, &mut stale), first);
    first
}

#[test]
fn layout_matches_the_c_structs() {
    assert_eq!(core::mem::size_of::<FakeObject>(), 112);
    assert_eq!(core::mem::size_of::<FakeModifier>(), 104);
    assert_eq!(core::mem::size_of::<FakeArmatureModifier>(), 184);
    assert_eq!(core::mem::size_of::<FakeProperty>(), 128);
    let l = layout();
    assert_eq!((l.object_mode, l.object_data, l.object_modifiers), (84, 88, 96));
    assert_eq!((l.modifier_uid, l.modifier_name), (Some(28), (32, 64)));
    assert_eq!((l.nodes_group, l.nodes_properties, l.modifier_system_properties), (104, 112, None));
    assert_eq!(ObjectStateLayout::new(&state_sdna(true)).unwrap().modifier_system_properties, Some(96));
    assert_eq!((l.property_pointer, l.property_group, l.property_val, l.property_len), (88, 96, 112, 120));
    assert_eq!((l.armature_object, l.armature_group), (112, (120, 64)));
    assert_eq!(l.mesh_groups, 80);
}

#[test]
fn reads_what_the_fast_check_compares() {
    let f = fixture();
    let s = unsafe { describe_object(&layout(), &f.object as *const FakeObject as usize) }.unwrap();
    assert_eq!(s.mode, 0);
    assert_eq!(s.vertex_groups, vec![b"Spine".to_vec(), b"Head".to_vec()]);
    let kinds: Vec<_> = s.modifiers.iter().map(|m| (m.kind, m.name.as_slice(), m.mode)).collect();
    assert_eq!(
        kinds,
        [(MODIFIER_NODES, &b"DQ Skin"[..], 3), (MODIFIER_ARMATURE, b"Armature", 3), (46, b"Mesh Cache", 3)]
    );
    let dq = &s.modifiers[0];
    assert_eq!(dq.node_group, &*f.node_group as *const FakeId as usize);
    let armature = &*f.armature as *const FakeObject as usize;
    assert_eq!(
        dq.inputs,
        vec![
            (b"Socket_0".to_vec(), PropertyValue::Id(armature)),
            (b"Socket_1".to_vec(), PropertyValue::Int(2)),
            (b"Socket_2".to_vec(), PropertyValue::Float(0.5)),
            (b"Socket_3".to_vec(), PropertyValue::String(b"{\"name\": \"A\"}\0".to_vec())),
            (
                b"Nested".to_vec(),
                PropertyValue::Group(vec![
                    (b"Double".to_vec(), PropertyValue::Double(0.25)),
                    (b"Flags".to_vec(), PropertyValue::Array(3)),
                ]),
            ),
        ]
    );
    assert_eq!(s.modifiers[1].object, armature);
    assert_eq!(state(&f), state(&f), "two reads of the same memory are the same bytes");
}

#[test]
fn every_change_the_fast_check_must_see_changes_the_state() {
    type Change = fn(&mut Fixture);
    let changes: [(&str, Change); 23] = [
        ("the object's mode", |f| f.object.mode = 2),
        ("the armature's mode", |f| f.armature.mode = 2),
        ("the object's data", |f| f.object.data = null()),
        ("a modifier switched off", |f| f.nodes.modifier.mode = 2),
        ("the companion switched on in the viewport", |f| f.companion.modifier.mode = 1),
        ("a modifier's flags", |f| f.cache.flag = 1),
        ("a modifier renamed", |f| f.cache.name = name("Cache")),
        ("a modifier's id", |f| f.nodes.modifier.uid = 99),
        ("the stack cut short", |f| f.companion.modifier.next = null()),
        ("the stack reordered", |f| {
            let (nodes, companion, cache): (*const FakeModifier, *const FakeModifier, *const FakeModifier) =
                (&f.nodes.modifier, &f.companion.modifier, &*f.cache);
            f.object.first = companion;
            f.companion.modifier.next = nodes;
            f.nodes.modifier.next = cache;
        }),
        ("the node group replaced", |f| f.nodes.group = &*f.other_group),
        ("an ID input", |f| f.input[0].pointer = null()),
        ("an int input", |f| f.input[1].val = 1),
        ("a float input", |f| f.input[2].val = 0.25f32.to_bits() as i32),
        ("a string input", |f| f.companion_text[10] = b'B'),
        ("a string input's length", |f| f.input[3].len = 13),
        ("a nested double", |f| f.inner[0].val2 += 1),
        ("a boolean array", |f| f.flags[1] = 1),
        ("an input renamed", |f| f.input[1].name = name("Socket_9")),
        ("the companion's settings", |f| f.companion.deformflag = 3),
        ("the companion's armature", |f| f.companion.object = null()),
        ("a vertex group renamed", |f| f.groups[1].name = name("Neck")),
        ("a vertex group removed", |f| f.groups[0].next = null()),
    ];
    let before = state(&fixture()).unwrap();
    for (what, change) in changes {
        let mut f = fixture();
        change(&mut f);
        assert_ne!(state(&f).unwrap(), before, "{what}");
    }
}

#[test]
fn implausible_memory_is_refused() {
    assert_eq!(
        unsafe { read_object_state(&layout(), 0, &mut Vec::new(), &mut StateHints::default()) },
        Err(ReadError::Null)
    );
    type Spoil = fn(&mut Fixture);
    let cases: [(&str, Spoil); 6] = [
        ("list length", |f| {
            let own: *const FakeGroup = &f.groups[1];
            f.groups[1].next = own;
        }),
        ("length", |f| f.input[3].len = -1),
        ("string", |f| f.input[3].pointer = null()),
        ("ID property type", |f| f.input[1].ty = 42),
        ("ID property array type", |f| f.inner[1].subtype = IDP_GROUP),
        ("ID property depth", |f| {
            let own: *const FakeProperty = &f.input[4];
            f.inner[1].ty = IDP_GROUP;
            f.inner[1].first = own;
        }),
    ];
    for (what, spoil) in cases {
        let mut f = fixture();
        spoil(&mut f);
        assert_eq!(state(&f), Err(ReadError::Implausible(what)), "{what}");
    }
}

#[test]
fn inputs_in_system_properties_are_read_as_from_blender_5_2() {
    // Blender 5.2 keeps a Geometry Nodes modifier's inputs in its system properties.
    let system = ObjectStateLayout::new(&state_sdna(true)).unwrap();
    let describe = |f: &Fixture, l: &ObjectStateLayout| {
        unsafe { describe_object(l, &f.object as *const FakeObject as usize) }.unwrap()
    };
    let mut moved = fixture();
    let expected = describe(&moved, &layout());
    moved.nodes.modifier.system = moved.nodes.properties;
    moved.nodes.properties = null();
    assert_eq!(describe(&moved, &system), expected);
    assert!(describe(&moved, &layout()).modifiers[0].inputs.is_empty(), "(an older Blender has no such field)");
    let before = state_with(&moved, &system).unwrap();
    moved.input[1].val = 1;
    assert_ne!(state_with(&moved, &system).unwrap(), before, "an input in the system properties");
}

#[test]
fn a_read_keeps_where_it_went_for_the_next() {
    let l = layout();
    let mut f = fixture();
    let object = &f.object as *const FakeObject as usize;
    let mut hints = StateHints::default();
    let mut out = Vec::new();
    unsafe { read_object_state(&l, object, &mut out, &mut hints) }.unwrap();
    // The object, its 3 modifiers, the armature the companion points to; the inputs' group,
    // its 5 properties, the string's bytes, the armature the ID input points to, the nested
    // group (again as a group) and its 2 properties, the array's bytes; the mesh and its 2
    // vertex groups.
    assert_eq!(hints.len(), 20);
    let before = out.clone();
    // The Mesh Cache removed: the hints still name it, and what is read is the stack as it is.
    f.companion.modifier.next = null();
    f.object.last = &f.companion.modifier;
    unsafe { read_object_state(&l, object, &mut out, &mut hints) }.unwrap();
    assert_ne!(out, before);
    assert_eq!(hints.len(), 19);
    assert_eq!(Ok(out), state(&f));
}

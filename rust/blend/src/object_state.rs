//! What decides whether the frame the feed skinned for a DQ Skin object stands, read from
//! Blender's memory in one pass, where the Python API takes dozens of calls per object and frame.
//!
//! Read: the object's mode and data; its modifier stack in order, each modifier's type,
//! switches (`mode`), flags, persistent id and name; a Geometry Nodes modifier's node group and
//! its input values (ID property groups: `settings.properties` up to Blender 5.1, the
//! modifier's `system_properties` from 5.2); an Armature modifier's settings; the mode of every object an input points to (the
//! armature); and the mesh's vertex-group names. [`read_object_state`] writes it as bytes that
//! are only ever compared with an earlier read of the same object: equal bytes say that none of
//! it changed. [`describe_object`] reads the same as values, for the check against Blender's
//! Python API that a layout must pass before its bytes are trusted.
//!
//! Every count and length read is bounded before it is used; anything out of range is
//! [`ReadError::Implausible`] (the caller then takes its Python path).

use crate::memory::{name_bytes, read, ReadError};
use crate::sdna::{DnaError, Sdna};

mod prefetch;
use prefetch::Kind;
pub use prefetch::StateHints;

/// `eModifierType` values (stored in files, so they never change).
const MODIFIER_ARMATURE: i32 = 8;
const MODIFIER_NODES: i32 = 57;
/// `eObjectType::OB_MESH`.
const OB_MESH: i16 = 1;
/// `eIDPropertyType` values (stored in files).
const IDP_STRING: u8 = 0;
const IDP_INT: u8 = 1;
const IDP_FLOAT: u8 = 2;
const IDP_ARRAY: u8 = 5;
const IDP_GROUP: u8 = 6;
const IDP_ID: u8 = 7;
const IDP_DOUBLE: u8 = 8;
const IDP_BOOLEAN: u8 = 10;
/// Bounds on what one read may walk.
const MAX_MODIFIERS: usize = 1 << 12;
const MAX_PROPERTIES: usize = 1 << 16;
const MAX_DEPTH: usize = 8;
const MAX_BYTES: usize = 1 << 20;
const MAX_VERTEX_GROUPS: usize = 1 << 16;

/// Byte offsets of everything [`read_object_state`] touches, from an [`Sdna`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ObjectStateLayout {
    id_name: usize,
    object_type: usize,
    object_mode: usize,
    object_data: usize,
    object_modifiers: usize,
    modifier_next: usize,
    modifier_type: usize,
    modifier_mode: usize,
    modifier_flag: usize,
    modifier_uid: Option<usize>,
    modifier_name: (usize, usize),
    nodes_group: usize,
    nodes_properties: usize,
    /// `ModifierData.system_properties` (5.2+), where a Geometry Nodes modifier's inputs went.
    modifier_system_properties: Option<usize>,
    armature_deformflag: usize,
    armature_multi: usize,
    armature_object: usize,
    armature_group: (usize, usize),
    property_next: usize,
    property_type: usize,
    property_subtype: usize,
    property_name: (usize, usize),
    property_pointer: usize,
    property_group: usize,
    property_val: usize,
    property_len: usize,
    mesh_groups: usize,
    group_next: usize,
    group_name: (usize, usize),
}

impl ObjectStateLayout {
    pub fn new(sdna: &Sdna) -> Result<Self, DnaError> {
        let first = sdna.pointer("ListBase", &["first"])?;
        let list = |s: &str, name: &str| sdna.embedded(s, &[name], "ListBase").map(|o| o + first);
        let data = sdna.embedded("IDProperty", &["data"], "IDPropertyData")?;
        let settings = sdna.embedded("NodesModifierData", &["settings"], "NodesModifierSettings")?;
        // Only the first 4 bytes of `val` are read as the value of an int, float or boolean;
        // a double spans `val` and `val2`, which follow it (checked).
        let val = sdna.number("IDPropertyData", &["val"], 4)?;
        if sdna.number("IDPropertyData", &["val2"], 4)? != val + 4 {
            return Err(DnaError::Inconsistent("IDPropertyData.val2 does not follow val".into()));
        }
        Ok(Self {
            id_name: sdna.chars("ID", "name")?.0,
            object_type: sdna.number("Object", &["type"], 2)?,
            object_mode: sdna.number("Object", &["mode"], 4)?,
            object_data: sdna.pointer("Object", &["data"])?,
            object_modifiers: list("Object", "modifiers")?,
            modifier_next: sdna.pointer("ModifierData", &["next"])?,
            modifier_type: sdna.number("ModifierData", &["type"], 4)?,
            modifier_mode: sdna.number("ModifierData", &["mode"], 4)?,
            modifier_flag: sdna.number("ModifierData", &["flag"], 2)?,
            modifier_uid: sdna.number("ModifierData", &["persistent_uid"], 4).ok(),
            modifier_name: sdna.chars("ModifierData", "name")?,
            nodes_group: sdna.pointer("NodesModifierData", &["node_group"])?,
            nodes_properties: settings + sdna.pointer("NodesModifierSettings", &["properties"])?,
            modifier_system_properties: sdna.pointer("ModifierData", &["system_properties"]).ok(),
            armature_deformflag: sdna.number("ArmatureModifierData", &["deformflag"], 2)?,
            armature_multi: sdna.number("ArmatureModifierData", &["multi"], 2)?,
            armature_object: sdna.pointer("ArmatureModifierData", &["object"])?,
            armature_group: sdna.chars("ArmatureModifierData", "defgrp_name")?,
            property_next: sdna.pointer("IDProperty", &["next"])?,
            property_type: sdna.number("IDProperty", &["type"], 1)?,
            property_subtype: sdna.number("IDProperty", &["subtype"], 1)?,
            property_name: sdna.chars("IDProperty", "name")?,
            property_pointer: data + sdna.pointer("IDPropertyData", &["pointer"])?,
            property_group: data + sdna.embedded("IDPropertyData", &["group"], "ListBase")? + first,
            property_val: data + val,
            property_len: sdna.number("IDProperty", &["len"], 4)?,
            mesh_groups: list("Mesh", "vertex_group_names")?,
            group_next: sdna.pointer("bDeformGroup", &["next"])?,
            group_name: sdna.chars("bDeformGroup", "name")?,
        })
    }
}

/// A value of an ID property, as [`describe_object`] gives it (arrays by length only).
#[derive(Clone, Debug, PartialEq)]
pub enum PropertyValue {
    Int(i32),
    Float(f32),
    Double(f64),
    Bool(bool),
    String(Vec<u8>),
    /// The address of the data-block (0: none).
    Id(usize),
    /// The group's properties (name, value), in order.
    Group(Vec<(Vec<u8>, PropertyValue)>),
    Array(usize),
}

/// One modifier as [`describe_object`] reads it.
#[derive(Clone, Debug, PartialEq)]
pub struct ModifierSummary {
    pub kind: i32,
    pub mode: i32,
    pub name: Vec<u8>,
    /// Geometry Nodes: the node group's address and the inputs (name, value), top level.
    pub node_group: usize,
    pub inputs: Vec<(Vec<u8>, PropertyValue)>,
    /// Armature: the object's address.
    pub object: usize,
}

/// An object as [`describe_object`] reads it.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectSummary {
    pub mode: i32,
    pub modifiers: Vec<ModifierSummary>,
    pub vertex_groups: Vec<Vec<u8>>,
}

/// Writes the state of the object at `object` to `out` (cleared first). `hints` are where the
/// last read of this object went (empty for none): they are prefetched first, then replaced by
/// where this read goes (`object_state/prefetch.rs`); they never change what is read.
///
/// # Safety
/// `object` must be the address of a live `Object` of the Blender whose SDNA built `layout`,
/// with nothing writing to it, its modifiers, their node groups, the objects their inputs
/// point to or its mesh during the call.
pub unsafe fn read_object_state(
    layout: &ObjectStateLayout,
    object: usize,
    out: &mut Vec<u8>,
    hints: &mut StateHints,
) -> Result<(), ReadError> {
    out.clear();
    hints.prefetch(layout);
    hints.clear();
    let mut walk = Walk { layout, out, properties: 0, hints };
    // SAFETY: the caller's contract, passed on.
    unsafe { walk.object(object) }
}

/// The same reads as [`read_object_state`], as values.
///
/// # Safety
/// As for [`read_object_state`].
pub unsafe fn describe_object(layout: &ObjectStateLayout, object: usize) -> Result<ObjectSummary, ReadError> {
    if object == 0 {
        return Err(ReadError::Null);
    }
    let l = layout;
    // SAFETY: (all reads) the caller's contract; each address is a field of a live struct
    // reached from the object, or a pointer Blender keeps valid (lists, ID pointers).
    unsafe {
        let mut modifiers = Vec::new();
        for md in modifiers_of(l, object)? {
            let kind: i32 = read(md + l.modifier_type);
            let mut m = ModifierSummary {
                kind,
                mode: read(md + l.modifier_mode),
                name: name_bytes(md + l.modifier_name.0, l.modifier_name.1).to_vec(),
                node_group: 0,
                inputs: Vec::new(),
                object: 0,
            };
            if kind == MODIFIER_NODES {
                m.node_group = read(md + l.nodes_group);
                for group in input_groups(l, md) {
                    if group != 0 {
                        m.inputs.extend(properties(l, group, 0)?);
                    }
                }
            } else if kind == MODIFIER_ARMATURE {
                m.object = read(md + l.armature_object);
            }
            modifiers.push(m);
        }
        Ok(ObjectSummary { mode: read(object + l.object_mode), modifiers, vertex_groups: vertex_groups(l, object)? })
    }
}

/// The ID property groups that hold the inputs of the Geometry Nodes modifier at `md`: its
/// settings' (up to Blender 5.1) and its system properties (from 5.2), 0 where there is none.
///
/// # Safety
/// `md` must be a live `NodesModifierData`.
unsafe fn input_groups(l: &ObjectStateLayout, md: usize) -> [usize; 2] {
    // SAFETY: the caller's guarantee.
    unsafe { [read(md + l.nodes_properties), l.modifier_system_properties.map_or(0, |o| read(md + o))] }
}

/// The addresses of a linked list's items from `first` (`next` at `next_offset`), at most `max`.
///
/// # Safety
/// Every item must be a live struct with its `next` pointer at `next_offset`.
unsafe fn list(first: usize, next_offset: usize, max: usize) -> Result<Vec<usize>, ReadError> {
    let mut items = Vec::new();
    // SAFETY: the caller's guarantee.
    unsafe { each_in_list(first, next_offset, max, |at| items.push(at)) }?;
    Ok(items)
}

/// Calls `each` with the address of every item of a linked list from `first` (`next` at
/// `next_offset`), at most `max` of them (more is an error).
///
/// # Safety
/// As for [`list`].
unsafe fn each_in_list(
    first: usize,
    next_offset: usize,
    max: usize,
    mut each: impl FnMut(usize),
) -> Result<(), ReadError> {
    let mut at = first;
    let mut count = 0;
    while at != 0 {
        if count == max {
            return Err(ReadError::Implausible("list length"));
        }
        each(at);
        count += 1;
        // SAFETY: the caller's guarantee.
        at = unsafe { read(at + next_offset) };
    }
    Ok(())
}

/// # Safety
/// As for [`read_object_state`].
unsafe fn modifiers_of(l: &ObjectStateLayout, object: usize) -> Result<Vec<usize>, ReadError> {
    // SAFETY: the caller's guarantee.
    unsafe { list(read(object + l.object_modifiers), l.modifier_next, MAX_MODIFIERS) }
}

/// The names of the object's mesh's vertex groups (none unless it is a mesh object).
///
/// # Safety
/// As for [`read_object_state`].
unsafe fn vertex_groups(l: &ObjectStateLayout, object: usize) -> Result<Vec<Vec<u8>>, ReadError> {
    let mut names = Vec::new();
    // SAFETY: the caller's guarantee.
    unsafe { each_vertex_group(l, object, |_, name| names.push(name.to_vec())) }?;
    Ok(names)
}

/// Calls `each` with the address and name of every vertex group of the object's mesh, in order
/// (none unless it is a mesh object), without copying the names.
///
/// # Safety
/// As for [`read_object_state`].
unsafe fn each_vertex_group(
    l: &ObjectStateLayout,
    object: usize,
    mut each: impl FnMut(usize, &[u8]),
) -> Result<(), ReadError> {
    // SAFETY: the caller's guarantee.
    unsafe {
        let mesh: usize = read(object + l.object_data);
        if read::<i16>(object + l.object_type) != OB_MESH || mesh == 0 {
            return Ok(());
        }
        each_in_list(read(mesh + l.mesh_groups), l.group_next, MAX_VERTEX_GROUPS, |g| {
            each(g, name_bytes(g + l.group_name.0, l.group_name.1))
        })
    }
}

/// The properties (name, value) of the ID property group at `group`, `depth` groups down.
///
/// # Safety
/// `group` must be a live `IDProperty` of type group.
unsafe fn properties(
    l: &ObjectStateLayout,
    group: usize,
    depth: usize,
) -> Result<Vec<(Vec<u8>, PropertyValue)>, ReadError> {
    if depth == MAX_DEPTH {
        return Err(ReadError::Implausible("ID property depth"));
    }
    // SAFETY: the caller's guarantee.
    unsafe {
        let children = list(read(group + l.property_group), l.property_next, MAX_PROPERTIES)?;
        children
            .into_iter()
            .map(|p| Ok((name_bytes(p + l.property_name.0, l.property_name.1).to_vec(), value(l, p, depth)?)))
            .collect()
    }
}

/// The value of the ID property at `p`, `depth` groups down.
///
/// # Safety
/// `p` must be a live `IDProperty`.
unsafe fn value(l: &ObjectStateLayout, p: usize, depth: usize) -> Result<PropertyValue, ReadError> {
    // SAFETY: the caller's guarantee; a string's bytes are bounded by its length (checked).
    unsafe {
        let len: i32 = read(p + l.property_len);
        Ok(match read::<u8>(p + l.property_type) {
            IDP_INT => PropertyValue::Int(read(p + l.property_val)),
            IDP_FLOAT => PropertyValue::Float(read(p + l.property_val)),
            IDP_DOUBLE => PropertyValue::Double(read(p + l.property_val)),
            IDP_BOOLEAN => PropertyValue::Bool(read::<i32>(p + l.property_val) != 0),
            IDP_ID => PropertyValue::Id(read(p + l.property_pointer)),
            IDP_STRING => PropertyValue::String(string(l, p)?.to_vec()),
            IDP_GROUP => PropertyValue::Group(properties(l, p, depth + 1)?),
            IDP_ARRAY => {
                PropertyValue::Array(usize::try_from(len).map_err(|_| ReadError::Implausible("array length"))?)
            }
            _ => return Err(ReadError::Implausible("ID property type")),
        })
    }
}

/// The bytes of the string property at `p` (its stored length, the NUL included).
///
/// # Safety
/// `p` must be a live `IDProperty` of type string.
unsafe fn string<'a>(l: &ObjectStateLayout, p: usize) -> Result<&'a [u8], ReadError> {
    // SAFETY: the caller's guarantee; the length is bounded before the bytes are read.
    unsafe {
        let len = bounded_len(read(p + l.property_len), 1)?;
        let at: usize = read(p + l.property_pointer);
        if at == 0 {
            return if len == 0 { Ok(&[]) } else { Err(ReadError::Implausible("string")) };
        }
        Ok(core::slice::from_raw_parts(at as *const u8, len))
    }
}

/// `len` items of `item` bytes, checked to be a sane length.
fn bounded_len(len: i32, item: usize) -> Result<usize, ReadError> {
    match usize::try_from(len) {
        Ok(n) if n * item <= MAX_BYTES => Ok(n * item),
        _ => Err(ReadError::Implausible("length")),
    }
}

/// One read of [`read_object_state`].
struct Walk<'a> {
    layout: &'a ObjectStateLayout,
    out: &'a mut Vec<u8>,
    properties: usize,
    hints: &'a mut StateHints,
}

impl Walk<'_> {
    fn int(&mut self, v: i64) {
        self.out.extend_from_slice(&v.to_le_bytes());
    }

    fn bytes(&mut self, b: &[u8]) {
        self.int(b.len() as i64);
        self.out.extend_from_slice(b);
    }

    /// # Safety
    /// As for [`read_object_state`].
    unsafe fn object(&mut self, object: usize) -> Result<(), ReadError> {
        if object == 0 {
            return Err(ReadError::Null);
        }
        let l = self.layout;
        // SAFETY: (all reads) the caller's contract, as in `describe_object`.
        unsafe {
            self.hints.visited(object, Kind::Object);
            self.int(read::<i32>(object + l.object_mode).into());
            let data: usize = read(object + l.object_data);
            self.int(data as i64);
            for md in modifiers_of(l, object)? {
                self.hints.visited(md, Kind::Modifier);
                let kind: i32 = read(md + l.modifier_type);
                self.int(kind.into());
                self.int(read::<i32>(md + l.modifier_mode).into());
                self.int(read::<i16>(md + l.modifier_flag).into());
                if let Some(uid) = l.modifier_uid {
                    self.int(read::<i32>(md + uid).into());
                }
                self.bytes(name_bytes(md + l.modifier_name.0, l.modifier_name.1));
                if kind == MODIFIER_NODES {
                    // (The group's own ID properties, the extension's tags, change only when
                    // the extension rebuilds the group, which it then evaluates fully.)
                    self.int(read::<usize>(md + l.nodes_group) as i64);
                    for group in input_groups(l, md) {
                        self.group(group, 0)?;
                    }
                } else if kind == MODIFIER_ARMATURE {
                    self.int(read::<i16>(md + l.armature_deformflag).into());
                    self.int(read::<i16>(md + l.armature_multi).into());
                    self.id(read(md + l.armature_object));
                    self.bytes(name_bytes(md + l.armature_group.0, l.armature_group.1));
                }
            }
            self.int(-1); // (the end of the stack: a modifier's fields cannot be taken for what follows)

            // The names streamed: a copy of each was a third of this read for a character's 160.
            self.hints.visited(data, Kind::Mesh);
            each_vertex_group(l, object, |g, name| {
                self.hints.visited(g, Kind::VertexGroup);
                self.bytes(name);
            })?;
        }
        Ok(())
    }

    /// An ID pointer, and the mode of the object it points to (an armature in Edit Mode is
    /// not posed).
    ///
    /// # Safety
    /// `id` is 0 or a live ID.
    unsafe fn id(&mut self, id: usize) {
        self.int(id as i64);
        let l = self.layout;
        // SAFETY: the caller's guarantee; an ID's name begins with its two-letter type code.
        unsafe {
            self.hints.visited(id, Kind::Object);
            if id != 0 && name_bytes(id + l.id_name, 2) == b"OB" {
                self.int(read::<i32>(id + l.object_mode).into());
            }
        }
    }

    /// An ID property group (0: none): each property's name, type and value, in order.
    ///
    /// # Safety
    /// `group` is 0 or a live `IDProperty` (of type group).
    unsafe fn group(&mut self, group: usize, depth: usize) -> Result<(), ReadError> {
        let l = self.layout;
        if group == 0 {
            self.int(-1);
            return Ok(());
        }
        if depth == MAX_DEPTH {
            return Err(ReadError::Implausible("ID property depth"));
        }
        // SAFETY: (all reads) the caller's guarantee; lengths are bounded before use.
        unsafe {
            self.hints.visited(group, Kind::Property);
            let children = list(read(group + l.property_group), l.property_next, MAX_PROPERTIES)?;
            self.int(children.len() as i64);
            for p in children {
                self.hints.visited(p, Kind::Property);
                self.properties += 1;
                if self.properties > MAX_PROPERTIES {
                    return Err(ReadError::Implausible("ID property count"));
                }
                let kind: u8 = read(p + l.property_type);
                let subtype: u8 = read(p + l.property_subtype);
                self.int(i64::from(kind) | i64::from(subtype) << 8);
                self.bytes(name_bytes(p + l.property_name.0, l.property_name.1));
                match kind {
                    IDP_INT | IDP_FLOAT | IDP_BOOLEAN => self.int(read::<i32>(p + l.property_val).into()),
                    IDP_DOUBLE => self.int(read::<i64>(p + l.property_val)),
                    IDP_ID => self.id(read(p + l.property_pointer)),
                    IDP_STRING => {
                        let text = string(l, p)?;
                        if !text.is_empty() {
                            self.hints.visited(text.as_ptr() as usize, Kind::Bytes);
                        }
                        self.bytes(text);
                    }
                    IDP_GROUP => self.group(p, depth + 1)?,
                    IDP_ARRAY => {
                        let item = match subtype {
                            IDP_INT | IDP_FLOAT => 4,
                            IDP_DOUBLE => 8,
                            IDP_BOOLEAN => 1,
                            _ => return Err(ReadError::Implausible("ID property array type")),
                        };
                        let len = bounded_len(read(p + l.property_len), item)?;
                        let at: usize = read(p + l.property_pointer);
                        if at == 0 && len != 0 {
                            return Err(ReadError::Implausible("ID property array"));
                        }
                        self.hints.visited(at, Kind::Bytes);
                        self.bytes(if len == 0 { &[] } else { core::slice::from_raw_parts(at as *const u8, len) });
                    }
                    _ => return Err(ReadError::Implausible("ID property type")),
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;

//! The SDNA ("structure DNA") of a `.blend` file: the names, sizes and fields of every struct
//! of the Blender that wrote it, which are exactly the structs it has in memory.
//!
//! File layout: a header (`BLENDER-v402`, 12 bytes, up to 4.x; `BLENDER17-01v0500`, 17 bytes,
//! from 5.0), then blocks, each a block header (24 bytes before 5.0: code, length, old
//! address, struct index, count; 32 bytes from 5.0: code, struct index, old address, 64-bit
//! length, 64-bit count) followed by its data. The `DNA1` block holds `SDNA`, then `NAME`,
//! `TYPE`, `TLEN` and `STRC` sections, each aligned to 4 bytes.
//!
//! Field names in the SDNA are the names stored in files, which may be older than the names in
//! Blender's headers (Blender renames fields at run time and keeps the stored names): callers
//! give every name a field has had, e.g. `["verts_num", "totvert"]`.

use std::collections::HashMap;

/// Why a `.blend` file or its SDNA could not be used.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DnaError {
    /// Not a `.blend` file Blender 2.5 or newer writes (or compressed).
    NotABlendFile(String),
    /// The file is cut short or inconsistent.
    Truncated(&'static str),
    /// Only little-endian files with 8-byte pointers are supported (every platform Blender 4.2+
    /// runs on).
    Unsupported(String),
    /// A struct is not in this SDNA.
    NoStruct(String),
    /// A struct has none of the given field names.
    NoField { strukt: String, names: Vec<String> },
    /// The layout disagrees with itself (the sizes of a struct's fields do not add up).
    Inconsistent(String),
}

impl core::fmt::Display for DnaError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            DnaError::NotABlendFile(why) => write!(f, "not an uncompressed .blend file: {why}"),
            DnaError::Truncated(what) => write!(f, "the .blend file is cut short ({what})"),
            DnaError::Unsupported(what) => write!(f, "unsupported .blend file: {what}"),
            DnaError::NoStruct(s) => write!(f, "this Blender has no struct {s}"),
            DnaError::NoField { strukt, names } => {
                write!(f, "struct {strukt} has none of the fields {}", names.join(", "))
            }
            DnaError::Inconsistent(why) => write!(f, "inconsistent SDNA: {why}"),
        }
    }
}

impl std::error::Error for DnaError {}

/// A field of a struct: where it starts and how many bytes it takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Field {
    pub offset: usize,
    pub size: usize,
    /// A pointer (or an array of pointers).
    pub pointer: bool,
}

#[derive(Clone, Debug)]
struct Struct {
    size: usize,
    /// Field name without `*` and array suffix -> field.
    fields: HashMap<String, Field>,
}

/// The parsed SDNA of one Blender build.
#[derive(Clone, Debug)]
pub struct Sdna {
    structs: HashMap<String, Struct>,
}

const POINTER_SIZE: usize = 8;

struct Reader<'a> {
    data: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn bytes(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], DnaError> {
        let end = self.at.checked_add(n).ok_or(DnaError::Truncated(what))?;
        let s = self.data.get(self.at..end).ok_or(DnaError::Truncated(what))?;
        self.at = end;
        Ok(s)
    }
    fn u16(&mut self, what: &'static str) -> Result<u16, DnaError> {
        Ok(u16::from_le_bytes(self.bytes(2, what)?.try_into().unwrap()))
    }
    fn i32(&mut self, what: &'static str) -> Result<i32, DnaError> {
        Ok(i32::from_le_bytes(self.bytes(4, what)?.try_into().unwrap()))
    }
    fn i64(&mut self, what: &'static str) -> Result<i64, DnaError> {
        Ok(i64::from_le_bytes(self.bytes(8, what)?.try_into().unwrap()))
    }
    fn count(&mut self, what: &'static str) -> Result<usize, DnaError> {
        let n = self.i32(what)?;
        // Each entry takes at least one byte: a count beyond the data is a corrupt file.
        usize::try_from(n).ok().filter(|&n| n <= self.data.len()).ok_or(DnaError::Truncated(what))
    }
    fn tag(&mut self, tag: &[u8; 4]) -> Result<(), DnaError> {
        let what = "section tag";
        let got = self.bytes(4, what)?;
        if got != tag {
            return Err(DnaError::Inconsistent(format!(
                "expected section {} at byte {}, found {:?}",
                String::from_utf8_lossy(tag),
                self.at - 4,
                String::from_utf8_lossy(got)
            )));
        }
        Ok(())
    }
    fn cstr(&mut self, what: &'static str) -> Result<&'a str, DnaError> {
        let rest = &self.data[self.at.min(self.data.len())..];
        let len = rest.iter().position(|&b| b == 0).ok_or(DnaError::Truncated(what))?;
        let s =
            core::str::from_utf8(&rest[..len]).map_err(|_| DnaError::Inconsistent(format!("{what} is not UTF-8")))?;
        self.at += len + 1;
        Ok(s)
    }
    fn align4(&mut self) {
        self.at = (self.at + 3) & !3;
    }
}

/// The `DNA1` block of a `.blend` file's bytes.
pub fn dna_block(file: &[u8]) -> Result<&[u8], DnaError> {
    if file.len() < 12 || &file[..7] != b"BLENDER" {
        let why = if file.starts_with(&[0x1f, 0x8b]) || file.starts_with(&[0x28, 0xb5, 0x2f, 0xfd]) {
            "it is compressed"
        } else {
            "it does not start with BLENDER"
        };
        return Err(DnaError::NotABlendFile(why.into()));
    }
    // 5.0+: "BLENDER17-01v0500": header size "17", pointer size '-', format "01", endianness.
    let (header, large) = if &file[7..9] == b"17" { (17usize, true) } else { (12usize, false) };
    let (pointer, endian) = if large { (file[9], file[12]) } else { (file[7], file[8]) };
    if pointer != b'-' {
        return Err(DnaError::Unsupported("4-byte pointers".into()));
    }
    if endian != b'v' {
        return Err(DnaError::Unsupported("big-endian data".into()));
    }
    let mut r = Reader { data: file, at: header };
    loop {
        let code = r.bytes(4, "block header")?;
        let len = if large {
            let _sdna = r.i32("block header")?;
            let _old = r.i64("block header")?;
            let len = r.i64("block header")?;
            let _nr = r.i64("block header")?;
            len
        } else {
            let len = r.i32("block header")? as i64;
            let _old = r.i64("block header")?;
            let _sdna = r.i32("block header")?;
            let _nr = r.i32("block header")?;
            len
        };
        let len = usize::try_from(len).map_err(|_| DnaError::Truncated("block length"))?;
        if code == b"DNA1" {
            return r.bytes(len, "DNA1 block");
        }
        if code == b"ENDB" {
            return Err(DnaError::Truncated("no DNA1 block before ENDB"));
        }
        r.bytes(len, "block data")?;
    }
}

/// Array length of a field name such as `name[68]` or `mat[4][4]` (1 for none).
fn array_len(name: &str) -> Result<usize, DnaError> {
    let mut n = 1usize;
    let mut rest = name;
    while let Some(open) = rest.find('[') {
        let close = rest[open..].find(']').ok_or_else(|| DnaError::Inconsistent(format!("field {name}")))? + open;
        let k: usize = rest[open + 1..close].parse().map_err(|_| DnaError::Inconsistent(format!("field {name}")))?;
        n = n.checked_mul(k).ok_or_else(|| DnaError::Inconsistent(format!("field {name}")))?;
        rest = &rest[close + 1..];
    }
    Ok(n)
}

/// `*dw` -> `dw`, `name[68]` -> `name`, `(*func)()` -> `func`.
fn bare_name(name: &str) -> &str {
    let s = name.trim_start_matches(['*', '(']);
    let end = s.find(['[', ')']).unwrap_or(s.len());
    &s[..end]
}

impl Sdna {
    /// The SDNA of the Blender that wrote `file` (an uncompressed `.blend`).
    pub fn from_blend_file(file: &[u8]) -> Result<Self, DnaError> {
        Self::parse(dna_block(file)?)
    }

    /// Parses the contents of a `DNA1` block.
    pub fn parse(dna: &[u8]) -> Result<Self, DnaError> {
        let mut r = Reader { data: dna, at: 0 };
        r.tag(b"SDNA")?;
        r.tag(b"NAME")?;
        let n = r.count("name count")?;
        let names = (0..n).map(|_| r.cstr("field name")).collect::<Result<Vec<_>, _>>()?;
        r.align4();
        r.tag(b"TYPE")?;
        let n = r.count("type count")?;
        let types = (0..n).map(|_| r.cstr("type name")).collect::<Result<Vec<_>, _>>()?;
        r.align4();
        r.tag(b"TLEN")?;
        let sizes = (0..types.len()).map(|_| r.u16("type size").map(usize::from)).collect::<Result<Vec<_>, _>>()?;
        r.align4();
        r.tag(b"STRC")?;
        let n = r.count("struct count")?;
        let mut structs = HashMap::with_capacity(n);
        for _ in 0..n {
            let ty = usize::from(r.u16("struct type")?);
            let fields_n = usize::from(r.u16("struct field count")?);
            let struct_name = *types.get(ty).ok_or_else(|| DnaError::Inconsistent(format!("struct type {ty}")))?;
            let mut offset = 0usize;
            let mut fields = HashMap::with_capacity(fields_n);
            for _ in 0..fields_n {
                let fty = usize::from(r.u16("field type")?);
                let fname = usize::from(r.u16("field name")?);
                let name = *names.get(fname).ok_or_else(|| DnaError::Inconsistent(format!("field name {fname}")))?;
                let pointer = name.starts_with('*') || name.starts_with("(*");
                let unit = if pointer {
                    POINTER_SIZE
                } else {
                    *sizes.get(fty).ok_or_else(|| DnaError::Inconsistent(format!("field type {fty}")))?
                };
                let size = unit.checked_mul(array_len(name)?).ok_or_else(|| DnaError::Inconsistent(name.into()))?;
                fields.insert(bare_name(name).to_string(), Field { offset, size, pointer });
                offset += size;
            }
            let size = sizes[ty];
            // Blender's DNA structs are padded explicitly, so the fields fill the struct exactly.
            if offset != size {
                return Err(DnaError::Inconsistent(format!(
                    "the fields of {struct_name} take {offset} bytes but the struct has {size}"
                )));
            }
            structs.insert(struct_name.to_string(), Struct { size, fields });
        }
        Ok(Self { structs })
    }

    fn strukt(&self, name: &str) -> Result<&Struct, DnaError> {
        self.structs.get(name).ok_or_else(|| DnaError::NoStruct(name.into()))
    }

    /// Size in bytes of a struct.
    pub fn struct_size(&self, name: &str) -> Result<usize, DnaError> {
        Ok(self.strukt(name)?.size)
    }

    /// The first of `names` that `strukt` has (give a field's current and older names).
    pub fn field(&self, strukt: &str, names: &[&str]) -> Result<Field, DnaError> {
        let s = self.strukt(strukt)?;
        names.iter().find_map(|n| s.fields.get(*n).copied()).ok_or_else(|| DnaError::NoField {
            strukt: strukt.into(),
            names: names.iter().map(|n| n.to_string()).collect(),
        })
    }

    /// Offset of the first of `names` in `strukt`, checked to be `size` bytes of plain data (a
    /// number or an array of numbers, not a pointer).
    pub fn number(&self, strukt: &str, names: &[&str], size: usize) -> Result<usize, DnaError> {
        let f = self.field(strukt, names)?;
        if f.size != size || f.pointer {
            return Err(DnaError::Inconsistent(format!("{strukt}.{} is not a {size}-byte number", names[0])));
        }
        Ok(f.offset)
    }

    /// Offset and size of the field `name` of `strukt`, checked to be a character array (a
    /// fixed-size C string).
    pub fn chars(&self, strukt: &str, name: &str) -> Result<(usize, usize), DnaError> {
        let f = self.field(strukt, &[name])?;
        if f.pointer || f.size == 0 {
            return Err(DnaError::Inconsistent(format!("{strukt}.{name} is not a character array")));
        }
        Ok((f.offset, f.size))
    }

    /// Offset of the first of `names` in `strukt`, checked to be one pointer.
    pub fn pointer(&self, strukt: &str, names: &[&str]) -> Result<usize, DnaError> {
        let f = self.field(strukt, names)?;
        if f.size != POINTER_SIZE || !f.pointer {
            return Err(DnaError::Inconsistent(format!("{strukt}.{} is not a pointer", names[0])));
        }
        Ok(f.offset)
    }

    /// Offset of the first of `names` in `strukt`, checked to be an embedded `inner` struct.
    pub fn embedded(&self, strukt: &str, names: &[&str], inner: &str) -> Result<usize, DnaError> {
        let f = self.field(strukt, names)?;
        if f.pointer || f.size != self.struct_size(inner)? {
            return Err(DnaError::Inconsistent(format!("{strukt}.{} is not a {inner}", names[0])));
        }
        Ok(f.offset)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-built DNA1 block: structs `Inner { int a; float *p; }` and
    /// `Outer { char name[6]; short pad; Inner in; Inner *list; }`.
    pub(crate) fn sample_dna() -> Vec<u8> {
        let mut d = Vec::new();
        d.extend_from_slice(b"SDNANAME");
        let names = ["a", "*p", "name[6]", "pad", "in", "*list"];
        d.extend_from_slice(&(names.len() as i32).to_le_bytes());
        for n in names {
            d.extend_from_slice(n.as_bytes());
            d.push(0);
        }
        while d.len() % 4 != 0 {
            d.push(0);
        }
        d.extend_from_slice(b"TYPE");
        let types = ["char", "short", "int", "float", "Inner", "Outer"];
        d.extend_from_slice(&(types.len() as i32).to_le_bytes());
        for t in types {
            d.extend_from_slice(t.as_bytes());
            d.push(0);
        }
        while d.len() % 4 != 0 {
            d.push(0);
        }
        d.extend_from_slice(b"TLEN");
        for s in [1u16, 2, 4, 4, 16, 32] {
            d.extend_from_slice(&s.to_le_bytes());
        }
        while d.len() % 4 != 0 {
            d.push(0);
        }
        d.extend_from_slice(b"STRC");
        d.extend_from_slice(&2i32.to_le_bytes());
        // Inner: int a (4) + pad? -> a at 0, *p at 4... 4 + 8 = 12: add an int pad via name "a" again.
        let inner: [(u16, u16); 3] = [(2, 0), (2, 3), (3, 1)]; // int a; int pad; float *p
        d.extend_from_slice(&4u16.to_le_bytes());
        d.extend_from_slice(&(inner.len() as u16).to_le_bytes());
        for (t, n) in inner {
            d.extend_from_slice(&t.to_le_bytes());
            d.extend_from_slice(&n.to_le_bytes());
        }
        let outer: [(u16, u16); 4] = [(0, 2), (1, 3), (4, 4), (4, 5)]; // char name[6]; short pad; Inner in; Inner *list
        d.extend_from_slice(&5u16.to_le_bytes());
        d.extend_from_slice(&(outer.len() as u16).to_le_bytes());
        for (t, n) in outer {
            d.extend_from_slice(&t.to_le_bytes());
            d.extend_from_slice(&n.to_le_bytes());
        }
        d
    }

    fn file_with(dna: &[u8], large: bool) -> Vec<u8> {
        let mut f = Vec::new();
        if large {
            f.extend_from_slice(b"BLENDER17-01v0500");
        } else {
            f.extend_from_slice(b"BLENDER-v402");
        }
        let block = |f: &mut Vec<u8>, code: &[u8; 4], data: &[u8]| {
            f.extend_from_slice(code);
            if large {
                f.extend_from_slice(&0i32.to_le_bytes());
                f.extend_from_slice(&0u64.to_le_bytes());
                f.extend_from_slice(&(data.len() as i64).to_le_bytes());
                f.extend_from_slice(&1i64.to_le_bytes());
            } else {
                f.extend_from_slice(&(data.len() as i32).to_le_bytes());
                f.extend_from_slice(&0u64.to_le_bytes());
                f.extend_from_slice(&0i32.to_le_bytes());
                f.extend_from_slice(&1i32.to_le_bytes());
            }
            f.extend_from_slice(data);
        };
        block(&mut f, b"GLOB", &[7u8; 40]);
        block(&mut f, b"DNA1", dna);
        block(&mut f, b"ENDB", &[]);
        f
    }

    #[test]
    fn offsets_and_sizes_follow_the_fields() {
        for large in [false, true] {
            let sdna = Sdna::from_blend_file(&file_with(&sample_dna(), large)).unwrap();
            assert_eq!(sdna.struct_size("Inner").unwrap(), 16);
            assert_eq!(sdna.field("Inner", &["p"]).unwrap(), Field { offset: 8, size: 8, pointer: true });
            assert_eq!(sdna.field("Outer", &["name"]).unwrap(), Field { offset: 0, size: 6, pointer: false });
            assert_eq!(sdna.field("Outer", &["in"]).unwrap().offset, 8);
            assert_eq!(
                sdna.field("Outer", &["renamed", "list"]).unwrap(),
                Field { offset: 24, size: 8, pointer: true }
            );
        }
    }

    #[test]
    fn typed_fields_are_checked() {
        let sdna = Sdna::parse(&sample_dna()).unwrap();
        assert_eq!(sdna.number("Inner", &["a"], 4), Ok(0));
        assert_eq!(sdna.number("Outer", &["name"], 6), Ok(0));
        assert!(matches!(sdna.number("Inner", &["a"], 2), Err(DnaError::Inconsistent(_))));
        assert!(matches!(sdna.number("Inner", &["p"], 8), Err(DnaError::Inconsistent(_))));
        assert_eq!(sdna.pointer("Outer", &["list"]), Ok(24));
        assert!(matches!(sdna.pointer("Inner", &["a"]), Err(DnaError::Inconsistent(_))));
        assert_eq!(sdna.embedded("Outer", &["in"], "Inner"), Ok(8));
        assert!(matches!(sdna.embedded("Outer", &["list"], "Inner"), Err(DnaError::Inconsistent(_))));
    }

    #[test]
    fn missing_things_are_named() {
        let sdna = Sdna::parse(&sample_dna()).unwrap();
        assert_eq!(sdna.struct_size("Mesh"), Err(DnaError::NoStruct("Mesh".into())));
        let e = sdna.field("Inner", &["b", "c"]).unwrap_err();
        assert_eq!(e.to_string(), "struct Inner has none of the fields b, c");
    }

    #[test]
    fn bad_files_are_refused_without_panicking() {
        let good = file_with(&sample_dna(), false);
        assert!(matches!(Sdna::from_blend_file(b"hello"), Err(DnaError::NotABlendFile(_))));
        assert!(matches!(
            Sdna::from_blend_file(&[0x1f, 0x8b, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
            Err(DnaError::NotABlendFile(_))
        ));
        let mut small = good.clone();
        small[7] = b'_';
        assert!(matches!(Sdna::from_blend_file(&small), Err(DnaError::Unsupported(_))));
        // Every truncation fails cleanly.
        for cut in 0..good.len() {
            let _ = Sdna::from_blend_file(&good[..cut]);
        }
        // And so does every single-byte corruption of the DNA.
        let dna = sample_dna();
        for i in 0..dna.len() {
            for v in [0u8, 0xff, 0x7f] {
                let mut bad = dna.clone();
                bad[i] = v;
                let _ = Sdna::parse(&bad);
            }
        }
    }

    #[test]
    fn field_sizes_must_add_up() {
        let mut dna = sample_dna();
        // TLEN of Outer: make it 40 instead of 32.
        let tlen = dna.windows(4).position(|w| w == b"TLEN").unwrap() + 4;
        dna[tlen + 10] = 40;
        assert!(matches!(Sdna::parse(&dna), Err(DnaError::Inconsistent(_))));
    }
}

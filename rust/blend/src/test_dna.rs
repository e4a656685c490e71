//! Hand-built SDNA blocks for tests: structs declared field by field, sizes summed as Blender's
//! explicitly padded DNA structs are.

/// An SDNA under construction: primitive types, opaque types and structs.
pub(crate) struct Dna {
    names: Vec<String>,
    types: Vec<(String, u16)>,
    structs: Vec<(u16, Vec<(u16, u16)>)>,
}

impl Dna {
    pub fn new() -> Self {
        let mut dna = Self { names: Vec::new(), types: Vec::new(), structs: Vec::new() };
        for (t, size) in [("char", 1), ("uchar", 1), ("short", 2), ("int", 4), ("float", 4), ("void", 0)] {
            dna.opaque(t, size);
        }
        dna
    }

    /// A type that is not a struct of this SDNA (a primitive, or a struct only pointed to).
    pub fn opaque(&mut self, name: &str, size: u16) -> &mut Self {
        self.types.push((name.into(), size));
        self
    }

    fn type_index(&self, name: &str) -> u16 {
        self.types.iter().position(|t| t.0 == name).unwrap_or_else(|| panic!("type {name} not declared")) as u16
    }

    fn name_index(&mut self, name: &str) -> u16 {
        match self.names.iter().position(|n| n == name) {
            Some(i) => i as u16,
            None => {
                self.names.push(name.into());
                (self.names.len() - 1) as u16
            }
        }
    }

    /// A struct with `fields` (type, name as the SDNA spells it: `*p`, `mat[4][4]`), its size the
    /// sum of theirs. Types only pointed to need not be declared (they are, as opaque, until a
    /// struct of that name is).
    pub fn strukt(&mut self, name: &str, fields: &[(&str, &str)]) -> &mut Self {
        let mut size = 0usize;
        let mut entries = Vec::new();
        for (ty, field) in fields {
            let pointer = field.starts_with('*');
            if pointer && !self.types.iter().any(|t| t.0 == *ty) {
                self.opaque(ty, 0);
            }
            let t = self.type_index(ty);
            let unit = if pointer { 8 } else { self.types[t as usize].1 as usize };
            let count: usize =
                field.split('[').skip(1).map(|d| d.trim_end_matches(']').parse::<usize>().unwrap()).product();
            size += unit * count;
            entries.push((t, self.name_index(field)));
        }
        let index = match self.types.iter().position(|t| t.0 == name) {
            Some(i) => {
                self.types[i].1 = size as u16;
                i
            }
            None => {
                self.types.push((name.into(), size as u16));
                self.types.len() - 1
            }
        };
        self.structs.push((index as u16, entries));
        self
    }

    /// The DNA1 block's contents.
    pub fn bytes(&self) -> Vec<u8> {
        let mut d = Vec::new();
        let pad = |d: &mut Vec<u8>| {
            while !d.len().is_multiple_of(4) {
                d.push(0)
            }
        };
        d.extend_from_slice(b"SDNANAME");
        d.extend_from_slice(&(self.names.len() as i32).to_le_bytes());
        for n in &self.names {
            d.extend_from_slice(n.as_bytes());
            d.push(0);
        }
        pad(&mut d);
        d.extend_from_slice(b"TYPE");
        d.extend_from_slice(&(self.types.len() as i32).to_le_bytes());
        for (t, _) in &self.types {
            d.extend_from_slice(t.as_bytes());
            d.push(0);
        }
        pad(&mut d);
        d.extend_from_slice(b"TLEN");
        for (_, size) in &self.types {
            d.extend_from_slice(&size.to_le_bytes());
        }
        pad(&mut d);
        d.extend_from_slice(b"STRC");
        d.extend_from_slice(&(self.structs.len() as i32).to_le_bytes());
        for (t, fields) in &self.structs {
            d.extend_from_slice(&t.to_le_bytes());
            d.extend_from_slice(&(fields.len() as u16).to_le_bytes());
            for (a, b) in fields {
                d.extend_from_slice(&a.to_le_bytes());
                d.extend_from_slice(&b.to_le_bytes());
            }
        }
        d
    }
}

//! Each vertex's number of influences, stored in as few bits as the largest needs.

/// Per-vertex counts, packed by the largest: two to a byte when every count is below 16 (most
/// characters: 4 or 8 influences at most), one to a byte below 256, else 16 bits (the most
/// allowed is 4096). A crowd keeps one set of influences per character, so every byte a vertex
/// is a byte per vertex of every character.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Counts {
    Nibbles { packed: Vec<u8>, len: usize },
    Bytes(Vec<u8>),
    Words(Vec<u16>),
}

impl Counts {
    /// `counts` packed; `max` is their largest (at most `u16::MAX`).
    pub(crate) fn pack(counts: impl ExactSizeIterator<Item = u16>, max: usize) -> Self {
        let len = counts.len();
        if max < 16 {
            let mut packed = vec![0u8; len.div_ceil(2)];
            for (v, c) in counts.enumerate() {
                // (Below 16: one nibble, the low one for even vertices.)
                packed[v / 2] |= (c as u8) << (4 * (v % 2));
            }
            Self::Nibbles { packed, len }
        } else if max < 256 {
            Self::Bytes(counts.map(|c| c as u8).collect())
        } else {
            Self::Words(counts.collect())
        }
    }

    #[inline]
    pub(crate) fn len(&self) -> usize {
        match self {
            Self::Nibbles { len, .. } => *len,
            Self::Bytes(c) => c.len(),
            Self::Words(c) => c.len(),
        }
    }

    /// The count of vertex `v` (below `len()`).
    #[inline]
    pub(crate) fn get(&self, v: usize) -> usize {
        match self {
            Self::Nibbles { packed, .. } => usize::from((packed[v / 2] >> (4 * (v % 2))) & 0xF),
            Self::Bytes(c) => usize::from(c[v]),
            Self::Words(c) => usize::from(c[v]),
        }
    }

    /// Bytes held on the heap.
    pub(crate) fn heap_bytes(&self) -> usize {
        match self {
            Self::Nibbles { packed, .. } => packed.capacity(),
            Self::Bytes(c) => c.capacity(),
            Self::Words(c) => c.capacity() * 2,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Counts;

    fn round_trip(counts: &[u16]) -> Counts {
        let max = counts.iter().copied().max().unwrap_or(0) as usize;
        let packed = Counts::pack(counts.iter().copied(), max);
        assert_eq!(packed.len(), counts.len());
        for (v, &c) in counts.iter().enumerate() {
            assert_eq!(packed.get(v), usize::from(c), "vertex {v}");
        }
        packed
    }

    #[test]
    fn each_width_gives_every_count_back() {
        // Odd lengths (the last byte half used), every boundary value of each width.
        assert!(matches!(round_trip(&[0, 15, 1, 7, 15]), Counts::Nibbles { .. }));
        assert!(matches!(round_trip(&[16, 0, 255, 3]), Counts::Bytes(_)));
        assert!(matches!(round_trip(&[256, 0, 4096, 65535, 1]), Counts::Words(_)));
        assert!(matches!(round_trip(&[]), Counts::Nibbles { .. }));
    }

    #[test]
    fn nibbles_take_half_a_byte_a_vertex() {
        let counts: Vec<u16> = (0..3273).map(|v| (v % 5) as u16).collect();
        assert_eq!(round_trip(&counts).heap_bytes(), 1637);
    }
}

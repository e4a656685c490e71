//! A fast digest of words, for telling what changed (poses, bindings, an object's state): not
//! for anything adversarial.

use glam::Mat4;

/// A fast word-by-word digest: FxHash's step on four interleaved lanes (word `i` into lane
/// `i % 4`, so that four steps are in flight rather than one chain), the lanes then stepped into
/// one, with a final mix. Each step is a bijection of the state for a fixed word and of the word
/// for a fixed state, so changing any single word always changes the result; unrelated inputs
/// collide with probability about 2⁻⁶⁴.
#[derive(Clone, Default)]
pub struct Digest {
    lanes: [u64; 4],
    words: u64,
}

/// Words from which a digest steps its lanes four at a time (below, the setup costs more than
/// it saves: a matrix is 8 words).
const WORDS_IN_BLOCKS_FROM: usize = 32;

impl Digest {
    const K: u64 = 0x517c_c1b7_2722_0a95;

    /// A digest whose lanes start at `seed`: digests of different seeds are unrelated functions
    /// of the same words (two of them make a 128-bit digest).
    pub fn seeded(seed: u64) -> Self {
        Self { lanes: [seed; 4], words: 0 }
    }

    fn step(state: u64, w: u64) -> u64 {
        (state.rotate_left(5) ^ w).wrapping_mul(Self::K)
    }

    pub fn word(&mut self, w: u64) {
        let lane = &mut self.lanes[(self.words % 4) as usize];
        *lane = Self::step(*lane, w);
        self.words += 1;
    }

    pub fn floats(&mut self, v: &[f32]) {
        let word = |p: &[f32]| u64::from(p[0].to_bits()) | u64::from(p.get(1).map_or(0, |f| f.to_bits())) << 32;
        if v.len() < 2 * WORDS_IN_BLOCKS_FROM {
            v.chunks(2).for_each(|pair| self.word(word(pair)));
            self.word(v.len() as u64);
            return;
        }
        let mut rest = v;
        while !self.words.is_multiple_of(4) && rest.len() >= 2 {
            self.word(word(&rest[..2]));
            rest = &rest[2..];
        }
        let mut blocks = rest.chunks_exact(8);
        self.blocks(blocks.by_ref().map(|b| [word(&b[0..2]), word(&b[2..4]), word(&b[4..6]), word(&b[6..8])]));
        for pair in blocks.remainder().chunks(2) {
            self.word(word(pair));
        }
        self.word(v.len() as u64);
    }

    pub fn matrix(&mut self, m: &Mat4) {
        self.floats(&m.to_cols_array());
    }

    pub fn bytes(&mut self, b: &[u8]) {
        let word = |w: &[u8]| u64::from_le_bytes(w.try_into().expect("8 bytes"));
        let (whole, tail) = b.split_at(b.len() - b.len() % 8);
        if whole.len() < 8 * WORDS_IN_BLOCKS_FROM {
            whole.chunks_exact(8).for_each(|w| self.word(word(w)));
        } else {
            let mut rest = whole;
            while !self.words.is_multiple_of(4) {
                self.word(word(&rest[..8]));
                rest = &rest[8..];
            }
            let mut blocks = rest.chunks_exact(32);
            self.blocks(blocks.by_ref().map(|b| [word(&b[0..8]), word(&b[8..16]), word(&b[16..24]), word(&b[24..32])]));
            blocks.remainder().chunks_exact(8).for_each(|w| self.word(word(w)));
        }
        if !tail.is_empty() {
            let mut w = [0u8; 8];
            w[..tail.len()].copy_from_slice(tail);
            self.word(u64::from_le_bytes(w));
        }
        self.word(b.len() as u64);
    }

    /// Blocks of four words, the first to lane 0 (the words so far a multiple of four): the
    /// same as [`Digest::word`] on each, with the lanes in registers.
    fn blocks(&mut self, blocks: impl Iterator<Item = [u64; 4]>) {
        debug_assert!(self.words.is_multiple_of(4));
        let mut lanes = self.lanes;
        let mut n = 0;
        for block in blocks {
            for (lane, w) in lanes.iter_mut().zip(block) {
                *lane = Self::step(*lane, w);
            }
            n += 4;
        }
        self.lanes = lanes;
        self.words += n;
    }

    pub fn finish(&self) -> u64 {
        let mut z = self.lanes.iter().fold(Self::step(0, self.words), |h, &lane| Self::step(h, lane));
        // splitmix64's finalizer, so that nearby inputs give unrelated outputs.
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn of(b: &[u8], seed: u64) -> u64 {
        let mut h = Digest::seeded(seed);
        h.bytes(b);
        h.finish()
    }

    /// The block paths give what one word at a time gives, from any starting word.
    #[test]
    fn blocks_equal_words_one_at_a_time() {
        let b: Vec<u8> = (0..403).map(|i| (i * 91 + 7) as u8).collect();
        let f: Vec<f32> = (0..177).map(|i| i as f32 * 0.37 - 5.0).collect();
        for lead in 0..5 {
            let (mut fast, mut slow) = (Digest::seeded(3), Digest::seeded(3));
            for w in 0..lead {
                fast.word(w);
                slow.word(w);
            }
            fast.bytes(&b);
            fast.floats(&f);
            for chunk in b.chunks(8) {
                let mut w = [0u8; 8];
                w[..chunk.len()].copy_from_slice(chunk);
                slow.word(u64::from_le_bytes(w));
            }
            slow.word(b.len() as u64);
            for pair in f.chunks(2) {
                slow.word(u64::from(pair[0].to_bits()) | u64::from(pair.get(1).map_or(0, |x| x.to_bits())) << 32);
            }
            slow.word(f.len() as u64);
            assert_eq!(fast.finish(), slow.finish(), "{lead}");
        }
    }

    /// Every single bit changed, in whole words and in the tail, changes the digest; so do
    /// trailing zero bytes (the length is digested) and the seed.
    #[test]
    fn any_change_changes_the_digest() {
        for len in [0, 1, 7, 8, 9, 31, 32, 33, 100, 300] {
            let b: Vec<u8> = (0..len).map(|i| (i * 37 + 11) as u8).collect();
            let d = of(&b, 0);
            assert_ne!(d, of(&b, 1), "{len}");
            for i in 0..len {
                for bit in 0..8 {
                    let mut c = b.clone();
                    c[i] ^= 1 << bit;
                    assert_ne!(of(&c, 0), d, "{len} {i} {bit}");
                }
            }
            let mut longer = b.clone();
            longer.push(0);
            assert_ne!(of(&longer, 0), d, "{len}");
        }
    }
}

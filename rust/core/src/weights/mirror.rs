//! Mirroring weights across the X = 0 plane by bone name: a vertex on the −X side takes the
//! weights of its mirror image on the +X side, each bone replaced by its mirrored namesake
//! (`hand.L` ↔ `hand.R`, as Blender names sides), and a vertex on the plane gets the mean of its
//! weights and their mirror, so both sides bend alike.

use std::collections::HashMap;

use glam::Vec3;

use super::sparse::{self, Pair};

/// Side markers Blender recognizes after (or before) a separator, and the words it flips.
const SEPARATORS: [char; 4] = ['.', '_', '-', ' '];
const WORDS: [(&str, &str); 3] = [("Left", "Right"), ("left", "right"), ("LEFT", "RIGHT")];

fn flip_letter(c: char) -> Option<char> {
    match c {
        'L' => Some('R'),
        'R' => Some('L'),
        'l' => Some('r'),
        'r' => Some('l'),
        _ => None,
    }
}

/// The name of the bone on the other side (`hand.L` → `hand.R`, `L_hand` → `R_hand`,
/// `hand.L.001` → `hand.R.001`, `LeftHand` → `RightHand`), or `None` for a name with no side.
pub fn mirrored_name(name: &str) -> Option<String> {
    // A trailing number (`.001`) is kept as it is.
    let (stem, number) = match name.rfind('.') {
        Some(i) if i + 1 < name.len() && name[i + 1..].bytes().all(|b| b.is_ascii_digit()) => name.split_at(i),
        _ => (name, ""),
    };
    let chars: Vec<char> = stem.chars().collect();
    let n = chars.len();
    // Suffix: separator + side letter.
    if n >= 2 && SEPARATORS.contains(&chars[n - 2]) {
        if let Some(f) = flip_letter(chars[n - 1]) {
            let mut out: String = chars[..n - 1].iter().collect();
            out.push(f);
            return Some(out + number);
        }
    }
    // Prefix: side letter + separator.
    if n >= 2 && SEPARATORS.contains(&chars[1]) {
        if let Some(f) = flip_letter(chars[0]) {
            let rest: String = chars[1..].iter().collect();
            return Some(format!("{f}{rest}{number}"));
        }
    }
    // Whole words at either end.
    for (a, b) in WORDS {
        for (from, to) in [(a, b), (b, a)] {
            if let Some(rest) = stem.strip_prefix(from) {
                return Some(format!("{to}{rest}{number}"));
            }
            if let Some(rest) = stem.strip_suffix(from) {
                return Some(format!("{rest}{to}{number}"));
            }
        }
    }
    None
}

/// For each bone, the index of its mirrored namesake (itself when it has none, or when that
/// name is not among `names`).
pub fn mirror_bone_map(names: &[&str]) -> Vec<u32> {
    let index: HashMap<&str, u32> = names.iter().enumerate().map(|(i, n)| (*n, i as u32)).collect();
    names
        .iter()
        .enumerate()
        .map(|(i, n)| mirrored_name(n).and_then(|m| index.get(m.as_str()).copied()).unwrap_or(i as u32))
        .collect()
}

/// Mirrors `lists` (one per vertex at `positions`) with `bone_map`: a vertex on the plane (within
/// a thousandth of `tolerance`) gets the mean of its weights and their mirror; a vertex on the −X
/// side takes the mirrored weights of the vertex nearest its mirror image on the other side, if
/// one is within `tolerance` (else it keeps its own).
pub(crate) fn mirror(lists: &mut [Vec<Pair>], positions: &[[f32; 3]], bone_map: &[u32], tolerance: f32, k: usize) {
    let tolerance = tolerance.max(f32::MIN_POSITIVE);
    let plane = tolerance * 1e-3;
    let flip = |pairs: &[Pair]| -> Vec<Pair> { pairs.iter().map(|&(b, w)| (bone_map[b as usize], w)).collect() };
    for (i, p) in positions.iter().enumerate() {
        if p[0].abs() <= plane {
            let mut both: Vec<Pair> = lists[i].iter().chain(flip(&lists[i]).iter()).copied().collect();
            sparse::merge_repeated(&mut both);
            sparse::keep_strongest(&mut both, usize::MAX);
            // A mirrored pair weighs the same: keep both or neither, so the vertex stays symmetric.
            let mut cut = k.min(both.len());
            while cut > 1 && cut < both.len() && both[cut - 1].1 == both[cut].1 {
                cut -= 1;
            }
            both.truncate(cut);
            if sparse::normalize(&mut both) {
                lists[i] = both;
            }
        }
    }
    let key = |p: Vec3| (p / tolerance).floor().as_ivec3().to_array();
    let mut cells: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
    for (i, p) in positions.iter().enumerate() {
        if p[0] >= -plane {
            cells.entry(key(Vec3::from_array(*p))).or_default().push(i as u32);
        }
    }
    for (i, p) in positions.iter().enumerate() {
        let p = Vec3::from_array(*p);
        if p.x >= -plane {
            continue;
        }
        let image = Vec3::new(-p.x, p.y, p.z);
        let [cx, cy, cz] = key(image);
        let mut best: Option<(f32, u32)> = None;
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    for &j in cells.get(&[cx + dx, cy + dy, cz + dz]).map(Vec::as_slice).unwrap_or(&[]) {
                        let d = Vec3::from_array(positions[j as usize]).distance(image);
                        if d <= tolerance && best.is_none_or(|(bd, bj)| d < bd || (d == bd && j < bj)) {
                            best = Some((d, j));
                        }
                    }
                }
            }
        }
        if let Some((_, j)) = best {
            lists[i] = flip(&lists[j as usize]);
        }
    }
}

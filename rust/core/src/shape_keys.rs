//! Shape keys as Blender mixes them before any modifier (`BKE_key_evaluate_object_ex` for
//! meshes with relative keys), so that the coordinates reaching a skinning modifier can be
//! computed without evaluating the mesh.
//!
//! Relative keys: start from the reference (basis) key's coordinates, then for each other key
//! in order that is not muted, has a non-zero value and as many points as the mesh:
//! `out -= w·(relative − key)` per coordinate, with `w = value` or `value · group weight` when
//! the key has a vertex group. A key whose relative key does not exist is skipped.
//! With *Shape Key Lock* (`Object.show_only_shape_key`) only the shown key is used:
//! `out = key`, or with a vertex group `out = reference − w·(reference − key)` (`w ≠ 0`).
//! The float operations follow Blender's order exactly.

/// One shape key, in the key's block order.
#[derive(Clone, Copy, Debug)]
pub struct KeyBlock<'a> {
    /// Its coordinates (`KeyBlock.data`), one per point.
    pub data: &'a [[f32; 3]],
    /// Index of the key it is relative to (`KeyBlock.relative_key`).
    pub relative_to: usize,
    /// Its current value (`KeyBlock.value`, Blender's `curval`).
    pub value: f32,
    /// `KeyBlock.mute`.
    pub muted: bool,
    /// Per-point weights of its vertex group, if it has one that exists.
    pub weights: Option<&'a [f32]>,
}

/// Why keys could not be mixed the way Blender mixes them.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ShapeKeyError {
    /// The reference key is not one of the blocks.
    NoReference { reference: usize, blocks: usize },
    /// The reference key's point count differs from the output's (Blender would then resample
    /// it; callers should use the evaluated mesh instead).
    ReferencePoints { expected: usize, got: usize },
    /// A vertex-group weight array has the wrong length.
    WeightsLength { block: usize, expected: usize, got: usize },
}

impl core::fmt::Display for ShapeKeyError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ShapeKeyError::NoReference { reference, blocks } => {
                write!(f, "reference key {reference} does not exist (there are {blocks} keys)")
            }
            ShapeKeyError::ReferencePoints { expected, got } => {
                write!(f, "the reference key has {got} points but out has {expected}")
            }
            ShapeKeyError::WeightsLength { block, expected, got } => {
                write!(f, "key {block}: its vertex group weights have {got} entries, expected {expected}")
            }
        }
    }
}

impl std::error::Error for ShapeKeyError {}

fn check(blocks: &[KeyBlock<'_>], reference: usize, points: usize) -> Result<(), ShapeKeyError> {
    let r = blocks.get(reference).ok_or(ShapeKeyError::NoReference { reference, blocks: blocks.len() })?;
    if r.data.len() != points {
        return Err(ShapeKeyError::ReferencePoints { expected: points, got: r.data.len() });
    }
    for (i, b) in blocks.iter().enumerate() {
        if let Some(w) = b.weights {
            if w.len() != b.data.len() {
                return Err(ShapeKeyError::WeightsLength { block: i, expected: b.data.len(), got: w.len() });
            }
        }
    }
    Ok(())
}

/// Relative keys mixed into `out` (one entry per mesh vertex).
pub fn mix_relative(blocks: &[KeyBlock<'_>], reference: usize, out: &mut [[f32; 3]]) -> Result<(), ShapeKeyError> {
    check(blocks, reference, out.len())?;
    out.copy_from_slice(blocks[reference].data);
    for (i, kb) in blocks.iter().enumerate() {
        if i == reference || kb.muted || kb.value == 0.0 || kb.data.len() != out.len() {
            continue;
        }
        let Some(relative) = blocks.get(kb.relative_to) else { continue };
        // Blender reads the relative key's points one by one; one with fewer points than the
        // mesh would be read past its end there, so it is not used here.
        if relative.data.len() != out.len() {
            continue;
        }
        for (v, o) in out.iter_mut().enumerate() {
            let w = match kb.weights {
                Some(ws) => ws[v] * kb.value,
                None => kb.value,
            };
            for a in 0..3 {
                o[a] -= w * (relative.data[v][a] - kb.data[v][a]);
            }
        }
    }
    Ok(())
}

/// The one key shown with *Shape Key Lock*, into `out`.
pub fn mix_locked(
    blocks: &[KeyBlock<'_>],
    reference: usize,
    shown: usize,
    out: &mut [[f32; 3]],
) -> Result<(), ShapeKeyError> {
    check(blocks, reference, out.len())?;
    // Blender falls back to the reference key for a muted or missing shown key.
    let kb = match blocks.get(shown) {
        Some(kb) if !kb.muted => kb,
        _ => &blocks[reference],
    };
    if kb.data.len() != out.len() {
        return Err(ShapeKeyError::ReferencePoints { expected: out.len(), got: kb.data.len() });
    }
    let refd = blocks[reference].data;
    match kb.weights {
        None => out.copy_from_slice(kb.data),
        Some(ws) => {
            for (v, o) in out.iter_mut().enumerate() {
                *o = refd[v];
                if ws[v] != 0.0 {
                    for a in 0..3 {
                        o[a] -= ws[v] * (refd[v][a] - kb.data[v][a]);
                    }
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kb<'a>(data: &'a [[f32; 3]], relative_to: usize, value: f32) -> KeyBlock<'a> {
        KeyBlock { data, relative_to, value, muted: false, weights: None }
    }

    #[test]
    fn relative_keys_add_their_offsets() {
        let basis = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
        let up = [[0.0, 0.0, 1.0], [1.0, 0.0, 2.0]];
        let side = [[0.5, 0.0, 0.0], [1.5, 0.0, 0.0]];
        let mut out = [[9.0; 3]; 2];
        mix_relative(&[kb(&basis, 0, 0.0), kb(&up, 0, 0.5), kb(&side, 0, 2.0)], 0, &mut out).unwrap();
        assert_eq!(out, [[1.0, 0.0, 0.5], [2.0, 0.0, 1.0]]);
    }

    #[test]
    fn muted_zero_and_broken_keys_are_skipped() {
        let basis = [[0.0; 3]];
        let k = [[1.0, 1.0, 1.0]];
        let short: [[f32; 3]; 0] = [];
        let mut muted = kb(&k, 0, 1.0);
        muted.muted = true;
        let mut out = [[5.0; 3]];
        mix_relative(&[kb(&basis, 0, 1.0), muted, kb(&k, 0, 0.0), kb(&k, 7, 1.0), kb(&short, 0, 1.0)], 0, &mut out)
            .unwrap();
        assert_eq!(out, [[0.0; 3]]);
    }

    #[test]
    fn keys_relative_to_other_keys_and_groups() {
        let basis = [[0.0; 3], [0.0; 3]];
        let a = [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
        let b = [[1.0, 2.0, 0.0], [1.0, 2.0, 0.0]]; // relative to a: +2 in y
        let w = [1.0, 0.25];
        let mut kb_b = kb(&b, 1, 1.0);
        kb_b.weights = Some(&w);
        let mut out = [[0.0; 3]; 2];
        mix_relative(&[kb(&basis, 0, 0.0), kb(&a, 0, 0.0), kb_b], 0, &mut out).unwrap();
        assert_eq!(out, [[0.0, 2.0, 0.0], [0.0, 0.5, 0.0]]);
    }

    #[test]
    fn locked_shows_one_key() {
        let basis = [[0.0; 3], [0.0; 3]];
        let k = [[2.0, 0.0, 0.0], [4.0, 0.0, 0.0]];
        let w = [0.5, 0.0];
        let mut out = [[0.0; 3]; 2];
        mix_locked(&[kb(&basis, 0, 0.0), kb(&k, 0, 0.0)], 0, 1, &mut out).unwrap();
        assert_eq!(out, k);
        let mut g = kb(&k, 0, 0.0);
        g.weights = Some(&w);
        mix_locked(&[kb(&basis, 0, 0.0), g], 0, 1, &mut out).unwrap();
        assert_eq!(out, [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]);
        let mut m = kb(&k, 0, 0.0);
        m.muted = true;
        mix_locked(&[kb(&basis, 0, 0.0), m], 0, 1, &mut out).unwrap();
        assert_eq!(out, basis);
    }

    #[test]
    fn inconsistent_inputs_are_errors() {
        let basis = [[0.0; 3]];
        let mut out = [[0.0; 3]; 2];
        assert_eq!(
            mix_relative(&[kb(&basis, 0, 0.0)], 0, &mut out),
            Err(ShapeKeyError::ReferencePoints { expected: 2, got: 1 })
        );
        assert!(matches!(
            mix_relative(&[kb(&basis, 0, 0.0)], 3, &mut out[..1]),
            Err(ShapeKeyError::NoReference { .. })
        ));
        let w = [1.0, 1.0];
        let mut k = kb(&basis, 0, 1.0);
        k.weights = Some(&w);
        assert!(matches!(
            mix_relative(&[kb(&basis, 0, 0.0), k], 0, &mut out[..1]),
            Err(ShapeKeyError::WeightsLength { .. })
        ));
    }
}

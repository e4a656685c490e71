//! The order of vertices in the kernels' lanes. A 16-vertex batch has as many slots as its vertex
//! with the most influences, so a character whose neighbouring vertices have 1 to 4 influences
//! pads about a third of its slots with weight 0 (CesiumMan: 1.31× its pairs). Within windows
//! of [`WINDOW`] vertices the lanes may take the vertices by decreasing count instead, which
//! leaves almost no padding; each vertex then keeps its position in its window (a byte), and the
//! kernels copy a window's inputs into that order and its results back (`kernels.rs`). The order
//! is kept only where it saves more bytes than it costs; a vertex's result does not depend on
//! its lane, so both orders give the same bits.

use super::LANES;

/// Vertices that may change lanes among themselves: a position in a window fits a byte.
pub(crate) const WINDOW: usize = 256;
const _: () = assert!(WINDOW.is_multiple_of(LANES) && WINDOW <= 1 << 8);

/// Each vertex's position within its window, by decreasing count (ties in vertex order),
/// where that needs fewer bytes (slots of `slot_bytes` saved, against a byte a vertex) than
/// the vertex order; `None` where it does not. Counted, not sorted: influences made on every
/// frame (B-Bones, envelopes) pay this each time, and a window whose vertices all have one
/// count (a grid) is passed over at once.
pub(super) fn choose(counts: &[u16], slot_bytes: usize) -> Option<Box<[u8]>> {
    let in_vertex_order: usize = counts.chunks(LANES).map(longest).sum();
    // Each count's number of vertices in the window, then where its run starts by decreasing
    // count (sized for the largest count, cleared up to each window's).
    let mut run_start = vec![0u32; longest(counts) + 1];
    let mut in_window_order = 0;
    for window in counts.chunks(WINDOW) {
        in_window_order += sorted_batch_maxima(window, &mut run_start);
    }
    let saved = in_vertex_order.saturating_sub(in_window_order) * slot_bytes;
    if saved <= counts.len() {
        return None;
    }
    let mut position = vec![0u8; counts.len()].into_boxed_slice();
    for (window, positions) in counts.chunks(WINDOW).zip(position.chunks_mut(WINDOW)) {
        sorted_batch_maxima(window, &mut run_start);
        for (&count, p) in window.iter().zip(positions) {
            let at = &mut run_start[usize::from(count)];
            // Below WINDOW ≤ 256 (asserted above).
            *p = *at as u8;
            *at += 1;
        }
    }
    Some(position)
}

/// The sum of the longest count of each 16-vertex batch of `window` by decreasing count;
/// leaves in `run_start[c]` where count `c`'s run starts in that order.
fn sorted_batch_maxima(window: &[u16], run_start: &mut [u32]) -> usize {
    let most = longest(window);
    let runs = &mut run_start[..=most];
    runs.fill(0);
    for &c in window {
        runs[usize::from(c)] += 1;
    }
    // Runs by decreasing count; a batch's longest vertex is the first of it.
    let (mut at, mut sum) = (0u32, 0);
    for c in (0..=most).rev() {
        let n = runs[c];
        runs[c] = at;
        // The batches that start inside this run: at positions at, at + 16, … below at + n.
        let first_batch = at.div_ceil(LANES as u32);
        let end_batch = (at + n).div_ceil(LANES as u32);
        sum += (end_batch - first_batch) as usize * c;
        at += n;
    }
    sum
}

/// The vertex in each lane position: the inverse of [`choose`]'s positions (the identity
/// without them).
pub(super) fn vertex_at(position: Option<&[u8]>, vertices: usize) -> Vec<u32> {
    let mut at: Vec<u32> = (0..vertices as u32).collect();
    if let Some(position) = position {
        for (v, &p) in position.iter().enumerate() {
            at[in_window(window_start(v), p)] = v as u32;
        }
    }
    at
}

/// The lane position of vertex `v`.
#[inline]
pub(super) fn position_of(position: Option<&[u8]>, v: usize) -> usize {
    match position {
        Some(p) => in_window(window_start(v), p[v]),
        None => v,
    }
}

/// Position `p` of the window that starts at `start`. (The start goes through `black_box`: the
/// LLVM of Rust 1.95 compiles `start + p`, which it turns into `(v & !255) | p`, to `p` alone on
/// x86-64: `readback_tests` below fails without it, checked.)
#[inline]
fn in_window(start: usize, p: u8) -> usize {
    core::hint::black_box(start) + usize::from(p)
}

/// The first vertex of `v`'s window.
#[inline]
fn window_start(v: usize) -> usize {
    v / WINDOW * WINDOW
}

fn longest(batch: &[u16]) -> usize {
    batch.iter().copied().max().map_or(0, usize::from)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_counts_keep_the_vertex_order() {
        assert_eq!(choose(&[4; 1000], 80), None);
        assert_eq!(choose(&[], 80), None);
    }

    #[test]
    fn mixed_counts_take_lanes_by_decreasing_count_within_their_window() {
        // Counts 1..=4 in turn: every batch in vertex order needs 4 slots.
        let counts: Vec<u16> = (0..600).map(|v| 1 + (v % 4) as u16).collect();
        let position = choose(&counts, 80).expect("sorting saves here");
        let at = vertex_at(Some(&position), counts.len());
        // A permutation of each window onto itself.
        let mut seen = at.clone();
        seen.sort_unstable();
        assert!(seen.iter().copied().eq(0..600));
        for (p, &v) in at.iter().enumerate() {
            assert_eq!(p / WINDOW, v as usize / WINDOW, "vertex {v} left its window");
            assert_eq!(position_of(Some(&position), v as usize), p, "vertex {v} position {} ", position[v as usize]);
        }
        // Decreasing counts within a window, ties in vertex order.
        for window in at.chunks(WINDOW) {
            for pair in window.windows(2) {
                let (a, b) = (counts[pair[0] as usize], counts[pair[1] as usize]);
                assert!(a > b || (a == b && pair[0] < pair[1]));
            }
        }
        // The last window (88 vertices) is sorted too.
        assert_eq!(counts[at[512] as usize], 4);
    }

    #[test]
    fn counted_batch_maxima_equal_those_of_a_sorted_window() {
        let mut seed = 7u32;
        for n in [1usize, 15, 16, 17, 100, 255, 256] {
            for most in [1u32, 4, 15, 300, 4096] {
                let window: Vec<u16> = (0..n)
                    .map(|_| {
                        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                        ((seed >> 8) % (most + 1)) as u16
                    })
                    .collect();
                let mut sorted = window.clone();
                sorted.sort_unstable_by(|a, b| b.cmp(a));
                let want: usize = sorted.chunks(LANES).map(|b| usize::from(b[0])).sum();
                let mut runs = vec![0u32; 4097];
                assert_eq!(sorted_batch_maxima(&window, &mut runs), want, "{n} vertices, counts to {most}");
            }
        }
    }

    #[test]
    fn the_order_is_kept_only_where_it_saves_more_than_its_bytes() {
        // One vertex of 2 influences among 1s in each batch: sorting saves one slot a batch
        // minus one (the 2s share batches), 80 bytes each, against a byte a vertex.
        let counts: Vec<u16> = (0..256).map(|v| if v % 16 == 0 { 2 } else { 1 }).collect();
        assert!(choose(&counts, 80).is_some());
        // With 1-byte slots it would cost more than it saves.
        assert_eq!(choose(&counts, 1), None);
    }
}

#[cfg(test)]
mod readback_tests {
    use crate::skin::Influences;

    /// Every vertex's pairs read back from its lane, in every window (the position in a window
    /// plus the window's start), also through the kernels' batch layout of a release build.
    #[test]
    fn pairs_read_back_from_lanes_in_window_order_in_every_window() {
        let lists: Vec<Vec<(u32, f32)>> = (0..1000u32)
            .map(|v| (0..(v.wrapping_mul(2654435761) >> 28) % 5).map(|k| (k * 2 + v % 2, v as f32 + 0.5)).collect())
            .collect();
        let influences = Influences::from_lists(&lists, 10).unwrap();
        assert!(influences.lane_positions().is_some());
        for (v, want) in lists.iter().enumerate() {
            let got: Vec<(u32, f32)> = influences.of_vertex(v).map(|i| (i.bone, i.weight)).collect();
            assert_eq!(&got, want, "vertex {v}");
        }
        let entries: Vec<(u32, f32)> = influences.entries().iter().map(|i| (i.bone, i.weight)).collect();
        assert_eq!(entries, lists.concat());
    }
}

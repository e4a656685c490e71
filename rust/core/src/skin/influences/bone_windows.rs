//! Each batch's bone window: the lowest of its weighted bones where they all lie within
//! [`LANES`] consecutive bones (the AVX-512 LBS then sums the batch from that window's records,
//! `avx512/bone_window.rs`). Made on the first call that reads them, from the lane-ordered slots,
//! and kept: two bytes a batch of sixteen vertices, which influences that never skin with that
//! LBS (a crowd on Dual Quaternion) do not hold.

use std::sync::OnceLock;

use super::{BoneIndex, LaneSlots, Slot, LANES};

/// A batch whose weighted bones lie further apart than [`LANES`] consecutive ones.
const NONE: u16 = u16::MAX;

/// The windows of a set of influences, once made. Equal whether made or not: they follow from
/// the slots, which the influences compare.
#[derive(Clone, Debug, Default)]
pub(super) struct BoneWindows(OnceLock<Box<[u16]>>);

impl PartialEq for BoneWindows {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl BoneWindows {
    /// Each batch's window (see [`bone_window`]), made on the first call.
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code, reason = "only the AVX-512 LBS reads them"))]
    pub(super) fn get(&self, slots: &LaneSlots, batch_starts: &[u32]) -> &[u16] {
        self.0.get_or_init(|| match slots {
            LaneSlots::Narrow(s) => make(s, batch_starts),
            LaneSlots::Wide(s) => make(s, batch_starts),
        })
    }

    pub(super) fn heap_bytes(&self) -> usize {
        self.0.get().map_or(0, |w| w.len() * 2)
    }
}

/// The first of [`LANES`] consecutive bones that hold every weighted bone of batch `b`, if
/// there are such (0 for a batch with no weight at all); `windows` as [`BoneWindows::get`] gives
/// them.
#[inline]
pub(crate) fn bone_window(windows: &[u16], b: usize) -> Option<u32> {
    let first = windows[b];
    (first != NONE).then_some(u32::from(first))
}

#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code, reason = "only the AVX-512 LBS reads them"))]
fn make<I: BoneIndex>(slots: &[Slot<I>], batch_starts: &[u32]) -> Box<[u16]> {
    batch_starts
        .windows(2)
        .map(|at| {
            let mut span: Option<(u32, u32)> = None;
            for slot in &slots[at[0] as usize..at[1] as usize] {
                for (bone, weight) in slot.bones.iter().zip(&slot.weights) {
                    if *weight != 0.0 {
                        let b = bone.index() as u32;
                        span = Some(span.map_or((b, b), |(lo, hi)| (lo.min(b), hi.max(b))));
                    }
                }
            }
            match span {
                None => 0,
                // A window at bone 65535 would read as none: such a batch is summed per lane.
                Some((lowest, highest)) if highest - lowest < LANES as u32 && lowest < u32::from(NONE) => lowest as u16,
                Some(_) => NONE,
            }
        })
        .collect()
}

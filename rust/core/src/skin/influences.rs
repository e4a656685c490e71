//! Sparse per-vertex bone influences, validated once and kept in a cache-friendly layout.

use super::SkinError;

mod bone_windows;
mod counts;
mod lane_order;
pub(crate) use bone_windows::bone_window;
use bone_windows::BoneWindows;
use counts::Counts;
pub(crate) use lane_order::WINDOW;

/// The most influences one vertex may have. Sums of weights run in single precision as in
/// Blender (at most 4096 · 2⁻²⁴ ≈ 2.4e-4 relative error), and the lane layout pads a vertex's
/// 15 neighbours to its count (96 bytes per influence of the largest), so both stay bounded.
pub const MAX_INFLUENCES_PER_VERTEX: usize = 4096;
const _: () = assert!(MAX_INFLUENCES_PER_VERTEX <= u16::MAX as usize);

/// Vertices the kernels process together, one per SIMD lane.
pub(crate) const LANES: usize = 16;
const _: () = assert!(core::mem::size_of::<Slot<u16>>() == LANES * 6);
const _: () = assert!(core::mem::size_of::<Slot<u8>>() == LANES * 5);

/// The `k`-th influence of each of [`LANES`] consecutive vertices: a bone index and a weight of
/// 32 bits per lane, the index in 8 bits where the bones number at most 256 (80 bytes), else 16
/// (96). The kernels read them and little else, so every byte less here is time and memory.
/// Vertices with fewer than `k + 1` influences have bone 0 with weight 0 there, which adds
/// nothing to any sum.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(16))]
pub(crate) struct Slot<I: BoneIndex> {
    /// Each lane's bone index (its record in a pose table: [`lane_record`]).
    pub bones: [I; LANES],
    pub weights: [f32; LANES],
}

impl<I: BoneIndex> Slot<I> {
    const EMPTY: Self = Slot { bones: [I::ZERO; LANES], weights: [0.0; LANES] };
}

/// The width of the bone indices of [`Slot`]s: `u8` or `u16`. The kernels are compiled for both
/// (a character's 100 bones or a crowd's need only 8 bits; 16 bits name up to [`MAX_BONES`]).
pub(crate) trait BoneIndex: Copy + core::fmt::Debug + PartialEq + Send + Sync + 'static {
    const ZERO: Self;
    /// How many bones an index of this width can name.
    const BONES: usize;
    /// `bone`, below [`BoneIndex::BONES`] (the caller checked).
    fn narrow(bone: u32) -> Self;
    fn index(self) -> usize;
}

macro_rules! bone_index {
    ($($width:ty),*) => {$(
        impl BoneIndex for $width {
            const ZERO: Self = 0;
            const BONES: usize = 1 << <$width>::BITS;
            #[inline(always)]
            fn narrow(bone: u32) -> Self {
                debug_assert!((bone as usize) < Self::BONES);
                bone as $width
            }
            #[inline(always)]
            fn index(self) -> usize {
                usize::from(self)
            }
        }
    )*};
}
bone_index!(u8, u16);

/// The lane-ordered slots of a set of influences, in the narrowest index width their bone
/// count allows.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum LaneSlots {
    Narrow(Vec<Slot<u8>>),
    Wide(Vec<Slot<u16>>),
}

impl LaneSlots {
    fn len(&self) -> usize {
        match self {
            LaneSlots::Narrow(s) => s.len(),
            LaneSlots::Wide(s) => s.len(),
        }
    }

    /// Bytes of one slot.
    fn slot_bytes(&self) -> usize {
        match self {
            LaneSlots::Narrow(_) => core::mem::size_of::<Slot<u8>>(),
            LaneSlots::Wide(_) => core::mem::size_of::<Slot<u16>>(),
        }
    }

    fn capacity_bytes(&self) -> usize {
        match self {
            LaneSlots::Narrow(s) => s.capacity() * self.slot_bytes(),
            LaneSlots::Wide(s) => s.capacity() * self.slot_bytes(),
        }
    }

    /// Pair `k` of lane `lane`, as `(bone, weight)`.
    #[inline]
    fn pair(&self, k: usize, lane: usize) -> Influence {
        match self {
            LaneSlots::Narrow(s) => Influence { bone: u32::from(s[k].bones[lane]), weight: s[k].weights[lane] },
            LaneSlots::Wide(s) => Influence { bone: u32::from(s[k].bones[lane]), weight: s[k].weights[lane] },
        }
    }

    fn as_words(&self) -> &[u32] {
        let (ptr, bytes) = match self {
            LaneSlots::Narrow(s) => (s.as_ptr().cast::<u32>(), core::mem::size_of_val(s.as_slice())),
            LaneSlots::Wide(s) => (s.as_ptr().cast::<u32>(), core::mem::size_of_val(s.as_slice())),
        };
        // SAFETY: `Slot` is `repr(C)` with only integer and f32 fields and no padding (LANES·5
        // or LANES·6 bytes, multiples of its 16-byte alignment), so it is a sequence of 32-bit words.
        unsafe { core::slice::from_raw_parts(ptr, bytes / 4) }
    }
}

/// The most bones influences can refer to: a slot holds a bone index in at most 16 bits.
pub const MAX_BONES: usize = u16::MAX as usize + 1;

/// The first float of the record of `table` that a slot's entry `bone` names.
///
/// # Safety
/// `bone` indexes `table` (true of every slot entry of influences whose bone count is the
/// table's length: validated when they were built).
#[inline(always)]
pub(crate) unsafe fn lane_record<T, I: BoneIndex>(table: &[T], bone: I) -> *const f32 {
    debug_assert!(bone.index() < table.len());
    // SAFETY: the caller's contract: the record lies inside `table`.
    unsafe { table.as_ptr().add(bone.index()).cast() }
}

/// One `(bone, weight)` pair.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct Influence {
    pub bone: u32,
    pub weight: f32,
}

/// Per-vertex influences: vertex `v` has `offsets[v+1] − offsets[v]` pairs, **in the order
/// given** (the order matters for dual quaternion skinning, whose sign choice follows it, as in
/// Blender). They are kept once, in the kernels' lane order (16-vertex batches, each padded to
/// its vertex with the most pairs, in vertex order or by count within windows: `lane_order.rs`);
/// [`Influences::of_vertex`] reads a vertex's back from its lane.
///
/// Invariants (checked by [`Influences::from_csr`]): `offsets` starts at 0, never decreases and
/// ends at the number of entries; every bone index is below `bone_count`; every weight is finite
/// and non-negative. Weights need not sum to one and may be zero.
#[derive(Clone, Debug, PartialEq)]
pub struct Influences {
    /// Each vertex's number of pairs (at most [`MAX_INFLUENCES_PER_VERTEX`]), packed in as few
    /// bits as the largest needs (4 on most characters, an eighth of the CSR offsets they stand for).
    counts: Counts,
    pairs: usize,
    bone_count: usize,
    max_per_vertex: usize,
    /// The same influences in lane order for the kernels: batch `b` (lane positions `b·LANES ..`) has
    /// slots `batch_starts[b]..batch_starts[b+1]`, as many as its vertex with the most influences.
    slots: LaneSlots,
    batch_starts: Vec<u32>,
    /// Each batch's bone window, made for the AVX-512 LBS on its first call (`bone_windows.rs`).
    bone_windows: BoneWindows,
    /// Each vertex's lane position within its window of [`WINDOW`] vertices, where the lanes
    /// take them by decreasing count (`lane_order.rs`); `None`: in vertex order.
    lane_positions: Option<Box<[u8]>>,
}

impl Influences {
    /// Validates CSR arrays: `offsets` (length V+1), `bones` and `weights` (one per entry).
    pub fn from_csr(offsets: &[u32], bones: &[u32], weights: &[f32], bone_count: usize) -> Result<Self, SkinError> {
        let invalid = |what: String| Err(SkinError::InvalidInfluences(what));
        if offsets.is_empty() {
            return invalid("offsets must have one entry per vertex plus one (got an empty array)".into());
        }
        if bones.len() != weights.len() {
            return invalid(format!(
                "bones has {} entries but weights has {}: they must have one entry per influence",
                bones.len(),
                weights.len()
            ));
        }
        if bone_count > MAX_BONES {
            return invalid(format!("bone_count is {bone_count}; at most {MAX_BONES} bones are supported"));
        }
        if bones.len() > u32::MAX as usize {
            return invalid("more than 2^32-1 influences".into());
        }
        if offsets[0] != 0 {
            return invalid(format!("offsets[0] must be 0, got {}", offsets[0]));
        }
        let total = *offsets.last().unwrap() as usize;
        if total != bones.len() {
            return invalid(format!(
                "offsets[-1] is {total} but there are {} influences: it must equal the number of influences",
                bones.len()
            ));
        }
        let mut max_per_vertex = 0;
        for (v, w) in offsets.windows(2).enumerate() {
            if w[1] < w[0] {
                return invalid(format!(
                    "offsets must not decrease, but offsets[{}] = {} > offsets[{}] = {}",
                    v,
                    w[0],
                    v + 1,
                    w[1]
                ));
            }
            max_per_vertex = max_per_vertex.max((w[1] - w[0]) as usize);
        }
        if max_per_vertex > MAX_INFLUENCES_PER_VERTEX {
            let v = offsets.windows(2).position(|w| (w[1] - w[0]) as usize == max_per_vertex).unwrap_or(0);
            return invalid(format!(
                "vertex {v} has {max_per_vertex} influences; at most {MAX_INFLUENCES_PER_VERTEX} per vertex are supported"
            ));
        }
        if let Some(i) = bones.iter().position(|&b| b as usize >= bone_count) {
            return invalid(format!("bones[{i}] = {} is out of range: bone_count = {bone_count}", bones[i]));
        }
        if let Some(i) = weights.iter().position(|w| !(*w >= 0.0) || !w.is_finite()) {
            return invalid(format!("weights[{i}] = {} is not a finite non-negative number", weights[i]));
        }
        let entries: Vec<Influence> =
            bones.iter().zip(weights).map(|(&bone, &weight)| Influence { bone, weight }).collect();
        // (Each count fits 16 bits: at most MAX_INFLUENCES_PER_VERTEX, checked above.)
        let counts: Vec<u16> = offsets.windows(2).map(|w| (w[1] - w[0]) as u16).collect();
        let narrow = bone_count <= u8::BONES;
        let slot_bytes = if narrow { core::mem::size_of::<Slot<u8>>() } else { core::mem::size_of::<Slot<u16>>() };
        let lane_positions = lane_order::choose(&counts, slot_bytes);
        let vertex_at = lane_order::vertex_at(lane_positions.as_deref(), counts.len());
        let (slots, batch_starts) = if narrow {
            let (slots, starts) = pack_lanes::<u8>(offsets, &entries, &vertex_at)?;
            (LaneSlots::Narrow(slots), starts)
        } else {
            let (slots, starts) = pack_lanes::<u16>(offsets, &entries, &vertex_at)?;
            (LaneSlots::Wide(slots), starts)
        };
        // Only the lane order is kept: a vertex's pairs are read back from its lane (a crowd
        // keeps one set of influences per character).
        let counts = Counts::pack(counts.into_iter(), max_per_vertex);
        Ok(Self {
            counts,
            pairs: total,
            bone_count,
            max_per_vertex,
            slots,
            batch_starts,
            bone_windows: BoneWindows::default(),
            lane_positions,
        })
    }

    /// From dense rows, as glTF stores joints and weights: vertex `v` lists the `per_vertex`
    /// pairs `bones[v·K + k]`, `weights[v·K + k]` (`K = per_vertex`, `vertex_count · K` entries
    /// each). Pairs with zero weight are dropped (they never change the result, and their bone
    /// is not checked: glTF pads with joint 0). Errors name the flat index of the dense arrays.
    pub fn from_dense(
        bones: &[u32],
        weights: &[f32],
        vertex_count: usize,
        per_vertex: usize,
        bone_count: usize,
    ) -> Result<Self, SkinError> {
        let invalid = |what: String| Err(SkinError::InvalidInfluences(what));
        if per_vertex > MAX_INFLUENCES_PER_VERTEX {
            return invalid(format!(
                "weights has {per_vertex} influences per vertex; at most {MAX_INFLUENCES_PER_VERTEX} are supported"
            ));
        }
        let entries = vertex_count.checked_mul(per_vertex);
        if entries != Some(weights.len()) || bones.len() != weights.len() {
            return invalid(format!(
                "bones has {} entries and weights {}: both must have {vertex_count} × {per_vertex}",
                bones.len(),
                weights.len()
            ));
        }
        if let Some(i) = weights.iter().position(|w| !(*w >= 0.0) || !w.is_finite()) {
            return invalid(format!("weights[{i}] = {} is not a finite non-negative number", weights[i]));
        }
        if let Some(i) = (0..bones.len()).find(|&i| weights[i] != 0.0 && bones[i] as usize >= bone_count) {
            return invalid(format!("bones[{i}] = {} is out of range: bone_count = {bone_count}", bones[i]));
        }
        let mut offsets = Vec::with_capacity(vertex_count + 1);
        let (mut kept_bones, mut kept_weights) = (Vec::new(), Vec::new());
        offsets.push(0u32);
        for v in 0..vertex_count {
            for i in v * per_vertex..(v + 1) * per_vertex {
                if weights[i] != 0.0 {
                    kept_bones.push(bones[i]);
                    kept_weights.push(weights[i]);
                }
            }
            offsets.push(
                u32::try_from(kept_bones.len())
                    .map_err(|_| SkinError::InvalidInfluences("more than 2^32-1 influences".into()))?,
            );
        }
        Self::from_csr(&offsets, &kept_bones, &kept_weights, bone_count)
    }

    /// From one list of `(bone, weight)` pairs per vertex (convenient for tests and examples).
    pub fn from_lists(lists: &[Vec<(u32, f32)>], bone_count: usize) -> Result<Self, SkinError> {
        let mut offsets = Vec::with_capacity(lists.len() + 1);
        let (mut bones, mut weights) = (Vec::new(), Vec::new());
        offsets.push(0u32);
        for list in lists {
            for &(b, w) in list {
                bones.push(b);
                weights.push(w);
            }
            offsets.push(
                u32::try_from(bones.len())
                    .map_err(|_| SkinError::InvalidInfluences("more than 2^32-1 influences".into()))?,
            );
        }
        Self::from_csr(&offsets, &bones, &weights, bone_count)
    }

    /// Number of vertices.
    #[inline]
    pub fn vertex_count(&self) -> usize {
        self.counts.len()
    }

    /// Number of bones the indices refer to.
    #[inline]
    pub fn bone_count(&self) -> usize {
        self.bone_count
    }

    /// Total number of `(bone, weight)` pairs.
    #[inline]
    pub fn len(&self) -> usize {
        self.pairs
    }

    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The largest number of pairs of any vertex.
    #[inline]
    pub fn max_per_vertex(&self) -> usize {
        self.max_per_vertex
    }

    /// The pairs of vertex `v`, in the given order (read from its lane of the kernels' slots).
    #[inline]
    pub fn of_vertex(&self, v: usize) -> impl ExactSizeIterator<Item = Influence> + Clone + '_ {
        let count = self.counts.get(v);
        let at = lane_order::position_of(self.lane_positions.as_deref(), v);
        let (start, lane) = (self.batch_starts[at / LANES] as usize, at % LANES);
        (start..start + count).map(move |k| self.slots.pair(k, lane))
    }

    /// The CSR offsets (`V+1`, a copy: only each vertex's count is kept).
    pub fn offsets(&self) -> Vec<u32> {
        let mut offsets = Vec::with_capacity(self.counts.len() + 1);
        offsets.push(0u32);
        let mut at = 0u32;
        for v in 0..self.counts.len() {
            at += self.counts.get(v) as u32;
            offsets.push(at);
        }
        offsets
    }

    /// Every pair, vertex by vertex (a copy: see [`Influences::of_vertex`]).
    pub fn entries(&self) -> Vec<Influence> {
        (0..self.vertex_count()).flat_map(|v| self.of_vertex(v)).collect()
    }

    /// Bytes the kernels read per call for the influences (the lane-ordered slots and their
    /// batch starts).
    pub fn byte_size(&self) -> usize {
        self.slots.len() * self.slots.slot_bytes()
            + self.batch_starts.len() * 4
            + self.lane_positions.as_ref().map_or(0, |p| p.len())
    }

    /// The bytes they hold on the heap (counts, lane-ordered slots, batch starts, bone windows
    /// once made): for memory accounting.
    pub fn heap_bytes(&self) -> usize {
        self.counts.heap_bytes()
            + self.slots.capacity_bytes()
            + self.batch_starts.capacity() * 4
            + self.bone_windows.heap_bytes()
            + self.lane_positions.as_ref().map_or(0, |p| p.len())
    }

    /// The lane-ordered layout the kernels read, as 32-bit words: `(batch starts, slots, words
    /// per slot)`.
    /// For benchmarks that need to touch exactly the kernels' bytes.
    #[doc(hidden)]
    pub fn kernel_words(&self) -> (&[u32], &[u32], usize) {
        (&self.batch_starts, self.slots.as_words(), self.slots.slot_bytes() / 4)
    }

    /// Each vertex's lane position within its window of [`WINDOW`] (`None`: the vertex order).
    #[inline]
    pub(crate) fn lane_positions(&self) -> Option<&[u8]> {
        self.lane_positions.as_deref()
    }

    /// The lane-ordered slots, in their index width.
    #[inline]
    pub(crate) fn lane_slots(&self) -> &LaneSlots {
        &self.slots
    }

    /// The slots of batch `b` (lane positions `b·LANES .. (b+1)·LANES`) of `slots`, the slots of
    /// [`Influences::lane_slots`].
    #[inline]
    pub(crate) fn batch<'a, I: BoneIndex>(&self, slots: &'a [Slot<I>], b: usize) -> &'a [Slot<I>] {
        &slots[self.batch_starts[b] as usize..self.batch_starts[b + 1] as usize]
    }

    /// Each batch's bone window, for [`bone_window`]: made on the first call, then kept.
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code, reason = "only the AVX-512 LBS reads them"))]
    pub(crate) fn bone_windows(&self) -> &[u16] {
        self.bone_windows.get(&self.slots, &self.batch_starts)
    }
}

/// Transposes CSR influences into lane order, padding each batch to its longest vertex.
/// Lane position `p` holds vertex `vertex_at[p]`.
fn pack_lanes<I: BoneIndex>(
    offsets: &[u32],
    entries: &[Influence],
    vertex_at: &[u32],
) -> Result<(Vec<Slot<I>>, Vec<u32>), SkinError> {
    let vertices = offsets.len() - 1;
    let batches = vertices.div_ceil(LANES);
    let count = |p: usize| {
        let v = vertex_at[p] as usize;
        (offsets[v + 1] - offsets[v]) as usize
    };
    let longest = |b: usize| (b * LANES..((b + 1) * LANES).min(vertices)).map(count).max().unwrap_or(0);
    // Counted first and allocated once: grown by pushing, the slots would keep up to twice the
    // memory they use (a crowd keeps one set per character).
    let mut slots = Vec::with_capacity((0..batches).map(longest).sum());
    let mut batch_starts = Vec::with_capacity(batches + 1);
    batch_starts.push(0u32);
    for b in 0..batches {
        let first = b * LANES;
        let last = (first + LANES).min(vertices);
        let longest = longest(b);
        let base = slots.len();
        slots.resize(base + longest, Slot::EMPTY);
        for p in first..last {
            let (lane, v) = (p - first, vertex_at[p] as usize);
            let list = &entries[offsets[v] as usize..offsets[v + 1] as usize];
            for (k, e) in list.iter().enumerate() {
                // Below the bone count, which the width `I` was chosen for (validated).
                slots[base + k].bones[lane] = I::narrow(e.bone);
                slots[base + k].weights[lane] = e.weight;
            }
        }
        batch_starts.push(
            u32::try_from(slots.len()).map_err(|_| {
                SkinError::InvalidInfluences("too many influences to pack (more than 2^32 slots)".into())
            })?,
        );
    }
    Ok((slots, batch_starts))
}

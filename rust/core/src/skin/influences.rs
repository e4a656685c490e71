//! Sparse per-vertex bone influences, validated once and kept in a cache-friendly layout.

use super::SkinError;

mod counts;
use counts::Counts;

/// The most influences one vertex may have. Sums of weights run in single precision as in
/// Blender (at most 4096 · 2⁻²⁴ ≈ 2.4e-4 relative error), and the lane layout pads a vertex's
/// 15 neighbours to its count (96 bytes per influence of the largest), so both stay bounded.
pub const MAX_INFLUENCES_PER_VERTEX: usize = 4096;
const _: () = assert!(MAX_INFLUENCES_PER_VERTEX <= u16::MAX as usize);

/// Vertices the kernels process together, one per SIMD lane.
pub(crate) const LANES: usize = 16;
const _: () = assert!(core::mem::size_of::<Slot>() == LANES * 6);

/// The `k`-th influence of each of [`LANES`] consecutive vertices: 96 bytes (a bone index of 16
/// bits and a weight of 32 per lane; the kernels read them and little else, so every byte less
/// here is time and memory). Vertices with fewer than `k + 1` influences have bone 0 with weight
/// 0 there, which adds nothing to any sum.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(32))]
pub(crate) struct Slot {
    /// Each lane's bone index (its record in a pose table: [`lane_record`]).
    pub bones: [u16; LANES],
    pub weights: [f32; LANES],
}

/// The most bones influences can refer to: a slot holds a bone index in 16 bits.
pub const MAX_BONES: usize = u16::MAX as usize + 1;

/// The first float of the record of `table` that a slot's entry `bone` names.
///
/// # Safety
/// `bone` indexes `table` (true of every slot entry of influences whose bone count is the
/// table's length: validated when they were built).
#[inline(always)]
pub(crate) unsafe fn lane_record<T>(table: &[T], bone: u16) -> *const f32 {
    debug_assert!(usize::from(bone) < table.len());
    // SAFETY: the caller's contract: the record lies inside `table`.
    unsafe { table.as_ptr().add(usize::from(bone)).cast() }
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
/// its vertex with the most pairs); [`Influences::of_vertex`] reads a vertex's back from its lane.
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
    /// The same influences in lane order for the kernels: batch `b` (vertices `b·LANES ..`) has
    /// slots `batch_starts[b]..batch_starts[b+1]`, as many as its vertex with the most influences.
    slots: Vec<Slot>,
    batch_starts: Vec<u32>,
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
        let (slots, batch_starts) = pack_lanes(offsets, &entries)?;
        // Only the lane order is kept: a vertex's pairs are read back from its lane (a crowd
        // keeps one set of influences per character).
        // (Each count fits 16 bits: at most MAX_INFLUENCES_PER_VERTEX, checked above.)
        let counts = Counts::pack(offsets.windows(2).map(|w| (w[1] - w[0]) as u16), max_per_vertex);
        Ok(Self { counts, pairs: total, bone_count, max_per_vertex, slots, batch_starts })
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
        let (start, lane) = (self.batch_starts[v / LANES] as usize, v % LANES);
        self.slots[start..start + count]
            .iter()
            .map(move |s| Influence { bone: u32::from(s.bones[lane]), weight: s.weights[lane] })
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
        self.slots.len() * core::mem::size_of::<Slot>() + self.batch_starts.len() * 4
    }

    /// The bytes they hold on the heap (counts, lane-ordered slots, batch starts): for memory
    /// accounting.
    pub fn heap_bytes(&self) -> usize {
        self.counts.heap_bytes()
            + self.slots.capacity() * core::mem::size_of::<Slot>()
            + self.batch_starts.capacity() * 4
    }

    /// The lane-ordered layout the kernels read, as 32-bit words: `(batch starts, slots, words
    /// per slot)`.
    /// For benchmarks that need to touch exactly the kernels' bytes.
    #[doc(hidden)]
    pub fn kernel_words(&self) -> (&[u32], &[u32], usize) {
        let words = core::mem::size_of::<Slot>() / 4;
        // SAFETY: `Slot` is `repr(C)` with only u16 and f32 fields and no padding (LANES·6
        // bytes, a multiple of its 32-byte alignment), so it is a sequence of 32-bit words.
        let slots = unsafe { core::slice::from_raw_parts(self.slots.as_ptr() as *const u32, self.slots.len() * words) };
        (&self.batch_starts, slots, words)
    }

    /// The slots of batch `b` (vertices `b·LANES .. (b+1)·LANES`).
    #[inline]
    pub(crate) fn batch(&self, b: usize) -> &[Slot] {
        &self.slots[self.batch_starts[b] as usize..self.batch_starts[b + 1] as usize]
    }
}

/// Transposes CSR influences into lane order, padding each batch to its longest vertex.
fn pack_lanes(offsets: &[u32], entries: &[Influence]) -> Result<(Vec<Slot>, Vec<u32>), SkinError> {
    let vertices = offsets.len() - 1;
    let batches = vertices.div_ceil(LANES);
    let longest = |b: usize| {
        let (first, last) = (b * LANES, ((b + 1) * LANES).min(vertices));
        (first..last).map(|v| offsets[v + 1] - offsets[v]).max().unwrap_or(0) as usize
    };
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
        slots.resize(base + longest, Slot { bones: [0; LANES], weights: [0.0; LANES] });
        for v in first..last {
            let lane = v - first;
            let list = &entries[offsets[v] as usize..offsets[v + 1] as usize];
            for (k, e) in list.iter().enumerate() {
                // Below MAX_BONES = 2¹⁶ (validated).
                slots[base + k].bones[lane] = e.bone as u16;
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

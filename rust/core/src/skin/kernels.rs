//! The dispatcher: runs a [`Job`] on the compiled copy of the kernels a [`Simd`] names, chunk by
//! chunk on the thread pool. Inputs are validated by [`super::skin`]; nothing here can fail or
//! panic on valid inputs.
//!
//! Vertices are processed [`LANES`] at a time from the lane-ordered influence slots: every lane
//! is an independent vertex, so the serial chain of DQS's running-sum sign choice runs in all
//! lanes at once. Every copy (the baseline, AVX2+FMA and AVX-512 on x86-64, NEON on aarch64)
//! runs the one arithmetic body of `batch.rs` on every batch, the last partial one padded,
//! except where a hand-written kernel measured faster (`baseline/kept.rs`, `avx2/kept.rs`,
//! `avx2/rigid_dqs.rs`, `avx512/kept.rs`).
//! Which copy runs by default is measured (`calibration.rs`); what the CPU has is detected in
//! `isa.rs`.

use glam::Affine3A;

use super::batch::{skin_batch, BatchJob, FullBatch, Scratch};
use super::influences::{bone_window, BoneIndex, LaneSlots, Slot, LANES, WINDOW};
use super::isa::{InstructionSet, Simd};
use super::job::{Job, Kind, BLEND, CENTERS, DUAL_QUATERNION, LINEAR};
#[cfg(target_arch = "x86_64")]
use super::pose::ColumnMove;
use super::pose::{CorRigidBone, DqBone, LinearBone};
use super::spaces::{fold_rigid_centers, fold_rigid_spaces, fold_spaces, Fold};

/// Vertices per parallel task: large enough to amortize scheduling, small enough to balance.
/// A multiple of [`LANES`] and of [`WINDOW`], so tasks start on batch and window boundaries.
pub(crate) const CHUNK: usize = 4096;
const _: () = assert!(CHUNK.is_multiple_of(LANES) && CHUNK.is_multiple_of(WINDOW));

/// The fewest vertices a bone for which the AVX-512 LBS makes the moves by component
/// (`avx512/bone_window.rs`): a bone's entries cost about what the bone windows save on eight
/// vertices (docs/performance.md), so from sixteen they pay back at least twice where the
/// batches have windows.
#[cfg(target_arch = "x86_64")]
const VERTICES_A_BONE_FOR_COLUMNS: usize = 16;

pub(crate) fn run(job: &Job<'_>, out: &mut [[f32; 3]], simd: Simd) {
    assert_eq!(out.len(), job.positions.len(), "one output point per vertex");
    assert!(job.kind() != Kind::CentersOfRotation || job.centers.is_some(), "centers of rotation need the centers");
    // The bones' records with the spaces folded in, once per call (`spaces.rs`): LBS's, and
    // for poses without scale DQS's, Blend's and the centers'.
    let (pose, premat, postmat) = (job.pose(), job.premat, job.postmat);
    let rigid = !pose.any_scaled();
    let dq = (rigid && matches!(job.kind(), Kind::DualQuaternion | Kind::Blend))
        .then(|| fold_rigid_spaces(pose, premat, postmat))
        .flatten();
    let cor_rigid =
        (rigid && job.kind() == Kind::CentersOfRotation).then(|| fold_rigid_centers(pose, premat, postmat)).flatten();
    let linear = match job.kind() {
        Kind::Linear => fold_spaces(pose, premat, postmat, linear_fold(simd)),
        Kind::Blend if dq.is_some() => fold_spaces(pose, premat, postmat, Fold::Matrices),
        _ => None,
    };
    // The moves by component too for the AVX-512 LBS's batches whose bones lie close together,
    // where the mesh has enough vertices a bone to repay making them.
    #[cfg(target_arch = "x86_64")]
    let linear_columns = match (&linear, simd.instruction_set()) {
        (Some(moves), InstructionSet::Avx512)
            if simd.runs_kept()
                && job.kind() == Kind::Linear
                && job.positions.len() >= VERTICES_A_BONE_FOR_COLUMNS * moves.len() =>
        {
            super::avx512::MoveColumns::new(moves)
        }
        _ => None,
    };
    // The moves by column for the AVX2 LBS.
    #[cfg(target_arch = "x86_64")]
    let column_moves: Option<Vec<ColumnMove>> = match (&linear, simd.instruction_set()) {
        (Some(moves), InstructionSet::Avx2Fma) if simd.runs_kept() && job.kind() == Kind::Linear => {
            Some(moves.iter().map(ColumnMove::new).collect())
        }
        _ => None,
    };
    let folded = Folded {
        linear: linear.as_deref(),
        #[cfg(target_arch = "x86_64")]
        linear_columns: linear_columns.as_ref(),
        #[cfg(target_arch = "x86_64")]
        column_moves: column_moves.as_deref(),
        dq: dq.as_deref(),
        cor_rigid: cor_rigid.as_deref(),
        prefetch: simd.prefetches(),
        #[cfg(test)]
        kept: simd.runs_kept(),
    };
    let task = |i: usize, chunk: &mut [[f32; 3]]| run_chunk(simd, job, folded, i * CHUNK, chunk);
    if out.len() <= CHUNK {
        task(0, out);
    } else {
        crate::pool::share_parts(out.chunks_mut(CHUNK).collect(), task);
    }
}

/// The compiled copies as const-generic codes.
const ISA_BASELINE: u8 = 0;
#[cfg(target_arch = "x86_64")]
const ISA_AVX2: u8 = 1;
#[cfg(target_arch = "x86_64")]
const ISA_AVX512: u8 = 2;
#[cfg(target_arch = "aarch64")]
const ISA_NEON: u8 = 3;

/// One call's bone records with the job's spaces folded in ([`fold_spaces`],
/// [`fold_rigid_spaces`]), where they fold.
#[derive(Clone, Copy, Default)]
struct Folded<'a> {
    /// LBS's records: the bones' moves, or for the baseline's LBS (and Blend's) their matrices.
    linear: Option<&'a [LinearBone]>,
    /// LBS's moves by component, for the AVX-512 copy's (`avx512/bone_window.rs`).
    #[cfg(target_arch = "x86_64")]
    linear_columns: Option<&'a super::avx512::MoveColumns>,
    /// LBS's moves by column, for the AVX2 copy's (`avx2/kept.rs`).
    #[cfg(target_arch = "x86_64")]
    column_moves: Option<&'a [ColumnMove]>,
    /// DQS's and Blend's dual quaternions, for poses without scale.
    dq: Option<&'a [DqBone]>,
    /// The centers' records, for poses without scale.
    cor_rigid: Option<&'a [CorRigidBone]>,
    /// Whether the batches ask for their inputs ahead (the copy's: [`Simd::prefetches`]).
    prefetch: bool,
    /// Whether the copy's hand-written kernels run where kept ([`Simd::runs_kept`]; a field in
    /// the tests only, so that elsewhere the answer is a constant and the one body's paths the
    /// hand-written kernels replace are not compiled in).
    #[cfg(test)]
    kept: bool,
}

impl Folded<'_> {
    #[cfg(not(test))]
    fn runs_kept(&self) -> bool {
        true
    }

    #[cfg(test)]
    fn runs_kept(&self) -> bool {
        self.kept
    }
}

/// The folded records the copy `simd`'s LBS reads: each bone's move, as the copies with fused
/// multiply-adds compute LBS (all in the same order, so they give the same bits); its matrix for
/// the baseline's hand-written LBS.
fn linear_fold(simd: Simd) -> Fold {
    if simd.instruction_set() == InstructionSet::Baseline {
        return Fold::Matrices;
    }
    Fold::Moves
}

/// Runs the copy `simd` of the kernels on vertices `start..start + out.len()`, with the call's
/// `folded` records.
fn run_chunk(simd: Simd, job: &Job<'_>, folded: Folded<'_>, start: usize, out: &mut [[f32; 3]]) {
    match simd.instruction_set() {
        InstructionSet::Baseline => chunk::<ISA_BASELINE>(job, folded, start, out),
        // SAFETY: a `Simd` of this set exists only where AVX2 and FMA were detected.
        #[cfg(target_arch = "x86_64")]
        InstructionSet::Avx2Fma => unsafe { chunk_avx2(job, folded, start, out) },
        // SAFETY: a `Simd` of this set exists only where AVX-512F, AVX2 and FMA were detected.
        #[cfg(target_arch = "x86_64")]
        InstructionSet::Avx512 => unsafe { chunk_avx512(job, folded, start, out) },
        // SAFETY: every aarch64 CPU has NEON.
        #[cfg(target_arch = "aarch64")]
        InstructionSet::Neon => unsafe { chunk_neon(job, folded, start, out) },
    }
}

/// # Safety
/// The CPU must support AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn chunk_avx2(job: &Job<'_>, folded: Folded<'_>, start: usize, out: &mut [[f32; 3]]) {
    chunk::<ISA_AVX2>(job, folded, start, out)
}

/// # Safety
/// The CPU must support AVX-512F, AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn chunk_avx512(job: &Job<'_>, folded: Folded<'_>, start: usize, out: &mut [[f32; 3]]) {
    chunk::<ISA_AVX512>(job, folded, start, out)
}

/// # Safety
/// The CPU must support NEON (every aarch64 CPU does; the attribute lets the intrinsics inline).
#[cfg(target_arch = "aarch64")]
#[target_feature(enable = "neon")]
unsafe fn chunk_neon(job: &Job<'_>, folded: Folded<'_>, start: usize, out: &mut [[f32; 3]]) {
    chunk::<ISA_NEON>(job, folded, start, out)
}

#[inline(always)]
fn chunk<const ISA: u8>(job: &Job<'_>, folded: Folded<'_>, start: usize, out: &mut [[f32; 3]]) {
    match job.influences().lane_slots() {
        LaneSlots::Narrow(slots) => methods::<ISA, u8>(job, folded, slots, start, out),
        LaneSlots::Wide(slots) => methods::<ISA, u16>(job, folded, slots, start, out),
    }
}

/// [`chunk`] for the influences' slots `slots`, whose bone indices are `I`.
#[inline(always)]
fn methods<const ISA: u8, I: BoneIndex>(
    job: &Job<'_>,
    folded: Folded<'_>,
    slots: &[Slot<I>],
    start: usize,
    out: &mut [[f32; 3]],
) {
    match (job.kind(), job.pose().any_scaled()) {
        (Kind::Linear, _) => batches::<ISA, I, LINEAR, false>(job, folded, slots, start, out),
        (Kind::DualQuaternion, false) => batches::<ISA, I, DUAL_QUATERNION, false>(job, folded, slots, start, out),
        (Kind::DualQuaternion, true) => batches::<ISA, I, DUAL_QUATERNION, true>(job, folded, slots, start, out),
        (Kind::Blend, false) => batches::<ISA, I, BLEND, false>(job, folded, slots, start, out),
        (Kind::Blend, true) => batches::<ISA, I, BLEND, true>(job, folded, slots, start, out),
        (Kind::CentersOfRotation, false) => batches::<ISA, I, CENTERS, false>(job, folded, slots, start, out),
        (Kind::CentersOfRotation, true) => batches::<ISA, I, CENTERS, true>(job, folded, slots, start, out),
    }
}

/// Skins vertices `start..start + out.len()` batch by batch: in vertex order, or where the
/// influences take their lanes in another order within windows (`influences/lane_order.rs`),
/// window by window, their inputs copied into lane order and their results back.
#[inline(always)]
fn batches<const ISA: u8, I: BoneIndex, const KIND: u8, const SCALED: bool>(
    job: &Job<'_>,
    folded: Folded<'_>,
    all_slots: &[Slot<I>],
    start: usize,
    out: &mut [[f32; 3]],
) {
    // A method whose every table was folded has no premat or postmat left to apply.
    let all_folded = match KIND {
        LINEAR => folded.linear.is_some(),
        DUAL_QUATERNION => !SCALED && folded.dq.is_some(),
        BLEND => !SCALED && folded.dq.is_some() && folded.linear.is_some(),
        CENTERS => !SCALED && folded.cor_rigid.is_some(),
        _ => false,
    };
    let kept = folded.runs_kept();
    let folded = if all_folded {
        folded
    } else {
        Folded {
            prefetch: folded.prefetch,
            #[cfg(test)]
            kept,
            ..Folded::default()
        }
    };
    let spaces = |m: Option<glam::Mat4>| if all_folded { None } else { m.map(Affine3A::from_mat4) };
    let (premat, postmat) = (spaces(job.premat), spaces(job.postmat));
    let pose = job.pose();
    // LBS reads the moves, but for the baseline's, which reads the folded matrices (as Blend).
    let reads_moves = ISA != ISA_BASELINE && KIND == LINEAR;
    let (linear, moves) = match folded.linear {
        Some(records) if reads_moves => (&pose.linear[..], Some(records)),
        Some(records) => (records, None),
        None => (&pose.linear[..], None),
    };
    let simd_job = BatchJob {
        linear,
        dq: folded.dq.unwrap_or(&pose.dq),
        pivot: &pose.pivot,
        pivot_dual: &pose.pivot_dual,
        cor: &pose.cor,
        cor_rigid: folded.cor_rigid.unwrap_or(&pose.cor_rigid),
        linear_moves: moves,
        #[cfg(target_arch = "x86_64")]
        linear_columns: folded.linear_columns.filter(|_| reads_moves),
        #[cfg(target_arch = "x86_64")]
        column_moves: folded.column_moves.filter(|_| reads_moves),
        premat: premat.as_ref(),
        postmat: postmat.as_ref(),
        blend_factor: job.blend_factor,
    };
    #[cfg(target_arch = "x86_64")]
    let bone_windows = simd_job.linear_columns.map(|_| job.influences().bone_windows());
    #[cfg(not(target_arch = "x86_64"))]
    let bone_windows = None;
    let mut run = BatchRun {
        job,
        simd_job: &simd_job,
        all_slots,
        bone_windows,
        kept,
        prefetch: folded.prefetch,
        scratch: Scratch::new(job.influences().max_per_vertex()),
    };
    let Some(lane_positions) = job.influences().lane_positions() else {
        let streams = Streams {
            positions: &job.positions[start..],
            mask: job.mask.map(|a| &a[start..]),
            blend_amount: job.blend_amount.map(|a| &a[start..]),
            centers: job.centers.map(|a| &a[start..]),
        };
        return run.batches::<ISA, KIND, SCALED>(streams, start, out);
    };
    let (mut window, mut lane_out) = (Window::new(), [[0.0f32; 3]; WINDOW]);
    for (w, out) in out.chunks_mut(WINDOW).enumerate() {
        let first = start + w * WINDOW;
        let n = out.len();
        let lanes = &lane_positions[first..first + n];
        let streams = window.gather(job, first, lanes);
        run.batches::<ISA, KIND, SCALED>(streams, first, &mut lane_out[..n]);
        for (o, &p) in out.iter_mut().zip(lanes) {
            *o = lane_out[usize::from(p)];
        }
    }
}

/// The inputs a batch reads, from its first vertex: the job's own, or a window's in lane order.
#[derive(Clone, Copy)]
struct Streams<'a> {
    positions: &'a [[f32; 3]],
    mask: Option<&'a [f32]>,
    blend_amount: Option<&'a [f32]>,
    centers: Option<&'a [[f32; 3]]>,
}

/// One window's inputs in its lanes' order (`influences/lane_order.rs`).
struct Window {
    positions: [[f32; 3]; WINDOW],
    mask: [f32; WINDOW],
    blend_amount: [f32; WINDOW],
    centers: [[f32; 3]; WINDOW],
}

impl Window {
    fn new() -> Self {
        Window {
            positions: [[0.0; 3]; WINDOW],
            mask: [0.0; WINDOW],
            blend_amount: [0.0; WINDOW],
            centers: [[0.0; 3]; WINDOW],
        }
    }

    /// The inputs of the window's vertices `first..first + lanes.len()`, each put in its lane
    /// position `lanes[i]` (a permutation of `0..lanes.len()`).
    fn gather(&mut self, job: &Job<'_>, first: usize, lanes: &[u8]) -> Streams<'_> {
        let n = lanes.len();
        fn put<T: Copy>(to: &mut [T; WINDOW], from: &[T], lanes: &[u8]) {
            for (x, &p) in from.iter().zip(lanes) {
                to[usize::from(p)] = *x;
            }
        }
        put(&mut self.positions, &job.positions[first..first + n], lanes);
        let mask = job.mask.map(|a| put(&mut self.mask, &a[first..first + n], lanes)).is_some();
        let blend = job.blend_amount.map(|a| put(&mut self.blend_amount, &a[first..first + n], lanes)).is_some();
        let centers = job.centers.map(|a| put(&mut self.centers, &a[first..first + n], lanes)).is_some();
        Streams {
            positions: &self.positions[..n],
            mask: mask.then_some(&self.mask[..n]),
            blend_amount: blend.then_some(&self.blend_amount[..n]),
            centers: centers.then_some(&self.centers[..n]),
        }
    }
}

/// What every batch of one task shares.
struct BatchRun<'a, 'j, I: BoneIndex> {
    job: &'a Job<'j>,
    simd_job: &'a BatchJob<'a>,
    all_slots: &'a [Slot<I>],
    /// The batches' bone windows, where the job's kernel reads them (the AVX-512 LBS).
    bone_windows: Option<&'a [u16]>,
    /// Whether the copy's hand-written kernels run where kept ([`Simd::runs_kept`]).
    kept: bool,
    /// Whether each batch asks for the inputs of a batch ahead ([`prefetch_ahead`]).
    prefetch: bool,
    scratch: Scratch,
}

impl<I: BoneIndex> BatchRun<'_, '_, I> {
    /// Skins the lane positions `at..at + out.len()` (a multiple of [`LANES`] from `at`), whose
    /// inputs `streams` start at lane position `at`.
    #[inline(always)]
    fn batches<const ISA: u8, const KIND: u8, const SCALED: bool>(
        &mut self,
        streams: Streams<'_>,
        at: usize,
        out: &mut [[f32; 3]],
    ) {
        let (job, simd_job) = (self.job, self.simd_job);
        for (k, out) in out.chunks_mut(LANES).enumerate() {
            let first = k * LANES;
            let n = out.len();
            let batch = (at + first) / LANES;
            let slots = job.influences().batch(self.all_slots, batch);
            let bone_window = self.bone_windows.and_then(|w| bone_window(w, batch));
            if self.prefetch {
                prefetch_ahead(streams, first, slots);
            }
            if ISA == ISA_BASELINE && KIND == LINEAR && self.kept {
                // The baseline's hand-written LBS, where it measures faster than the one body.
                let (positions, mask) =
                    (&streams.positions[first..first + n], streams.mask.map(|a| &a[first..first + n]));
                // SAFETY: the job's influences and pose fit together (`Job::new`), so every bone
                // index of the batch's slots indexes `linear` (the pose's table, or its folded
                // copy with one record per bone).
                unsafe {
                    super::baseline::linear_batch(
                        positions,
                        mask,
                        simd_job.linear,
                        simd_job.premat,
                        simd_job.postmat,
                        slots,
                        out,
                    )
                };
                continue;
            }
            if n == LANES {
                fn full<T>(a: &[T], first: usize) -> &[T; LANES] {
                    a[first..first + LANES].try_into().expect("a full batch")
                }
                let inputs = BatchInputs {
                    positions: full(streams.positions, first),
                    strength: streams.mask.map(|a| full(a, first)),
                    blend_amount: streams.blend_amount.map(|a| full(a, first)),
                    centers: streams.centers.map(|c| full(c, first)),
                    slots,
                    bone_window,
                };
                // SAFETY: `ISA` is the copy `Simd::chunk` chose from a `Simd`, whose instruction
                // sets were detected; the job's influences and pose fit together (`Job::new`), so
                // every bone index of the batch's slots indexes every table the method reads.
                unsafe {
                    full_batch::<ISA, I, KIND, SCALED>(
                        simd_job,
                        self.kept,
                        inputs,
                        out.try_into().expect("a full batch"),
                        &mut self.scratch,
                    )
                };
            } else {
                // The last, partial batch goes through the same SIMD body, padded (the padding
                // lanes' slots have weight 0 and their results are dropped): a vertex's result
                // does not depend on where it is in the mesh, so vertices split at one place
                // (UV seams, sharp edges) stay together, as they do under Blender's modifier.
                let pad = |a: Option<&[f32]>| {
                    a.map(|a| {
                        let mut p = [0.0f32; LANES];
                        p[..n].copy_from_slice(&a[first..first + n]);
                        p
                    })
                };
                let pad_points = |a: &[[f32; 3]]| {
                    let mut p = [[0.0f32; 3]; LANES];
                    p[..n].copy_from_slice(&a[first..first + n]);
                    p
                };
                let positions = pad_points(streams.positions);
                let (strength, blend_amount) = (pad(streams.mask), pad(streams.blend_amount));
                let centers = streams.centers.map(pad_points);
                let inputs = BatchInputs {
                    positions: &positions,
                    strength: strength.as_ref(),
                    blend_amount: blend_amount.as_ref(),
                    centers: centers.as_ref(),
                    slots,
                    bone_window,
                };
                let mut padded = [[0.0f32; 3]; LANES];
                // SAFETY: as for a full batch; the padding lanes' bone indices are 0, which
                // indexes every table (a pose has at least one bone).
                unsafe {
                    full_batch::<ISA, I, KIND, SCALED>(simd_job, self.kept, inputs, &mut padded, &mut self.scratch)
                };
                out.copy_from_slice(&padded[..n]);
            }
        }
    }
}

/// How many batches ahead [`prefetch_ahead`] asks for (measured: docs/performance-history.md).
const PREFETCH_AHEAD: usize = 8;

/// Asks the CPU to bring the inputs of the batch [`PREFETCH_AHEAD`] batches after the one at
/// vertex `first` (whose slots are `slots`) into the cache before the kernels read them. The
/// kernels do much work per byte, and the hardware prefetchers alone did not keep their streams
/// ahead on meshes larger than the caches (measured in docs/performance-history.md, "Kernels at
/// the memory limit"); on meshes that fit the caches it measured the same. The addresses are
/// this batch's moved by the same distance (batches mostly have as many slots as their
/// neighbours; each batch asks from its own start, so together they cover every line): no
/// lookup, no bounds check. A hint: nothing is read, and an address past an array's end asks
/// for nothing harmful. It was chosen on an Intel Xeon and costs a few per cent on a Zen 3, so
/// each copy runs with and without it and the trial of copies chooses (`isa.rs`, `calibration.rs`).
#[inline(always)]
fn prefetch_ahead<I: BoneIndex>(streams: Streams<'_>, first: usize, slots: &[Slot<I>]) {
    let lines = |p: *const u8, bytes: usize| {
        let ahead = p.wrapping_add(PREFETCH_AHEAD * bytes);
        (0..bytes.div_ceil(64)).for_each(|l| prefetch(ahead.wrapping_add(64 * l)))
    };
    lines(slots.as_ptr().cast(), core::mem::size_of_val(slots));
    let points = LANES * core::mem::size_of::<[f32; 3]>();
    lines(streams.positions.as_ptr().wrapping_add(first).cast(), points);
    if let Some(c) = streams.centers {
        lines(c.as_ptr().wrapping_add(first).cast(), points);
    }
    for a in [streams.mask, streams.blend_amount].into_iter().flatten() {
        lines(a.as_ptr().wrapping_add(first).cast(), LANES * 4);
    }
}

/// A prefetch of the cache line at `p` (which need not be valid: the hint cannot fault).
#[inline(always)]
fn prefetch(p: *const u8) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: PREFETCHT0 (SSE, part of x86-64) reads no memory and cannot fault.
    unsafe {
        core::arch::x86_64::_mm_prefetch::<{ core::arch::x86_64::_MM_HINT_T0 }>(p.cast())
    };
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p; // ARM: unmeasured there, so not asked for (its prefetchers may do this already).
}

/// What one batch of `LANES` vertices reads: sliced from the job, or a partial batch padded.
struct BatchInputs<'a, I: BoneIndex> {
    positions: &'a [[f32; 3]; LANES],
    strength: Option<&'a [f32; LANES]>,
    blend_amount: Option<&'a [f32; LANES]>,
    centers: Option<&'a [[f32; 3]; LANES]>,
    slots: &'a [Slot<I>],
    /// The slots' bone window (`influences/bone_windows.rs`).
    bone_window: Option<u32>,
}

/// One full batch with the SIMD kernels of the copy `ISA`.
///
/// # Safety
/// The CPU has the instruction sets of `ISA`; every bone index of the batch's
/// slots indexes every table of `simd_job` that the method reads.
#[inline(always)]
unsafe fn full_batch<const ISA: u8, I: BoneIndex, const KIND: u8, const SCALED: bool>(
    simd_job: &BatchJob<'_>,
    kept: bool,
    inputs: BatchInputs<'_, I>,
    out: &mut [[f32; 3]; LANES],
    scratch: &mut Scratch,
) {
    let BatchInputs { positions, strength, blend_amount, centers, slots, bone_window } = inputs;
    // The hand-written kernels where they measure faster than the one body (docs/performance.md):
    // AVX-512's LBS and rigid centers, AVX2's LBS and rigid DQS (in mesh space: the spaces
    // folded into its records, or none); every other method runs the one body of `batch.rs`.
    #[cfg(target_arch = "x86_64")]
    if let (ISA_AVX512, LINEAR, true, Some(moves)) = (ISA, KIND, kept, simd_job.linear_moves) {
        let window = simd_job.linear_columns.zip(bone_window);
        // SAFETY: the caller's contract (the moves are one per bone of the pose); the columns
        // are these moves by component (`run`), the window the batch's (`bone_windows.rs`).
        return unsafe { super::avx512::linear_batch(moves, window, positions, out, slots, strength) };
    }
    #[cfg(target_arch = "x86_64")]
    if let (ISA_AVX2, LINEAR, true, Some(moves)) = (ISA, KIND, kept, simd_job.column_moves) {
        // SAFETY: the caller's contract (the moves are one per bone of the pose).
        return unsafe { super::avx2::linear_batch(moves, positions, out, slots, strength) };
    }
    #[cfg(target_arch = "x86_64")]
    if let (ISA_AVX2, DUAL_QUATERNION, false, true, None, None) =
        (ISA, KIND, SCALED, kept, simd_job.premat, simd_job.postmat)
    {
        let signed = scratch.signed(slots.len());
        // SAFETY: the caller's contract.
        return unsafe { super::avx2::dual_quaternion_batch(simd_job.dq, positions, out, slots, strength, signed) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (bone_window, kept); // Only x86-64's copies have hand-written SIMD kernels.
    #[cfg(target_arch = "x86_64")]
    if let (ISA_AVX512, CENTERS, false, true, Some(centers)) = (ISA, KIND, SCALED, kept, centers) {
        // SAFETY: the caller's contract.
        return unsafe { super::avx512::centers_rigid_batch(simd_job, positions, centers, out, slots, strength) };
    }
    let batch = FullBatch { positions, out, slots, strength, blend_amount, centers };
    match ISA {
        // SAFETY: the caller's contract.
        ISA_BASELINE => unsafe {
            skin_batch::<_, I, KIND, SCALED, 4>(super::baseline::Baseline, simd_job, batch, scratch)
        },
        // SAFETY: the caller's contract.
        #[cfg(target_arch = "x86_64")]
        ISA_AVX2 => unsafe { skin_batch::<_, I, KIND, SCALED, 2>(super::avx2::Avx2::new(), simd_job, batch, scratch) },
        // SAFETY: the caller's contract.
        #[cfg(target_arch = "x86_64")]
        ISA_AVX512 => unsafe {
            skin_batch::<_, I, KIND, SCALED, 1>(super::avx512::Avx512::new(), simd_job, batch, scratch)
        },
        // SAFETY: the caller's contract.
        #[cfg(target_arch = "aarch64")]
        ISA_NEON => unsafe { skin_batch::<_, I, KIND, SCALED, 4>(super::neon::Neon::new(), simd_job, batch, scratch) },
        _ => unreachable!("no SIMD kernels for copy {ISA}"),
    }
}

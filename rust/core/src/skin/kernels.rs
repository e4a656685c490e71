//! The kernels and their parallel driver. Inputs are validated by [`super::skin`]; nothing here
//! can fail or panic on valid inputs.
//!
//! Vertices are processed [`LANES`] at a time from the lane-ordered influence slots: every lane
//! is an independent vertex, so the serial chain of DQS's running-sum sign choice runs in all
//! lanes at once. Compiled copies for AVX2+FMA and for AVX-512 (x86-64) and for NEON (aarch64)
//! are chosen at run time by what the CPU has (see [`Simd::detect`]); full batches run their
//! SIMD kernels (`batch.rs` for AVX2 and NEON, `avx512.rs`), the last partial batch of a call
//! and the baseline copy run the portable code below (which the compiler vectorizes where it
//! can).

use glam::{Affine3A, Mat4, Vec4};
use rayon::prelude::*;

use super::batch::{skin_batch, BatchJob, FullBatch, Scratch};
use super::influences::{lane_record, Slot, LANES};
use super::pose::{CorBone, CorRigidBone, DqBone, LinearBone, PivotBone};
use super::{Influences, Pose, MIN_TOTAL_WEIGHT};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    Linear,
    DualQuaternion,
    Blend,
    CentersOfRotation,
}

/// One skinning call's inputs, as the kernels read them.
///
/// The kernels read bone records without bounds checks (see [`bone`]); what makes that sound
/// is carried by this type: [`Job::new`] checks that the influences and the pose fit together
/// (every bone index of the influences, validated against their bone count when they were
/// built, indexes every table of the pose the method reads), and those fields are private.
/// The other inputs are read through checked slices.
pub(crate) struct Job<'a> {
    kind: Kind,
    influences: &'a Influences,
    pose: &'a Pose,
    pub positions: &'a [[f32; 3]],
    pub premat: Option<Mat4>,
    pub postmat: Option<Mat4>,
    pub mask: Option<&'a [f32]>,
    pub blend_amount: Option<&'a [f32]>,
    pub blend_factor: f32,
    /// One center per vertex (mesh space) for [`Kind::CentersOfRotation`].
    pub centers: Option<&'a [[f32; 3]]>,
}

impl<'a> Job<'a> {
    /// A job without options (set the public fields for them).
    ///
    /// # Panics
    /// If the pose does not have one bone per bone index of the influences, or a method other
    /// than LBS is asked for without the pose's rest data, or `positions` does not have one
    /// point per vertex. [`super::skin`] checks these first and reports what is wrong.
    pub(crate) fn new(kind: Kind, positions: &'a [[f32; 3]], influences: &'a Influences, pose: &'a Pose) -> Self {
        assert_eq!(pose.bone_count(), influences.bone_count(), "the pose must have one bone per bone index");
        assert!(kind == Kind::Linear || pose.has_dual_quaternions(), "this method needs the rest matrices");
        assert!(kind != Kind::CentersOfRotation || pose.has_centers(), "this method needs the centers tables");
        assert_eq!(positions.len(), influences.vertex_count(), "one position per vertex");
        Job {
            kind,
            influences,
            pose,
            positions,
            premat: None,
            postmat: None,
            mask: None,
            blend_amount: None,
            blend_factor: 0.0,
            centers: None,
        }
    }
}

/// Vertices per parallel task: large enough to amortize scheduling, small enough to balance.
/// A multiple of [`LANES`], so tasks start on batch boundaries.
pub(crate) const CHUNK: usize = 4096;
const _: () = assert!(CHUNK.is_multiple_of(LANES));

pub(crate) fn run(job: &Job<'_>, out: &mut [[f32; 3]], simd: Simd) {
    assert_eq!(out.len(), job.positions.len(), "one output point per vertex");
    assert!(job.kind != Kind::CentersOfRotation || job.centers.is_some(), "centers of rotation need the centers");
    let task = |(i, chunk): (usize, &mut [[f32; 3]])| simd.chunk(job, i * CHUNK, chunk);
    if rayon::current_num_threads() <= 1 || out.len() <= CHUNK {
        out.chunks_mut(CHUNK).enumerate().for_each(task);
    } else {
        out.par_chunks_mut(CHUNK).enumerate().for_each(task);
    }
}

/// Instruction sets the kernels are compiled for; the best one the CPU has is chosen at run time.
const ISA_BASELINE: u8 = 0;
#[cfg(target_arch = "x86_64")]
const ISA_AVX2: u8 = 1;
#[cfg(target_arch = "x86_64")]
const ISA_AVX512: u8 = 2;
#[cfg(target_arch = "aarch64")]
const ISA_NEON: u8 = 3;

/// The compiled copies of the kernels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum InstructionSet {
    /// Portable code, compiled for the target's baseline.
    Baseline,
    #[cfg(target_arch = "x86_64")]
    Avx2Fma,
    #[cfg(target_arch = "x86_64")]
    Avx512,
    /// Part of every aarch64 target, so always there.
    #[cfg(target_arch = "aarch64")]
    Neon,
}

impl InstructionSet {
    /// The name `DQSKIN_SIMD` gives the copy.
    pub(crate) fn name(self) -> &'static str {
        match self {
            InstructionSet::Baseline => "baseline",
            #[cfg(target_arch = "x86_64")]
            InstructionSet::Avx2Fma => "avx2",
            #[cfg(target_arch = "x86_64")]
            InstructionSet::Avx512 => "avx512",
            #[cfg(target_arch = "aarch64")]
            InstructionSet::Neon => "neon",
        }
    }
}

/// Which compiled copy of the kernels to run. A value is proof that the CPU has the copy's
/// instruction sets: it is only made by [`Simd::available`] (and so [`Simd::detect`]) after
/// detecting them, so code holding one may run that copy's `#[target_feature]` functions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Simd {
    set: InstructionSet,
}

impl Simd {
    /// The copies this CPU can run, best last.
    pub(crate) fn available() -> Vec<Simd> {
        let mut all = vec![Simd { set: InstructionSet::Baseline }];
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            if has!("avx2") && has!("fma") {
                all.push(Simd { set: InstructionSet::Avx2Fma });
                if has!("avx512f") {
                    all.push(Simd { set: InstructionSet::Avx512 });
                }
            }
        }
        #[cfg(target_arch = "aarch64")]
        all.push(Simd { set: InstructionSet::Neon });
        all
    }

    /// The best available copy, or the one `DQSKIN_SIMD` (`baseline`, `avx2`, `avx512`, `neon`)
    /// asks for if the CPU has it (for debugging and comparisons).
    pub(crate) fn detect() -> Self {
        let available = Self::available();
        let requested = std::env::var("DQSKIN_SIMD").ok().and_then(|v| match v.trim() {
            "baseline" => Some(InstructionSet::Baseline),
            #[cfg(target_arch = "x86_64")]
            "avx2" => Some(InstructionSet::Avx2Fma),
            #[cfg(target_arch = "x86_64")]
            "avx512" => Some(InstructionSet::Avx512),
            #[cfg(target_arch = "aarch64")]
            "neon" => Some(InstructionSet::Neon),
            _ => None,
        });
        match available.iter().find(|s| Some(s.set) == requested) {
            Some(s) => *s,
            None => *available.last().expect("baseline is always available"),
        }
    }

    /// The instruction set of this copy (a value of it proves the CPU has it).
    pub(crate) fn instruction_set(self) -> InstructionSet {
        self.set
    }

    fn chunk(self, job: &Job<'_>, start: usize, out: &mut [[f32; 3]]) {
        match self.set {
            InstructionSet::Baseline => chunk::<ISA_BASELINE>(job, start, out),
            // SAFETY: a `Simd` of this set exists only where AVX2 and FMA were detected.
            #[cfg(target_arch = "x86_64")]
            InstructionSet::Avx2Fma => unsafe { chunk_avx2(job, start, out) },
            // SAFETY: a `Simd` of this set exists only where AVX-512F, AVX2 and FMA were detected.
            #[cfg(target_arch = "x86_64")]
            InstructionSet::Avx512 => unsafe { chunk_avx512(job, start, out) },
            // SAFETY: every aarch64 CPU has NEON.
            #[cfg(target_arch = "aarch64")]
            InstructionSet::Neon => unsafe { chunk_neon(job, start, out) },
        }
    }
}

/// # Safety
/// The CPU must support AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn chunk_avx2(job: &Job<'_>, start: usize, out: &mut [[f32; 3]]) {
    chunk::<ISA_AVX2>(job, start, out)
}

/// # Safety
/// The CPU must support AVX-512F, AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn chunk_avx512(job: &Job<'_>, start: usize, out: &mut [[f32; 3]]) {
    chunk::<ISA_AVX512>(job, start, out)
}

/// # Safety
/// The CPU must support NEON (every aarch64 CPU does; the attribute lets the intrinsics inline).
#[cfg(target_arch = "aarch64")]
#[target_feature(enable = "neon")]
unsafe fn chunk_neon(job: &Job<'_>, start: usize, out: &mut [[f32; 3]]) {
    chunk::<ISA_NEON>(job, start, out)
}

#[inline(always)]
fn chunk<const ISA: u8>(job: &Job<'_>, start: usize, out: &mut [[f32; 3]]) {
    match (job.kind, job.pose.any_scaled()) {
        (Kind::Linear, _) => batches::<ISA, LINEAR, false>(job, start, out),
        (Kind::DualQuaternion, false) => batches::<ISA, DUAL_QUATERNION, false>(job, start, out),
        (Kind::DualQuaternion, true) => batches::<ISA, DUAL_QUATERNION, true>(job, start, out),
        (Kind::Blend, false) => batches::<ISA, BLEND, false>(job, start, out),
        (Kind::Blend, true) => batches::<ISA, BLEND, true>(job, start, out),
        (Kind::CentersOfRotation, false) => batches::<ISA, CENTERS, false>(job, start, out),
        (Kind::CentersOfRotation, true) => batches::<ISA, CENTERS, true>(job, start, out),
    }
}

pub(super) const LINEAR: u8 = 0;
pub(super) const DUAL_QUATERNION: u8 = 1;
pub(super) const BLEND: u8 = 2;
pub(super) const CENTERS: u8 = 3;

type Lanes = [f32; LANES];
const ZERO: Lanes = [0.0; LANES];

/// `a·b + c`, fused in the SIMD copies (where `mul_add` is one instruction; in the x86-64
/// baseline copy it would be a slow library call).
#[inline(always)]
fn madd<const ISA: u8>(a: f32, b: f32, c: f32) -> f32 {
    if ISA != ISA_BASELINE {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// Positions of one batch, one coordinate array per axis.
#[derive(Clone, Copy)]
pub(super) struct Points {
    pub x: Lanes,
    pub y: Lanes,
    pub z: Lanes,
}

impl Points {
    #[inline(always)]
    fn transform<const ISA: u8>(&self, m: &Affine3A) -> Self {
        let (c0, c1, c2, t) = (m.matrix3.x_axis, m.matrix3.y_axis, m.matrix3.z_axis, m.translation);
        let mut r = Points { x: ZERO, y: ZERO, z: ZERO };
        for l in 0..LANES {
            let (x, y, z) = (self.x[l], self.y[l], self.z[l]);
            r.x[l] = madd::<ISA>(c0.x, x, madd::<ISA>(c1.x, y, madd::<ISA>(c2.x, z, t.x)));
            r.y[l] = madd::<ISA>(c0.y, x, madd::<ISA>(c1.y, y, madd::<ISA>(c2.y, z, t.y)));
            r.z[l] = madd::<ISA>(c0.z, x, madd::<ISA>(c1.z, y, madd::<ISA>(c2.z, z, t.z)));
        }
        r
    }
}

/// One batch of up to [`LANES`] vertices, loaded and moved into armature space.
struct Batch<'a> {
    first: usize,
    n: usize,
    original: Points,
    co: Points,
    strength: Lanes,
    slots: &'a [Slot],
}

/// Skins vertices `start..start + out.len()` batch by batch.
#[inline(always)]
fn batches<const ISA: u8, const KIND: u8, const SCALED: bool>(job: &Job<'_>, start: usize, out: &mut [[f32; 3]]) {
    let premat = job.premat.map(Affine3A::from_mat4);
    let postmat = job.postmat.map(Affine3A::from_mat4);
    let pose = job.pose;
    let simd_job = BatchJob {
        linear: &pose.linear,
        dq: &pose.dq,
        pivot: &pose.pivot,
        pivot_dual: &pose.pivot_dual,
        cor: &pose.cor,
        #[cfg(target_arch = "x86_64")]
        cor_rigid: &pose.cor_rigid,
        #[cfg(target_arch = "x86_64")]
        scaled: SCALED,
        premat: premat.as_ref(),
        postmat: postmat.as_ref(),
        blend_factor: job.blend_factor,
    };
    let mut scratch = Scratch::new(job.influences.max_per_vertex());
    for (k, out) in out.chunks_mut(LANES).enumerate() {
        let first = start + k * LANES;
        let n = out.len();
        let slots = job.influences.batch(first / LANES);
        prefetch_ahead(job, first, slots);
        if ISA != ISA_BASELINE {
            if n == LANES {
                fn full<T>(a: &[T], first: usize) -> &[T; LANES] {
                    a[first..first + LANES].try_into().expect("a full batch")
                }
                let inputs = BatchInputs {
                    positions: full(job.positions, first),
                    strength: job.mask.map(|a| full(a, first)),
                    blend_amount: job.blend_amount.map(|a| full(a, first)),
                    centers: job.centers.map(|c| full(c, first)),
                    slots,
                };
                // SAFETY: `ISA` is the copy `Simd::chunk` chose from a `Simd`, whose instruction
                // sets were detected; the job's influences and pose fit together (`Job::new`), so
                // every bone index of the batch's slots indexes every table the method reads.
                unsafe { full_batch::<ISA, KIND, SCALED>(&simd_job, inputs, out.try_into().expect("a full batch"), &mut scratch) };
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
                let positions = pad_points(job.positions);
                let (strength, blend_amount) = (pad(job.mask), pad(job.blend_amount));
                let centers = job.centers.map(pad_points);
                let inputs = BatchInputs {
                    positions: &positions,
                    strength: strength.as_ref(),
                    blend_amount: blend_amount.as_ref(),
                    centers: centers.as_ref(),
                    slots,
                };
                let mut padded = [[0.0f32; 3]; LANES];
                // SAFETY: as for a full batch; the padding lanes' bone indices are 0, which
                // indexes every table (a pose has at least one bone).
                unsafe { full_batch::<ISA, KIND, SCALED>(&simd_job, inputs, &mut padded, &mut scratch) };
                out.copy_from_slice(&padded[..n]);
            }
            continue;
        }
        let original = load_points::<ISA>(&job.positions[first..first + n]);
        let mut strength: Lanes = [1.0; LANES];
        if let Some(mask) = job.mask {
            strength[..n].copy_from_slice(&mask[first..first + n]);
        }
        let co = match &premat {
            Some(m) => original.transform::<ISA>(m),
            None => original,
        };
        let batch = Batch { first, n, original, co, strength, slots };
        // The sums' contract: the job's influences and pose fit together (`Job::new`), so every
        // bone index of the batch's slots indexes every table the method reads.
        if let (CENTERS, Some(centers)) = (KIND, job.centers) {
            let center = load_points::<ISA>(&centers[first..first + n]);
            let center = match &premat {
                Some(m) => center.transform::<ISA>(m),
                None => center,
            };
            // SAFETY: see above.
            let sum = unsafe { accumulate_centers::<ISA, SCALED>(&batch.co, &center, batch.slots, &pose.cor, &pose.cor_rigid) };
            let moved = finish_centers::<ISA, SCALED>(&batch.co, &center, &sum, &batch.strength);
            finish_points::<ISA>(&batch, moved, postmat.as_ref(), out);
            continue;
        }
        let sum = (KIND != LINEAR).then(|| {
            // SAFETY: see above.
            unsafe { accumulate_dual_quaternion::<ISA, SCALED>(&batch.co, batch.slots, &pose.dq, &pose.pivot) }
        });
        // SAFETY: see above.
        unsafe { finish_batch::<ISA, KIND>(job, &batch, sum.as_ref(), postmat.as_ref(), out) };
    }
}

/// How many batches ahead [`prefetch_ahead`] asks for (4–16 measured the same; 2 and 32 less).
const PREFETCH_AHEAD: usize = 8;

/// Asks the CPU to bring the inputs of the batch [`PREFETCH_AHEAD`] batches after the one at
/// vertex `first` (whose slots are `slots`) into the cache before the kernels read them. The
/// kernels do much work per byte, and the hardware prefetchers alone did not keep their streams
/// ahead: on meshes larger than the caches (16M vertices, 4 influences, one thread, Intel) LBS
/// went from 71 % to 90–96 % of the bandwidth reference and rigid DQS from 61 % to 71–72 %; on
/// meshes that fit the caches it measured the same. The addresses are this batch's moved by the
/// same distance (batches mostly have as many slots as their neighbours; each batch asks from
/// its own start, so together they cover every line): no lookup, no bounds check. A hint:
/// nothing is read, and an address past an array's end asks for nothing harmful.
#[inline(always)]
fn prefetch_ahead(job: &Job<'_>, first: usize, slots: &[Slot]) {
    let lines = |p: *const u8, bytes: usize| {
        let ahead = p.wrapping_add(PREFETCH_AHEAD * bytes);
        (0..bytes.div_ceil(64)).for_each(|l| prefetch(ahead.wrapping_add(64 * l)))
    };
    lines(slots.as_ptr().cast(), core::mem::size_of_val(slots));
    let points = LANES * core::mem::size_of::<[f32; 3]>();
    lines(job.positions.as_ptr().wrapping_add(first).cast(), points);
    if let Some(c) = job.centers {
        lines(c.as_ptr().wrapping_add(first).cast(), points);
    }
    for a in [job.mask, job.blend_amount].into_iter().flatten() {
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
struct BatchInputs<'a> {
    positions: &'a [[f32; 3]; LANES],
    strength: Option<&'a [f32; LANES]>,
    blend_amount: Option<&'a [f32; LANES]>,
    centers: Option<&'a [[f32; 3]; LANES]>,
    slots: &'a [Slot],
}

/// One full batch with the SIMD kernels of the copy `ISA`.
///
/// # Safety
/// The CPU has the instruction sets of `ISA` (not the baseline); every bone index of the batch's
/// slots indexes every table of `simd_job` that the method reads.
#[inline(always)]
unsafe fn full_batch<const ISA: u8, const KIND: u8, const SCALED: bool>(
    simd_job: &BatchJob<'_>,
    inputs: BatchInputs<'_>,
    out: &mut [[f32; 3]; LANES],
    scratch: &mut Scratch,
) {
    let BatchInputs { positions, strength, blend_amount, centers, slots } = inputs;
    match ISA {
        // DQS with scaled bones stays at 256 bits in the AVX-512 copy: it transposes two 16-float
        // records per slot, and Intel's cores run 512-bit shuffles on one port but 256-bit ones on
        // two (Sapphire Rapids, 1M vertices: 108 → 125 Mverts/s at 4 influences, 49 → 67 at 8;
        // on a Zen 5 the two were within 10 % of each other).
        #[cfg(target_arch = "x86_64")]
        ISA_AVX512 if !(KIND == DUAL_QUATERNION && SCALED) => {
            if let (CENTERS, Some(centers)) = (KIND, centers) {
                // SAFETY: the caller's contract.
                unsafe { super::avx512::batch_centers::<SCALED>(simd_job, positions, centers, out, slots, strength) };
            } else {
                // SAFETY: the caller's contract.
                unsafe { super::avx512::batch::<KIND>(simd_job, positions, out, slots, strength, blend_amount) };
            }
        }
        _ => {
            let batch = FullBatch { positions, out, slots, strength, blend_amount, centers };
            match ISA {
                // SAFETY: the caller's contract (the AVX-512 copy is only chosen where AVX2 and
                // FMA are there too, `Simd::available`).
                #[cfg(target_arch = "x86_64")]
                ISA_AVX2 | ISA_AVX512 => unsafe { skin_batch::<_, KIND, SCALED, 2>(super::avx2::Avx2::new(), simd_job, batch, scratch) },
                // SAFETY: the caller's contract.
                #[cfg(target_arch = "aarch64")]
                ISA_NEON => unsafe { skin_batch::<_, KIND, SCALED, 4>(super::neon::Neon::new(), simd_job, batch, scratch) },
                _ => unreachable!("no SIMD kernels for copy {ISA}"),
            }
        }
    }
}

/// Finishes a loaded batch (LBS, DQS from its sums, or their blend), applies `postmat` and the
/// mask, and writes it.
///
/// # Safety
/// Every bone index of the batch's slots indexes the pose's `linear` table.
#[inline(always)]
unsafe fn finish_batch<const ISA: u8, const KIND: u8>(
    job: &Job<'_>,
    batch: &Batch<'_>,
    sum: Option<&DqSum>,
    postmat: Option<&Affine3A>,
    out: &mut [[f32; 3]],
) {
    let pose = job.pose;
    let (co, strength) = (&batch.co, &batch.strength);
    let moved = match (KIND, sum) {
        (DUAL_QUATERNION, Some(sum)) => finish_dual_quaternion::<ISA>(co, sum, strength),
        (BLEND, Some(sum)) => {
            // SAFETY: the caller's contract.
            let lbs = unsafe { linear::<ISA>(co, batch.slots, &pose.linear, strength) };
            let dqs = finish_dual_quaternion::<ISA>(co, sum, strength);
            let mut alpha: Lanes = [job.blend_factor; LANES];
            if let Some(amount) = job.blend_amount {
                for l in 0..batch.n {
                    alpha[l] *= amount[batch.first + l];
                }
            }
            let mut r = lbs;
            for l in 0..LANES {
                r.x[l] = madd::<ISA>(alpha[l], dqs.x[l] - lbs.x[l], lbs.x[l]);
                r.y[l] = madd::<ISA>(alpha[l], dqs.y[l] - lbs.y[l], lbs.y[l]);
                r.z[l] = madd::<ISA>(alpha[l], dqs.z[l] - lbs.z[l], lbs.z[l]);
            }
            r
        }
        // SAFETY: the caller's contract.
        _ => unsafe { linear::<ISA>(co, batch.slots, &pose.linear, strength) },
    };
    finish_points::<ISA>(batch, moved, postmat, out);
}

/// Applies `postmat` and the mask to a batch's moved points and writes them.
#[inline(always)]
fn finish_points<const ISA: u8>(batch: &Batch<'_>, moved: Points, postmat: Option<&Affine3A>, out: &mut [[f32; 3]]) {
    let strength = &batch.strength;
    let mut result = match postmat {
        Some(m) => moved.transform::<ISA>(m),
        None => moved,
    };
    // A mask weight of 0 leaves the vertex bit-identical (no space round trip).
    for l in 0..LANES {
        if strength[l] == 0.0 {
            result.x[l] = batch.original.x[l];
            result.y[l] = batch.original.y[l];
            result.z[l] = batch.original.z[l];
        }
    }
    store_points::<ISA>(&result, out);
}

/// Coordinates of up to [`LANES`] points (missing lanes zero).
#[inline(always)]
fn load_points<const ISA: u8>(points: &[[f32; 3]]) -> Points {
    #[cfg(target_arch = "x86_64")]
    if ISA == ISA_AVX512 {
        if let Ok(full) = points.try_into() {
            // SAFETY: this copy only runs where AVX-512F was detected.
            return unsafe { super::avx512::load_points(full) };
        }
    }
    let mut p = Points { x: ZERO, y: ZERO, z: ZERO };
    for (l, v) in points.iter().enumerate() {
        [p.x[l], p.y[l], p.z[l]] = *v;
    }
    p
}

/// Writes the first `out.len()` lanes.
#[inline(always)]
fn store_points<const ISA: u8>(p: &Points, out: &mut [[f32; 3]]) {
    #[cfg(target_arch = "x86_64")]
    if ISA == ISA_AVX512 {
        if let Ok(full) = out.try_into() {
            // SAFETY: this copy only runs where AVX-512F was detected.
            return unsafe { super::avx512::store_points(p, full) };
        }
    }
    for (l, v) in out.iter_mut().enumerate() {
        *v = [p.x[l], p.y[l], p.z[l]];
    }
}

/// Bone data for one lane of a slot (its entry `scaled`, see [`RECORD_UNIT`]), without a bounds
/// check (the kernels' innermost loads).
///
/// # Safety
/// `scaled / RECORD_UNIT < table.len()`. For a slot of a [`Job`]'s influences and a table of its
/// pose this holds: bone indices were validated against the bone count when the influences were
/// built, `Job::new` checked that the pose has that many bones (and the rest tables the method
/// reads), and padding lanes use bone 0, which exists whenever there is a slot at all.
///
/// [`RECORD_UNIT`]: super::influences::RECORD_UNIT
#[inline(always)]
unsafe fn bone<T>(table: &[T], scaled: u32) -> &T {
    // SAFETY: the caller's contract; the record is a whole, aligned `T` of `table`.
    unsafe { &*lane_record(table, scaled).cast::<T>() }
}

/// LBS: `co + (a/contrib)·(Σ wᵢ·Mᵢ·co − contrib·co)`; `co` where `contrib ≤ 0.0001`.
/// Lane by lane with 4-wide rows: LBS has no serial dependency between influences, so this keeps
/// the accumulators in registers.
///
/// # Safety
/// Every bone index of `slots` indexes `linear` (see [`bone`]).
#[inline(always)]
unsafe fn linear<const ISA: u8>(co: &Points, slots: &[Slot], linear: &[LinearBone], strength: &Lanes) -> Points {
    let mut r = *co;
    for l in 0..LANES {
        let mut acc = [Vec4::ZERO; 3];
        let mut contrib = 0.0f32;
        for slot in slots {
            // SAFETY: the caller's contract.
            let m = unsafe { bone(linear, slot.records[l]) };
            let w = slot.weights[l];
            let ws = Vec4::splat(w);
            for (a, row) in acc.iter_mut().zip(&m.matrix.rows) {
                *a = if ISA != ISA_BASELINE { row.mul_add(ws, *a) } else { *row * ws + *a };
            }
            contrib += w;
        }
        let h = Vec4::new(co.x[l], co.y[l], co.z[l], 1.0);
        let f = if contrib > MIN_TOTAL_WEIGHT { strength[l] / contrib } else { 0.0 };
        r.x[l] = madd::<ISA>(acc[0].dot(h) - h.x * contrib, f, h.x);
        r.y[l] = madd::<ISA>(acc[1].dot(h) - h.y * contrib, f, h.y);
        r.z[l] = madd::<ISA>(acc[2].dot(h) - h.z * contrib, f, h.z);
    }
    r
}

/// An unnormalized dual quaternion per lane: real (x, y, z, w), dual (x, y, z, w), total weight.
pub(super) struct DqSum {
    pub real: [Lanes; 4],
    pub dual: [Lanes; 4],
    pub contrib: Lanes,
}

/// Sums `±wᵢ·q̂ᵢ` with each sign chosen against the running sum (Blender's
/// `add_weighted_dq_dq`); for bones with scale the dual part moves `co` exactly where the bone's
/// matrix puts it (`add_weighted_dq_dq_pivot`).
///
/// # Safety
/// Every bone index of `slots` indexes `dq` and `pivot` (see [`bone`]); with `ISA` AVX-512, the
/// CPU has it.
#[inline(always)]
unsafe fn accumulate_dual_quaternion<const ISA: u8, const SCALED: bool>(
    co: &Points,
    slots: &[Slot],
    dq: &[DqBone],
    pivot: &[PivotBone],
) -> DqSum {
    #[cfg(target_arch = "x86_64")]
    match (ISA, SCALED) {
        // SAFETY: the caller's contract.
        (ISA_AVX512, false) => return unsafe { super::avx512::accumulate_rigid(slots, dq) },
        // SAFETY: the caller's contract.
        (ISA_AVX512, true) => return unsafe { super::avx512::accumulate_scaled(co, slots, pivot) },
        _ => {}
    }
    let mut s = DqSum { real: [ZERO; 4], dual: [ZERO; 4], contrib: ZERO };
    for slot in slots {
        for l in 0..LANES {
            let (q, d) = if SCALED {
                // SAFETY: the caller's contract.
                let p = unsafe { bone(pivot, slot.records[l]) };
                let q = [p.real.x, p.real.y, p.real.z, p.real.w];
                let (x, y, z) = (co.x[l], co.y[l], co.z[l]);
                let t = |r: usize| {
                    let row = p.translation.rows[r];
                    madd::<ISA>(row.x, x, madd::<ISA>(row.y, y, madd::<ISA>(row.z, z, row.w)))
                };
                let (tx, ty, tz) = (t(0), t(1), t(2));
                // ½·(0, t)·q = ½·(w·t + t × v, −t·v)
                let d = [
                    0.5 * (tx * q[3] + ty * q[2] - tz * q[1]),
                    0.5 * (ty * q[3] + tz * q[0] - tx * q[2]),
                    0.5 * (tz * q[3] + tx * q[1] - ty * q[0]),
                    -0.5 * (tx * q[0] + ty * q[1] + tz * q[2]),
                ];
                (q, d)
            } else {
                // SAFETY: the caller's contract.
                let b = unsafe { bone(dq, slot.records[l]) };
                ([b.real.x, b.real.y, b.real.z, b.real.w], [b.dual.x, b.dual.y, b.dual.z, b.dual.w])
            };
            let dot = q[0] * s.real[0][l] + q[1] * s.real[1][l] + q[2] * s.real[2][l] + q[3] * s.real[3][l];
            let w = slot.weights[l];
            let w = if dot < 0.0 { -w } else { w };
            for c in 0..4 {
                s.real[c][l] = madd::<ISA>(q[c], w, s.real[c][l]);
                s.dual[c][l] = madd::<ISA>(d[c], w, s.dual[c][l]);
            }
            s.contrib[l] += slot.weights[l];
        }
    }
    s
}

/// Applies the summed dual quaternions (Blender's `mul_v3m3_dq`: `(M·co + t)/|q|²`), then the
/// strength: `co + a·(r − co)`; `co` where `contrib ≤ 0.0001` or the sum is zero. Computed as
/// `co + u·(2a/|q|²)` without the matrix (see `dual_quaternion` in `batch.rs`, which the SIMD
/// copies run). Written with selects, not branches, so the lane loop vectorizes.
#[inline(always)]
fn finish_dual_quaternion<const ISA: u8>(co: &Points, s: &DqSum, strength: &Lanes) -> Points {
    let mut r = *co;
    for l in 0..LANES {
        let q = [s.real[0][l], s.real[1][l], s.real[2][l], s.real[3][l]];
        let (x, y, z, w) = (q[0], q[1], q[2], q[3]);
        let (tx, ty, tz, t0) = (s.dual[0][l], s.dual[1][l], s.dual[2][l], s.dual[3][l]);
        let p = [co.x[l], co.y[l], co.z[l]];
        // b = v × p + t⃗, u = w·b + v × b − t₀·v
        let b = [
            madd::<ISA>(-z, p[1], madd::<ISA>(y, p[2], tx)),
            madd::<ISA>(-x, p[2], madd::<ISA>(z, p[0], ty)),
            madd::<ISA>(-y, p[0], madd::<ISA>(x, p[1], tz)),
        ];
        let u = [
            madd::<ISA>(-t0, x, madd::<ISA>(-z, b[1], madd::<ISA>(y, b[2], w * b[0]))),
            madd::<ISA>(-t0, y, madd::<ISA>(-x, b[2], madd::<ISA>(z, b[0], w * b[1]))),
            madd::<ISA>(-t0, z, madd::<ISA>(-y, b[0], madd::<ISA>(x, b[1], w * b[2]))),
        ];
        let len2 = length_squared::<ISA>(q);
        let valid = s.contrib[l] > MIN_TOTAL_WEIGHT && len2 > 0.0;
        let a = strength[l];
        let g = if valid { (a + a) / len2 } else { 0.0 };
        r.x[l] = madd::<ISA>(u[0], g, p[0]);
        r.y[l] = madd::<ISA>(u[1], g, p[1]);
        r.z[l] = madd::<ISA>(u[2], g, p[2]);
    }
    r
}

/// `|q|²` of a quaternion sum `(x, y, z, w)`, in the SIMD copies' order.
#[inline(always)]
fn length_squared<const ISA: u8>([x, y, z, w]: [f32; 4]) -> f32 {
    madd::<ISA>(z, z, madd::<ISA>(y, y, madd::<ISA>(x, x, w * w)))
}

/// `w·b + v × b` with `b = v × d` for the quaternion sum `(v, w)`: half of `|q|²·(R·d − d)`, `R`
/// its rotation (see `rotation_terms` in `batch.rs`).
#[inline(always)]
fn rotation_terms<const ISA: u8>([x, y, z, w]: [f32; 4], d: [f32; 3]) -> [f32; 3] {
    let b = [madd::<ISA>(-z, d[1], y * d[2]), madd::<ISA>(-x, d[2], z * d[0]), madd::<ISA>(-y, d[0], x * d[1])];
    [
        madd::<ISA>(-z, b[1], madd::<ISA>(y, b[2], w * b[0])),
        madd::<ISA>(-x, b[2], madd::<ISA>(z, b[0], w * b[1])),
        madd::<ISA>(-y, b[0], madd::<ISA>(x, b[1], w * b[2])),
    ]
}

/// Per-lane sums for centers of rotation: where LBS puts the center, `Σ wᵢ·Mᵢ·c` (scaled poses)
/// or how far it moves it, `Σ wᵢ·(Mᵢ·c − c)` (rigid poses, where that is cheaper: see
/// [`rotation_offset`]); the sign-aligned quaternion sum, `Σ wᵢ·Sᵢ·(co − c)` (scaled poses only)
/// and the total weight.
pub(super) struct CorSum {
    pub anchor: [Lanes; 3],
    pub real: [Lanes; 4],
    pub offset: [Lanes; 3],
    pub contrib: Lanes,
}

/// Sums for centers of rotation; the quaternion signs are chosen against the running sum as in
/// [`accumulate_dual_quaternion`].
///
/// # Safety
/// Every bone index of `slots` indexes `cor` and `cor_rigid` (see [`bone`]).
#[inline(always)]
unsafe fn accumulate_centers<const ISA: u8, const SCALED: bool>(
    co: &Points,
    center: &Points,
    slots: &[Slot],
    cor: &[CorBone],
    cor_rigid: &[CorRigidBone],
) -> CorSum {
    let mut s = CorSum { anchor: [ZERO; 3], real: [ZERO; 4], offset: [ZERO; 3], contrib: ZERO };
    for slot in slots {
        for l in 0..LANES {
            let w = slot.weights[l];
            let (cx, cy, cz) = (center.x[l], center.y[l], center.z[l]);
            let q = if SCALED {
                // SAFETY: the caller's contract.
                let b = unsafe { bone(cor, slot.records[l]) };
                for r in 0..3 {
                    let row = b.matrix.rows[r];
                    let moved = madd::<ISA>(row.x, cx, madd::<ISA>(row.y, cy, madd::<ISA>(row.z, cz, row.w)));
                    s.anchor[r][l] = madd::<ISA>(w, moved, s.anchor[r][l]);
                }
                let (dx, dy, dz) = (co.x[l] - cx, co.y[l] - cy, co.z[l] - cz);
                for r in 0..3 {
                    let row = b.stretch_row(r);
                    let stretched = madd::<ISA>(row[0], dx, madd::<ISA>(row[1], dy, row[2] * dz));
                    s.offset[r][l] = madd::<ISA>(w, stretched, s.offset[r][l]);
                }
                b.real
            } else {
                // SAFETY: the caller's contract.
                let r = unsafe { bone(cor_rigid, slot.records[l]) };
                let moved = rotation_offset::<ISA>(r.real, r.half_translation, [cx, cy, cz]);
                let w2 = w + w;
                for k in 0..3 {
                    s.anchor[k][l] = madd::<ISA>(w2, moved[k], s.anchor[k][l]);
                }
                r.real
            };
            let q = [q.x, q.y, q.z, q.w];
            let dot = q[0] * s.real[0][l] + q[1] * s.real[1][l] + q[2] * s.real[2][l] + q[3] * s.real[3][l];
            let ws = if dot < 0.0 { -w } else { w };
            for c in 0..4 {
                s.real[c][l] = madd::<ISA>(q[c], ws, s.real[c][l]);
            }
            s.contrib[l] += w;
        }
    }
    s
}

/// `½·(R·p + t − p)` for the unit quaternion `q = (v, w)` of `R`, given `h = t/2`:
/// `R·p = p + 2·(w·(v × p) + v × (v × p))`, so this is `w·a + (v × a + h)` with `a = v × p`,
/// where `h` enters as the addend of `v × a`'s second product (no extra instruction). Weighted by
/// `2·wᵢ` it sums to `Σ wᵢ·(Mᵢ·c − c)`; the `c` comes back once per vertex (`contrib·c`).
#[inline(always)]
fn rotation_offset<const ISA: u8>(q: Vec4, h: Vec4, p: [f32; 3]) -> [f32; 3] {
    let v = [q.x, q.y, q.z];
    let a = [
        madd::<ISA>(v[1], p[2], -(v[2] * p[1])),
        madd::<ISA>(v[2], p[0], -(v[0] * p[2])),
        madd::<ISA>(v[0], p[1], -(v[1] * p[0])),
    ];
    let b = [
        madd::<ISA>(v[1], a[2], -madd::<ISA>(v[2], a[1], -h.x)),
        madd::<ISA>(v[2], a[0], -madd::<ISA>(v[0], a[2], -h.y)),
        madd::<ISA>(v[0], a[1], -madd::<ISA>(v[1], a[0], -h.z)),
    ];
    core::array::from_fn(|k| madd::<ISA>(q.w, a[k], b[k]))
}

/// `co' = c + anchor/contrib + R·d` (rigid: `anchor = Σ wᵢ·(Mᵢ·c − c)`, `d = co − c`) or
/// `co' = anchor/contrib + R·o/contrib` (scaled: `anchor = Σ wᵢ·Mᵢ·c`, `o` the offset sum), `R` the
/// rotation of the summed quaternion, through [`rotation_terms`] `u` of `d` or `o`:
/// `R·d = d + 2u/|q|²`; then the strength: `co + a·(co' − co)`, that is
/// `co + anchor·(a/contrib) + u·(2a/|q|²)` (rigid) or
/// `co + (anchor + o − contrib·co)·(a/contrib) + u·(2a/(|q|²·contrib))` (scaled); `co` where
/// `contrib ≤ 0.0001` or the sum is zero. One division, `a/(|q|²·contrib)`, serves both factors.
/// Selects, not branches, so the lane loop vectorizes.
#[inline(always)]
fn finish_centers<const ISA: u8, const SCALED: bool>(co: &Points, center: &Points, s: &CorSum, strength: &Lanes) -> Points {
    let mut r = *co;
    for l in 0..LANES {
        let q = [s.real[0][l], s.real[1][l], s.real[2][l], s.real[3][l]];
        let len2 = length_squared::<ISA>(q);
        let p = [co.x[l], co.y[l], co.z[l]];
        let d = if SCALED {
            [s.offset[0][l], s.offset[1][l], s.offset[2][l]]
        } else {
            [p[0] - center.x[l], p[1] - center.y[l], p[2] - center.z[l]]
        };
        let u = rotation_terms::<ISA>(q, d);
        let contrib = s.contrib[l];
        let valid = contrib > MIN_TOTAL_WEIGHT && len2 > 0.0;
        let a = strength[l];
        let inv = if valid { a / (len2 * contrib) } else { 0.0 };
        let fa = inv * len2;
        let fr = if SCALED { inv + inv } else { (inv + inv) * contrib };
        let anchor = |k: usize| if SCALED { madd::<ISA>(-p[k], contrib, s.anchor[k][l] + d[k]) } else { s.anchor[k][l] };
        r.x[l] = madd::<ISA>(anchor(0), fa, madd::<ISA>(u[0], fr, p[0]));
        r.y[l] = madd::<ISA>(anchor(1), fa, madd::<ISA>(u[1], fr, p[1]));
        r.z[l] = madd::<ISA>(anchor(2), fa, madd::<ISA>(u[2], fr, p[2]));
    }
    r
}

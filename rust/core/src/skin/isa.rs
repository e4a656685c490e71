//! The instruction sets the kernels are compiled for, and which of them this CPU has. Every copy
//! of the kernels, the dispatcher (`kernels.rs`) and the precompute take a [`Simd`] from here;
//! which copy runs by default is measured (`calibration.rs`).

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
    /// The name `DQSKIN_SIMD` and [`super::set_kernel_copy`] give the copy.
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
/// instruction sets: it is only made by [`Simd::available`] after detecting them, so code
/// holding one may run that copy's `#[target_feature]` functions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Simd {
    set: InstructionSet,
    /// Whether each batch asks the memory for the inputs of a batch ahead (`kernels.rs`,
    /// `prefetch_ahead`): a hint that gives the same bits either way, worth a fifth on an Intel
    /// Xeon's large meshes and a few per cent less on a Zen 3's (docs/performance.md), so both
    /// are measured ([`Simd::without_prefetch`]).
    prefetch: bool,
    /// Whether the copy's hand-written kernels run where they are kept (`*/kept.rs`): only the
    /// tests that hold them to the one body's bits turn them off ([`Simd::one_body`]).
    #[cfg(test)]
    kept: bool,
}

impl Simd {
    /// The copies this CPU can run, widest last.
    pub(crate) fn available() -> Vec<Simd> {
        let mut all = vec![Simd::of(InstructionSet::Baseline)];
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            if has!("avx2") && has!("fma") {
                all.push(Simd::of(InstructionSet::Avx2Fma));
                if has!("avx512f") {
                    all.push(Simd::of(InstructionSet::Avx512));
                }
            }
        }
        #[cfg(target_arch = "aarch64")]
        all.push(Simd::of(InstructionSet::Neon));
        all
    }

    /// The widest copy this CPU has.
    pub(crate) fn widest() -> Self {
        *Self::available().last().expect("the baseline is always available")
    }

    /// The available copy named `name` (`baseline`, `avx2`, `avx512`, `neon`, or one of those
    /// with `-noprefetch`: [`Simd::name`]), if the CPU has it.
    pub(crate) fn named(name: &str) -> Option<Self> {
        Self::copies().into_iter().find(|s| s.name() == name.trim())
    }

    /// Every copy this CPU can run: each available instruction set without prefetching where it
    /// has the hint, then with it (widest last).
    pub(crate) fn copies() -> Vec<Simd> {
        Self::available().into_iter().flat_map(|s| s.without_prefetch().into_iter().chain([s])).collect()
    }

    /// The copy's name: its instruction set's (`avx2`), with `-noprefetch` where its batches do
    /// not ask for their inputs ahead.
    pub(crate) fn name(self) -> &'static str {
        if self.prefetch {
            return self.set.name();
        }
        match self.set {
            #[cfg(target_arch = "x86_64")]
            InstructionSet::Avx2Fma => "avx2-noprefetch",
            #[cfg(target_arch = "x86_64")]
            InstructionSet::Avx512 => "avx512-noprefetch",
            set => set.name(),
        }
    }

    /// The same instruction set with its batches not asking for their inputs ahead: for the
    /// copies with fused multiply-adds on x86-64, where the hint exists (None elsewhere).
    pub(crate) fn without_prefetch(self) -> Option<Self> {
        #[cfg(target_arch = "x86_64")]
        if self.prefetch && matches!(self.set, InstructionSet::Avx2Fma | InstructionSet::Avx512) {
            return Some(Simd { prefetch: false, ..self });
        }
        None
    }

    /// Whether the copy's batches ask for their inputs ahead.
    pub(crate) fn prefetches(self) -> bool {
        self.prefetch
    }

    /// The copy `DQSKIN_SIMD` asks for, if it names one the CPU has (for debugging and
    /// comparisons; read once per process).
    pub(crate) fn requested() -> Option<Self> {
        static REQUESTED: std::sync::OnceLock<Option<Simd>> = std::sync::OnceLock::new();
        *REQUESTED.get_or_init(|| std::env::var("DQSKIN_SIMD").ok().and_then(|v| Self::named(&v)))
    }

    /// The copy `DQSKIN_SIMD` asks for, else the widest: the precompute's inner loops, which are
    /// compute-bound and gain from every wider copy.
    pub(crate) fn detect() -> Self {
        Self::requested().unwrap_or_else(Self::widest)
    }

    /// The instruction set of this copy (a value of it proves the CPU has it).
    pub(crate) fn instruction_set(self) -> InstructionSet {
        self.set
    }

    /// A copy of the instruction set `set`, which the CPU must have.
    fn of(set: InstructionSet) -> Self {
        Simd {
            set,
            prefetch: true,
            #[cfg(test)]
            kept: true,
        }
    }

    /// Whether the copy's hand-written kernels run where they are kept: always outside the
    /// tests, a constant the compiler folds.
    #[cfg(not(test))]
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code, reason = "read where x86-64's kernels are chosen"))]
    pub(crate) fn runs_kept(self) -> bool {
        true
    }

    #[cfg(test)]
    pub(crate) fn runs_kept(self) -> bool {
        self.kept
    }

    /// The same copy running the one body of `batch.rs` for every method, its hand-written
    /// kernels left out: what the tests hold those to.
    #[cfg(test)]
    pub(crate) fn one_body(self) -> Self {
        Simd { kept: false, ..self }
    }
}

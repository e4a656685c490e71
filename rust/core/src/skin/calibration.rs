//! Which compiled copy of the kernels runs by default: the fastest on this CPU, measured rather
//! than guessed from the vendor or from the widest instruction set (a wider copy is not always
//! faster: see docs/performance.md), among copies that give the same bits ([`candidates`]).
//!
//! Measured on the user's own calls: each kernel variant and [`Size`] starts with a trial, in
//! which its calls take the candidate copies in turn and are timed, until each copy has
//! [`Size::samples`] timings; then the copy with the best time per byte moved runs every later
//! call of that variant and size in the process. The copies give the same bits, so a trial
//! changes no result, only which instructions compute it; and it measures what the calls
//! really meet (a large mesh's data streamed from memory after Blender's evaluation, a small
//! one's in the caches), which a calibration on a fixed small mesh did not: it chose the slower
//! copy in a tenth to a third of processes (docs/performance.md).
//! [`set_kernel_copy`] (the API) and `DQSKIN_SIMD` (the environment) override it, in that order.

use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::{Mutex, OnceLock, RwLock};
use std::time::Instant;

use super::isa::{InstructionSet, Simd};
use super::job::Kind;
use super::SkinError;

/// The kernel variants whose copy is chosen separately: the method, and whether some bone takes
/// Blender's scale path (a different body with different loads and shuffles).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Variant {
    Linear,
    DualQuaternion,
    DualQuaternionScaled,
    Blend,
    BlendScaled,
    Centers,
    CentersScaled,
}

impl Variant {
    pub(crate) const ALL: [Variant; 7] = [
        Variant::Linear,
        Variant::DualQuaternion,
        Variant::DualQuaternionScaled,
        Variant::Blend,
        Variant::BlendScaled,
        Variant::Centers,
        Variant::CentersScaled,
    ];

    pub(crate) fn of(kind: Kind, scaled: bool) -> Self {
        match (kind, scaled) {
            (Kind::Linear, _) => Variant::Linear,
            (Kind::DualQuaternion, false) => Variant::DualQuaternion,
            (Kind::DualQuaternion, true) => Variant::DualQuaternionScaled,
            (Kind::Blend, false) => Variant::Blend,
            (Kind::Blend, true) => Variant::BlendScaled,
            (Kind::CentersOfRotation, false) => Variant::Centers,
            (Kind::CentersOfRotation, true) => Variant::CentersScaled,
        }
    }

    pub(crate) fn name(self) -> &'static str {
        match self {
            Variant::Linear => "linear",
            Variant::DualQuaternion => "dual_quaternion",
            Variant::DualQuaternionScaled => "dual_quaternion_scaled",
            Variant::Blend => "blend",
            Variant::BlendScaled => "blend_scaled",
            Variant::Centers => "centers",
            Variant::CentersScaled => "centers_scaled",
        }
    }

    fn index(self) -> usize {
        Variant::ALL.iter().position(|&v| v == self).unwrap_or(0)
    }
}

/// The copy the API asked for ([`set_kernel_copy`]); `None`: none asked for.
static OVERRIDE: RwLock<Option<Simd>> = RwLock::new(None);

/// Runs every later call on the copy `name` (`baseline`, `avx2`, `avx512`, `neon`), or again on the
/// measured fastest with `None`. Refused, changing nothing, for a name this CPU has no copy of.
pub fn set_kernel_copy(name: Option<&str>) -> Result<(), SkinError> {
    let simd = match name {
        Some(name) => Some(Simd::named(name).ok_or_else(|| SkinError::UnavailableKernelCopy(name.to_string()))?),
        None => None,
    };
    *OVERRIDE.write().unwrap_or_else(|e| e.into_inner()) = simd;
    Ok(())
}

/// Jobs whose copy is chosen apart: a copy that is faster while a mesh's data stay in a core's
/// caches may be slower when they stream from memory (docs/performance.md has a case).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Size {
    /// Fewer than [`Size::STREAMED_FROM`] vertices.
    Cached,
    Streamed,
}

impl Size {
    /// From this many vertices a job's positions, influences and output (about 45 bytes a vertex
    /// with four influences, 3 MB here) outgrow a core's L2 cache.
    pub(crate) const STREAMED_FROM: usize = 65_536;
    const ALL: [Size; 2] = [Size::Cached, Size::Streamed];

    pub(crate) fn of(vertices: usize) -> Self {
        if vertices < Self::STREAMED_FROM {
            Size::Cached
        } else {
            Size::Streamed
        }
    }

    /// Timed calls per copy before the choice: small calls vary more (a few microseconds, where
    /// an interrupt counts), large ones cost more to repeat on the slower copy.
    pub(crate) fn samples(self) -> u32 {
        match self {
            Size::Cached => 8,
            Size::Streamed => 3,
        }
    }

    pub(crate) fn name(self) -> &'static str {
        match self {
            Size::Cached => "cached",
            Size::Streamed => "streamed",
        }
    }
}

/// The copy the override or the environment asks for, if any.
fn fixed_copy() -> Option<Simd> {
    if let Some(simd) = *OVERRIDE.read().unwrap_or_else(|e| e.into_inner()) {
        return Some(simd);
    }
    Simd::requested()
}

/// Runs `run` on the copy for `variant` and a job of `vertices` vertices moving `bytes` bytes:
/// the API's override, else `DQSKIN_SIMD`'s, else the one measured fastest here for that variant
/// and size, or, while that is being measured, the next copy of its trial, timed.
pub(crate) fn run_on_copy(variant: Variant, vertices: usize, bytes: usize, run: impl FnOnce(Simd)) {
    if let Some(simd) = fixed_copy() {
        return run(simd);
    }
    let trial = &TRIALS[variant.index()][Size::of(vertices) as usize];
    let simd = match trial.chosen() {
        Some(simd) => return run(simd),
        None => trial.next(),
    };
    let start = Instant::now();
    run(simd);
    trial.record(simd, start.elapsed().as_secs_f64() / bytes.max(1) as f64);
}

/// The copy chosen for `variant` on jobs of `size`: the override's or the environment's, else
/// the measured one; None while its trial runs.
pub(crate) fn chosen_copy(variant: Variant, size: Size) -> Option<Simd> {
    fixed_copy().or_else(|| TRIALS[variant.index()][size as usize].chosen())
}

/// Every variant's choice per size, for [`super::kernel_copies`].
pub(crate) fn chosen_copies() -> Vec<(Variant, Size, Option<Simd>)> {
    Variant::ALL.iter().flat_map(|&v| Size::ALL.map(|size| (v, size, chosen_copy(v, size)))).collect()
}

static TRIALS: [[Trial; Size::ALL.len()]; Variant::ALL.len()] =
    [const { [Trial::new(Size::Cached), Trial::new(Size::Streamed)] }; Variant::ALL.len()];

/// The most candidate copies (AVX2 and AVX-512 on x86-64, each with and without prefetching).
const MAX_COPIES: usize = 4;

/// One variant and size's measurement: which copy was chosen (its index among [`candidates`]
/// plus one, 0 while the trial runs), read without a lock on every call, and the trial's
/// timings.
struct Trial {
    size: Size,
    chosen: AtomicU8,
    timings: Mutex<Timings>,
}

#[derive(Clone, Copy)]
struct Timings {
    /// Each candidate's timed calls so far and its best time per byte.
    samples: [u32; MAX_COPIES],
    best: [f64; MAX_COPIES],
}

impl Trial {
    const fn new(size: Size) -> Self {
        Trial {
            size,
            chosen: AtomicU8::new(0),
            timings: Mutex::new(Timings { samples: [0; MAX_COPIES], best: [f64::INFINITY; MAX_COPIES] }),
        }
    }

    /// The copy chosen; the one candidate where there is one (nothing to measure).
    fn chosen(&self) -> Option<Simd> {
        let candidates = candidate_list();
        match self.chosen.load(Ordering::Acquire) {
            0 if candidates.len() == 1 => Some(candidates[0]),
            0 => None,
            k => Some(candidates[k as usize - 1]),
        }
    }

    /// The copy for the next call of the trial: the one with the fewest timings (the first of
    /// them), so that the copies take turns.
    fn next(&self) -> Simd {
        let candidates = candidate_list();
        let t = self.timings.lock().unwrap_or_else(|e| e.into_inner());
        let k = (0..candidates.len()).min_by_key(|&k| t.samples[k]).unwrap_or(0);
        candidates[k]
    }

    /// One timed call of `simd`, `per_byte` seconds for each byte it moved; once every copy has
    /// enough, the choice.
    fn record(&self, simd: Simd, per_byte: f64) {
        let candidates = candidate_list();
        let Some(k) = candidates.iter().position(|&c| c == simd) else { return };
        let mut t = self.timings.lock().unwrap_or_else(|e| e.into_inner());
        t.samples[k] += 1;
        t.best[k] = t.best[k].min(per_byte);
        let needed = self.size.samples();
        if self.chosen.load(Ordering::Relaxed) == 0 && t.samples[..candidates.len()].iter().all(|&n| n >= needed) {
            let k = fastest(&t.best[..candidates.len()]);
            self.chosen.store(k as u8 + 1, Ordering::Release);
        }
    }
}

/// [`candidates`], computed once.
fn candidate_list() -> &'static [Simd] {
    static LIST: OnceLock<Vec<Simd>> = OnceLock::new();
    LIST.get_or_init(|| {
        let mut list = candidates();
        debug_assert!(list.len() <= MAX_COPIES);
        list.truncate(MAX_COPIES); // (cannot happen: at most two instruction sets, two copies each)
        list
    })
}

/// The copies calibration chooses between: those with fused multiply-adds where there are any,
/// each without and with prefetching where it has the hint (x86-64). They give the same bits
/// (every copy's arithmetic in the same order; a prefetch reads nothing), so the choice, which
/// timing noise can flip between processes, never changes a result; the baseline rounds each
/// product and differs from them in the last bits, so it runs only where it is the one copy (or
/// when asked for). Within an instruction set the copy that prefetches comes second, so that a
/// tie keeps it (as the wider copy keeps a tie).
pub(crate) fn candidates() -> Vec<Simd> {
    let all = Simd::copies();
    let fused: Vec<Simd> = all.iter().copied().filter(|s| s.instruction_set() != InstructionSet::Baseline).collect();
    if fused.is_empty() {
        all
    } else {
        fused
    }
}

/// Copies within this share of the fastest time count as tied, and a tie goes to the wider copy
/// (the later in [`Simd::available`]): the choice should not flip between processes with noise.
const TIE: f64 = 0.03;

/// The index of the fastest of the candidates (widest last) by their best times, ties within
/// [`TIE`] going to the wider copy.
pub(crate) fn fastest(best: &[f64]) -> usize {
    let quickest = best.iter().copied().fold(f64::INFINITY, f64::min);
    best.iter().rposition(|&t| t <= quickest * (1.0 + TIE)).unwrap_or(best.len().saturating_sub(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fastest_copy_wins_and_a_tie_goes_to_the_wider() {
        assert_eq!(fastest(&[1.0, 2.0]), 0);
        assert_eq!(fastest(&[2.0, 1.0]), 1);
        assert_eq!(fastest(&[1.0, 1.0 + TIE / 2.0]), 1, "within the tie margin, the wider");
        assert_eq!(fastest(&[1.0, 1.0 + 2.0 * TIE]), 0);
        assert_eq!(fastest(&[1.0, 1.0 + TIE / 2.0, 3.0]), 1);
        assert_eq!(fastest(&[5.0]), 0);
    }

    /// A trial of its own (not one of the process's), fed timings by the test.
    fn decide(trial: &Trial, time: impl Fn(Simd) -> f64) -> (Simd, Vec<Simd>) {
        let mut taken = Vec::new();
        while trial.chosen().is_none() {
            let simd = trial.next();
            taken.push(simd);
            trial.record(simd, time(simd));
            assert!(taken.len() < 100, "a trial ends");
        }
        (trial.chosen().unwrap(), taken)
    }

    #[test]
    fn a_trial_takes_the_copies_in_turn_then_keeps_the_fastest() {
        let all = candidate_list();
        let widest = *all.last().unwrap();
        if all.len() == 1 {
            return; // nothing to measure (`one_candidate_needs_no_trial`)
        }
        for size in Size::ALL {
            // The narrowest clearly fastest, and in one call of each copy very slow (an
            // interrupt): the best time counts.
            let calls = std::cell::Cell::new(0);
            let time = |simd: Simd| {
                calls.set(calls.get() + 1);
                if calls.get() <= all.len() {
                    10.0
                } else if simd == all[0] {
                    1.0
                } else {
                    2.0
                }
            };
            let trial = Trial::new(size);
            let (chosen, taken) = decide(&trial, time);
            assert_eq!(chosen, all[0], "{size:?}");
            assert_eq!(taken.len(), all.len() * size.samples() as usize, "{size:?}: every copy timed as often");
            for (i, simd) in taken.iter().enumerate() {
                assert_eq!(*simd, all[i % all.len()], "{size:?}: in turn");
            }
            // A tie: the widest.
            let (chosen, _) = decide(&Trial::new(size), |simd| if simd == widest { 1.0 + TIE / 2.0 } else { 1.0 });
            assert_eq!(chosen, widest);
            // Timings after the choice change nothing.
            trial.record(widest, 0.0);
            assert_eq!(trial.chosen(), Some(all[0]));
        }
    }

    #[test]
    fn one_candidate_needs_no_trial() {
        let trial = Trial::new(Size::Cached);
        if candidate_list().len() == 1 {
            assert_eq!(trial.chosen(), Some(candidate_list()[0]));
        } else {
            assert_eq!(trial.chosen(), None, "several candidates: a trial first");
        }
    }

    #[test]
    fn sizes_are_told_apart_at_the_threshold() {
        assert_eq!(Size::of(0), Size::Cached);
        assert_eq!(Size::of(Size::STREAMED_FROM - 1), Size::Cached);
        assert_eq!(Size::of(Size::STREAMED_FROM), Size::Streamed);
        assert!(Size::Cached.samples() >= Size::Streamed.samples());
    }

    #[test]
    fn every_variant_and_size_has_a_slot_of_its_own() {
        for (i, variant) in Variant::ALL.into_iter().enumerate() {
            assert_eq!(variant.index(), i);
            for size in Size::ALL {
                assert_eq!(TRIALS[i][size as usize].size, size);
            }
        }
    }

    #[test]
    fn the_baseline_is_chosen_only_where_it_is_the_one_copy() {
        let (all, chosen) = (Simd::available(), candidates());
        assert_eq!(all.len() == 1, chosen.contains(&all[0]), "{all:?} gives {chosen:?}");
        let sets: Vec<InstructionSet> = chosen.iter().map(|s| s.instruction_set()).collect();
        assert!(sets.iter().all(|set| all.iter().any(|a| a.instruction_set() == *set)));
        // Each instruction set with fused multiply-adds twice on x86-64 (without prefetching,
        // then with it, which keeps a tie), once elsewhere.
        let fused = all.len().max(2) - 1;
        let per_set = if cfg!(target_arch = "x86_64") && all.len() > 1 { 2 } else { 1 };
        assert_eq!(chosen.len(), fused * per_set, "{chosen:?}");
        for pair in chosen.chunks(per_set) {
            assert!(pair.iter().all(|s| s.instruction_set() == pair[0].instruction_set()), "{sets:?}");
            assert!(pair.last().unwrap().prefetches(), "{pair:?}");
            assert!(pair.len() == 1 || !pair[0].prefetches(), "{pair:?}");
        }
    }

    #[test]
    fn every_candidate_is_found_by_its_name() {
        for simd in candidates() {
            assert_eq!(Simd::named(simd.name()), Some(simd), "{simd:?}");
            assert_eq!(simd.name().ends_with("-noprefetch"), !simd.prefetches(), "{simd:?}");
        }
        // The instruction set's own name keeps its batches asking ahead (as before the choice).
        for simd in Simd::available() {
            assert!(simd.prefetches() && Simd::named(simd.instruction_set().name()) == Some(simd));
        }
        assert_eq!(Simd::named("baseline-noprefetch"), None, "the baseline has one copy");
    }

    #[test]
    fn unknown_copies_are_refused_and_change_nothing() {
        assert!(matches!(set_kernel_copy(Some("sse9")), Err(SkinError::UnavailableKernelCopy(_))));
        assert!(OVERRIDE.read().unwrap().is_none());
        assert!(set_kernel_copy(None).is_ok());
    }
}

//! Which compiled copy of the kernels runs by default: the fastest on this CPU, measured rather
//! than guessed from the vendor or from the widest instruction set (a wider copy is not always
//! faster: see docs/performance.md), among copies that give the same bits ([`candidates`]). Each
//! kernel variant is timed once per process, on first use, on a small mesh that stays in the
//! caches, every candidate in turn; the result is kept for the life of the process.
//! [`set_kernel_copy`] (the API) and `DQSKIN_SIMD` (the environment) override it, in that order.

use std::sync::{OnceLock, RwLock};
use std::time::Instant;

use glam::{Mat4, Quat, Vec3};

use super::isa::{InstructionSet, Simd};
use super::job::{Job, Kind};
use super::{kernels, Influences, Pose, SkinError};

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

    fn kind(self) -> Kind {
        match self {
            Variant::Linear => Kind::Linear,
            Variant::DualQuaternion | Variant::DualQuaternionScaled => Kind::DualQuaternion,
            Variant::Blend | Variant::BlendScaled => Kind::Blend,
            Variant::Centers | Variant::CentersScaled => Kind::CentersOfRotation,
        }
    }

    fn scaled(self) -> bool {
        matches!(self, Variant::DualQuaternionScaled | Variant::BlendScaled | Variant::CentersScaled)
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

/// The copy that runs `variant`: the API's override, else `DQSKIN_SIMD`'s, else the one measured
/// fastest here (timed on first use).
pub(crate) fn copy_for(variant: Variant) -> Simd {
    if let Some(simd) = *OVERRIDE.read().unwrap_or_else(|e| e.into_inner()) {
        return simd;
    }
    if let Some(simd) = Simd::requested() {
        return simd;
    }
    measured(variant)
}

/// The copy measured fastest for `variant` (measured once per process; concurrent first callers
/// wait for the one measurement).
pub(crate) fn measured(variant: Variant) -> Simd {
    static CHOSEN: [OnceLock<Simd>; 7] = [const { OnceLock::new() }; 7];
    *CHOSEN[variant.index()].get_or_init(|| {
        let candidates = candidates();
        if candidates.len() == 1 {
            return candidates[0];
        }
        match Fixture::new(variant) {
            Ok(fixture) => fastest(&candidates, BUDGET, |simd| fixture.time(simd)),
            // Cannot happen (the fixture is valid by construction); the widest is the safe guess.
            Err(_) => Simd::widest(),
        }
    })
}

/// The copies calibration chooses between: those with fused multiply-adds where there are any.
/// They give the same bits (every copy's arithmetic in the same order), so the choice, which
/// timing noise can flip between processes, never changes a result; the baseline rounds each
/// product and differs from them in the last bits, so it runs only where it is the one copy (or
/// when asked for).
pub(crate) fn candidates() -> Vec<Simd> {
    let all = Simd::available();
    let fused: Vec<Simd> = all.iter().copied().filter(|s| s.instruction_set() != InstructionSet::Baseline).collect();
    if fused.is_empty() {
        all
    } else {
        fused
    }
}

/// The most timed rounds per copy (after one warm-up each), interleaved so that every copy sees the
/// same conditions; each keeps its best.
const MAX_ROUNDS: usize = 5;

/// Seconds of kernel time after which no new round starts (there is always one timed round): a
/// variant's calibration costs about this much, or two passes of each copy where one pass is
/// slower (an emulated CPU).
const BUDGET: f64 = 0.5e-3;

/// Copies within this share of the fastest time count as tied, and a tie goes to the wider copy
/// (the later in [`Simd::available`]): the choice should not flip between processes with noise.
const TIE: f64 = 0.03;

/// The fastest of `candidates` (widest last) by the best of its timings (`time` returns seconds),
/// with ties within [`TIE`] going to the wider copy: a warm-up round, then timed rounds until
/// `budget` seconds have been timed in all (at least one, at most [`MAX_ROUNDS`]).
pub(crate) fn fastest(candidates: &[Simd], budget: f64, mut time: impl FnMut(Simd) -> f64) -> Simd {
    let mut best = vec![f64::INFINITY; candidates.len()];
    let mut spent = 0.0;
    for round in 0..=MAX_ROUNDS {
        for (k, &simd) in candidates.iter().enumerate() {
            let t = time(simd);
            spent += t;
            if round > 0 {
                best[k] = best[k].min(t);
            }
        }
        if round > 0 && spent >= budget {
            break;
        }
    }
    let quickest = best.iter().copied().fold(f64::INFINITY, f64::min);
    let k = best.iter().rposition(|&t| t <= quickest * (1.0 + TIE)).unwrap_or(candidates.len() - 1);
    candidates[k]
}

/// Vertices of the calibration mesh: 64 batches, enough for each copy's steady state, few enough
/// that one pass takes microseconds (the cost of a calibration: docs/performance.md).
const VERTICES: usize = 1024;
const BONES: usize = 32;
const INFLUENCES: usize = 4;

/// A small mesh with four influences per vertex on neighbouring bones, as a real mesh has.
struct Fixture {
    variant: Variant,
    positions: Vec<[f32; 3]>,
    centers: Vec<[f32; 3]>,
    influences: Influences,
    pose: Pose,
    out: std::cell::RefCell<Vec<[f32; 3]>>,
}

impl Fixture {
    fn new(variant: Variant) -> Result<Self, SkinError> {
        // A fixed sequence (an LCG): the same mesh in every process.
        let mut state = 0x2545_F491_u32;
        let mut unit = move || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32
        };
        let positions: Vec<[f32; 3]> =
            (0..VERTICES).map(|_| [2.0 * unit() - 1.0, 2.0 * unit(), 2.0 * unit() - 1.0]).collect();
        let centers = positions.iter().map(|p| [0.9 * p[0], p[1], 0.9 * p[2]]).collect();
        let mut offsets = vec![0u32];
        let (mut bones, mut weights) = (Vec::new(), Vec::new());
        for v in 0..VERTICES {
            let base = v * BONES / VERTICES;
            for k in 0..INFLUENCES {
                bones.push(((base + 3 * k) % BONES) as u32);
                weights.push(0.1 + unit());
            }
            offsets.push(bones.len() as u32);
        }
        let influences = Influences::from_csr(&offsets, &bones, &weights, BONES)?;
        let rest: Vec<Mat4> =
            (0..BONES).map(|b| Mat4::from_translation(Vec3::new(0.0, b as f32 / 16.0, 0.0))).collect();
        let deform: Vec<Mat4> = rest
            .iter()
            .enumerate()
            .map(|(b, r)| {
                let angle = 0.1 * b as f32;
                let q = Quat::from_axis_angle(Vec3::new(1.0, 2.0, 0.5).normalize(), angle);
                let s = if variant.scaled() && b % 2 == 1 { Vec3::new(1.0, 1.3, 0.9) } else { Vec3::ONE };
                Mat4::from_scale_rotation_translation(s, q, Vec3::new(0.1, -0.2, 0.05 * angle)) * r.inverse()
            })
            .collect();
        let pose = Pose::new(&deform, Some(&rest))?;
        let out = std::cell::RefCell::new(vec![[0.0; 3]; VERTICES]);
        Ok(Fixture { variant, positions, centers, influences, pose, out })
    }

    /// Seconds one pass of the copy `simd` takes (on this thread: the mesh is one chunk).
    fn time(&self, simd: Simd) -> f64 {
        let mut job = Job::new(self.variant.kind(), &self.positions, &self.influences, &self.pose);
        job.premat = Some(Mat4::from_translation(Vec3::new(0.5, -1.0, 2.0)));
        job.postmat = Some(Mat4::from_translation(Vec3::new(-0.5, 1.0, -2.0)));
        job.blend_factor = 0.5;
        if self.variant.kind() == Kind::CentersOfRotation {
            job.centers = Some(&self.centers);
        }
        let mut out = self.out.borrow_mut();
        let start = Instant::now();
        kernels::run(&job, &mut out, simd);
        start.elapsed().as_secs_f64()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fastest_copy_wins_and_a_tie_goes_to_the_wider() {
        let all = Simd::available();
        let widest = *all.last().unwrap();
        // The widest slowest: another wins when it is clearly faster.
        let times = |slow: Simd| move |simd: Simd| if simd == slow { 2.0 } else { 1.0 };
        if all.len() > 1 {
            assert_ne!(fastest(&all, 0.0, times(widest)), widest);
            assert_eq!(fastest(&all, 0.0, times(all[0])), widest);
        }
        // Within the tie margin, the wider copy.
        let close = |simd: Simd| if simd == widest { 1.0 + TIE / 2.0 } else { 1.0 };
        assert_eq!(fastest(&all, 0.0, close), widest);
        // Each copy keeps its best timed round; the warm-up does not count.
        let mut calls = 0;
        let noisy = |simd: Simd| {
            calls += 1;
            if calls <= all.len() {
                0.0 // the warm-up round, ignored
            } else if simd == all[0] {
                3.0
            } else {
                1.0 + calls as f64
            }
        };
        assert_eq!(fastest(&all, 0.0, noisy), if all.len() > 1 { all[0] } else { widest });
    }

    #[test]
    fn rounds_stop_at_the_budget() {
        let all = Simd::available();
        let rounds = |budget: f64, pass: f64| {
            let mut calls = 0;
            fastest(&all, budget, |_| {
                calls += 1;
                pass
            });
            calls / all.len() - 1 // timed rounds, after the warm-up
        };
        // One pass of each copy costs 1 ms: a 0.5 ms budget allows one timed round, a huge one
        // every round, and a budget of three rounds' worth (counting the warm-up) two.
        assert_eq!(rounds(0.5e-3 * all.len() as f64, 1e-3), 1);
        assert_eq!(rounds(1e9, 1e-3), MAX_ROUNDS);
        assert_eq!(rounds(3e-3 * all.len() as f64, 1e-3), 2);
    }

    #[test]
    fn every_variant_chooses_an_available_copy_once() {
        let all = candidates();
        for variant in Variant::ALL {
            let chosen = measured(variant);
            assert!(all.contains(&chosen));
            assert_eq!(measured(variant), chosen, "remembered");
            assert_eq!(Variant::of(variant.kind(), variant.scaled()), variant);
        }
    }

    #[test]
    fn a_calibration_is_cheap() {
        let start = Instant::now();
        let mut passes = 0;
        for variant in Variant::ALL {
            let fixture = Fixture::new(variant).unwrap();
            fastest(&Simd::available(), BUDGET, |simd| {
                passes += 1;
                fixture.time(simd)
            });
        }
        let seconds = start.elapsed().as_secs_f64();
        let copies = Simd::available().len();
        eprintln!(
            "calibrating all {} variants on {copies} copies: {:.2} ms, {passes} passes",
            Variant::ALL.len(),
            seconds * 1e3
        );
        // Bounded by rounds, not by the clock (emulated CPUs run slower): at most all rounds.
        assert!(passes <= Variant::ALL.len() * copies * (MAX_ROUNDS + 1));
        assert!(passes >= Variant::ALL.len() * copies * 2);
    }

    #[test]
    fn the_baseline_is_chosen_only_where_it_is_the_one_copy() {
        let (all, chosen) = (Simd::available(), candidates());
        assert_eq!(all.len() == 1, chosen.contains(&all[0]), "{all:?} gives {chosen:?}");
        assert!(chosen.iter().all(|s| all.contains(s)));
        assert_eq!(chosen.len(), all.len().max(2) - 1);
    }

    #[test]
    fn unknown_copies_are_refused_and_change_nothing() {
        assert!(matches!(set_kernel_copy(Some("sse9")), Err(SkinError::UnavailableKernelCopy(_))));
        assert!(OVERRIDE.read().unwrap().is_none());
        assert!(set_kernel_copy(None).is_ok());
    }
}

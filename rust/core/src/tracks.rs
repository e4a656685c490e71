//! Animation tracks: keys at times (frames), sampled along Slerp, Squad, ScLERP or Spring curves,
//! and the measures used to judge them (angular speed, curvature).
//!
//! Squad's inner control points are adapted to uneven key spacing so that the angular velocity is
//! continuous in *time* at the keys: with `Lₚ = log(qᵢ₋₁*qᵢ)`, `Lₙ = log(qᵢ*qᵢ₊₁)` and segment
//! durations `Δₚ`, `Δₙ`, the tangent velocity is `V = (Δₙ·Lₚ/Δₚ + Δₚ·Lₙ/Δₙ)/(Δₚ + Δₙ)` and the
//! outgoing and incoming control points are `qᵢ·exp((V·Δₙ − Lₙ)/2)` and `qᵢ·exp((Lₚ − V·Δₚ)/2)`.
//! With even spacing both are Shoemake's `qᵢ·exp((Lₚ − Lₙ)/4)` (Dam et al. eq. 6.15).

use glam::{Quat, Vec4};

use crate::blend::sclerp;
use crate::dual_quat::{normalize_quat, DualQuat};
use crate::quat_interp::{make_signs_continuous, quat_exp, quat_log, slerp};

/// Why a track is unusable.
#[derive(Clone, Debug, PartialEq)]
pub enum TrackError {
    /// Times and keys differ in length, or there are no keys.
    Shape(String),
    /// Key times are not finite and strictly increasing.
    Times(String),
    /// A key is not a usable rotation or transform.
    Key(String),
    /// Spring settings out of range.
    Settings(String),
    /// Stopped by the caller's interrupt check (e.g. Ctrl-C).
    Interrupted,
}

impl core::fmt::Display for TrackError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            TrackError::Shape(m) | TrackError::Times(m) | TrackError::Key(m) | TrackError::Settings(m) => {
                f.write_str(m)
            }
            TrackError::Interrupted => f.write_str("interrupted"),
        }
    }
}

impl std::error::Error for TrackError {}

fn check_times(times: &[f32], count: usize) -> Result<(), TrackError> {
    if times.len() != count {
        return Err(TrackError::Shape(format!(
            "{} key times for {} keys: there must be one time per key",
            times.len(),
            count
        )));
    }
    if count == 0 {
        return Err(TrackError::Shape("a track needs at least one key".into()));
    }
    if let Some(i) = times.iter().position(|t| !t.is_finite()) {
        return Err(TrackError::Times(format!("times[{i}] is not finite")));
    }
    if let Some(i) = times.windows(2).position(|w| !(w[1] > w[0])) {
        return Err(TrackError::Times(format!(
            "times must increase strictly, but times[{}] = {} follows {}",
            i + 1,
            times[i + 1],
            times[i]
        )));
    }
    Ok(())
}

/// The segment containing `t` (clamped) and the local parameter in `[0, 1]`.
fn locate(times: &[f32], t: f32) -> (usize, f32) {
    let n = times.len();
    if n < 2 || !(t > times[0]) {
        return (0, 0.0);
    }
    if t >= times[n - 1] {
        return (n - 2, 1.0);
    }
    let i = times.partition_point(|&k| k <= t) - 1;
    let i = i.min(n - 2);
    (i, (t - times[i]) / (times[i + 1] - times[i]))
}

/// A rotation track: unit quaternion keys at strictly increasing times, made sign-continuous.
#[derive(Clone, Debug)]
pub struct RotationTrack {
    times: Vec<f32>,
    keys: Vec<Quat>,
    /// Squad control points per key: (incoming, outgoing).
    controls: Vec<(Quat, Quat)>,
    /// Keys negated to make the track sign-continuous.
    pub flipped: usize,
}

impl RotationTrack {
    pub fn new(times: &[f32], keys: &[Quat]) -> Result<Self, TrackError> {
        check_times(times, keys.len())?;
        if let Some(i) = keys.iter().position(|q| !q.is_finite() || q.length_squared() == 0.0) {
            return Err(TrackError::Key(format!("keys[{i}] is not a rotation (zero or not finite)")));
        }
        let mut keys = keys.to_vec();
        let flipped = make_signs_continuous(&mut keys);
        let n = keys.len();
        let controls = (0..n)
            .map(|i| {
                if i == 0 || i + 1 == n {
                    return (keys[i], keys[i]);
                }
                let q = keys[i];
                let (dp, dn) = (f64::from(times[i] - times[i - 1]), f64::from(times[i + 1] - times[i]));
                let lp = quat_log(keys[i - 1].conjugate() * q);
                let ln = quat_log(q.conjugate() * keys[i + 1]);
                let (lp, ln) = (Vec4::from(lp), Vec4::from(ln));
                let v = (lp * (dn / dp) as f32 + ln * (dp / dn) as f32) / (dp + dn) as f32;
                let out = (v * dn as f32 - ln) * 0.5;
                let inc = (lp - v * dp as f32) * 0.5;
                (normalize_quat(q * quat_exp(Quat::from_vec4(inc))), normalize_quat(q * quat_exp(Quat::from_vec4(out))))
            })
            .collect();
        Ok(Self { times: times.to_vec(), keys, controls, flipped })
    }

    pub fn times(&self) -> &[f32] {
        &self.times
    }

    /// The normalized, sign-continuous keys.
    pub fn keys(&self) -> &[Quat] {
        &self.keys
    }

    /// Slerp between the neighbouring keys (constant angular speed within each segment).
    pub fn slerp(&self, t: f32) -> Quat {
        if self.keys.len() == 1 {
            return self.keys[0];
        }
        let (i, u) = locate(&self.times, t);
        slerp(self.keys[i], self.keys[i + 1], u)
    }

    /// Squad through the keys, C¹ in time at the keys.
    pub fn squad(&self, t: f32) -> Quat {
        if self.keys.len() == 1 {
            return self.keys[0];
        }
        let (i, h) = locate(&self.times, t);
        let a = slerp_arc(self.keys[i], self.keys[i + 1], h);
        let b = slerp_arc(self.controls[i].1, self.controls[i + 1].0, h);
        slerp_arc(a, b, 2.0 * h * (1.0 - h))
    }
}

/// Slerp along the arc as given (no hemisphere flip), as Squad needs.
fn slerp_arc(p: Quat, q: Quat, t: f32) -> Quat {
    normalize_quat(p * quat_exp(quat_log(p.conjugate() * q) * t))
}

/// ScLERP between neighbouring transform keys at strictly increasing times: each segment is a
/// constant-speed screw motion.
pub fn screw_track(times: &[f32], keys: &[DualQuat], t: f32) -> Result<DualQuat, TrackError> {
    check_times(times, keys.len())?;
    if let Some(i) = keys.iter().position(|k| k.try_normalize().is_none()) {
        return Err(TrackError::Key(format!("keys[{i}] has a zero real part and is not a rigid transform")));
    }
    if keys.len() == 1 {
        return Ok(keys[0].normalize_or_identity());
    }
    let (i, u) = locate(times, t);
    Ok(sclerp(&keys[i], &keys[i + 1], u))
}

/// Rotation angle (radians) between consecutive rotations: the angular speed per sample step.
pub fn angular_speeds(rotations: &[Quat]) -> Vec<f32> {
    rotations
        .windows(2)
        .map(|w| {
            let r = w[0].conjugate() * w[1];
            2.0 * glam::Vec3::new(r.x, r.y, r.z).length().atan2(r.w.abs())
        })
        .collect()
}

/// Dam et al.'s discrete curvature energy `Σ |κ̃ᵢ|²` (eq. 6.23 with `l = 1`) of evenly spaced
/// samples, `κ̃ᵢ` the part of `qᵢ₋₁ − 2qᵢ + qᵢ₊₁` orthogonal to `qᵢ`. Samples are made
/// sign-continuous first.
pub fn curvature_energy(samples: &[Quat]) -> f64 {
    let mut q: Vec<Quat> = samples.to_vec();
    make_signs_continuous(&mut q);
    let v: Vec<[f64; 4]> = q.iter().map(|q| Vec4::from(*q).to_array().map(f64::from)).collect();
    (1..v.len().saturating_sub(1)).map(|i| norm2(&curvature(&v, i))).sum()
}

fn dot(a: &[f64; 4], b: &[f64; 4]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]
}

fn norm2(a: &[f64; 4]) -> f64 {
    dot(a, a)
}

/// `κ̃ᵢ` = the part of `qᵢ₋₁ + qᵢ₊₁` orthogonal to `qᵢ` (the `−2qᵢ` term is along `qᵢ`).
fn curvature(q: &[[f64; 4]], i: usize) -> [f64; 4] {
    let a: [f64; 4] = core::array::from_fn(|c| q[i - 1][c] + q[i + 1][c]);
    let k = dot(&a, &q[i]) / dot(&q[i], &q[i]);
    core::array::from_fn(|c| a[c] - k * q[i][c])
}

/// Settings of [`spring`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpringSettings {
    /// Spacing of the output samples, in the key times' unit (e.g. 1 frame).
    pub step: f32,
    /// Coarse-to-fine levels (Dam et al.'s multi-step minimization); the last level is the
    /// output spacing, each earlier one twice as coarse.
    pub levels: u32,
    /// Gradient steps per level.
    pub iterations: u32,
    /// Extra weight on the curvature at the key frames (Dam et al. suggest about 1.2).
    pub key_weight: f32,
}

impl Default for SpringSettings {
    fn default() -> Self {
        Self { step: 1.0, levels: 3, iterations: 400, key_weight: 1.2 }
    }
}

/// Dam et al.'s *Spring*: evenly spaced samples (every `step` from the first key time to the
/// last) that pass exactly through the keys and minimize the discrete curvature energy, by
/// projected gradient descent from Slerp, coarse to fine. Key times must lie on the sample grid.
/// Returns the samples (unit quaternions) at `times[0] + k·step`.
pub fn spring(times: &[f32], keys: &[Quat], settings: &SpringSettings) -> Result<Vec<Quat>, TrackError> {
    spring_with(times, keys, settings, &|| false)
}

/// The most samples [`spring`] makes (about 80 MB of working memory).
pub const MAX_SPRING_SAMPLES: usize = 5_000_000;
/// The most gradient steps per level (the default is 400; more stops improving long before).
pub const MAX_SPRING_ITERATIONS: u32 = 1_000_000;

/// [`spring`], calling `stop` now and then (about every millisecond of work) and returning
/// [`TrackError::Interrupted`] as soon as it returns true.
pub fn spring_with(
    times: &[f32],
    keys: &[Quat],
    settings: &SpringSettings,
    stop: &dyn Fn() -> bool,
) -> Result<Vec<Quat>, TrackError> {
    let track = RotationTrack::new(times, keys)?;
    let s = settings;
    if !(s.step > 0.0 && s.step.is_finite()) || s.levels == 0 || !(s.key_weight > 0.0 && s.key_weight.is_finite()) {
        return Err(TrackError::Settings("step and key_weight must be positive and finite, levels at least 1".into()));
    }
    if s.iterations > MAX_SPRING_ITERATIONS {
        return Err(TrackError::Settings(format!(
            "iterations = {} is more than {MAX_SPRING_ITERATIONS}",
            s.iterations
        )));
    }
    // Fine samples per segment; keys must sit on the grid.
    let mut segs = Vec::with_capacity(times.len().saturating_sub(1));
    let mut total = 0usize;
    for (i, w) in times.windows(2).enumerate() {
        let n = (f64::from(w[1]) - f64::from(w[0])) / f64::from(s.step);
        let r = n.round();
        if !(r <= MAX_SPRING_SAMPLES as f64) || total + r as usize > MAX_SPRING_SAMPLES {
            return Err(TrackError::Settings(format!(
                "too many samples: the keys span {} steps of {} (at most {MAX_SPRING_SAMPLES})",
                (f64::from(times[times.len() - 1]) - f64::from(times[0])) / f64::from(s.step),
                s.step
            )));
        }
        total += r as usize;
        if (n - r).abs() > 1e-3 * n.max(1.0) || r < 1.0 {
            return Err(TrackError::Times(format!(
                "times[{}] = {} is not on the sample grid (step = {} from times[0] = {})",
                i + 1,
                times[i + 1],
                s.step,
                times[0]
            )));
        }
        segs.push(r as usize);
    }
    if keys.len() == 1 {
        return Ok(vec![track.keys()[0]]);
    }
    let keys = track.keys().to_vec();
    // Level 0: Slerp on the coarsest grid.
    let counts: Vec<usize> = segs.iter().map(|&n| coarse(n, s.levels - 1)).collect();
    let mut curve: Vec<Vec<[f64; 4]>> = keys
        .windows(2)
        .zip(&counts)
        .map(|(k, &n)| (0..=n).map(|j| quat64(slerp_arc(k[0], k[1], j as f32 / n as f32))).collect())
        .collect();
    for level in 0..s.levels {
        if level > 0 {
            let next: Vec<usize> = segs.iter().map(|&n| coarse(n, s.levels - 1 - level)).collect();
            curve = curve.iter().zip(&next).map(|(c, &n)| resample(c, n)).collect();
        }
        if !descend(&mut curve, s.iterations, f64::from(s.key_weight), stop) {
            return Err(TrackError::Interrupted);
        }
    }
    let mut out = Vec::with_capacity(segs.iter().sum::<usize>() + 1);
    for (i, c) in curve.iter().enumerate() {
        let skip = usize::from(i > 0);
        out.extend(
            c[skip..]
                .iter()
                .map(|q| normalize_quat(Quat::from_xyzw(q[0] as f32, q[1] as f32, q[2] as f32, q[3] as f32))),
        );
    }
    Ok(out)
}

/// Sub-intervals at a level `k` steps coarser than `n` (at least one).
fn coarse(n: usize, k: u32) -> usize {
    (n >> k.min(31)).max(1)
}

fn quat64(q: Quat) -> [f64; 4] {
    Vec4::from(q).to_array().map(f64::from)
}

/// Resamples one segment's samples (evenly spaced, ends included) to `n` sub-intervals by
/// spherical interpolation between neighbouring samples.
fn resample(c: &[[f64; 4]], n: usize) -> Vec<[f64; 4]> {
    let m = c.len() - 1;
    (0..=n)
        .map(|j| {
            let x = j as f64 * m as f64 / n as f64;
            let i = (x.floor() as usize).min(m.saturating_sub(1));
            let u = (x - i as f64) as f32;
            let q = |a: &[f64; 4]| Quat::from_xyzw(a[0] as f32, a[1] as f32, a[2] as f32, a[3] as f32);
            if m == 0 {
                return c[0];
            }
            quat64(slerp_arc(q(&c[i]), q(&c[i + 1]), u))
        })
        .collect()
}

/// Projected gradient descent on the curvature energy with the keys (segment ends) fixed.
/// Returns false if `stop` asked to stop (checked about every 2^18 sample updates).
fn descend(curve: &mut [Vec<[f64; 4]>], iterations: u32, key_weight: f64, stop: &dyn Fn() -> bool) -> bool {
    // Flatten to one sequence with key flags (shared segment ends appear once).
    let mut q: Vec<[f64; 4]> = Vec::new();
    let mut is_key: Vec<bool> = Vec::new();
    for (s, c) in curve.iter().enumerate() {
        let start = usize::from(s > 0);
        for (j, v) in c.iter().enumerate().skip(start) {
            q.push(*v);
            is_key.push(j == 0 || j + 1 == c.len());
        }
    }
    let n = q.len();
    if n < 3 {
        return true;
    }
    let check_every = ((1usize << 18) / n).max(1);
    // Explicit descent on a fourth-difference energy is stable below 2/32 (eigenvalues of
    // 2·ΔᵀΔ reach 32); 0.04 leaves room for the key weight.
    let step = 0.04;
    let mut grad = vec![[0.0f64; 4]; n];
    for iteration in 0..iterations {
        if (iteration as usize).is_multiple_of(check_every) && stop() {
            return false;
        }
        let kappa: Vec<[f64; 4]> =
            (0..n).map(|i| if i == 0 || i + 1 == n { [0.0; 4] } else { curvature(&q, i) }).collect();
        for i in 1..n - 1 {
            if is_key[i] {
                continue;
            }
            // ∂/∂qᵢ of Σ|κ̃ⱼ|²: neighbours contribute 2κ̃ⱼ (weighted at keys), the frame itself
            // −2(aᵢ·qᵢ)/(qᵢ·qᵢ)·κ̃ᵢ with aᵢ = qᵢ₋₁ + qᵢ₊₁.
            let wp = if is_key[i - 1] { key_weight } else { 1.0 };
            let wn = if is_key[i + 1] { key_weight } else { 1.0 };
            let a: [f64; 4] = core::array::from_fn(|c| q[i - 1][c] + q[i + 1][c]);
            let own = -2.0 * dot(&a, &q[i]) / dot(&q[i], &q[i]);
            grad[i] = core::array::from_fn(|c| 2.0 * (wp * kappa[i - 1][c] + wn * kappa[i + 1][c]) + own * kappa[i][c]);
        }
        for i in 1..n - 1 {
            if is_key[i] {
                continue;
            }
            let mut v: [f64; 4] = core::array::from_fn(|c| q[i][c] - step * grad[i][c]);
            let len = norm2(&v).sqrt();
            if len > 0.0 {
                v.iter_mut().for_each(|x| *x /= len);
                q[i] = v;
            }
        }
    }
    // Write back into the segments.
    let mut k = 0;
    for (s, c) in curve.iter_mut().enumerate() {
        let start = usize::from(s > 0);
        if s > 0 {
            c[0] = q[k - 1];
        }
        for v in c.iter_mut().skip(start) {
            *v = q[k];
            k += 1;
        }
    }
    true
}

#[cfg(test)]
mod tests;

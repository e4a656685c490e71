//! Rotation interpolation on unit quaternions (Dam, Koch & Lillholm, "Quaternions, Interpolation
//! and Animation", 1998, §6): Slerp between two rotations and Shoemake's Squad through a series
//! of keys.

use glam::{Quat, Vec3};

use crate::dual_quat::{normalize_quat, pure, quat};
use crate::scalar::sinc;

/// Logarithm of a unit quaternion: the pure quaternion `(0, axis·θ/2)`. The sign is kept, so the
/// half-angle is in `[0, π]`.
#[inline]
pub fn quat_log(q: Quat) -> Quat {
    let v = Vec3::new(q.x, q.y, q.z);
    let h = v.length().atan2(q.w);
    let s = sinc(h);
    if s <= 1e-7 {
        // A full turn: the axis is undetermined.
        return pure(Vec3::X * h);
    }
    pure(v / s)
}

/// Exponential of a pure quaternion `(0, v)` (the scalar part is ignored): `(cos|v|, v·sinc|v|)`.
#[inline]
pub fn quat_exp(q: Quat) -> Quat {
    let v = Vec3::new(q.x, q.y, q.z);
    let h = v.length();
    quat(h.cos(), v * sinc(h))
}

/// `q^t` for a unit quaternion (sign kept).
#[inline]
pub fn quat_pow(q: Quat, t: f32) -> Quat {
    quat_exp(quat_log(q) * t)
}

/// Spherical linear interpolation `p·(p*·q)^t` along the shortest arc (`q` is negated when
/// `p·q < 0`). Constant angular speed. Inputs are normalized.
pub fn slerp(p: Quat, q: Quat, t: f32) -> Quat {
    let p = normalize_quat(p);
    let mut q = normalize_quat(q);
    if p.dot(q) < 0.0 {
        q = -q;
    }
    slerp_unchecked(p, q, t)
}

/// Slerp without the hemisphere check: follows the arc from `p` to `q` as given, which Squad's
/// inner interpolations need to stay differentiable.
#[inline]
fn slerp_unchecked(p: Quat, q: Quat, t: f32) -> Quat {
    normalize_quat(p * quat_pow(p.conjugate() * q, t))
}

/// Makes each key's sign agree with the previous one (`qᵢ·qᵢ₋₁ ≥ 0`) so that interpolation takes
/// the short way between neighbours; returns the number of keys negated. Keys are normalized.
pub fn make_signs_continuous(keys: &mut [Quat]) -> usize {
    let mut flipped = 0;
    for i in 0..keys.len() {
        keys[i] = normalize_quat(keys[i]);
        if i > 0 && keys[i].dot(keys[i - 1]) < 0.0 {
            keys[i] = -keys[i];
            flipped += 1;
        }
    }
    flipped
}

/// Shoemake's Squad (spherical quadrangle interpolation) through a series of keys:
/// on segment `i`, `Squad(qᵢ, qᵢ₊₁, sᵢ, sᵢ₊₁, h) = Slerp(Slerp(qᵢ, qᵢ₊₁, h), Slerp(sᵢ, sᵢ₊₁, h),
/// 2h(1−h))` with inner control points `sᵢ = qᵢ·exp(−(log(qᵢ*qᵢ₊₁) + log(qᵢ*qᵢ₋₁))/4)` and
/// `s₀ = q₀`, `s_N = q_N` (Dam et al. eq. 6.14–6.15). It passes through every key and its
/// angular velocity is continuous at the keys (C¹).
#[derive(Clone, Debug, PartialEq)]
pub struct Squad {
    keys: Vec<Quat>,
    inner: Vec<Quat>,
}

impl Squad {
    /// Builds the curve; keys are normalized and made sign-continuous first. An empty key list
    /// gives a curve that is the identity everywhere.
    pub fn new(keys: &[Quat]) -> Self {
        let mut keys = keys.to_vec();
        make_signs_continuous(&mut keys);
        let n = keys.len();
        let inner = (0..n)
            .map(|i| {
                if i == 0 || i + 1 == n {
                    keys[i]
                } else {
                    let qi = keys[i];
                    let qc = qi.conjugate();
                    let sum = quat_log(qc * keys[i + 1]) + quat_log(qc * keys[i - 1]);
                    normalize_quat(qi * quat_exp(sum * -0.25))
                }
            })
            .collect();
        Self { keys, inner }
    }

    /// The sign-continuous, normalized keys.
    pub fn keys(&self) -> &[Quat] {
        &self.keys
    }

    /// The inner control points `sᵢ`.
    pub fn control_points(&self) -> &[Quat] {
        &self.inner
    }

    /// The rotation at parameter `u ∈ [0, N−1]`: segment `⌊u⌋`, local parameter `u − ⌊u⌋`.
    /// `u` is clamped to the key range; NaN gives the first key.
    pub fn evaluate(&self, u: f32) -> Quat {
        let n = self.keys.len();
        if n == 0 {
            return Quat::IDENTITY;
        }
        if n == 1 || !(u > 0.0) {
            return self.keys[0];
        }
        let last = (n - 1) as f32;
        if u >= last {
            return self.keys[n - 1];
        }
        let i = (u.floor() as usize).min(n - 2);
        self.segment(i, u - i as f32)
    }

    /// Squad on segment `i` (between keys `i` and `i+1`) at `h ∈ [0, 1]`.
    pub fn segment(&self, i: usize, h: f32) -> Quat {
        let (q0, q1) = (self.keys[i], self.keys[i + 1]);
        let (s0, s1) = (self.inner[i], self.inner[i + 1]);
        let a = slerp_unchecked(q0, q1, h);
        let b = slerp_unchecked(s0, s1, h);
        slerp_unchecked(a, b, 2.0 * h * (1.0 - h))
    }
}

#[cfg(test)]
mod tests;

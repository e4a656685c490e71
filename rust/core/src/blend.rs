//! Blending and interpolation of rigid transforms (Kavan et al. 2006, §4):
//! ScLERP for two transforms, DLB (fast, approximate) and DIB (iterative, exact) for `n`.
//!
//! All inputs are normalized to unit dual quaternions first; weights must be finite and
//! non-negative with a positive sum and are divided by that sum (blends are convex).

use crate::dual_quat::DualQuat;

/// Why a blend could not be computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlendError {
    /// No transforms were given.
    Empty,
    /// The numbers of transforms and weights differ.
    LengthMismatch { transforms: usize, weights: usize },
    /// A weight is negative, NaN or infinite.
    InvalidWeight { index: usize },
    /// All weights are zero.
    ZeroWeightSum,
    /// A transform has a zero (or non-finite) real part, so it is not a rigid transform.
    NotATransform { index: usize },
}

impl core::fmt::Display for BlendError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            BlendError::Empty => write!(f, "no transforms to blend"),
            BlendError::LengthMismatch { transforms, weights } => {
                write!(f, "{transforms} transforms but {weights} weights: there must be one weight per transform")
            }
            BlendError::InvalidWeight { index } => {
                write!(f, "weight {index} is negative or not finite")
            }
            BlendError::ZeroWeightSum => write!(f, "the weights sum to zero"),
            BlendError::NotATransform { index } => {
                write!(f, "transform {index} has a zero or non-finite real part and is not a rigid transform")
            }
        }
    }
}

impl std::error::Error for BlendError {}

/// Screw linear interpolation `p·(p*·q)^t` along the shortest path (`q` is negated when the real
/// parts point into opposite hemispheres). Constant speed, shortest path, bi-invariant. At
/// exactly 180° of relative rotation both ways are equally short; the one given by the sign of
/// `q` is taken, without panicking or producing NaN.
pub fn sclerp(p: &DualQuat, q: &DualQuat, t: f32) -> DualQuat {
    let p = p.normalize_or_identity();
    let mut q = q.normalize_or_identity();
    if p.real.dot(q.real) < 0.0 {
        q = -q;
    }
    let delta = p.conjugate() * q;
    (p * delta.powf(t)).normalize_or_identity()
}

/// Dual quaternion linear blending: `Σ wᵢ·qᵢ / ‖Σ wᵢ·qᵢ‖`.
///
/// Antipodality: each `qᵢ` is negated if its real part points away from the real part of the
/// transform with the largest weight (the first such one on ties), so the result does not
/// depend on the signs or the order of the inputs.
pub fn dlb(transforms: &[DualQuat], weights: &[f32]) -> Result<DualQuat, BlendError> {
    let (units, weights) = prepare(transforms, weights)?;
    Ok(dlb_prepared(&units, &weights))
}

/// The result of [`dib`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DibResult {
    pub blend: DualQuat,
    /// Number of updates `b ← b·exp(x)` performed after the DLB start (0 when DLB was already
    /// within precision).
    pub iterations: u32,
    /// Whether the last tangent-space mean was below the precision.
    pub converged: bool,
    /// Length of the last tangent-space mean `Σ wᵢ·log(b*·qᵢ)` (see
    /// [`DualQuat::tangent_length`]).
    pub residual: f32,
}

/// Dual quaternion iterative blending: starting from DLB, repeat
/// `x = Σ wᵢ·log(b*·qᵢ)`, `b ← b·exp(x)` until `|x| < precision` or `max_iterations` updates.
/// `|x|` is the length of the 6-vector of the pure dual quaternion `x` (half-angles in radians
/// and half-displacements in scene units). Each `b*·qᵢ` is taken in the hemisphere `w ≥ 0`.
pub fn dib(
    transforms: &[DualQuat],
    weights: &[f32],
    precision: f32,
    max_iterations: u32,
) -> Result<DibResult, BlendError> {
    let (units, weights) = prepare(transforms, weights)?;
    let mut b = dlb_prepared(&units, &weights);
    let mut iterations = 0;
    loop {
        let x = tangent_mean(&b, &units, &weights);
        let residual = x.tangent_length();
        if !(residual >= precision) || iterations >= max_iterations {
            return Ok(DibResult { blend: b, iterations, converged: !(residual >= precision), residual });
        }
        b = (b * x.exp()).normalize_or_identity();
        iterations += 1;
    }
}

/// `Σ wᵢ·log(b*·qᵢ)` with each relative transform on the shortest path: the mean of the inputs
/// in the tangent space at `b`, zero exactly when `b` is the DIB blend.
pub fn tangent_mean(b: &DualQuat, units: &[DualQuat], weights: &[f32]) -> DualQuat {
    let bc = b.conjugate();
    let mut x = DualQuat::ZERO;
    for (q, &w) in units.iter().zip(weights) {
        x = x + (bc * *q).shortest().log() * w;
    }
    x
}

fn dlb_prepared(units: &[DualQuat], weights: &[f32]) -> DualQuat {
    let mut pivot = 0;
    for (i, &w) in weights.iter().enumerate() {
        if w > weights[pivot] {
            pivot = i;
        }
    }
    let reference = units[pivot].real;
    let mut sum = DualQuat::ZERO;
    for (q, &w) in units.iter().zip(weights) {
        let w = if q.real.dot(reference) < 0.0 { -w } else { w };
        sum = sum + *q * w;
    }
    // The sum of weighted unit quaternions aligned to one hemisphere cannot vanish unless all
    // weight sits on exactly opposite rotations, which the alignment above rules out.
    sum.normalize_or_identity()
}

/// Normalizes transforms and weights, or says which input is bad.
fn prepare(transforms: &[DualQuat], weights: &[f32]) -> Result<(Vec<DualQuat>, Vec<f32>), BlendError> {
    if transforms.is_empty() {
        return Err(BlendError::Empty);
    }
    if transforms.len() != weights.len() {
        return Err(BlendError::LengthMismatch { transforms: transforms.len(), weights: weights.len() });
    }
    let mut total = 0.0f64;
    for (index, &w) in weights.iter().enumerate() {
        if !(w >= 0.0) || !w.is_finite() {
            return Err(BlendError::InvalidWeight { index });
        }
        total += f64::from(w);
    }
    if total <= 0.0 {
        return Err(BlendError::ZeroWeightSum);
    }
    let units = transforms
        .iter()
        .enumerate()
        .map(|(index, q)| q.try_normalize().ok_or(BlendError::NotATransform { index }))
        .collect::<Result<Vec<_>, _>>()?;
    let weights = weights.iter().map(|&w| (f64::from(w) / total) as f32).collect();
    Ok((units, weights))
}

#[cfg(test)]
mod tests;

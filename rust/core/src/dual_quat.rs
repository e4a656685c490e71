//! Dual quaternions `real + ε·dual` on glam's `f32` quaternions.
//!
//! A *unit* dual quaternion (`|real| = 1`, `⟨real, dual⟩ = 0`) is a rigid transform: `real` is the
//! rotation and `dual = ½·(0, t)·real` carries the translation `t`. Both `q` and `-q` are the same
//! transform (antipodality). Conventions follow Kavan et al., "Dual Quaternions for Rigid
//! Transformation Blending" (2006): `q*` is the quaternion conjugate of both parts, the dual
//! conjugate flips the sign of the dual part, and the screw form is
//! `q = cos(θ̂/2) + ŝ·sin(θ̂/2)` with dual angle `θ̂ = angle + ε·pitch` and dual axis
//! `ŝ = axis + ε·moment`.

use core::ops::{Add, Mul, Neg, Sub};
use glam::{Affine3A, Mat3, Mat4, Quat, Vec3, Vec4};

use crate::scalar::{cos_minus_sinc_over_sq, one_minus_x_cot_x_over_sin_sq, sinc, x_cot_x};

/// A dual number `re + ε·du` (`ε² = 0`), the value of a dual quaternion's norm.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct DualNumber {
    pub re: f32,
    pub du: f32,
}

/// Screw parameters of a rigid transform (Chasles' theorem): a rotation by `angle` radians about
/// the line with direction `axis` and moment `moment = p × axis` (for any point `p` on the line),
/// together with a translation by `pitch` along that same line.
///
/// `pitch` is the displacement along the axis in scene units (the dual part of the dual angle),
/// not a displacement per radian.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Screw {
    pub axis: Vec3,
    pub moment: Vec3,
    pub angle: f32,
    pub pitch: f32,
}

impl Screw {
    /// A point of the screw axis: the one closest to the origin.
    pub fn point(&self) -> Vec3 {
        self.axis.cross(self.moment)
    }
}

/// Why a matrix could not be turned into a unit dual quaternion.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NotRigid {
    /// Some entry is NaN or infinite.
    NonFinite,
    /// The bottom row is not `(0, 0, 0, 1)`.
    NotAffine,
    /// The 3×3 part has scale, shear or a reflection.
    NotOrthonormal,
}

impl core::fmt::Display for NotRigid {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            NotRigid::NonFinite => "matrix has a NaN or infinite entry",
            NotRigid::NotAffine => "matrix is not affine (bottom row must be 0, 0, 0, 1)",
            NotRigid::NotOrthonormal => {
                "matrix is not a rigid transform (its 3x3 part has scale, shear or a reflection)"
            }
        })
    }
}

impl std::error::Error for NotRigid {}

/// A dual quaternion. See the module documentation for conventions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DualQuat {
    /// Real (non-dual) part: the rotation for a unit dual quaternion.
    pub real: Quat,
    /// Dual part: `½·(0, t)·real` for a unit dual quaternion with translation `t`.
    pub dual: Quat,
}

const QZERO: Quat = Quat::from_xyzw(0.0, 0.0, 0.0, 0.0);

/// Below this length a quaternion's vector part gives no usable rotation axis.
const AXIS_EPSILON: f32 = 1e-7;

impl Default for DualQuat {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl DualQuat {
    /// The identity transform.
    pub const IDENTITY: Self = Self { real: Quat::IDENTITY, dual: QZERO };
    /// All eight components zero (not a transform; the neutral element of addition).
    pub const ZERO: Self = Self { real: QZERO, dual: QZERO };

    #[inline]
    pub const fn from_parts(real: Quat, dual: Quat) -> Self {
        Self { real, dual }
    }

    /// Components as `[rw, rx, ry, rz, dw, dx, dy, dz]` (scalar first, as Blender writes them).
    #[inline]
    pub fn to_array_wxyz(&self) -> [f32; 8] {
        let (r, d) = (self.real, self.dual);
        [r.w, r.x, r.y, r.z, d.w, d.x, d.y, d.z]
    }

    /// Inverse of [`Self::to_array_wxyz`].
    #[inline]
    pub fn from_array_wxyz(a: [f32; 8]) -> Self {
        Self { real: Quat::from_xyzw(a[1], a[2], a[3], a[0]), dual: Quat::from_xyzw(a[5], a[6], a[7], a[4]) }
    }

    /// Rotation `rotation` (any non-zero quaternion; it is normalized) followed by translation `t`.
    #[inline]
    pub fn from_rotation_translation(rotation: Quat, t: Vec3) -> Self {
        let real = normalize_quat(rotation);
        Self { real, dual: pure(t * 0.5) * real }
    }

    #[inline]
    pub fn from_rotation(rotation: Quat) -> Self {
        Self::from_rotation_translation(rotation, Vec3::ZERO)
    }

    #[inline]
    pub fn from_translation(t: Vec3) -> Self {
        Self { real: Quat::IDENTITY, dual: pure(t * 0.5) }
    }

    /// From a rigid 4×4 matrix, without checks: the rotation is taken from the normalized columns
    /// of the 3×3 part (as Blender's `mat4_to_quat` does), the translation from the last column.
    /// Use [`Self::try_from_mat4`] to reject scaled, sheared or non-affine matrices.
    pub fn from_mat4(m: &Mat4) -> Self {
        let rot = rotation_from_mat3(&Mat3::from_mat4(*m));
        Self::from_rotation_translation(rot, m.w_axis.truncate())
    }

    /// From a rigid affine transform, without checks (see [`Self::from_mat4`]).
    pub fn from_affine3a(a: &Affine3A) -> Self {
        let rot = rotation_from_mat3(&Mat3::from(a.matrix3));
        Self::from_rotation_translation(rot, Vec3::from(a.translation))
    }

    /// From a 4×4 matrix that must be rigid within `tolerance` (on the dot products of its
    /// columns, as Blender's `is_orthonormal_m3` checks with `1e-5`).
    pub fn try_from_mat4(m: &Mat4, tolerance: f32) -> Result<Self, NotRigid> {
        if !m.is_finite() {
            return Err(NotRigid::NonFinite);
        }
        let row3 = m.row(3);
        if (row3 - Vec4::W).abs().max_element() > tolerance {
            return Err(NotRigid::NotAffine);
        }
        let m3 = Mat3::from_mat4(*m);
        if !is_orthonormal(&m3, tolerance) || m3.determinant() < 0.0 {
            return Err(NotRigid::NotOrthonormal);
        }
        Ok(Self::from_mat4(m))
    }

    /// The rigid transform as a 4×4 matrix. A non-unit dual quaternion is normalized first; the
    /// zero dual quaternion gives the identity.
    pub fn to_mat4(&self) -> Mat4 {
        let n = self.normalize_or_identity();
        Mat4::from_rotation_translation(n.real, n.translation())
    }

    /// The rigid transform as an affine transform (see [`Self::to_mat4`]).
    pub fn to_affine3a(&self) -> Affine3A {
        let n = self.normalize_or_identity();
        Affine3A::from_rotation_translation(n.real, n.translation())
    }

    /// The rotation (the normalized real part; identity if the real part is zero).
    #[inline]
    pub fn rotation(&self) -> Quat {
        normalize_quat(self.real)
    }

    /// The translation `2·dual·real* / |real|²` (zero if the real part is zero).
    #[inline]
    pub fn translation(&self) -> Vec3 {
        let n2 = self.real.length_squared();
        if n2 == 0.0 {
            return Vec3::ZERO;
        }
        let t = self.dual * self.real.conjugate();
        Vec3::new(t.x, t.y, t.z) * (2.0 / n2)
    }

    /// Quaternion conjugate of both parts: `q* = real* + ε·dual*`. For a unit dual quaternion
    /// this is the inverse transform.
    #[inline]
    pub fn conjugate(&self) -> Self {
        Self { real: self.real.conjugate(), dual: self.dual.conjugate() }
    }

    /// Dual-number conjugate: `real − ε·dual`.
    #[inline]
    pub fn dual_conjugate(&self) -> Self {
        Self { real: self.real, dual: -self.dual }
    }

    /// Both conjugates: `real* − ε·dual*`. Transforms points as `q·(1 + ε·p)·q̄*`.
    #[inline]
    pub fn full_conjugate(&self) -> Self {
        Self { real: self.real.conjugate(), dual: -self.dual.conjugate() }
    }

    /// The dual-number norm `‖q‖ = |real| + ε·⟨real, dual⟩/|real|`.
    pub fn norm(&self) -> DualNumber {
        let re = self.real.length();
        let du = if re > 0.0 { self.real.dot(self.dual) / re } else { 0.0 };
        DualNumber { re, du }
    }

    /// Whether this is a unit dual quaternion within `tolerance`.
    pub fn is_unit(&self, tolerance: f32) -> bool {
        (self.real.length_squared() - 1.0).abs() <= tolerance && self.real.dot(self.dual).abs() <= tolerance
    }

    /// Divides by the dual-number norm, giving a unit dual quaternion, or `None` when the real
    /// part is zero (or the input is not finite).
    pub fn try_normalize(&self) -> Option<Self> {
        let n2 = self.real.length_squared();
        if !(n2 > 0.0) || !n2.is_finite() {
            return None;
        }
        let inv = n2.sqrt().recip();
        let real = self.real * inv;
        let dual = self.dual * inv;
        // 1/(a + εb) = 1/a − ε·b/a²; with unit `real` this is removing dual's component along real.
        let dual = dual - real * real.dot(dual);
        let out = Self { real, dual };
        out.is_finite().then_some(out)
    }

    /// [`Self::try_normalize`], or the identity when that fails.
    #[inline]
    pub fn normalize_or_identity(&self) -> Self {
        self.try_normalize().unwrap_or(Self::IDENTITY)
    }

    /// The multiplicative inverse `real⁻¹ − ε·real⁻¹·dual·real⁻¹`, for any dual quaternion with a
    /// non-zero real part (`None` otherwise).
    pub fn inverse(&self) -> Option<Self> {
        let n2 = self.real.length_squared();
        if !(n2 > 0.0) || !n2.is_finite() {
            return None;
        }
        let ri = self.real.conjugate() * n2.recip();
        Some(Self { real: ri, dual: -(ri * self.dual * ri) })
    }

    #[inline]
    pub fn is_finite(&self) -> bool {
        self.real.is_finite() && self.dual.is_finite()
    }

    /// Eight-component dot product.
    #[inline]
    pub fn dot(&self, other: &Self) -> f32 {
        self.real.dot(other.real) + self.dual.dot(other.dual)
    }

    /// Transforms a point: rotation by the normalized real part, then the translation. Works for
    /// non-unit dual quaternions as Blender's `mul_v3m3_dq` does (dividing by `|real|²`).
    #[inline]
    pub fn transform_point3(&self, p: Vec3) -> Vec3 {
        let n2 = self.real.length_squared();
        if n2 == 0.0 {
            return p;
        }
        let r = self.real * n2.sqrt().recip();
        r * p + self.translation()
    }

    /// Rotates a direction (no translation).
    #[inline]
    pub fn transform_vector3(&self, v: Vec3) -> Vec3 {
        normalize_quat(self.real) * v
    }

    /// The same transform with the real part in the hemisphere `w ≥ 0`, so that powers and
    /// interpolation take the shortest path.
    #[inline]
    pub fn shortest(&self) -> Self {
        if self.real.w < 0.0 {
            -*self
        } else {
            *self
        }
    }

    /// Screw parameters of a unit dual quaternion. The angle is in `[0, 2π]` (the real part's sign
    /// is kept: call [`Self::shortest`] first for `[0, π]`). For a pure translation the axis is the
    /// translation direction; for the identity the axis is `+Z` and everything else zero.
    pub fn to_screw(&self) -> Screw {
        let r = self.real;
        let v = Vec3::new(r.x, r.y, r.z);
        let s = v.length();
        let t = self.translation();
        let half = s.atan2(r.w);
        if s > AXIS_EPSILON {
            let axis = v / s;
            let pitch = t.dot(axis);
            let t_perp = t - axis * pitch;
            // Moment m = ½·(t × axis + cot(θ/2)·t⊥).
            let moment = 0.5 * (t.cross(axis) + t_perp * (half.cos() / half.sin()));
            Screw { axis, moment, angle: 2.0 * half, pitch }
        } else {
            let len = t.length();
            let axis = if len > 0.0 { t / len } else { Vec3::Z };
            // Rotation 0 (w > 0) or a full turn (w < 0) about an undetermined axis.
            let angle = if r.w < 0.0 { core::f32::consts::TAU } else { 0.0 };
            Screw { axis, moment: Vec3::ZERO, angle, pitch: len }
        }
    }

    /// The unit dual quaternion with the given screw parameters (`axis` is normalized; the part
    /// of `moment` along the axis is ignored).
    pub fn from_screw(screw: &Screw) -> Self {
        let axis = screw.axis.try_normalize().unwrap_or(Vec3::Z);
        let moment = screw.moment - axis * axis.dot(screw.moment);
        let (sin_h, cos_h) = (0.5 * screw.angle).sin_cos();
        let k = 0.5 * screw.pitch;
        Self { real: quat(cos_h, axis * sin_h), dual: quat(-k * sin_h, moment * sin_h + axis * (k * cos_h)) }
    }

    /// Logarithm of a unit dual quaternion: the pure dual quaternion `ŝ·θ̂/2` (zero scalar
    /// parts), i.e. `(0, axis·angle/2) + ε·(0, moment·angle/2 + axis·pitch/2)`. Smooth through
    /// the identity and pure translations. The real part's sign is kept (see [`Self::to_screw`]);
    /// near a full turn (`real.w → −1`) the moment grows like `cot(angle/2)` and the result loses
    /// precision in `f32`, so take [`Self::shortest`] first unless the long way is wanted.
    pub fn log(&self) -> Self {
        let r = self.real;
        let v = Vec3::new(r.x, r.y, r.z);
        let s = v.length();
        let h = s.atan2(r.w); // half angle in [0, π]
        let t = self.translation();
        if h.sin() <= AXIS_EPSILON && r.w < 0.0 {
            // Near a full turn: the axis is undetermined; use the translation or +Z.
            let screw = self.to_screw();
            let a = screw.axis * h;
            return Self { real: pure(a), dual: pure(screw.axis * (0.5 * screw.pitch)) };
        }
        let sc = sinc(h);
        let a = v / sc; // axis·h
                        // b = moment·h + axis·pitch/2 with moment = ½·(t × axis + cot(h)·t⊥), rewritten in terms of
                        // v = axis·sin h so that it stays smooth as h → 0 (where b → t/2):
                        // b = ½·[(t × v)/sinc(h) + h·cot(h)·t + g(h)·(t·v)·v], g(h) = (1 − h·cot h)/sin²h.
        let b = 0.5 * (t.cross(v) / sc + t * x_cot_x(h) + v * (one_minus_x_cot_x_over_sin_sq(h) * t.dot(v)));
        Self { real: pure(a), dual: pure(b) }
    }

    /// Exponential of a pure dual quaternion `(0, a) + ε·(0, b)` (scalar parts are ignored):
    /// `(cos h, a·sinc h) + ε·(−(a·b)·sinc h, b·sinc h + a·(a·b)·(cos h − sinc h)/h²)`, `h = |a|`.
    /// The result is a unit dual quaternion.
    pub fn exp(&self) -> Self {
        let a = Vec3::new(self.real.x, self.real.y, self.real.z);
        let b = Vec3::new(self.dual.x, self.dual.y, self.dual.z);
        let h = a.length();
        let cos_h = h.cos();
        let sc = sinc(h);
        let ab = a.dot(b);
        Self { real: quat(cos_h, a * sc), dual: quat(-ab * sc, b * sc + a * (ab * cos_minus_sinc_over_sq(h))) }
    }

    /// `q^t = exp(t·log q)` for a unit dual quaternion: the screw motion scaled by `t` (same axis,
    /// `t`·angle, `t`·pitch). The real part's sign is kept.
    pub fn powf(&self, t: f32) -> Self {
        let l = self.log();
        Self { real: l.real * t, dual: l.dual * t }.exp()
    }

    /// Length of a pure dual quaternion as a 6-vector `(a, b)`: the size of a tangent-space step.
    #[inline]
    pub fn tangent_length(&self) -> f32 {
        (self.real.length_squared() + self.dual.length_squared()).sqrt()
    }
}

impl Mul for DualQuat {
    type Output = Self;
    /// Composition: `(a·b)` applies `b` first, then `a` (like matrices).
    #[inline]
    fn mul(self, rhs: Self) -> Self {
        Self { real: self.real * rhs.real, dual: self.real * rhs.dual + self.dual * rhs.real }
    }
}

impl Mul<f32> for DualQuat {
    type Output = Self;
    #[inline]
    fn mul(self, s: f32) -> Self {
        Self { real: self.real * s, dual: self.dual * s }
    }
}

impl Add for DualQuat {
    type Output = Self;
    #[inline]
    fn add(self, rhs: Self) -> Self {
        Self { real: self.real + rhs.real, dual: self.dual + rhs.dual }
    }
}

impl Sub for DualQuat {
    type Output = Self;
    #[inline]
    fn sub(self, rhs: Self) -> Self {
        Self { real: self.real - rhs.real, dual: self.dual - rhs.dual }
    }
}

impl Neg for DualQuat {
    type Output = Self;
    #[inline]
    fn neg(self) -> Self {
        Self { real: -self.real, dual: -self.dual }
    }
}

/// The quaternion `(w, v)`.
#[inline]
pub(crate) fn quat(w: f32, v: Vec3) -> Quat {
    Quat::from_xyzw(v.x, v.y, v.z, w)
}

/// The pure quaternion `(0, v)`.
#[inline]
pub(crate) fn pure(v: Vec3) -> Quat {
    Quat::from_xyzw(v.x, v.y, v.z, 0.0)
}

/// Normalizes a quaternion; zero (or non-finite) gives the identity instead of NaN.
#[inline]
pub(crate) fn normalize_quat(q: Quat) -> Quat {
    let n2 = q.length_squared();
    if n2 > 0.0 && n2.is_finite() {
        q * n2.sqrt().recip()
    } else {
        Quat::IDENTITY
    }
}

/// Whether the columns of `m` are orthonormal within `tol` (Blender's `is_orthonormal_m3`).
pub(crate) fn is_orthonormal(m: &Mat3, tol: f32) -> bool {
    let (x, y, z) = (m.x_axis, m.y_axis, m.z_axis);
    x.dot(y).abs() <= tol
        && x.dot(z).abs() <= tol
        && y.dot(z).abs() <= tol
        && (x.length_squared() - 1.0).abs() <= tol
        && (y.length_squared() - 1.0).abs() <= tol
        && (z.length_squared() - 1.0).abs() <= tol
}

/// Rotation quaternion of a 3×3 matrix with its columns normalized first, as Blender's
/// `mat4_to_quat` computes it: a matrix with a non-finite determinant gives the identity, one with
/// a negative determinant is negated, a zero matrix gives the identity, and `w ≥ 0`.
pub(crate) fn rotation_from_mat3(m: &Mat3) -> Quat {
    let mut m = Mat3::from_cols(normalize_or_zero(m.x_axis), normalize_or_zero(m.y_axis), normalize_or_zero(m.z_axis));
    let det = m.determinant();
    if !det.is_finite() {
        return Quat::IDENTITY;
    }
    if det < 0.0 {
        m = -m;
    }
    quat_from_normalized_mat3(&m)
}

#[inline]
fn normalize_or_zero(v: Vec3) -> Vec3 {
    let len = v.length();
    if len != 0.0 && len.is_finite() {
        v / len
    } else {
        Vec3::ZERO
    }
}

/// Blender's `mat3_normalized_to_quat_fast` (Mike Day's method, which picks the branch by the
/// diagonal and makes `w ≥ 0`), so that our per-bone quaternions match Blender's to the last bits
/// that matter. `m.c.r` is column `c`, row `r` (Blender's `mat[c][r]`).
fn quat_from_normalized_mat3(m: &Mat3) -> Quat {
    let (m00, m01, m02) = (m.x_axis.x, m.x_axis.y, m.x_axis.z);
    let (m10, m11, m12) = (m.y_axis.x, m.y_axis.y, m.y_axis.z);
    let (m20, m21, m22) = (m.z_axis.x, m.z_axis.y, m.z_axis.z);
    // q = [w, x, y, z]
    let mut q = [0.0f32; 4];
    let branch = |trace: f32, negate: bool| {
        let s = 2.0 * trace.max(0.0).sqrt();
        if negate {
            -s
        } else {
            s
        }
    };
    if m22 < 0.0 {
        if m00 > m11 {
            let trace = 1.0 + m00 - m11 - m22;
            let s = branch(trace, m12 < m21);
            q[1] = 0.25 * s;
            let s = 1.0 / s;
            q[0] = (m12 - m21) * s;
            q[2] = (m01 + m10) * s;
            q[3] = (m20 + m02) * s;
            if trace == 1.0 && q[0] == 0.0 && q[2] == 0.0 && q[3] == 0.0 {
                q[1] = 1.0;
            }
        } else {
            let trace = 1.0 - m00 + m11 - m22;
            let s = branch(trace, m20 < m02);
            q[2] = 0.25 * s;
            let s = 1.0 / s;
            q[0] = (m20 - m02) * s;
            q[1] = (m01 + m10) * s;
            q[3] = (m12 + m21) * s;
            if trace == 1.0 && q[0] == 0.0 && q[1] == 0.0 && q[3] == 0.0 {
                q[2] = 1.0;
            }
        }
    } else if m00 < -m11 {
        let trace = 1.0 - m00 - m11 + m22;
        let s = branch(trace, m01 < m10);
        q[3] = 0.25 * s;
        let s = 1.0 / s;
        q[0] = (m01 - m10) * s;
        q[1] = (m20 + m02) * s;
        q[2] = (m12 + m21) * s;
        if trace == 1.0 && q[0] == 0.0 && q[1] == 0.0 && q[2] == 0.0 {
            q[3] = 1.0;
        }
    } else {
        // A zero matrix lands here and gives the identity, as in Blender.
        let trace = 1.0 + m00 + m11 + m22;
        let s = branch(trace, false);
        q[0] = 0.25 * s;
        let s = 1.0 / s;
        q[1] = (m12 - m21) * s;
        q[2] = (m20 - m02) * s;
        q[3] = (m01 - m10) * s;
        if trace == 1.0 && q[1] == 0.0 && q[2] == 0.0 && q[3] == 0.0 {
            q[0] = 1.0;
        }
    }
    let out = Quat::from_xyzw(q[1], q[2], q[3], q[0]);
    if !out.is_finite() {
        return Quat::IDENTITY;
    }
    // Blender renormalizes only when round-off made the length noticeably wrong.
    if (out.length_squared() - 1.0).abs() >= 0.0006 {
        normalize_quat(out)
    } else {
        out
    }
}

#[cfg(test)]
mod tests;

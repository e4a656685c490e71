//! The `DualQuat` class and batch conversions between matrices and dual quaternions.

use dqskin_core::glam::{Mat4, Vec3};
use dqskin_core::{DualQuat, Screw};
use numpy::{PyArray1, PyArray2, PyArray3, PyArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::args;
use crate::arrays::{self, mat4_from_row_major, mat4_to_row_major, quat_from_wxyz, quat_to_wxyz};
use crate::guard;

/// A dual quaternion ``real + ε·dual``; unit dual quaternions are rigid transforms.
///
/// Quaternions are written scalar first, ``(w, x, y, z)``, as in Blender's ``mathutils``.
/// Matrices are row-major 4×4 with the translation in the last column (``m[:3, 3]``).
#[pyclass(name = "DualQuat", module = "dqskin", frozen, eq)]
#[derive(Clone, Copy, PartialEq)]
pub struct PyDualQuat(pub DualQuat);

/// Screw parameters: rotation by ``angle`` about the line with direction ``axis`` and moment
/// ``moment`` (= p × axis for any point p on it), plus translation ``pitch`` along it.
#[pyclass(name = "Screw", module = "dqskin", frozen, get_all)]
#[derive(Clone)]
pub struct PyScrew {
    axis: (f32, f32, f32),
    moment: (f32, f32, f32),
    angle: f32,
    pitch: f32,
}

#[pymethods]
impl PyScrew {
    #[new]
    fn new(
        axis: &Bound<'_, PyAny>,
        moment: &Bound<'_, PyAny>,
        angle: &Bound<'_, PyAny>,
        pitch: &Bound<'_, PyAny>,
    ) -> PyResult<Self> {
        guard(|| {
            let axis = vec3(axis, "axis")?;
            let moment = vec3(moment, "moment")?;
            let angle = args::float(angle, "angle")?;
            let pitch = args::float(pitch, "pitch")?;
            Ok(Self { axis: to_tuple(axis), moment: to_tuple(moment), angle, pitch })
        })
    }

    /// The point of the axis closest to the origin.
    fn point(&self) -> (f32, f32, f32) {
        to_tuple(self.screw().point())
    }

    fn __repr__(&self) -> String {
        format!("Screw(axis={:?}, moment={:?}, angle={}, pitch={})", self.axis, self.moment, self.angle, self.pitch)
    }
}

impl PyScrew {
    fn screw(&self) -> Screw {
        Screw { axis: Vec3::from(self.axis), moment: Vec3::from(self.moment), angle: self.angle, pitch: self.pitch }
    }
}

fn to_tuple(v: Vec3) -> (f32, f32, f32) {
    (v.x, v.y, v.z)
}

fn vec3(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec3> {
    let (v, _) = arrays::small(obj, name, &[Some(3)], &[])?;
    Ok(Vec3::new(v[0], v[1], v[2]))
}

#[pymethods]
impl PyDualQuat {
    /// From the real and dual parts, each ``(w, x, y, z)``. Defaults to the identity.
    #[new]
    #[pyo3(signature = (real = None, dual = None))]
    fn new(real: Option<&Bound<'_, PyAny>>, dual: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        guard(|| {
            let part = |obj: Option<&Bound<'_, PyAny>>, name: &str, default: [f32; 4]| -> PyResult<[f32; 4]> {
                match obj {
                    None => Ok(default),
                    Some(o) => Ok(arrays::small(o, name, &[Some(4)], &[])?.0.try_into().unwrap()),
                }
            };
            let r = part(real, "real", [1.0, 0.0, 0.0, 0.0])?;
            let d = part(dual, "dual", [0.0; 4])?;
            Ok(Self(DualQuat::from_parts(quat_from_wxyz(&r), quat_from_wxyz(&d))))
        })
    }

    /// The identity transform.
    #[staticmethod]
    fn identity() -> Self {
        Self(DualQuat::IDENTITY)
    }

    /// Rotation (a quaternion ``(w, x, y, z)``, normalized here) followed by a translation.
    #[staticmethod]
    #[pyo3(signature = (rotation, translation = None))]
    fn from_rotation_translation(
        rotation: &Bound<'_, PyAny>,
        translation: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        guard(|| {
            let (q, _) = arrays::small(rotation, "rotation", &[Some(4)], &[])?;
            let q = quat_from_wxyz(&q);
            if q.length_squared() == 0.0 {
                return Err(PyValueError::new_err("rotation must be a non-zero quaternion"));
            }
            let t = match translation {
                Some(t) => vec3(t, "translation")?,
                None => Vec3::ZERO,
            };
            Ok(Self(DualQuat::from_rotation_translation(q, t)))
        })
    }

    /// A pure translation.
    #[staticmethod]
    fn from_translation(translation: &Bound<'_, PyAny>) -> PyResult<Self> {
        guard(|| Ok(Self(DualQuat::from_translation(vec3(translation, "translation")?))))
    }

    /// From a rigid 4×4 matrix (row-major, translation in the last column). With
    /// ``check=True`` (default) a matrix with scale, shear, reflection or a non-affine last row
    /// raises ``ValueError``; with ``check=False`` the rotation is taken from the normalized
    /// columns, as Blender's ``mat4_to_quat`` does.
    #[staticmethod]
    #[pyo3(signature = (matrix, check = None, tolerance = None))]
    fn from_matrix(
        matrix: &Bound<'_, PyAny>,
        check: Option<&Bound<'_, PyAny>>,
        tolerance: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        guard(|| {
            let check = args::or(check, true, |o| args::boolean(o, "check"))?;
            let tolerance = args::or(tolerance, 1e-5, |o| args::float_in(o, "tolerance", 0.0, 1.0))?;
            let (m, _) = arrays::small(matrix, "matrix", &[Some(4), Some(4)], &[])?;
            let m = mat4_from_row_major(&m);
            if check {
                DualQuat::try_from_mat4(&m, tolerance)
                    .map(Self)
                    .map_err(|e| PyValueError::new_err(format!("matrix: {e} (tolerance = {tolerance})")))
            } else {
                Ok(Self(DualQuat::from_mat4(&m)))
            }
        })
    }

    /// From screw parameters (see :class:`Screw`).
    #[staticmethod]
    fn from_screw(screw: &Bound<'_, PyAny>) -> PyResult<Self> {
        guard(|| {
            let screw = screw.cast::<PyScrew>().map_err(|_| {
                let ty = screw.get_type().name().map(|n| n.to_string()).unwrap_or_default();
                pyo3::exceptions::PyTypeError::new_err(format!("screw must be a dqskin.Screw, got {ty}"))
            })?;
            Ok(Self(DualQuat::from_screw(&screw.get().screw())))
        })
    }

    /// Real part ``(w, x, y, z)``.
    #[getter]
    fn real(&self) -> (f32, f32, f32, f32) {
        let q = self.0.real;
        (q.w, q.x, q.y, q.z)
    }

    /// Dual part ``(w, x, y, z)``.
    #[getter]
    fn dual(&self) -> (f32, f32, f32, f32) {
        let q = self.0.dual;
        (q.w, q.x, q.y, q.z)
    }

    /// The rotation (normalized real part) ``(w, x, y, z)``.
    #[getter]
    fn rotation(&self) -> (f32, f32, f32, f32) {
        let q = quat_to_wxyz(self.0.rotation());
        (q[0], q[1], q[2], q[3])
    }

    /// The translation ``(x, y, z)``.
    #[getter]
    fn translation(&self) -> (f32, f32, f32) {
        to_tuple(self.0.translation())
    }

    /// ``[rw, rx, ry, rz, dw, dx, dy, dz]`` as float32, the layout the array functions use.
    fn to_array<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_slice(py, &self.0.to_array_wxyz())
    }

    /// The rigid transform as a row-major 4×4 float32 matrix.
    fn to_matrix<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let m = mat4_to_row_major(&self.0.to_mat4());
        PyArray1::from_slice(py, &m).reshape([4, 4])
    }

    /// Quaternion conjugate of both parts (the inverse, for a unit dual quaternion).
    fn conjugate(&self) -> Self {
        Self(self.0.conjugate())
    }

    /// Dual-number conjugate ``real − ε·dual``.
    fn dual_conjugate(&self) -> Self {
        Self(self.0.dual_conjugate())
    }

    /// Both conjugates ``real* − ε·dual*``.
    fn full_conjugate(&self) -> Self {
        Self(self.0.full_conjugate())
    }

    /// The dual-number norm as ``(real, dual)``.
    fn norm(&self) -> (f32, f32) {
        let n = self.0.norm();
        (n.re, n.du)
    }

    /// Whether this is a unit dual quaternion (a rigid transform) within ``tolerance``.
    #[pyo3(signature = (tolerance = None))]
    fn is_unit(&self, tolerance: Option<&Bound<'_, PyAny>>) -> PyResult<bool> {
        guard(|| Ok(self.0.is_unit(args::or(tolerance, 1e-5, |o| args::float_in(o, "tolerance", 0.0, 1.0))?)))
    }

    /// Divided by its dual-number norm; ``ValueError`` if the real part is zero.
    fn normalized(&self) -> PyResult<Self> {
        self.0
            .try_normalize()
            .map(Self)
            .ok_or_else(|| PyValueError::new_err("cannot normalize a dual quaternion whose real part is zero"))
    }

    /// The multiplicative inverse; ``ValueError`` if the real part is zero.
    fn inverse(&self) -> PyResult<Self> {
        self.0
            .inverse()
            .map(Self)
            .ok_or_else(|| PyValueError::new_err("a dual quaternion whose real part is zero has no inverse"))
    }

    /// The same transform with ``real.w ≥ 0`` (shortest-path powers and interpolation).
    fn shortest(&self) -> Self {
        Self(self.0.shortest())
    }

    /// Logarithm of a unit dual quaternion (a pure dual quaternion).
    fn log(&self) -> Self {
        Self(self.0.log())
    }

    /// Exponential of a pure dual quaternion (scalar parts ignored); a unit dual quaternion.
    fn exp(&self) -> Self {
        Self(self.0.exp())
    }

    /// ``self**t = exp(t·log(self))``: the screw motion scaled by ``t``.
    fn pow(&self, t: &Bound<'_, PyAny>) -> PyResult<Self> {
        guard(|| Ok(Self(self.0.powf(args::float(t, "t")?))))
    }

    fn __pow__(&self, t: &Bound<'_, PyAny>, _modulo: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        self.pow(t)
    }

    /// Screw parameters of a unit dual quaternion.
    fn screw(&self) -> PyScrew {
        let s = self.0.to_screw();
        PyScrew { axis: to_tuple(s.axis), moment: to_tuple(s.moment), angle: s.angle, pitch: s.pitch }
    }

    /// Transforms one point ``(x, y, z)``.
    fn transform_point(&self, point: &Bound<'_, PyAny>) -> PyResult<(f32, f32, f32)> {
        guard(|| Ok(to_tuple(self.0.transform_point3(vec3(point, "point")?))))
    }

    /// Transforms an ``(N, 3)`` float32 array of points into a new array.
    fn transform_points<'py>(&self, points: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray2<f32>>> {
        guard(|| {
            let py = points.py();
            let p = arrays::readonly::<f32>(points, "points", &[None, Some(3)], &["N"])?;
            let src = p.as_slice()?;
            let q = self.0.normalize_or_identity();
            let out: Vec<f32> = py.detach(|| {
                src.chunks_exact(3).flat_map(|c| q.transform_point3(Vec3::new(c[0], c[1], c[2])).to_array()).collect()
            });
            PyArray1::from_vec(py, out).reshape([src.len() / 3, 3])
        })
    }

    fn __mul__(&self, other: &Bound<'_, PyAny>) -> PyResult<Py<PyAny>> {
        let py = other.py();
        if let Ok(o) = other.cast::<PyDualQuat>() {
            return Ok(Py::new(py, Self(self.0 * o.get().0))?.into_any());
        }
        if other.extract::<f64>().is_ok() {
            let s = args::float(other, "the factor")?;
            return Ok(Py::new(py, Self(self.0 * s))?.into_any());
        }
        Ok(py.NotImplemented())
    }

    fn __rmul__(&self, other: &Bound<'_, PyAny>) -> PyResult<Py<PyAny>> {
        self.__mul__(other)
    }

    fn __add__(&self, other: &Self) -> Self {
        Self(self.0 + other.0)
    }

    fn __sub__(&self, other: &Self) -> Self {
        Self(self.0 - other.0)
    }

    fn __neg__(&self) -> Self {
        Self(-self.0)
    }

    fn __repr__(&self) -> String {
        let (r, d) = (self.real(), self.dual());
        format!("DualQuat(real={r:?}, dual={d:?})")
    }
}

/// ``(N, 4, 4)`` rigid matrices to ``(N, 8)`` unit dual quaternions. With ``check=True`` a matrix
/// that is not rigid raises ``ValueError`` naming it.
#[pyfunction]
#[pyo3(signature = (matrices, check = None, tolerance = None))]
fn dual_quats_from_matrices<'py>(
    matrices: &Bound<'py, PyAny>,
    check: Option<&Bound<'py, PyAny>>,
    tolerance: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    guard(|| {
        let check = args::or(check, true, |o| args::boolean(o, "check"))?;
        let tolerance = args::or(tolerance, 1e-5, |o| args::float_in(o, "tolerance", 0.0, 1.0))?;
        let py = matrices.py();
        let m = arrays::readonly::<f32>(matrices, "matrices", &[None, Some(4), Some(4)], &["N"])?;
        let data = m.as_slice()?;
        arrays::check_finite("matrices", data)?;
        let n = data.len() / 16;
        let mut out = Vec::with_capacity(n * 8);
        for (i, c) in data.chunks_exact(16).enumerate() {
            let mat: Mat4 = mat4_from_row_major(c);
            let dq = if check {
                DualQuat::try_from_mat4(&mat, tolerance)
                    .map_err(|e| PyValueError::new_err(format!("matrices[{i}]: {e} (tolerance = {tolerance})")))?
            } else {
                DualQuat::from_mat4(&mat)
            };
            out.extend_from_slice(&dq.to_array_wxyz());
        }
        PyArray1::from_vec(py, out).reshape([n, 8])
    })
}

/// ``(N, 8)`` dual quaternions to ``(N, 4, 4)`` rigid matrices (each normalized first; a zero real
/// part raises ``ValueError``).
#[pyfunction]
fn matrices_from_dual_quats<'py>(dual_quats: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray3<f32>>> {
    guard(|| {
        let py = dual_quats.py();
        let q = arrays::readonly::<f32>(dual_quats, "dual_quats", &[None, Some(8)], &["N"])?;
        let data = q.as_slice()?;
        arrays::check_finite("dual_quats", data)?;
        let n = data.len() / 8;
        let mut out = Vec::with_capacity(n * 16);
        for (i, c) in data.chunks_exact(8).enumerate() {
            let dq = arrays::dq_from_slice(c).try_normalize().ok_or_else(|| {
                PyValueError::new_err(format!("dual_quats[{i}] has a zero real part and is not a transform"))
            })?;
            out.extend_from_slice(&mat4_to_row_major(&dq.to_mat4()));
        }
        PyArray1::from_vec(py, out).reshape([n, 4, 4])
    })
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyDualQuat>()?;
    m.add_class::<PyScrew>()?;
    m.add_function(wrap_pyfunction!(dual_quats_from_matrices, m)?)?;
    m.add_function(wrap_pyfunction!(matrices_from_dual_quats, m)?)?;
    Ok(())
}

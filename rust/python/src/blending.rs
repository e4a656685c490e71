//! Blending and interpolation on arrays: ScLERP, DLB, DIB, Slerp, Squad, forward kinematics.
//! Dual quaternions are ``(8,)`` arrays ``[rw, rx, ry, rz, dw, dx, dy, dz]``, quaternions
//! ``(4,)`` arrays ``[w, x, y, z]``.

use dqskin_core::glam::Quat;
use dqskin_core::{BlendError, DualQuat, HierarchyError, Squad};
use numpy::{PyArray1, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::args;
use crate::arrays::{self, dq_from_slice, quat_from_wxyz, quat_to_wxyz};
use crate::guard;

fn blend_error(e: BlendError) -> PyErr {
    let msg = match e {
        BlendError::Empty => "transforms must not be empty".to_string(),
        BlendError::LengthMismatch { transforms, weights } => {
            format!("weights has {weights} entries but there are {transforms} transforms")
        }
        BlendError::InvalidWeight { index } => format!("weights[{index}] is negative or not finite"),
        BlendError::ZeroWeightSum => "weights sum to zero".to_string(),
        BlendError::NotATransform { index } => {
            format!("transforms[{index}] has a zero real part and is not a rigid transform")
        }
    };
    PyValueError::new_err(msg)
}

/// A parameter that is a number or a 1-D array of numbers.
enum Params {
    One(f32),
    Many(Vec<f32>),
}

fn params(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Params> {
    // Only a plain number or a 0-d array is one parameter: numpy would also let a one-element
    // array pass as a float, but that must give a (1, width) result.
    let is_array = obj.cast::<numpy::PyUntypedArray>().is_ok_and(|a| a.ndim() > 0);
    let is_sequence = obj.cast::<pyo3::types::PySequence>().is_ok();
    if is_array || is_sequence {
        let (v, _) = arrays::small(obj, name, &[None], &["T"])?;
        return Ok(Params::Many(v));
    }
    Ok(Params::One(args::float(obj, name)?))
}

/// Evaluates `f` at each parameter, giving `(width,)` for a number or `(T, width)` for an array.
fn evaluate<'py>(py: Python<'py>, t: Params, width: usize, f: impl Fn(f32) -> Vec<f32>) -> PyResult<Bound<'py, PyAny>> {
    Ok(match t {
        Params::One(t) => PyArray1::from_vec(py, f(t)).into_any(),
        Params::Many(ts) => {
            let n = ts.len();
            let flat: Vec<f32> = ts.into_iter().flat_map(&f).collect();
            PyArray1::from_vec(py, flat).reshape([n, width])?.into_any()
        }
    })
}

fn unit_dq(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<DualQuat> {
    let (v, _) = arrays::small(obj, name, &[Some(8)], &[])?;
    dq_from_slice(&v)
        .try_normalize()
        .ok_or_else(|| PyValueError::new_err(format!("{name} has a zero real part and is not a rigid transform")))
}

fn dq_list(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<DualQuat>> {
    let (v, _) = arrays::small(obj, name, &[None, Some(8)], &["N"])?;
    Ok(v.chunks_exact(8).map(dq_from_slice).collect())
}

/// Screw linear interpolation from ``a`` (t = 0) to ``b`` (t = 1) along the shortest path:
/// constant speed, fixed screw axis. ``t`` is a number (returns ``(8,)``) or an array of ``T``
/// numbers (returns ``(T, 8)``). Inputs are normalized. Well defined at 180° of relative rotation.
#[pyfunction]
fn sclerp<'py>(a: &Bound<'py, PyAny>, b: &Bound<'py, PyAny>, t: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    guard(|| {
        let (p, q) = (unit_dq(a, "a")?, unit_dq(b, "b")?);
        let t = params(t, "t")?;
        evaluate(a.py(), t, 8, |t| dqskin_core::sclerp(&p, &q, t).to_array_wxyz().to_vec())
    })
}

/// Dual quaternion linear blending of ``(N, 8)`` transforms with ``(N,)`` non-negative weights
/// (divided by their sum). Signs are aligned to the transform with the largest weight, so the
/// result does not depend on input signs or order. Returns ``(8,)``.
#[pyfunction]
fn dlb<'py>(transforms: &Bound<'py, PyAny>, weights: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f32>>> {
    guard(|| {
        let qs = dq_list(transforms, "transforms")?;
        let (w, _) = arrays::small(weights, "weights", &[None], &["N"])?;
        let r = dqskin_core::dlb(&qs, &w).map_err(blend_error)?;
        Ok(PyArray1::from_slice(transforms.py(), &r.to_array_wxyz()))
    })
}

/// Dual quaternion iterative blending (exact, constant speed, bi-invariant): starts at DLB and
/// repeats ``b ← b·exp(Σ wᵢ·log(b*·qᵢ))`` until the step is shorter than ``precision`` or
/// ``max_iterations`` updates were made. Returns ``(blend (8,), iterations, converged)``.
#[pyfunction]
#[pyo3(signature = (transforms, weights, precision = None, max_iterations = None))]
fn dib<'py>(
    transforms: &Bound<'py, PyAny>,
    weights: &Bound<'py, PyAny>,
    precision: Option<&Bound<'py, PyAny>>,
    max_iterations: Option<&Bound<'py, PyAny>>,
) -> PyResult<(Bound<'py, PyArray1<f32>>, u32, bool)> {
    guard(|| {
        let precision = args::or(precision, 1e-6, |o| args::float(o, "precision"))?;
        if !(precision >= 0.0) {
            return Err(PyValueError::new_err("precision must be a finite number ≥ 0"));
        }
        // DIB converges in a handful of iterations when it converges at all; the bound keeps a
        // call from running for hours.
        let max_iterations = args::or(max_iterations, 32, |o| args::int(o, "max_iterations", 0, 100_000))? as u32;
        let qs = dq_list(transforms, "transforms")?;
        let (w, _) = arrays::small(weights, "weights", &[None], &["N"])?;
        let r = dqskin_core::dib(&qs, &w, precision, max_iterations).map_err(blend_error)?;
        Ok((PyArray1::from_slice(transforms.py(), &r.blend.to_array_wxyz()), r.iterations, r.converged))
    })
}

fn quat_arg(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Quat> {
    let (v, _) = arrays::small(obj, name, &[Some(4)], &[])?;
    let q = quat_from_wxyz(&v);
    if q.length_squared() == 0.0 {
        return Err(PyValueError::new_err(format!("{name} must be a non-zero quaternion")));
    }
    Ok(q)
}

/// Spherical linear interpolation of rotations ``(w, x, y, z)`` along the shortest arc, with
/// constant angular speed. ``t`` is a number (returns ``(4,)``) or an array (returns ``(T, 4)``).
#[pyfunction]
fn slerp<'py>(q0: &Bound<'py, PyAny>, q1: &Bound<'py, PyAny>, t: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    guard(|| {
        let (a, b) = (quat_arg(q0, "q0")?, quat_arg(q1, "q1")?);
        let t = params(t, "t")?;
        evaluate(q0.py(), t, 4, |t| quat_to_wxyz(dqskin_core::slerp(a, b, t)).to_vec())
    })
}

fn squad_curve(keys: &Bound<'_, PyAny>) -> PyResult<Squad> {
    let (k, _) = arrays::small(keys, "keys", &[None, Some(4)], &["K"])?;
    let quats: Vec<Quat> = k.chunks_exact(4).map(quat_from_wxyz).collect();
    if quats.is_empty() {
        return Err(PyValueError::new_err("keys must contain at least one rotation"));
    }
    if let Some(i) = quats.iter().position(|q| q.length_squared() == 0.0) {
        return Err(PyValueError::new_err(format!("keys[{i}] is a zero quaternion")));
    }
    Ok(Squad::new(&quats))
}

/// Shoemake's Squad through ``(K, 4)`` key rotations, evaluated at ``u`` in ``[0, K−1]``
/// (segment ``floor(u)``; clamped): passes through every key with continuous angular velocity.
/// Keys are made sign-continuous first. ``u`` is a number (returns ``(4,)``) or an array
/// (returns ``(T, 4)``).
#[pyfunction]
fn squad<'py>(keys: &Bound<'py, PyAny>, u: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    guard(|| {
        let curve = squad_curve(keys)?;
        let u = params(u, "u")?;
        evaluate(keys.py(), u, 4, |u| quat_to_wxyz(curve.evaluate(u)).to_vec())
    })
}

/// Squad's inner control points ``sᵢ`` for ``(K, 4)`` keys, as ``(K, 4)``.
#[pyfunction]
fn squad_control_points<'py>(keys: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    guard(|| {
        let curve = squad_curve(keys)?;
        let flat: Vec<f32> = curve.control_points().iter().flat_map(|q| quat_to_wxyz(*q)).collect();
        let n = flat.len() / 4;
        Ok(PyArray1::from_vec(keys.py(), flat).reshape([n, 4])?.into_any())
    })
}

/// Global transforms ``(B, 8)`` of a bone hierarchy from local ones ``(B, 8)``:
/// ``global[i] = global[parents[i]] · local[i]``; ``parents[i] < 0`` marks a root. Bones may come in
/// any order; cycles and out-of-range parents raise ``ValueError``.
#[pyfunction]
fn forward_kinematics<'py>(parents: &Bound<'py, PyAny>, locals: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    guard(|| {
        let p = parents_arg(parents)?;
        let l = dq_list(locals, "locals")?;
        let g = dqskin_core::forward_kinematics(&p, &l).map_err(|e| {
            PyValueError::new_err(match e {
                HierarchyError::LengthMismatch { parents, locals } => {
                    format!("parents has {parents} entries but locals has {locals}")
                }
                HierarchyError::ParentOutOfRange { bone, parent } => {
                    format!("parents[{bone}] = {parent} is not a bone index (use -1 for a root)")
                }
                HierarchyError::Cycle { bone } => format!("parents form a cycle through bone {bone}"),
                HierarchyError::NotATransform { bone } => {
                    format!("locals[{bone}] has a zero real part and is not a rigid transform")
                }
            })
        })?;
        let flat: Vec<f32> = g.iter().flat_map(|q| q.to_array_wxyz()).collect();
        Ok(PyArray1::from_vec(parents.py(), flat).reshape([g.len(), 8])?.into_any())
    })
}

fn parents_arg(obj: &Bound<'_, PyAny>) -> PyResult<Vec<i64>> {
    let np = obj.py().import("numpy")?;
    let arr = np.call_method1("asarray", (obj,)).map_err(|e| {
        pyo3::exceptions::PyTypeError::new_err(format!(
            "parents must be an array of integers: {}",
            arrays::one_line(&e, obj.py())
        ))
    })?;
    let kind: String = arr.getattr("dtype")?.getattr("kind")?.extract()?;
    if kind != "i" && kind != "u" {
        return Err(pyo3::exceptions::PyTypeError::new_err("parents must be an array of integers"));
    }
    let ndim: usize = arr.getattr("ndim")?.extract()?;
    if ndim != 1 {
        return Err(PyValueError::new_err("parents must be one-dimensional"));
    }
    arr.call_method0("tolist")?
        .extract::<Vec<i64>>()
        .map_err(|_| PyValueError::new_err("parents has an index too large for a 64-bit integer"))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(sclerp, m)?)?;
    m.add_function(wrap_pyfunction!(dlb, m)?)?;
    m.add_function(wrap_pyfunction!(dib, m)?)?;
    m.add_function(wrap_pyfunction!(slerp, m)?)?;
    m.add_function(wrap_pyfunction!(squad, m)?)?;
    m.add_function(wrap_pyfunction!(squad_control_points, m)?)?;
    m.add_function(wrap_pyfunction!(forward_kinematics, m)?)?;
    Ok(())
}

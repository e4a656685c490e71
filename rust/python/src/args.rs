//! Scalar arguments (numbers, flags, names) checked with errors that name the argument: a
//! `TypeError` for the wrong kind of value, a `ValueError` for one out of range (never an
//! `OverflowError`, whatever the size of the integer).

use pyo3::exceptions::{PyOverflowError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyComplex, PyFloat, PyString};

fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type().name().map(|n| n.to_string()).unwrap_or_else(|_| "?".into())
}

/// The numpy dtype kind of a numpy scalar or array ("b", "i", "f", "c", ...), or None.
fn numpy_kind(obj: &Bound<'_, PyAny>) -> Option<String> {
    obj.getattr("dtype").and_then(|d| d.getattr("kind")).and_then(|k| k.extract::<String>()).ok()
}

fn is_numpy_bool(obj: &Bound<'_, PyAny>) -> bool {
    numpy_kind(obj).is_some_and(|k| k == "b")
}

/// An integer in `[min, max]` (Python ints, numpy integers; not floats or bools).
pub fn int(obj: &Bound<'_, PyAny>, name: &str, min: i64, max: i64) -> PyResult<i64> {
    if obj.is_instance_of::<PyBool>()
        || obj.is_instance_of::<PyFloat>()
        || obj.is_instance_of::<PyString>()
        || is_numpy_bool(obj)
    {
        return Err(PyTypeError::new_err(format!("{name} must be an integer, got {}", type_name(obj))));
    }
    let index = obj
        .call_method0("__index__")
        .map_err(|_| PyTypeError::new_err(format!("{name} must be an integer, got {}", type_name(obj))))?;
    match index.extract::<i64>() {
        Ok(v) if (min..=max).contains(&v) => Ok(v),
        Ok(v) => Err(PyValueError::new_err(format!("{name} must be between {min} and {max}, got {v}"))),
        Err(e) if e.is_instance_of::<PyOverflowError>(obj.py()) => {
            Err(PyValueError::new_err(format!("{name} must be between {min} and {max}, got {index}")))
        }
        Err(_) => Err(PyTypeError::new_err(format!("{name} must be an integer, got {}", type_name(obj)))),
    }
}

/// A finite number that fits in single precision (ints and floats, numpy scalars; not bools,
/// strings or complex numbers).
pub fn float(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<f32> {
    if obj.is_instance_of::<PyBool>() || obj.is_instance_of::<PyString>() || obj.is_instance_of::<PyComplex>() {
        return Err(PyTypeError::new_err(format!("{name} must be a real number, got {}", type_name(obj))));
    }
    if let Ok(arr) = obj.cast::<numpy::PyUntypedArray>() {
        if numpy::PyUntypedArrayMethods::ndim(arr) > 0 {
            return Err(PyTypeError::new_err(format!(
                "{name} must be a number, got an array of shape {:?}",
                numpy::PyUntypedArrayMethods::shape(arr)
            )));
        }
    }
    if numpy_kind(obj).is_some_and(|k| k == "c") {
        // numpy complex scalars: refuse rather than drop the imaginary part.
        return Err(PyTypeError::new_err(format!("{name} must be a real number, got a complex {}", type_name(obj))));
    }
    let v: f64 = match obj.extract::<f64>() {
        Ok(v) => v,
        Err(e) if e.is_instance_of::<PyOverflowError>(obj.py()) => {
            return Err(PyValueError::new_err(format!("{name} is too large")))
        }
        Err(_) => return Err(PyTypeError::new_err(format!("{name} must be a real number, got {}", type_name(obj)))),
    };
    if !v.is_finite() {
        return Err(PyValueError::new_err(format!("{name} must be finite, got {v}")));
    }
    if v.abs() > f64::from(f32::MAX) {
        return Err(PyValueError::new_err(format!("{name} = {v} is too large for single precision")));
    }
    Ok(v as f32)
}

/// A finite number in `[min, max]`.
pub fn float_in(obj: &Bound<'_, PyAny>, name: &str, min: f32, max: f32) -> PyResult<f32> {
    let v = float(obj, name)?;
    if !(min..=max).contains(&v) {
        return Err(PyValueError::new_err(format!("{name} must be between {min} and {max}, got {v}")));
    }
    Ok(v)
}

/// `True` or `False` (also numpy booleans).
pub fn boolean(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<bool> {
    if obj.is_instance_of::<PyBool>() {
        return obj.extract::<bool>();
    }
    let is_numpy_bool =
        is_numpy_bool(obj) && obj.getattr("ndim").and_then(|n| n.extract::<usize>()).is_ok_and(|n| n == 0);
    if is_numpy_bool {
        return obj.call_method0("__bool__")?.extract::<bool>();
    }
    Err(PyTypeError::new_err(format!("{name} must be True or False, got {}", type_name(obj))))
}

/// A string.
pub fn string(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<String> {
    obj.cast::<PyString>()
        .map_err(|_| PyTypeError::new_err(format!("{name} must be a string, got {}", type_name(obj))))?
        .to_str()
        .map(str::to_owned)
        .map_err(|_| PyValueError::new_err(format!("{name} is not valid text")))
}

/// An optional argument: `None` (or absent) gives `default`.
pub fn or<'py, T>(
    obj: Option<&Bound<'py, PyAny>>,
    default: T,
    f: impl FnOnce(&Bound<'py, PyAny>) -> PyResult<T>,
) -> PyResult<T> {
    match obj {
        Some(o) if !o.is_none() => f(o),
        _ => Ok(default),
    }
}

/// An optional ``progress(done, total)`` callback: None for an absent or None argument, else the
/// callable (anything else is a TypeError naming it).
pub fn progress_callback(obj: Option<&Bound<'_, PyAny>>) -> PyResult<Option<Py<PyAny>>> {
    match obj {
        Some(p) if !p.is_none() => {
            if !p.is_callable() {
                let ty = p.get_type().name().map(|n| n.to_string()).unwrap_or_default();
                return Err(PyTypeError::new_err(format!(
                    "progress must be callable as progress(done, total), got {ty}"
                )));
            }
            Ok(Some(p.clone().unbind()))
        }
        _ => Ok(None),
    }
}

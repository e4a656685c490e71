//! Argument checking and conversion between numpy arrays and core types. Every error names the
//! argument and says what is wrong and how to fix it.

use dqskin_core::glam::{Mat4, Quat};
use dqskin_core::DualQuat;
use numpy::{
    dtype, Element, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyReadwriteArrayDyn,
    PyUntypedArray, PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;

/// Expected shape: `None` for any length, `Some(n)` for exactly `n`.
pub type Shape<'a> = &'a [Option<usize>];

fn describe_shape(shape: Shape<'_>, names: &[&str]) -> String {
    let parts: Vec<String> = shape
        .iter()
        .zip(names.iter().chain(std::iter::repeat(&"N")))
        .map(|(d, n)| d.map_or_else(|| n.to_string(), |v| v.to_string()))
        .collect();
    if parts.len() == 1 {
        format!("({},)", parts[0])
    } else {
        format!("({})", parts.join(", "))
    }
}

fn check_shape(name: &str, got: &[usize], shape: Shape<'_>, names: &[&str]) -> PyResult<()> {
    let ok = got.len() == shape.len() && got.iter().zip(shape).all(|(g, s)| s.is_none_or(|s| s == *g));
    if ok {
        return Ok(());
    }
    Err(PyValueError::new_err(format!("{name} must have shape {}, got {:?}", describe_shape(shape, names), got)))
}

pub fn as_numpy<'a, 'py>(
    obj: &'a Bound<'py, PyAny>,
    name: &str,
    want: &str,
) -> PyResult<&'a Bound<'py, PyUntypedArray>> {
    obj.cast::<PyUntypedArray>().map_err(|_| {
        let ty = obj.get_type().name().map(|n| n.to_string()).unwrap_or_else(|_| "?".into());
        PyTypeError::new_err(format!("{name} must be a numpy array of {want}, got {ty}"))
    })
}

/// `obj` as a numpy array of `T` with the given shape, C-contiguous, or an error that says
/// which of these it is not.
fn checked<'a, 'py, T: Element>(
    obj: &'a Bound<'py, PyAny>,
    name: &str,
    shape: Shape<'_>,
    names: &[&str],
) -> PyResult<&'a Bound<'py, PyArrayDyn<T>>> {
    // (Spelled out only for an error: every skinning call checks several arrays.)
    let want = || std::any::type_name::<T>().replace("f32", "float32").replace("u32", "uint32").replace("i32", "int32");
    let arr = obj.cast::<PyUntypedArray>().or_else(|_| as_numpy(obj, name, &want()))?;
    if !arr.dtype().is_equiv_to(&dtype::<T>(obj.py())) {
        let want = want();
        return Err(PyTypeError::new_err(format!(
            "{name} must have dtype {want}, got {} (convert with np.asarray({name}, dtype=np.{want}))",
            arr.dtype()
        )));
    }
    check_shape(name, arr.shape(), shape, names)?;
    if !arr.is_c_contiguous() {
        return Err(PyValueError::new_err(format!("{name} must be C-contiguous (use np.ascontiguousarray({name}))")));
    }
    let typed = obj.cast::<PyArrayDyn<T>>()?;
    if !(typed.data() as usize).is_multiple_of(core::mem::align_of::<T>()) {
        return Err(PyValueError::new_err(format!(
            "{name} is not aligned in memory (a view at an odd byte offset; use np.ascontiguousarray({name}).copy())"
        )));
    }
    Ok(typed)
}

/// A C-contiguous numpy array of `T` with the given shape, borrowed read-only (no copy).
pub fn readonly<'py, T: Element>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    shape: Shape<'_>,
    names: &[&str],
) -> PyResult<PyReadonlyArrayDyn<'py, T>> {
    checked::<T>(obj, name, shape, names)?
        .try_readonly()
        .map_err(|_| PyValueError::new_err(format!("{name} overlaps an array that is written by this call (out)")))
}

/// Like [`readonly`] but writable; `out` must not overlap any input.
pub fn readwrite<'py, T: Element>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    shape: Shape<'_>,
    names: &[&str],
) -> PyResult<PyReadwriteArrayDyn<'py, T>> {
    checked::<T>(obj, name, shape, names)?.try_readwrite().map_err(|e| match e {
        numpy::BorrowError::NotWriteable => PyValueError::new_err(format!("{name} is read-only")),
        _ => PyValueError::new_err(format!(
            "{name} must not be (or overlap) one of the input arrays; pass a separate buffer"
        )),
    })
}

/// Integer index arrays in any integer dtype, converted to `u32` with range checks.
pub fn indices(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<u32>> {
    let arr = as_numpy(obj, name, "integers")?;
    if arr.ndim() != 1 {
        return Err(PyValueError::new_err(format!("{name} must be one-dimensional, got shape {:?}", arr.shape())));
    }
    let kind = arr.dtype().kind();
    if kind != b'i' && kind != b'u' {
        return Err(PyTypeError::new_err(format!("{name} must have an integer dtype, got {}", arr.dtype())));
    }
    let as_i64 = aligned_copy(obj, "int64")?;
    let a = as_i64.cast::<PyArrayDyn<i64>>()?.try_readonly()?;
    let slice = a.as_slice().map_err(|e| PyValueError::new_err(format!("{name}: {e}")))?;
    slice
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            u32::try_from(v)
                .map_err(|_| PyValueError::new_err(format!("{name}[{i}] = {v} is out of range (must be 0 to 2^32-1)")))
        })
        .collect()
}

/// An integer array of the given shape, in any integer dtype, flattened (C order) to `u32` with
/// range checks.
pub fn index_array(obj: &Bound<'_, PyAny>, name: &str, shape: Shape<'_>, names: &[&str]) -> PyResult<Vec<u32>> {
    let arr = as_numpy(obj, name, "integers")?;
    check_shape(name, arr.shape(), shape, names)?;
    let flat = obj.py().import("numpy")?.call_method1("ravel", (obj,))?;
    indices(&flat, name)
}

/// A small input (a transform, a few weights): anything numpy can turn into float32, copied.
/// Must be finite.
pub fn small(obj: &Bound<'_, PyAny>, name: &str, shape: Shape<'_>, names: &[&str]) -> PyResult<(Vec<f32>, Vec<usize>)> {
    // Fast path (per-frame matrices): already a C-contiguous, aligned float32 array.
    if let Ok(arr) = obj.cast::<PyArrayDyn<f32>>() {
        if arr.is_c_contiguous() && (arr.data() as usize).is_multiple_of(4) {
            if let Ok(ro) = arr.try_readonly() {
                let dims = ro.shape().to_vec();
                check_shape(name, &dims, shape, names)?;
                let data = ro.as_slice()?.to_vec();
                check_finite(name, &data)?;
                return Ok((data, dims));
            }
        }
    }
    let np = obj.py().import("numpy")?;
    if obj.is_none() {
        return Err(PyTypeError::new_err(format!("{name} must be an array of numbers, got None")));
    }
    if obj.is_instance_of::<pyo3::types::PyString>() || obj.is_instance_of::<pyo3::types::PyBytes>() {
        return Err(PyTypeError::new_err(format!("{name} must be an array of numbers, got a string")));
    }
    // Real numbers only: numpy would silently drop an imaginary part or parse strings.
    let arr = np
        .call_method1("asarray", (obj,))
        .map_err(|e| PyTypeError::new_err(format!("{name} must be an array of numbers: {}", one_line(&e, obj.py()))))?;
    let kind: String = arr.getattr("dtype")?.getattr("kind")?.extract()?;
    if !matches!(kind.as_str(), "i" | "u" | "f" | "b") {
        let what = match kind.as_str() {
            "c" => "complex numbers".to_string(),
            "O" => "Python objects (a ragged list or a list with non-numbers?)".to_string(),
            "U" | "S" => "strings".to_string(),
            _ => format!("dtype {}", arr.getattr("dtype")?),
        };
        return Err(PyTypeError::new_err(format!("{name} must be an array of real numbers, got {what}")));
    }
    let dims: Vec<usize> = arr.getattr("shape")?.extract()?;
    check_shape(name, &dims, shape, names)?;
    let arr = aligned_copy(&arr, "float32").map_err(|e| {
        PyValueError::new_err(format!("{name} cannot be converted to float32: {}", one_line(&e, obj.py())))
    })?;
    let arr = arr.cast::<PyArrayDyn<f32>>()?;
    let ro = arr.try_readonly()?;
    let data = ro.as_slice().map_err(|e| PyValueError::new_err(format!("{name}: {e}")))?.to_vec();
    if let Some(i) = data.iter().position(|v| !v.is_finite()) {
        return Err(PyValueError::new_err(format!("{name} contains a NaN or infinite value (flat index {i})")));
    }
    Ok((data, dims))
}

/// `obj` as a C-contiguous, aligned numpy array of `dtype` (a copy unless it is one already):
/// `np.ascontiguousarray` alone keeps a view at an odd byte offset, which cannot be read as a
/// slice.
fn aligned_copy<'py>(obj: &Bound<'py, PyAny>, dtype: &str) -> PyResult<Bound<'py, PyAny>> {
    let np = obj.py().import("numpy")?;
    np.call_method1("require", (obj, np.getattr(dtype)?, "CA"))
}

/// The first line of an exception's message.
pub fn one_line(e: &PyErr, py: Python<'_>) -> String {
    e.value(py).to_string().lines().next().unwrap_or("").to_string()
}

/// Whether a float32 array has a NaN or infinity; names the first flat index.
pub fn check_finite(name: &str, data: &[f32]) -> PyResult<()> {
    match dqskin_core::first_not_finite(data) {
        Some(i) => Err(PyValueError::new_err(format!("{name} contains a NaN or infinite value (flat index {i})"))),
        None => Ok(()),
    }
}

/// Row-major 4×4 (numpy / mathutils order, translation in the last column) to glam.
#[inline]
pub fn mat4_from_row_major(m: &[f32]) -> Mat4 {
    Mat4::from_cols_array(m.try_into().expect("16 floats")).transpose()
}

#[inline]
pub fn mat4_to_row_major(m: &Mat4) -> [f32; 16] {
    m.transpose().to_cols_array()
}

/// `[w, x, y, z]` (scalar first, as Blender and mathutils write quaternions).
#[inline]
pub fn quat_from_wxyz(a: &[f32]) -> Quat {
    Quat::from_xyzw(a[1], a[2], a[3], a[0])
}

#[inline]
pub fn quat_to_wxyz(q: Quat) -> [f32; 4] {
    [q.w, q.x, q.y, q.z]
}

#[inline]
pub fn dq_from_slice(a: &[f32]) -> DualQuat {
    DualQuat::from_array_wxyz(a.try_into().expect("8 floats"))
}

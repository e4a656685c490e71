//! The `dqskin._dqskin` extension module: a thin pyo3 layer over `dqskin-core`. It checks
//! arguments, converts arrays without copying the large ones, releases the GIL while kernels run,
//! and turns every core error into a `ValueError`/`TypeError` naming the argument. A Rust panic
//! never reaches Python as `PanicException`: [`guard`] turns it into a `RuntimeError`.

// `!(x >= 0.0)` is deliberate: unlike `x < 0.0` it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// pyo3 methods take `&self`.
#![allow(clippy::wrong_self_convention)]

mod args;
mod armature;
mod arrays;
mod background;
mod blender;
mod blending;
mod centers_job;
mod dual_quat;
mod job;
mod kept;
mod method;
mod object_state;
mod rigs;
mod skinning;
mod tracks;
mod weights;

use std::panic::{catch_unwind, AssertUnwindSafe};

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;

/// Runs `f`, converting a panic into a `RuntimeError` (a bug in dqskin, never bad input).
pub(crate) fn guard<T>(f: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    catch_unwind(AssertUnwindSafe(f)).unwrap_or_else(|payload| Err(internal_error(&panic_message(payload.as_ref()))))
}

/// What a panic said (its payload, when it is text).
pub(crate) fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".into())
}

/// The `RuntimeError` a panic becomes.
pub(crate) fn internal_error(msg: &str) -> PyErr {
    PyRuntimeError::new_err(format!("internal error in dqskin (please report it): {msg}"))
}

/// Sets the number of worker threads the kernels use: at least 1, at most 4 per core (at least
/// 16, at most 1024); checked before any thread starts.
#[pyfunction]
fn set_num_threads(threads: &Bound<'_, PyAny>) -> PyResult<()> {
    guard(|| {
        let max = dqskin_core::pool::max_threads();
        let n = args::int(threads, "threads", 1, max as i64)? as usize;
        dqskin_core::pool::set_num_threads(n)
            .map_err(|e| pyo3::exceptions::PyValueError::new_err(format!("threads: {e}")))
    })
}

/// The number of worker threads the kernels use.
#[pyfunction]
fn get_num_threads() -> PyResult<usize> {
    guard(|| Ok(dqskin_core::pool::num_threads()))
}

/// Which compiled copy of the kernels runs each kernel variant in this process, per size of job:
/// a list of ``(variant, size, copy)``, ``copy`` ``None`` while its first calls still measure the
/// copies (see ``dqskin_core::kernel_copies``).
#[pyfunction]
fn kernel_copies() -> PyResult<Vec<(&'static str, &'static str, Option<&'static str>)>> {
    guard(|| Ok(dqskin_core::kernel_copies()))
}

/// Panics on purpose (tests check that no `PanicException` escapes).
#[pyfunction]
fn _panic_for_tests() -> PyResult<()> {
    guard(|| panic!("deliberate panic"))
}

#[pymodule]
fn _dqskin(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("MAX_INFLUENCES_PER_VERTEX", dqskin_core::MAX_INFLUENCES_PER_VERTEX)?;
    m.add("MAX_BONES", dqskin_core::MAX_BONES)?;
    m.add_function(wrap_pyfunction!(set_num_threads, m)?)?;
    m.add_function(wrap_pyfunction!(get_num_threads, m)?)?;
    m.add_function(wrap_pyfunction!(kernel_copies, m)?)?;
    m.add_function(wrap_pyfunction!(_panic_for_tests, m)?)?;
    dual_quat::register(m)?;
    blending::register(m)?;
    blender::register(m)?;
    armature::register(m)?;
    object_state::register(m)?;
    skinning::register(m)?;
    centers_job::register(m)?;
    background::register(m)?;
    job::register(m)?;
    rigs::register(m)?;
    tracks::register(m)?;
    weights::register(m)?;
    Ok(())
}

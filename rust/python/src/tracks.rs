//! Keyed tracks on arrays: sampling rotation keys (Slerp, Squad) and transform keys (ScLERP),
//! sign cleanup, Spring smoothing, angular speeds and curvature.

use dqskin_core::glam::Quat;
use dqskin_core::tracks::{self, RotationTrack, SpringSettings, TrackError};
use numpy::{PyArray1, PyArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::args;
use crate::arrays::{self, dq_from_slice, quat_from_wxyz, quat_to_wxyz};
use crate::guard;

fn track_error(e: TrackError) -> PyErr {
    PyValueError::new_err(e.to_string())
}

fn quats(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<Quat>> {
    let (v, _) = arrays::small(obj, name, &[None, Some(4)], &["K"])?;
    Ok(v.chunks_exact(4).map(quat_from_wxyz).collect())
}

fn floats(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<f32>> {
    Ok(arrays::small(obj, name, &[None], &["N"])?.0)
}

fn quat_array<'py>(py: Python<'py>, q: &[Quat]) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<f32> = q.iter().flat_map(|q| quat_to_wxyz(*q)).collect();
    Ok(PyArray1::from_vec(py, flat).reshape([q.len(), 4])?.into_any())
}

/// Keys ``(K, 4)`` made sign-continuous (each key in the hemisphere of the previous one, so no
/// interpolation spins the long way) and normalized. Returns ``(keys, flipped)``, ``flipped`` the
/// number of keys negated.
#[pyfunction]
fn continuous_signs<'py>(keys: &Bound<'py, PyAny>) -> PyResult<(Bound<'py, PyAny>, usize)> {
    guard(|| {
        let mut k = quats(keys, "keys")?;
        if let Some(i) = k.iter().position(|q| q.length_squared() == 0.0) {
            return Err(PyValueError::new_err(format!("keys[{i}] is a zero quaternion")));
        }
        let flipped = dqskin_core::make_signs_continuous(&mut k);
        Ok((quat_array(keys.py(), &k)?, flipped))
    })
}

/// Rotation keys ``(K, 4)`` at strictly increasing ``times`` ``(K,)``, sampled at ``at`` ``(T,)``
/// (clamped to the key range) with ``method='slerp'`` (shortest arc between neighbouring keys,
/// constant speed per segment) or ``'squad'`` (smooth through the keys, angular velocity
/// continuous in time even with uneven key spacing). Keys are made sign-continuous first.
/// Returns ``(T, 4)`` unit quaternions.
#[pyfunction]
#[pyo3(signature = (times, keys, at, method = None))]
fn sample_rotations<'py>(
    times: &Bound<'py, PyAny>,
    keys: &Bound<'py, PyAny>,
    at: &Bound<'py, PyAny>,
    method: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    guard(|| {
        let method = args::or(method, "squad".to_string(), |o| args::string(o, "method"))?;
        let method = method.as_str();
        let track = RotationTrack::new(&floats(times, "times")?, &quats(keys, "keys")?).map_err(track_error)?;
        let at = floats(at, "at")?;
        let out: Vec<Quat> = match method {
            "slerp" => at.iter().map(|&t| track.slerp(t)).collect(),
            "squad" => at.iter().map(|&t| track.squad(t)).collect(),
            _ => return Err(PyValueError::new_err(format!("method must be 'slerp' or 'squad', got {method:?}"))),
        };
        quat_array(times.py(), &out)
    })
}

/// Transform keys ``(K, 8)`` (dual quaternions) at strictly increasing ``times``, sampled at
/// ``at`` along the ScLERP screw between neighbouring keys (constant angular and linear speed
/// per segment). Returns ``(T, 8)``.
#[pyfunction]
fn sample_transforms<'py>(
    times: &Bound<'py, PyAny>,
    keys: &Bound<'py, PyAny>,
    at: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    guard(|| {
        let t = floats(times, "times")?;
        let (k, _) = arrays::small(keys, "keys", &[None, Some(8)], &["K"])?;
        let k: Vec<_> = k.chunks_exact(8).map(dq_from_slice).collect();
        let at = floats(at, "at")?;
        let mut flat = Vec::with_capacity(at.len() * 8);
        for &x in &at {
            flat.extend_from_slice(&tracks::screw_track(&t, &k, x).map_err(track_error)?.to_array_wxyz());
        }
        Ok(PyArray1::from_vec(times.py(), flat).reshape([at.len(), 8])?.into_any())
    })
}

/// Dam et al.'s *Spring* (experimental): samples every ``step`` from the first key time to the
/// last that pass exactly through the keys and minimize the summed squared curvature, by
/// coarse-to-fine projected gradient descent from Slerp (``levels``, ``iterations`` per level,
/// ``key_weight`` on the curvature at the keys). Key times must lie on the sample grid.
/// Returns ``(T, 4)``.
#[pyfunction]
#[pyo3(signature = (times, keys, step = None, levels = None, iterations = None, key_weight = None))]
fn spring<'py>(
    times: &Bound<'py, PyAny>,
    keys: &Bound<'py, PyAny>,
    step: Option<&Bound<'py, PyAny>>,
    levels: Option<&Bound<'py, PyAny>>,
    iterations: Option<&Bound<'py, PyAny>>,
    key_weight: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    guard(|| {
        let py = times.py();
        let step = args::or(step, 1.0, |o| args::float(o, "step"))?;
        if !(step > 0.0) {
            return Err(PyValueError::new_err(format!("step must be positive, got {step}")));
        }
        let levels = args::or(levels, 3, |o| args::int(o, "levels", 1, 20))? as u32;
        let iterations = args::or(iterations, 400, |o| {
            args::int(o, "iterations", 0, i64::from(dqskin_core::tracks::MAX_SPRING_ITERATIONS))
        })? as u32;
        let key_weight = args::or(key_weight, 1.2, |o| args::float(o, "key_weight"))?;
        if !(key_weight > 0.0) {
            return Err(PyValueError::new_err(format!("key_weight must be positive, got {key_weight}")));
        }
        let t = floats(times, "times")?;
        let k = quats(keys, "keys")?;
        let settings = SpringSettings { step, levels, iterations, key_weight };
        // Long runs stop on Ctrl-C: the GIL is taken back now and then to look for signals.
        let interrupted = std::sync::Mutex::new(None);
        let stop = || {
            let mut slot = interrupted.lock().unwrap_or_else(|e| e.into_inner());
            if slot.is_none() {
                if let Err(e) = Python::attach(|py| py.check_signals()) {
                    *slot = Some(e);
                }
            }
            slot.is_some()
        };
        let result = py.detach(|| tracks::spring_with(&t, &k, &settings, &stop));
        if let Some(e) = interrupted.into_inner().unwrap_or_else(|e| e.into_inner()) {
            return Err(e);
        }
        let out = result.map_err(track_error)?;
        quat_array(py, &out)
    })
}

/// Rotation angle in radians between consecutive rotations of ``(T, 4)``: the angular speed per
/// sample step, ``(T−1,)``.
#[pyfunction]
fn angular_speeds<'py>(rotations: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f32>>> {
    guard(|| Ok(PyArray1::from_vec(rotations.py(), tracks::angular_speeds(&quats(rotations, "rotations")?))))
}

/// Dam et al.'s discrete curvature energy of evenly spaced rotations ``(T, 4)``.
#[pyfunction]
fn curvature_energy(rotations: &Bound<'_, PyAny>) -> PyResult<f64> {
    guard(|| Ok(tracks::curvature_energy(&quats(rotations, "rotations")?)))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(continuous_signs, m)?)?;
    m.add_function(wrap_pyfunction!(sample_rotations, m)?)?;
    m.add_function(wrap_pyfunction!(sample_transforms, m)?)?;
    m.add_function(wrap_pyfunction!(spring, m)?)?;
    m.add_function(wrap_pyfunction!(angular_speeds, m)?)?;
    m.add_function(wrap_pyfunction!(curvature_energy, m)?)?;
    Ok(())
}

//! The procedural twisted-cylinder rig.

use dqskin_core::rigs::TwistCylinder;
use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;

use dqskin_core::rigs::{MAX_RINGS, MAX_SEGMENTS, MAX_VERTICES};
use pyo3::exceptions::PyValueError;

use crate::args;
use crate::arrays::mat4_to_row_major;
use crate::guard;
use crate::skinning::{skin_error, PyInfluences};

/// A closed cylinder along +Y with two bones meeting in the middle (the "candy wrapper" test):
/// ``rings × segments`` side vertices ring by ring from y = 0, then the two cap centres.
#[pyclass(name = "TwistCylinder", module = "dqskin", frozen)]
pub struct PyTwistCylinder {
    rig: TwistCylinder,
    /// Built once, so that reading `.influences` every frame costs nothing.
    influences: Py<PyInfluences>,
}

#[pymethods]
impl PyTwistCylinder {
    /// Weights blend linearly from the lower bone to the upper one over the middle
    /// ``blend_zone`` fraction of the length.
    #[new]
    #[pyo3(signature = (rings = None, segments = None, length = None, radius = None, blend_zone = None))]
    fn new(
        py: Python<'_>,
        rings: Option<&Bound<'_, PyAny>>,
        segments: Option<&Bound<'_, PyAny>>,
        length: Option<&Bound<'_, PyAny>>,
        radius: Option<&Bound<'_, PyAny>>,
        blend_zone: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        guard(|| {
            let rings = args::or(rings, 33, |o| args::int(o, "rings", 2, MAX_RINGS as i64))? as usize;
            let segments = args::or(segments, 48, |o| args::int(o, "segments", 3, MAX_SEGMENTS as i64))? as usize;
            if rings * segments > MAX_VERTICES {
                return Err(PyValueError::new_err(format!(
                    "rings × segments = {rings} × {segments} is more than {MAX_VERTICES} vertices"
                )));
            }
            let length = args::or(length, 4.0, |o| args::float(o, "length"))?;
            let radius = args::or(radius, 0.5, |o| args::float(o, "radius"))?;
            let blend_zone = args::or(blend_zone, 0.5, |o| args::float_in(o, "blend_zone", 0.0, 1.0))?;
            if !(length > 0.0) {
                return Err(PyValueError::new_err("length must be positive"));
            }
            if !(radius > 0.0) {
                return Err(PyValueError::new_err("radius must be positive"));
            }
            let rig = TwistCylinder::new(rings, segments, length, radius, blend_zone).map_err(skin_error)?;
            let influences = Py::new(py, PyInfluences::wrap(rig.influences.clone()))?;
            Ok(Self { rig, influences })
        })
    }

    /// Rest positions, ``(V, 3)`` float32.
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let flat: Vec<f32> = self.rig.positions.iter().flatten().copied().collect();
        Ok(PyArray1::from_vec(py, flat).reshape([self.rig.positions.len(), 3])?.into_any())
    }

    /// Triangles, ``(T, 3)`` uint32, outward-facing.
    #[getter]
    fn triangles<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let flat: Vec<u32> = self.rig.triangles.iter().flatten().copied().collect();
        Ok(PyArray1::from_vec(py, flat).reshape([self.rig.triangles.len(), 3])?.into_any())
    }

    /// The influences (two bones); the same object every time.
    #[getter]
    fn influences(&self, py: Python<'_>) -> Py<PyInfluences> {
        self.influences.clone_ref(py)
    }

    /// Rest matrices of the two bones, ``(2, 4, 4)`` float32.
    #[getter]
    fn rest<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let flat: Vec<f32> = self.rig.rest.iter().flat_map(mat4_to_row_major).collect();
        Ok(PyArray1::from_vec(py, flat).reshape([2, 4, 4])?.into_any())
    }

    #[getter]
    fn rings(&self) -> usize {
        self.rig.rings
    }

    #[getter]
    fn segments(&self) -> usize {
        self.rig.segments
    }

    /// Deform matrices ``(2, 4, 4)`` with the upper bone twisted by ``angle`` radians about the
    /// cylinder's axis.
    fn twist<'py>(&self, py: Python<'py>, angle: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        let angle = args::float(angle, "angle")?;
        let flat: Vec<f32> = self.rig.twist(angle).iter().flat_map(mat4_to_row_major).collect();
        Ok(PyArray1::from_vec(py, flat).reshape([2, 4, 4])?.into_any())
    }

    /// Vertex indices of side ring ``r`` (0 at the bottom), as a ``(segments,)`` int64 array.
    fn ring<'py>(&self, py: Python<'py>, r: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let r = args::int(r, "r", 0, self.rig.rings as i64 - 1)? as usize;
        let v: Vec<i64> = self.rig.ring(r).map(|i| i as i64).collect();
        Ok(PyArray1::from_vec(py, v))
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyTwistCylinder>()
}

//! The procedural twisted-cylinder rig.

use dqskin_core::rigs::TwistCylinder;
use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;

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
    #[pyo3(signature = (rings = 33, segments = 48, length = 4.0, radius = 0.5, blend_zone = 0.5))]
    fn new(py: Python<'_>, rings: usize, segments: usize, length: f32, radius: f32, blend_zone: f32) -> PyResult<Self> {
        guard(|| {
            let rig = TwistCylinder::new(rings, segments, length, radius, blend_zone).map_err(skin_error)?;
            let influences = Py::new(py, PyInfluences(rig.influences.clone()))?;
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
    fn twist<'py>(&self, py: Python<'py>, angle: f32) -> PyResult<Bound<'py, PyAny>> {
        let flat: Vec<f32> = self.rig.twist(angle).iter().flat_map(mat4_to_row_major).collect();
        Ok(PyArray1::from_vec(py, flat).reshape([2, 4, 4])?.into_any())
    }

    /// Vertex indices of side ring ``r`` (0 at the bottom), as a ``(segments,)`` int64 array.
    fn ring<'py>(&self, py: Python<'py>, r: usize) -> PyResult<Bound<'py, PyArray1<i64>>> {
        if r >= self.rig.rings {
            return Err(pyo3::exceptions::PyIndexError::new_err(format!(
                "ring {r} does not exist: there are {} rings",
                self.rig.rings
            )));
        }
        let v: Vec<i64> = self.rig.ring(r).map(|i| i as i64).collect();
        Ok(PyArray1::from_vec(py, v))
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyTwistCylinder>()
}

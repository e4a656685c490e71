//! `CentersJob`: Optimized Centers of Rotation computed on a thread of dqskin's own that never
//! runs Python (see `background.rs`).

use std::sync::{Arc, Mutex};

use dqskin_core::{CenterSums, Centers, Influences, PreviousCenters, SkinError};
use numpy::{PyArray1, PyArrayMethods};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;

use crate::background::{Outcome, Reports, Task};
use crate::skinning::{as_points, previous_centers, skin_error, triangle_indices, PyInfluences};
use crate::{args, arrays, guard};

/// The inputs the thread owns (copied from the caller's arrays at the start).
struct Inputs {
    positions: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
    influences: Influences,
    sigma: f32,
    previous: Option<(Influences, Centers, Option<CenterSums>)>,
}

impl Inputs {
    /// The centers; an update also leaves what it kept for the next one in `kept`.
    fn run(mut self, reports: &Reports<'_, Centers>, kept: &Mutex<Option<CenterSums>>) -> Outcome<Centers> {
        let mut progress = |done: usize, total: usize| reports.progress(done, total);
        let mut interrupted = || reports.cancelled();
        let result = match &mut self.previous {
            Some((influences, centers, before)) => dqskin_core::centers_of_rotation_update_keeping(
                &self.positions,
                &self.triangles,
                &self.influences,
                self.sigma,
                PreviousCenters { influences, centers },
                before.take(),
                &mut progress,
                &mut interrupted,
            )
            .map(|(centers, sums)| {
                *kept.lock().unwrap_or_else(|p| p.into_inner()) = Some(sums);
                centers
            }),
            None => dqskin_core::centers_of_rotation_interruptible(
                &self.positions,
                &self.triangles,
                &self.influences,
                self.sigma,
                &mut progress,
                &mut interrupted,
            ),
        };
        match result {
            Ok(centers) => Outcome::Done(centers),
            Err(SkinError::Cancelled) => Outcome::Cancelled,
            Err(e) => Outcome::Failed(e.to_string()),
        }
    }
}

/// :func:`centers_of_rotation` on a thread of its own, started at once: for a caller that must
/// not block and must not run a Python thread next to its host's code (Blender). The thread
/// never runs Python nor holds the GIL; the caller reads ``done``/``total``, may ``cancel()``,
/// and takes the centers with ``result()`` once ``finished``. The arguments are those of
/// :func:`centers_of_rotation` (checked now: bad input raises here, not later) and copied, so
/// the caller's arrays may change meanwhile. Dropping a running job cancels it.
#[pyclass(name = "CentersJob", module = "dqskin", frozen)]
pub struct PyCentersJob {
    task: Arc<Task<Centers>>,
    /// What an update kept for the next one, until `result()` hands it to `influences`.
    kept: Arc<Mutex<Option<CenterSums>>>,
    /// The weights the centers are for.
    influences: Py<PyInfluences>,
    vertices: usize,
}

impl Drop for PyCentersJob {
    fn drop(&mut self) {
        self.task.cancel();
    }
}

#[pymethods]
impl PyCentersJob {
    #[new]
    #[pyo3(signature = (positions, triangles, influences, sigma = None, *, previous = None))]
    fn new(
        positions: &Bound<'_, PyAny>,
        triangles: &Bound<'_, PyAny>,
        influences: &Bound<'_, PyAny>,
        sigma: Option<&Bound<'_, PyAny>>,
        previous: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        guard(|| {
            let sigma = args::or(sigma, dqskin_core::skin::DEFAULT_SIGMA, |o| args::float(o, "sigma"))?;
            let infl = influences.cast::<PyInfluences>().map_err(|_| {
                PyTypeError::new_err("influences must be a dqskin.Influences (the weights of the same vertices)")
            })?;
            let v = infl.get().0.vertex_count();
            let pos = arrays::readonly::<f32>(positions, "positions", &[Some(v), Some(3)], &["V"])?;
            let points = as_points(pos.as_slice()?).to_vec();
            let tris = triangle_indices(triangles)?;
            let previous = match previous {
                Some(p) if !p.is_none() => Some(previous_centers(p, &points)?),
                _ => None,
            };
            let inputs =
                Inputs { positions: points, triangles: tris, influences: infl.get().0.clone(), sigma, previous };
            let before = inputs.previous.as_ref().map(|(i, c, _)| PreviousCenters { influences: i, centers: c });
            dqskin_core::check_centers_inputs(&inputs.positions, &inputs.triangles, &inputs.influences, sigma, before)
                .map_err(skin_error)?;
            let kept = Arc::new(Mutex::new(None));
            let theirs = Arc::clone(&kept);
            let task = Task::spawn("dqskin centers", move |reports| inputs.run(reports, &theirs))?;
            Ok(Self { task, kept, influences: infl.clone().unbind(), vertices: v })
        })
    }

    /// Units of work done so far (of ``total``).
    #[getter]
    fn done(&self) -> usize {
        self.task.done()
    }

    /// Units of work in all (1 until the setup has counted them).
    #[getter]
    fn total(&self) -> usize {
        self.task.total()
    }

    /// The number of vertices.
    #[getter]
    fn vertices(&self) -> usize {
        self.vertices
    }

    /// Whether the thread has ended (with the centers, an error, or cancelled).
    #[getter]
    fn finished(&self) -> bool {
        self.task.finished()
    }

    /// Asks the thread to stop at its next step (within a fraction of a second); ``result()``
    /// then raises :class:`Cancelled` unless the centers were already complete.
    fn cancel(&self) {
        self.task.cancel();
    }

    /// Waits (the GIL released) until the thread ends or ``timeout`` seconds pass; returns
    /// ``finished``. Ctrl-C stops the wait (``KeyboardInterrupt``), not the job.
    #[pyo3(signature = (timeout = None))]
    fn wait(&self, py: Python<'_>, timeout: Option<&Bound<'_, PyAny>>) -> PyResult<bool> {
        guard(|| self.task.wait(py, timeout))
    }

    /// The centers, ``(V, 3)`` float32 (with ``with_mask=True`` also the ``(V,)`` bool mask), as
    /// :func:`centers_of_rotation` returns them, bit for bit. Waits for the thread if it is still
    /// running. Raises :class:`Cancelled` if it was cancelled, ``ValueError`` if the inputs could
    /// not give centers. An update (``previous``) hands what it kept to ``influences`` here.
    #[pyo3(signature = (*, with_mask = None))]
    fn result<'py>(&self, py: Python<'py>, with_mask: Option<&Bound<'py, PyAny>>) -> PyResult<Bound<'py, PyAny>> {
        guard(|| {
            let with_mask = args::or(with_mask, false, |o| args::boolean(o, "with_mask"))?;
            self.task.with_result(py, "the centers' computation", |centers| {
                if let Some(sums) = self.kept.lock().unwrap_or_else(|p| p.into_inner()).take() {
                    self.influences.bind(py).get().keep_center_sums(sums);
                }
                let flat: Vec<f32> = centers.centers.iter().flatten().copied().collect();
                let array = PyArray1::from_vec(py, flat).reshape([self.vertices, 3])?.into_any();
                if with_mask {
                    let mask = PyArray1::from_vec(py, centers.has_center.clone()).into_any();
                    Ok(pyo3::types::PyTuple::new(py, [array, mask])?.into_any())
                } else {
                    Ok(array)
                }
            })
        })
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyCentersJob>()
}

//! `centers_of_rotation_job`: Optimized Centers of Rotation computed on a thread of dqskin's own
//! that never runs Python (see `background.rs`).

use std::sync::{Arc, Mutex};

use dqskin_core::{CenterSums, Centers, Influences, PreviousCenters, SkinError};
use pyo3::prelude::*;

use crate::background::{Finish, Outcome, PyJob, Reports, Task};
use crate::guard;
use crate::skinning::{as_points, centers_output, previous_centers, skin_error, CentersArgs, PyInfluences};

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

/// A `centers_of_rotation_job`'s result and how it becomes Python objects.
struct CentersFinish {
    task: Arc<Task<Centers>>,
    /// What an update kept for the next one, until `result()` hands it to `influences`.
    kept: Arc<Mutex<Option<CenterSums>>>,
    /// The weights the centers are for.
    influences: Py<PyInfluences>,
    with_mask: bool,
}

impl Finish for CentersFinish {
    type Output = Centers;

    fn task(&self) -> &Task<Centers> {
        &self.task
    }

    fn what(&self) -> &str {
        "centers_of_rotation"
    }

    fn convert<'py>(&self, py: Python<'py>, centers: &Centers) -> PyResult<Bound<'py, PyAny>> {
        if let Some(sums) = self.kept.lock().unwrap_or_else(|p| p.into_inner()).take() {
            self.influences.bind(py).get().keep_center_sums(sums);
        }
        centers_output(py, centers, self.with_mask)
    }
}

/// :func:`centers_of_rotation` as a :class:`Job` (the same arguments but ``progress``), started
/// at once on a thread of dqskin's own that never runs Python nor holds the GIL. The arguments
/// are checked now (bad input raises here, not from ``result()``) and copied, so the caller's
/// arrays may change meanwhile. ``result()`` gives what :func:`centers_of_rotation` gives, bit
/// for bit; an update (``previous``) hands what it kept to ``influences`` then.
#[pyfunction]
#[pyo3(signature = (positions, triangles, influences, sigma = None, *, with_mask = None, previous = None))]
fn centers_of_rotation_job(
    positions: &Bound<'_, PyAny>,
    triangles: &Bound<'_, PyAny>,
    influences: &Bound<'_, PyAny>,
    sigma: Option<&Bound<'_, PyAny>>,
    with_mask: Option<&Bound<'_, PyAny>>,
    previous: Option<&Bound<'_, PyAny>>,
) -> PyResult<PyJob> {
    guard(|| {
        let CentersArgs { sigma, with_mask, influences: infl, positions: pos, triangles: tris } =
            CentersArgs::read(positions, triangles, influences, sigma, with_mask)?;
        let points = as_points(pos.as_slice()?).to_vec();
        let previous = match previous {
            Some(p) if !p.is_none() => Some(previous_centers(p, &points)?),
            _ => None,
        };
        let inputs = Inputs { positions: points, triangles: tris, influences: infl.get().0.clone(), sigma, previous };
        let before = inputs.previous.as_ref().map(|(i, c, _)| PreviousCenters { influences: i, centers: c });
        dqskin_core::check_centers_inputs(&inputs.positions, &inputs.triangles, &inputs.influences, sigma, before)
            .map_err(skin_error)?;
        let kept = Arc::new(Mutex::new(None));
        let theirs = Arc::clone(&kept);
        let task = Task::spawn("dqskin centers", move |reports| inputs.run(reports, &theirs))?;
        Ok(PyJob::new(CentersFinish { task, kept, influences: infl.unbind(), with_mask }))
    })
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(centers_of_rotation_job, m)?)
}

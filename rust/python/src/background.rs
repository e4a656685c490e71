//! Long computations on a thread of dqskin's own that never runs Python nor holds the GIL
//! (`dqskin.Job`: the centers of rotation, automatic weights, weight transfer). A host such as Blender runs its
//! own code (operators, evaluation, the UI) with the GIL released; a Python thread running then
//! is a hazard there, so the work, its progress and its cancellation live in Rust and the
//! caller polls from its own thread.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;

use crate::args;
use crate::skinning::Cancelled;

/// How a task ended.
pub(crate) enum Outcome<T> {
    Done(T),
    /// Its inputs could not give a result (the message of the `ValueError`).
    Failed(String),
    Cancelled,
    Panicked(String),
}

/// A task's progress, cancel flag and outcome, shared by its thread and its owner.
pub(crate) struct Task<T> {
    done: AtomicUsize,
    total: AtomicUsize,
    cancel: AtomicBool,
    outcome: Mutex<Option<Outcome<T>>>,
    ended: Condvar,
}

/// What a task's work gets: `progress(done, total)` (false once cancelled) and `cancelled()`.
pub(crate) struct Reports<'a, T> {
    task: &'a Task<T>,
}

impl<T> Reports<'_, T> {
    pub fn progress(&self, done: usize, total: usize) -> bool {
        self.task.total.store(total, Ordering::Relaxed);
        self.task.done.store(done, Ordering::Relaxed);
        !self.cancelled()
    }

    pub fn cancelled(&self) -> bool {
        self.task.cancel.load(Ordering::Relaxed)
    }
}

impl<T: Send + 'static> Task<T> {
    /// Starts `work` on a thread named `name`; a panic in it becomes `Outcome::Panicked`.
    pub fn spawn(name: &str, work: impl FnOnce(&Reports<'_, T>) -> Outcome<T> + Send + 'static) -> PyResult<Arc<Self>> {
        let task = Arc::new(Self {
            done: AtomicUsize::new(0),
            total: AtomicUsize::new(1),
            cancel: AtomicBool::new(false),
            outcome: Mutex::new(None),
            ended: Condvar::new(),
        });
        let theirs = Arc::clone(&task);
        std::thread::Builder::new()
            .name(name.into())
            .spawn(move || {
                let reports = Reports { task: &theirs };
                let outcome = catch_unwind(AssertUnwindSafe(|| work(&reports)))
                    .unwrap_or_else(|payload| Outcome::Panicked(crate::panic_message(payload.as_ref())));
                *theirs.outcome() = Some(outcome);
                theirs.ended.notify_all();
            })
            .map_err(|e| PyRuntimeError::new_err(format!("cannot start a thread for {name}: {e}")))?;
        Ok(task)
    }
}

impl<T: Send> Task<T> {
    fn outcome(&self) -> MutexGuard<'_, Option<Outcome<T>>> {
        self.outcome.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub fn done(&self) -> usize {
        self.done.load(Ordering::Relaxed)
    }

    pub fn total(&self) -> usize {
        self.total.load(Ordering::Relaxed).max(1)
    }

    pub fn finished(&self) -> bool {
        self.outcome().is_some()
    }

    pub fn cancel(&self) {
        self.cancel.store(true, Ordering::Relaxed);
    }

    /// Waits (the GIL released) until the thread ends or `timeout` seconds pass (None: no
    /// limit), in slices so that Ctrl-C stops the wait (not the task); returns `finished`.
    pub fn wait(&self, py: Python<'_>, timeout: Option<&Bound<'_, PyAny>>) -> PyResult<bool> {
        let timeout = match timeout {
            Some(t) if !t.is_none() => {
                let t = args::float(t, "timeout")?;
                let fits = (t >= 0.0 && t.is_finite()).then(|| Duration::try_from_secs_f32(t).ok()).flatten();
                let Some(t) = fits.filter(|t| Instant::now().checked_add(*t).is_some()) else {
                    return Err(PyValueError::new_err(format!(
                        "timeout must be a finite number of seconds >= 0 (None: no limit), got {t}"
                    )));
                };
                Some(t)
            }
            _ => None,
        };
        let deadline = timeout.map(|t| Instant::now() + t);
        loop {
            let slice = Duration::from_millis(100);
            let step = deadline.map_or(slice, |d| d.saturating_duration_since(Instant::now()).min(slice));
            let finished = py.detach(|| {
                let guard = self.outcome();
                let (guard, _) =
                    self.ended.wait_timeout_while(guard, step, |o| o.is_none()).unwrap_or_else(|p| p.into_inner());
                guard.is_some()
            });
            if finished || deadline.is_some_and(|d| Instant::now() >= d) {
                return Ok(finished);
            }
            py.check_signals()?;
        }
    }

    /// Waits for the end, then gives `read` the result: `Cancelled` if the task was cancelled
    /// (`what` names it), `ValueError` if it failed, `RuntimeError` for a panic.
    pub fn with_result<R>(&self, py: Python<'_>, what: &str, read: impl FnOnce(&T) -> PyResult<R>) -> PyResult<R> {
        self.wait(py, None)?;
        let outcome = self.outcome();
        match outcome.as_ref() {
            Some(Outcome::Done(result)) => read(result),
            Some(Outcome::Cancelled) => Err(Cancelled::new_err(format!("{what} was cancelled"))),
            Some(Outcome::Failed(e)) => Err(PyValueError::new_err(e.clone())),
            Some(Outcome::Panicked(msg)) => Err(crate::internal_error(msg)),
            None => unreachable!("wait returned before the thread ended"),
        }
    }
}

/// How a finished task's result becomes Python objects (one per kind of job).
pub(crate) trait Finish: Send + Sync {
    type Output: Send + 'static;
    fn task(&self) -> &Task<Self::Output>;
    /// What cancelling is called in its message (``automatic_weights``, ...).
    fn what(&self) -> &str;
    fn convert<'py>(&self, py: Python<'py>, result: &Self::Output) -> PyResult<Bound<'py, PyAny>>;
}

/// A [`Finish`] with its output type hidden, as the one Python class holds it.
trait AnyJob: Send + Sync {
    fn done(&self) -> usize;
    fn total(&self) -> usize;
    fn finished(&self) -> bool;
    fn cancel(&self);
    fn wait(&self, py: Python<'_>, timeout: Option<&Bound<'_, PyAny>>) -> PyResult<bool>;
    fn result<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>>;
}

impl<F: Finish> AnyJob for F {
    fn done(&self) -> usize {
        self.task().done()
    }
    fn total(&self) -> usize {
        self.task().total()
    }
    fn finished(&self) -> bool {
        self.task().finished()
    }
    fn cancel(&self) {
        self.task().cancel()
    }
    fn wait(&self, py: Python<'_>, timeout: Option<&Bound<'_, PyAny>>) -> PyResult<bool> {
        self.task().wait(py, timeout)
    }
    fn result<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.task().with_result(py, self.what(), |r| self.convert(py, r))
    }
}

/// A long computation running on a thread of dqskin's own that never runs Python nor holds
/// the GIL, started by :func:`centers_of_rotation_job`, :func:`automatic_weights_job` or
/// :func:`transfer_weights_job` (for hosts such as Blender, where a Python thread running
/// beside the host's own code is a hazard). Read ``done``/``total``, ``cancel()``, ``wait()``,
/// and take what the function would have returned with ``result()``. Dropping a running job
/// cancels it.
#[pyclass(name = "Job", module = "dqskin", frozen)]
pub struct PyJob(Box<dyn AnyJob>);

impl PyJob {
    pub(crate) fn new(finish: impl Finish + 'static) -> Self {
        Self(Box::new(finish))
    }
}

impl Drop for PyJob {
    fn drop(&mut self) {
        self.0.cancel();
    }
}

#[pymethods]
impl PyJob {
    /// Units of work done so far (of ``total``).
    #[getter]
    fn done(&self) -> usize {
        self.0.done()
    }

    /// Units of work in all (1 until the work has counted them).
    #[getter]
    fn total(&self) -> usize {
        self.0.total()
    }

    /// Whether the thread has ended (with a result, an error, or cancelled).
    #[getter]
    fn finished(&self) -> bool {
        self.0.finished()
    }

    /// Asks the thread to stop at its next step (within a fraction of a second); ``result()``
    /// then raises :class:`Cancelled` unless the work was already complete.
    fn cancel(&self) {
        self.0.cancel()
    }

    /// Waits (the GIL released) until the thread ends or ``timeout`` seconds pass (None: no
    /// limit); returns ``finished``. Ctrl-C stops the wait (``KeyboardInterrupt``), not the job.
    #[pyo3(signature = (timeout = None))]
    fn wait(&self, py: Python<'_>, timeout: Option<&Bound<'_, PyAny>>) -> PyResult<bool> {
        crate::guard(|| self.0.wait(py, timeout))
    }

    /// What the function would have returned, the same bit for bit (waits for the thread if it
    /// is still running). Raises :class:`Cancelled` if the job was cancelled, ``ValueError`` if
    /// its inputs could not give a result.
    fn result<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        crate::guard(|| self.0.result(py))
    }
}

/// A job whose work panics (tests check that the panic becomes a `RuntimeError` from
/// `result()`, never a `PanicException` nor a dead process).
struct PanickingJob(Arc<Task<()>>);

impl Finish for PanickingJob {
    type Output = ();

    fn task(&self) -> &Task<()> {
        &self.0
    }

    fn what(&self) -> &str {
        "_panicking_job_for_tests"
    }

    fn convert<'py>(&self, py: Python<'py>, _: &()) -> PyResult<Bound<'py, PyAny>> {
        Ok(py.None().into_bound(py))
    }
}

#[pyfunction]
fn _panicking_job_for_tests() -> PyResult<PyJob> {
    crate::guard(|| Ok(PyJob::new(PanickingJob(Task::spawn("dqskin test", |_| panic!("deliberate panic"))?))))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyJob>()?;
    m.add_function(wrap_pyfunction!(_panicking_job_for_tests, m)?)
}

//! One skinning's arguments, checked in one place for `skin()` and for `SkinJob`, the typed job
//! a caller keeps (one per mesh) and runs many at a time with `skin_many()`.

use dqskin_core::glam::Mat4;
use dqskin_core::{ManyJob, SkinOptions};
use numpy::{PyReadonlyArrayDyn, PyReadwriteArrayDyn, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PySequence;

use crate::args;
use crate::arrays::{self, Shape};
use crate::blender::PyMeshPositions;
use crate::guard;
use crate::method::PyMethod;
use crate::skinning::{as_points, as_points_mut, matrices, skin_error, space, PyInfluences};

/// The arguments of one skinning, as given (`None` for an argument left out or passed as None).
struct Args<'py> {
    method: PyMethod,
    positions: Bound<'py, PyAny>,
    influences: Bound<'py, PyInfluences>,
    deform: Bound<'py, PyAny>,
    rest: Option<Bound<'py, PyAny>>,
    premat: Option<Bound<'py, PyAny>>,
    postmat: Option<Bound<'py, PyAny>>,
    mask: Option<Bound<'py, PyAny>>,
    blend: Option<Bound<'py, PyAny>>,
    blend_factor: f32,
    centers: Option<Bound<'py, PyAny>>,
    out: Bound<'py, PyAny>,
}

/// The arguments checked and borrowed for one run: the inputs read-only, `out` writable (so an
/// `out` that overlaps an input is refused), the small matrices converted.
struct Borrowed<'py> {
    method: PyMethod,
    influences: Bound<'py, PyInfluences>,
    positions: Points<'py>,
    deform: Vec<Mat4>,
    rest: Option<Vec<Mat4>>,
    premat: Option<Mat4>,
    postmat: Option<Mat4>,
    mask: Option<PyReadonlyArrayDyn<'py, f32>>,
    blend: Option<PyReadonlyArrayDyn<'py, f32>>,
    blend_factor: f32,
    centers: Option<PyReadonlyArrayDyn<'py, f32>>,
    out: PyReadwriteArrayDyn<'py, f32>,
}

/// The positions a run reads: an array, or a mesh's own in Blender's memory
/// (`dqskin.memory.MeshPositions`), found for this run (or why they could not be).
enum Points<'py> {
    Array(PyReadonlyArrayDyn<'py, f32>),
    InBlender(Result<&'py [[f32; 3]], String>),
}

/// `positions` (an array or a `MeshPositions`) for a run over `v` vertices.
fn points<'py>(obj: &Bound<'py, PyAny>, v: usize) -> PyResult<Points<'py>> {
    let Ok(handle) = obj.cast::<PyMeshPositions>() else {
        return Ok(Points::Array(per_vertex(obj, "positions", &[Some(v), Some(3)], v)?));
    };
    let handle = handle.get();
    if handle.vertex_count() != v {
        return Err(PyValueError::new_err(format!(
            "positions: a mesh of {} vertices (influences has {v} vertices)",
            handle.vertex_count()
        )));
    }
    // SAFETY: the slice lives in a `Borrowed`, which lives only for the call that made it (a
    // `skin`, `skin_many` or `SkinJob` call made from Python while Blender waits on it).
    let found = unsafe { handle.resolve(obj.py()) };
    Ok(Points::InBlender(found.map_err(|e| e.value(obj.py()).to_string())))
}

fn given<'py>(obj: Option<&Bound<'py, PyAny>>) -> Option<Bound<'py, PyAny>> {
    obj.filter(|o| !o.is_none()).cloned()
}

/// `checked`, with a refused shape of an array whose rows follow the influences also saying how
/// many the influences have (they may be the argument that is wrong).
pub(crate) fn sized_by_influences<T>(
    obj: &Bound<'_, PyAny>,
    rows: usize,
    what: &str,
    checked: PyResult<T>,
) -> PyResult<T> {
    checked.map_err(|e| {
        let py = obj.py();
        let first = obj.cast::<PyUntypedArray>().ok().and_then(|a| a.shape().first().copied());
        if e.is_instance_of::<PyValueError>(py) && first.is_some_and(|n| n != rows) {
            PyValueError::new_err(format!("{} (influences has {rows} {what})", e.value(py)))
        } else {
            e
        }
    })
}

/// A float32 array with one row per vertex of the influences (`v`), borrowed read-only.
fn per_vertex<'py>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    shape: Shape<'_>,
    v: usize,
) -> PyResult<PyReadonlyArrayDyn<'py, f32>> {
    sized_by_influences(obj, v, "vertices", arrays::readonly::<f32>(obj, name, shape, &["V"]))
}

/// One finite 4×4 matrix per bone of the influences (`b`).
fn per_bone(obj: &Bound<'_, PyAny>, name: &str, b: usize) -> PyResult<Vec<Mat4>> {
    sized_by_influences(obj, b, "bones", matrices(obj, name, Some(b)))
}

impl<'py> Args<'py> {
    /// The arguments of a `skin()` or `SkinJob()` call; `out` is allocated if not given.
    #[allow(clippy::too_many_arguments)]
    fn from_call(
        positions: &Bound<'py, PyAny>,
        influences: &Bound<'py, PyAny>,
        deform: &Bound<'py, PyAny>,
        rest: Option<&Bound<'py, PyAny>>,
        method: Option<&Bound<'py, PyAny>>,
        blend: Option<&Bound<'py, PyAny>>,
        blend_factor: Option<&Bound<'py, PyAny>>,
        premat: Option<&Bound<'py, PyAny>>,
        postmat: Option<&Bound<'py, PyAny>>,
        mask: Option<&Bound<'py, PyAny>>,
        out: Option<&Bound<'py, PyAny>>,
        centers: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Self> {
        let method = args::or(method, PyMethod::DualQuaternion, |o| PyMethod::from_arg(o, "method"))?;
        let blend_factor = args::or(blend_factor, 1.0, |o| args::float(o, "blend_factor"))?;
        let influences = influences.cast::<PyInfluences>().map_err(|_| {
            let ty = influences.get_type().name().map(|n| n.to_string()).unwrap_or_default();
            PyTypeError::new_err(format!(
                "influences must be a dqskin.Influences (build one from CSR arrays once and reuse it), got {ty}"
            ))
        })?;
        let out = match given(out) {
            Some(o) => o,
            None => {
                let v = influences.get().0.vertex_count();
                numpy::PyArray2::<f32>::zeros(positions.py(), [v, 3], false).into_any()
            }
        };
        Ok(Self {
            method,
            positions: positions.clone(),
            influences: influences.clone(),
            deform: deform.clone(),
            rest: given(rest),
            premat: given(premat),
            postmat: given(postmat),
            mask: given(mask),
            blend: given(blend),
            blend_factor,
            centers: given(centers),
            out,
        })
    }

    /// Checks every argument against the influences (errors name the argument) and borrows the
    /// arrays for a run.
    fn borrow(&self) -> PyResult<Borrowed<'py>> {
        let infl = &self.influences.get().0;
        let (v, b) = (infl.vertex_count(), infl.bone_count());
        let method = self.method;
        let positions = points(&self.positions, v)?;
        let deform = per_bone(&self.deform, "deform", b)?;
        let rest = self.rest.as_ref().map(|r| per_bone(r, "rest", b)).transpose()?;
        if method != PyMethod::Linear && rest.is_none() {
            return Err(PyValueError::new_err(format!(
                "rest is required for method='{}': the (B, 4, 4) rest matrices (Bone.matrix_local); only method='linear' takes rest=None",
                method.key()
            )));
        }
        let premat = space(self.premat.as_ref(), "premat")?;
        let postmat = space(self.postmat.as_ref(), "postmat")?;
        let mask = self.mask.as_ref().map(|m| per_vertex(m, "mask", &[Some(v)], v)).transpose()?;
        let blend = self.blend.as_ref().map(|m| per_vertex(m, "blend", &[Some(v)], v)).transpose()?;
        if method != PyMethod::Blend && blend.is_some() {
            return Err(PyValueError::new_err("blend is only used with method='blend'"));
        }
        let centers = match (&self.centers, method == PyMethod::CentersOfRotation) {
            (Some(c), true) => {
                let a = per_vertex(c, "centers", &[Some(v), Some(3)], v)?;
                arrays::check_finite("centers", a.as_slice()?)?;
                Some(a)
            }
            (None, true) => {
                return Err(PyValueError::new_err(
                    "centers is required for method='centers_of_rotation': the (V, 3) float32 array from dqskin.centers_of_rotation()",
                ))
            }
            (Some(_), false) => return Err(PyValueError::new_err("centers is only used with method='centers_of_rotation'")),
            (None, false) => None,
        };
        if self.out.is_none() {
            return Err(PyValueError::new_err(
                "out is not set: give the job the (V, 3) float32 array to write (job.out = ...) before it runs",
            ));
        }
        let out = sized_by_influences(
            &self.out,
            v,
            "vertices",
            arrays::readwrite::<f32>(&self.out, "out", &[Some(v), Some(3)], &["V"]),
        )?;
        Ok(Borrowed {
            method,
            influences: self.influences.clone(),
            positions,
            deform,
            rest,
            premat,
            postmat,
            mask,
            blend,
            blend_factor: self.blend_factor,
            centers,
            out,
        })
    }
}

/// Whether `out`'s bytes overlap `points`' (numpy refuses an `out` that overlaps an input array;
/// Blender's memory is checked here).
fn overlaps(points: &[[f32; 3]], out: &PyReadwriteArrayDyn<'_, f32>) -> bool {
    let Ok(o) = out.as_slice() else { return false }; // (not contiguous: refused when borrowed)
    let (a, o) = (points.as_flattened().as_ptr_range(), o.as_ptr_range());
    a.start < o.end && o.start < a.end
}

fn slice<'a>(a: &'a Option<PyReadonlyArrayDyn<'_, f32>>) -> PyResult<Option<&'a [f32]>> {
    Ok(a.as_ref().map(|a| a.as_slice()).transpose()?)
}

impl Borrowed<'_> {
    /// Why this run cannot read its positions (a mesh gone or changed since the job was made),
    /// or None.
    fn missing(&self) -> Option<String> {
        match &self.positions {
            Points::InBlender(Err(e)) => Some(e.clone()),
            Points::InBlender(Ok(p)) if overlaps(p, &self.out) => Some("out overlaps the positions".into()),
            _ => None,
        }
    }

    /// The core's job over the borrowed arrays (`missing()` is None).
    fn job(&mut self) -> PyResult<ManyJob<'_>> {
        let centers = slice(&self.centers)?.map(as_points);
        let positions = match &self.positions {
            Points::Array(a) => as_points(a.as_slice()?),
            Points::InBlender(Ok(p)) => p,
            Points::InBlender(Err(e)) => return Err(PyValueError::new_err(e.clone())),
        };
        Ok(ManyJob {
            method: self.method.core(slice(&self.blend)?, self.blend_factor, centers),
            positions,
            influences: &self.influences.get().0,
            deform: &self.deform,
            rest: self.rest.as_deref(),
            options: SkinOptions { premat: self.premat, postmat: self.postmat, mask: slice(&self.mask)? },
            out: as_points_mut(self.out.as_slice_mut()?),
        })
    }
}

/// Skins ``positions`` (``(V, 3)`` float32) and returns the result (``out`` if given).
///
/// - ``influences``: an :class:`Influences` for the same ``V`` vertices.
/// - ``deform``: ``(B, 4, 4)`` float32, each bone's posed matrix times the inverse of its rest
///   matrix in armature space (Blender's ``PoseBone.matrix_channel``), row-major.
/// - ``rest``: ``(B, 4, 4)`` float32 rest matrices (``Bone.matrix_local``); a required argument,
///   which may be None only with ``method='linear'`` (Blender's scale path for every other method
///   depends on them, so there is no default that would be right).
/// - ``method``: a :class:`Method` or its name (default ``Method.DUAL_QUATERNION``):
///   ``'linear'`` (Preserve Volume off), ``'dual_quaternion'`` (on), ``'blend'``:
///   ``(1−α)·linear + α·dual_quaternion`` with ``α = blend_factor · blend[v]`` (or
///   ``blend_factor`` alone without ``blend``); all in ``[0, 1]``; or
///   ``'centers_of_rotation'`` (Le & Hodgins 2016) with ``centers``, the ``(V, 3)`` float32
///   array from :func:`centers_of_rotation`. Names are case-insensitive; ``'lbs'``, ``'dqs'``,
///   ``'cor'`` and the labels (``'Optimized Centers'``, ...) work too.
/// - ``premat``/``postmat``: 4×4 mesh→armature and armature→mesh transforms (identity if None).
/// - ``mask``: ``(V,)`` float32 per-vertex strength in ``[0, 1]``; 0 leaves a vertex unchanged.
/// - ``out``: optional ``(V, 3)`` float32 C-contiguous buffer that does not overlap the inputs.
///
/// The GIL is released while the kernel runs on dqskin's thread pool.
#[pyfunction]
#[pyo3(signature = (positions, influences, deform, rest, *, method = None,
    blend = None, blend_factor = None, premat = None, postmat = None, mask = None, out = None, centers = None))]
#[allow(clippy::too_many_arguments)]
fn skin<'py>(
    positions: &Bound<'py, PyAny>,
    influences: &Bound<'py, PyAny>,
    deform: &Bound<'py, PyAny>,
    rest: Option<&Bound<'py, PyAny>>,
    method: Option<&Bound<'py, PyAny>>,
    blend: Option<&Bound<'py, PyAny>>,
    blend_factor: Option<&Bound<'py, PyAny>>,
    premat: Option<&Bound<'py, PyAny>>,
    postmat: Option<&Bound<'py, PyAny>>,
    mask: Option<&Bound<'py, PyAny>>,
    out: Option<&Bound<'py, PyAny>>,
    centers: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    guard(|| {
        let args = Args::from_call(
            positions,
            influences,
            deform,
            rest,
            method,
            blend,
            blend_factor,
            premat,
            postmat,
            mask,
            out,
            centers,
        )?;
        let mut borrowed = args.borrow()?;
        if let Some(e) = borrowed.missing() {
            return Err(PyValueError::new_err(e));
        }
        let mut job = borrowed.job()?;
        let result = positions.py().detach(|| dqskin_core::skin_many(std::slice::from_mut(&mut job)));
        result.into_iter().next().unwrap_or(Ok(())).map_err(skin_error)?;
        Ok(args.out)
    })
}

/// One mesh's skinning, kept by the caller and run (with others) by :func:`skin_many`.
///
/// Built with the arguments of :func:`skin` and checked then, against the influences, with
/// errors naming the argument; ``out`` is allocated when not given. The job keeps references to
/// its arrays and reads them when it runs, so they may be filled in place between runs. The
/// inputs that change every frame, ``positions``, ``deform``, ``premat`` and ``postmat``, and the
/// ``out`` array, can be replaced (``job.deform = ...``), checked the same way (a refused value leaves the job as it
/// was); everything is checked again when the job runs. Values the kernel checks (mask and blend
/// amounts and ``blend_factor`` in ``[0, 1]``, premat/postmat affine, every bone matrix usable)
/// make that job's entry of :func:`skin_many` an error message.
#[pyclass(name = "SkinJob", module = "dqskin")]
pub struct SkinJob {
    method: PyMethod,
    positions: Py<PyAny>,
    influences: Py<PyInfluences>,
    deform: Py<PyAny>,
    rest: Option<Py<PyAny>>,
    premat: Option<Py<PyAny>>,
    postmat: Option<Py<PyAny>>,
    mask: Option<Py<PyAny>>,
    blend: Option<Py<PyAny>>,
    blend_factor: f32,
    centers: Option<Py<PyAny>>,
    out: Py<PyAny>,
}

impl SkinJob {
    fn keep(a: Args<'_>) -> Self {
        let keep = |o: Option<Bound<'_, PyAny>>| o.map(Bound::unbind);
        Self {
            method: a.method,
            positions: a.positions.unbind(),
            influences: a.influences.unbind(),
            deform: a.deform.unbind(),
            rest: keep(a.rest),
            premat: keep(a.premat),
            postmat: keep(a.postmat),
            mask: keep(a.mask),
            blend: keep(a.blend),
            blend_factor: a.blend_factor,
            centers: keep(a.centers),
            out: a.out.unbind(),
        }
    }

    fn args<'py>(&self, py: Python<'py>) -> Args<'py> {
        let bind = |o: &Option<Py<PyAny>>| o.as_ref().map(|o| o.bind(py).clone());
        Args {
            method: self.method,
            positions: self.positions.bind(py).clone(),
            influences: self.influences.bind(py).clone(),
            deform: self.deform.bind(py).clone(),
            rest: bind(&self.rest),
            premat: bind(&self.premat),
            postmat: bind(&self.postmat),
            mask: bind(&self.mask),
            blend: bind(&self.blend),
            blend_factor: self.blend_factor,
            centers: bind(&self.centers),
            out: self.out.bind(py).clone(),
        }
    }

    fn counts(&self, py: Python<'_>) -> (usize, usize) {
        let infl = &self.influences.bind(py).get().0;
        (infl.vertex_count(), infl.bone_count())
    }
}

fn optional<'py>(o: Option<&Py<PyAny>>, py: Python<'py>) -> Bound<'py, PyAny> {
    o.map_or_else(|| py.None().into_bound(py), |o| o.bind(py).clone())
}

#[pymethods]
impl SkinJob {
    #[new]
    #[pyo3(signature = (positions, influences, deform, rest, *, method = None,
        blend = None, blend_factor = None, premat = None, postmat = None, mask = None, out = None, centers = None))]
    #[allow(clippy::too_many_arguments)]
    fn new<'py>(
        positions: &Bound<'py, PyAny>,
        influences: &Bound<'py, PyAny>,
        deform: &Bound<'py, PyAny>,
        rest: Option<&Bound<'py, PyAny>>,
        method: Option<&Bound<'py, PyAny>>,
        blend: Option<&Bound<'py, PyAny>>,
        blend_factor: Option<&Bound<'py, PyAny>>,
        premat: Option<&Bound<'py, PyAny>>,
        postmat: Option<&Bound<'py, PyAny>>,
        mask: Option<&Bound<'py, PyAny>>,
        out: Option<&Bound<'py, PyAny>>,
        centers: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Self> {
        guard(|| {
            let args = Args::from_call(
                positions,
                influences,
                deform,
                rest,
                method,
                blend,
                blend_factor,
                premat,
                postmat,
                mask,
                out,
                centers,
            )?;
            if let Some(e) = args.borrow()?.missing() {
                return Err(PyValueError::new_err(e));
            }
            Ok(Self::keep(args))
        })
    }

    #[getter]
    fn method(&self) -> PyMethod {
        self.method
    }

    /// ``(V, 3)`` float32 positions, or a ``dqskin.memory.MeshPositions`` (settable).
    #[getter]
    fn positions(&self, py: Python<'_>) -> Py<PyAny> {
        self.positions.clone_ref(py)
    }

    #[setter]
    fn set_positions(&mut self, py: Python<'_>, value: Bound<'_, PyAny>) -> PyResult<()> {
        guard(|| {
            let (v, _) = self.counts(py);
            if let Points::InBlender(Err(e)) = points(&value, v)? {
                return Err(PyValueError::new_err(e));
            }
            self.positions = value.unbind();
            Ok(())
        })
    }

    #[getter]
    fn influences(&self, py: Python<'_>) -> Py<PyInfluences> {
        self.influences.clone_ref(py)
    }

    /// ``(B, 4, 4)`` float32 deform matrices (settable).
    #[getter]
    fn deform(&self, py: Python<'_>) -> Py<PyAny> {
        self.deform.clone_ref(py)
    }

    #[setter]
    fn set_deform(&mut self, py: Python<'_>, value: Bound<'_, PyAny>) -> PyResult<()> {
        guard(|| {
            let (_, b) = self.counts(py);
            per_bone(&value, "deform", b)?;
            self.deform = value.unbind();
            Ok(())
        })
    }

    #[getter]
    fn rest<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        optional(self.rest.as_ref(), py)
    }

    /// Mesh to armature space, or None for the identity (settable).
    #[getter]
    fn premat<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        optional(self.premat.as_ref(), py)
    }

    #[setter]
    fn set_premat(&mut self, value: Bound<'_, PyAny>) -> PyResult<()> {
        guard(|| {
            space(Some(&value), "premat")?;
            self.premat = given(Some(&value)).map(Bound::unbind);
            Ok(())
        })
    }

    /// Armature to mesh space, or None for the identity (settable).
    #[getter]
    fn postmat<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        optional(self.postmat.as_ref(), py)
    }

    #[setter]
    fn set_postmat(&mut self, value: Bound<'_, PyAny>) -> PyResult<()> {
        guard(|| {
            space(Some(&value), "postmat")?;
            self.postmat = given(Some(&value)).map(Bound::unbind);
            Ok(())
        })
    }

    #[getter]
    fn mask<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        optional(self.mask.as_ref(), py)
    }

    #[getter]
    fn blend<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        optional(self.blend.as_ref(), py)
    }

    #[getter]
    fn blend_factor(&self) -> f32 {
        self.blend_factor
    }

    #[getter]
    fn centers<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        optional(self.centers.as_ref(), py)
    }

    /// The ``(V, 3)`` float32 array the result is written to (settable: a writable,
    /// C-contiguous array of the same shape, such as a view of memory the caller owns; or None
    /// between runs, so that the job keeps no array: set it again before the job runs).
    #[getter]
    fn out(&self, py: Python<'_>) -> Py<PyAny> {
        self.out.clone_ref(py)
    }

    #[setter]
    fn set_out(&mut self, py: Python<'_>, value: Bound<'_, PyAny>) -> PyResult<()> {
        guard(|| {
            if value.is_none() {
                self.out = value.unbind();
                return Ok(());
            }
            let (v, _) = self.counts(py);
            let checked = arrays::readwrite::<f32>(&value, "out", &[Some(v), Some(3)], &["V"]).map(drop);
            sized_by_influences(&value, v, "vertices", checked)?;
            self.out = value.unbind();
            Ok(())
        })
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let infl = &self.influences.bind(py).get().0;
        format!(
            "SkinJob(method=Method.{}, vertices={}, bones={})",
            self.method.key().to_uppercase(),
            infl.vertex_count(),
            infl.bone_count()
        )
    }
}

/// Runs many :class:`SkinJob` at once, in parallel across meshes: for scenes with many small
/// characters. ``jobs`` is a sequence of ``SkinJob``. Returns one entry per job: None, or the
/// error message of a job that failed (its ``out`` untouched). A job whose arrays no longer
/// pass its checks (reshaped in place, or sharing an ``out`` with another job) raises at once,
/// naming the job and the argument, before any job runs. The GIL is released while they run.
///
/// ``share_from``: the least number of vertices, over all the jobs, for which the call shares
/// its work with the pool's threads; below it the calling thread runs every job alone (None:
/// it always shares). Inside a host's own multithreaded evaluation (Blender's, whose threads
/// hold the other cores) waking a helper costs more than it gains on small meshes.
#[pyfunction]
#[pyo3(signature = (jobs, *, share_from=None))]
fn skin_many<'py>(
    py: Python<'py>,
    jobs: &Bound<'py, PyAny>,
    share_from: Option<&Bound<'py, PyAny>>,
) -> PyResult<Vec<Option<String>>> {
    guard(|| {
        let share_from = match share_from.filter(|s| !s.is_none()) {
            Some(s) => crate::args::int(s, "share_from", 0, i64::MAX)? as usize,
            None => 0,
        };
        let jobs = jobs.cast::<PySequence>().map_err(|_| {
            let ty = jobs.get_type().name().map(|n| n.to_string()).unwrap_or_default();
            PyTypeError::new_err(format!("jobs must be a list of dqskin.SkinJob, got {ty}"))
        })?;
        let count = jobs.len()?;
        let mut borrowed = Vec::with_capacity(count);
        for i in 0..count {
            let item = jobs.get_item(i)?;
            let job = item.cast::<SkinJob>().map_err(|_| {
                let ty = item.get_type().name().map(|n| n.to_string()).unwrap_or_default();
                PyTypeError::new_err(format!("jobs[{i}] must be a dqskin.SkinJob, got {ty}"))
            })?;
            let args = job.borrow().args(py);
            borrowed.push(args.borrow().map_err(|e| naming_the_job(py, i, e))?);
        }
        // A job whose mesh is gone or changed since it was made fails alone, as a kernel error would.
        let mut entries: Vec<Option<String>> = borrowed.iter().map(Borrowed::missing).collect();
        let runs: Vec<usize> = (0..count).filter(|&i| entries[i].is_none()).collect();
        let mut many = borrowed
            .iter_mut()
            .zip(&entries)
            .filter(|(_, e)| e.is_none())
            .map(|(b, _)| b.job())
            .collect::<PyResult<Vec<_>>>()?;
        let vertices: usize = many.iter().map(|j| j.positions.len()).sum();
        let results = py.detach(|| {
            if vertices < share_from {
                dqskin_core::pool::alone(|| dqskin_core::skin_many(&mut many))
            } else {
                dqskin_core::skin_many(&mut many)
            }
        });
        for (i, r) in runs.into_iter().zip(results) {
            entries[i] = r.err().map(|e| e.to_string());
        }
        Ok(entries)
    })
}

/// `e` with `jobs[i]: ` before its message, of the same kind.
fn naming_the_job(py: Python<'_>, i: usize, e: PyErr) -> PyErr {
    let msg = format!("jobs[{i}]: {}", e.value(py));
    if e.is_instance_of::<PyTypeError>(py) {
        PyTypeError::new_err(msg)
    } else {
        PyValueError::new_err(msg)
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyMethod>()?;
    m.add_class::<SkinJob>()?;
    m.add_function(wrap_pyfunction!(skin, m)?)?;
    m.add_function(wrap_pyfunction!(skin_many, m)?)?;
    Ok(())
}

//! Skin weights: `automatic_weights` (geodesic voxel binding) and `transfer_weights` (closest
//! points and inpainting), over `dqskin_core::weights`.

use std::sync::Arc;

use dqskin_core::weights::{self, AutoOptions, AutoWeights, Bone, TransferOptions, Transferred, WeightsError};
use dqskin_core::Influences;
use numpy::{PyArray1, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString, PyTuple};

use crate::args;
use crate::arrays;
use crate::background::{Finish, Outcome, PyJob, Task};
use crate::guard;
use crate::skinning::{as_points, named_triangle_indices, triangle_indices, Cancelled, PyInfluences};

fn weights_error(e: WeightsError) -> PyErr {
    match e {
        WeightsError::Cancelled => Cancelled::new_err("cancelled by the progress callback"),
        e => PyValueError::new_err(e.to_string()),
    }
}

/// Runs `work` without the GIL, giving it a progress function that takes the GIL back to check
/// Ctrl-C and to call `callback(done, total)` (returning ``False`` stops the work).
fn with_progress<T: Send>(
    py: Python<'_>,
    callback: Option<&Bound<'_, PyAny>>,
    what: &str,
    work: impl FnOnce(&mut dyn FnMut(usize, usize) -> bool) -> Result<T, WeightsError> + Send,
) -> PyResult<T> {
    let callback = crate::args::progress_callback(callback)?;
    let stopped: std::sync::Mutex<Option<PyErr>> = std::sync::Mutex::new(None);
    let stop = |e: PyErr| {
        *stopped.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
        false
    };
    let result = py.detach(|| {
        let mut progress = |done: usize, total: usize| {
            Python::attach(|py| {
                if let Err(e) = py.check_signals() {
                    return stop(e);
                }
                let Some(cb) = &callback else { return true };
                match cb.bind(py).call1((done, total)) {
                    Ok(r) if r.is_instance_of::<pyo3::types::PyBool>() && !r.is_truthy().unwrap_or(true) => {
                        stop(Cancelled::new_err(format!("{what} was cancelled by its progress callback")))
                    }
                    Ok(_) => true,
                    Err(e) => stop(e),
                }
            })
        };
        work(&mut progress)
    });
    if let Some(e) = stopped.into_inner().unwrap_or_else(|p| p.into_inner()) {
        return Err(e);
    }
    result.map_err(weights_error)
}

fn names(obj: &Bound<'_, PyAny>, what: &str, count: usize) -> PyResult<Vec<String>> {
    if obj.is_instance_of::<PyString>() {
        return Err(PyTypeError::new_err(format!("{what} must be a sequence of bone names, got a string")));
    }
    let list: Vec<Bound<'_, PyAny>> = obj
        .try_iter()
        .map_err(|_| PyTypeError::new_err(format!("{what} must be a sequence of bone names")))?
        .collect::<PyResult<_>>()?;
    if list.len() != count {
        return Err(PyValueError::new_err(format!("{what} must name the {count} bones, got {} names", list.len())));
    }
    list.iter().enumerate().map(|(i, n)| args::string(n, &format!("{what}[{i}]"))).collect()
}

/// Automatic skin weights of a rest mesh for bones given as segments (geodesic voxel binding,
/// Dionne & de Lasa 2013): the mesh is voxelized (inside found by a flood fill from outside, so
/// open, intersecting and multi-part meshes work), each voxel's nearest bones found by shortest
/// paths through the solid, and each vertex weighted by the falloff
/// ``1 / ((1 − falloff)·d + falloff·d²)²`` of its distances (``d`` a fraction of the bounding-box
/// diagonal) to at most ``max_influences`` bones, normalized. A vertex that no bone reaches (a
/// loose part away from every bone) takes its nearest bones in straight lines.
///
/// - ``positions`` ``(V, 3)`` float32, ``triangles`` ``(T, 3)`` integers;
/// - ``heads``, ``tails`` ``(B, 3)`` float32: the bones' segments, in the positions' space;
/// - ``resolution``: voxels along the bounding box's longest side (16 to 512, default 128);
/// - ``falloff`` in [0, 1] (default 0.2); ``max_influences`` 1 to 16 (default 4);
/// - ``smoothing``: smoothing passes over the mesh (default 0);
/// - ``mirror``: the bones' names, to mirror the weights across X = 0 (``hand.L`` ↔ ``hand.R``);
/// - ``progress``: called as ``progress(done, total)``; returning ``False`` stops with
///   :class:`Cancelled`.
///
/// Returns ``(influences, report)``: :class:`Influences` over the ``B`` bones, and a dict with
/// ``unreached`` (vertices weighted to their nearest bones in straight lines), ``outside_bones``
/// (bones crossing no solid voxel: they reach the mesh in straight lines), ``grid`` and
/// ``solid_voxels``. A resolution that would need more than 1 GB is refused (``ValueError``).
#[pyfunction]
#[pyo3(signature = (positions, triangles, heads, tails, *, resolution = None, falloff = None, max_influences = None,
    smoothing = None, mirror = None, progress = None))]
#[allow(clippy::too_many_arguments)]
fn automatic_weights<'py>(
    positions: &Bound<'py, PyAny>,
    triangles: &Bound<'py, PyAny>,
    heads: &Bound<'py, PyAny>,
    tails: &Bound<'py, PyAny>,
    resolution: Option<&Bound<'py, PyAny>>,
    falloff: Option<&Bound<'py, PyAny>>,
    max_influences: Option<&Bound<'py, PyAny>>,
    smoothing: Option<&Bound<'py, PyAny>>,
    mirror: Option<&Bound<'py, PyAny>>,
    progress: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    guard(|| {
        let py = positions.py();
        let request = AutoRequest::new(
            positions,
            triangles,
            heads,
            tails,
            resolution,
            falloff,
            max_influences,
            smoothing,
            mirror,
        )?;
        let result = with_progress(py, progress, "automatic_weights", |p| request.run(p))?;
        auto_output(py, &result)
    })
}

/// `automatic_weights`' arguments, checked and owned (a job's thread takes them).
struct AutoRequest {
    positions: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
    bones: Vec<Bone>,
    options: AutoOptions,
}

impl AutoRequest {
    #[allow(clippy::too_many_arguments)]
    fn new(
        positions: &Bound<'_, PyAny>,
        triangles: &Bound<'_, PyAny>,
        heads: &Bound<'_, PyAny>,
        tails: &Bound<'_, PyAny>,
        resolution: Option<&Bound<'_, PyAny>>,
        falloff: Option<&Bound<'_, PyAny>>,
        max_influences: Option<&Bound<'_, PyAny>>,
        smoothing: Option<&Bound<'_, PyAny>>,
        mirror: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let defaults = AutoOptions::default();
        let resolution = args::or(resolution, defaults.resolution as i64, |o| {
            args::int(o, "resolution", weights::MIN_RESOLUTION as i64, weights::MAX_RESOLUTION as i64)
        })? as usize;
        let falloff = args::or(falloff, defaults.falloff, |o| args::float_in(o, "falloff", 0.0, 1.0))?;
        let max_influences = args::or(max_influences, defaults.max_influences as i64, |o| {
            args::int(o, "max_influences", 1, weights::MAX_WEIGHT_INFLUENCES as i64)
        })? as usize;
        let smoothing = args::or(smoothing, 0, |o| args::int(o, "smoothing", 0, 1000))? as u32;
        let pos = arrays::readonly::<f32>(positions, "positions", &[None, Some(3)], &["V"])?;
        let tris = triangle_indices(triangles)?;
        let h = arrays::readonly::<f32>(heads, "heads", &[None, Some(3)], &["B"])?;
        let b = h.shape()[0];
        let t = arrays::readonly::<f32>(tails, "tails", &[None, Some(3)], &["B"])?;
        if t.shape()[0] != b {
            return Err(PyValueError::new_err(format!(
                "heads and tails must have one row per bone each: heads has {b}, tails {}",
                t.shape()[0]
            )));
        }
        for (name, points) in [("heads", as_points(h.as_slice()?)), ("tails", as_points(t.as_slice()?))] {
            if let Some(i) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
                return Err(PyValueError::new_err(format!("{name}[{i}] has a NaN or infinite coordinate")));
            }
        }
        let bones: Vec<Bone> = as_points(h.as_slice()?)
            .iter()
            .zip(as_points(t.as_slice()?))
            .map(|(&head, &tail)| Bone { head, tail })
            .collect();
        let mirror = match mirror {
            Some(m) if !m.is_none() => {
                let names = names(m, "mirror", b)?;
                let refs: Vec<&str> = names.iter().map(String::as_str).collect();
                Some(weights::mirror_bone_map(&refs))
            }
            _ => None,
        };
        let options = AutoOptions { resolution, falloff, max_influences, smoothing, mirror };
        Ok(Self { positions: as_points(pos.as_slice()?).to_vec(), triangles: tris, bones, options })
    }

    fn run(&self, progress: &mut dyn FnMut(usize, usize) -> bool) -> Result<AutoWeights, WeightsError> {
        weights::automatic_weights(&self.positions, &self.triangles, &self.bones, &self.options, progress)
    }
}

/// `(influences, report)` as `automatic_weights` returns them.
fn auto_output<'py>(py: Python<'py>, result: &AutoWeights) -> PyResult<Bound<'py, PyTuple>> {
    let report = PyDict::new(py);
    report.set_item("unreached", result.unreached)?;
    report.set_item("outside_bones", PyArray1::from_vec(py, result.outside_bones.clone()))?;
    report.set_item("grid", PyTuple::new(py, result.grid)?)?;
    report.set_item("solid_voxels", result.solid_voxels)?;
    let influences = Bound::new(py, PyInfluences::wrap(result.influences.clone()))?;
    PyTuple::new(py, [influences.into_any(), report.into_any()])
}

/// Transfers skin weights from a body to clothing (Abdrashitov et al., "Robust Skin Weights
/// Transfer via Weight Inpainting", 2023): each clothing vertex whose closest point on the
/// body's surface is within ``max_distance`` and whose normal is within ``max_angle`` degrees of
/// the body's there takes the body's weights at that point (barycentric); the others are filled
/// by minimizing a Laplacian energy with the matched ones fixed. A loose part with no match
/// takes the weights of the matched vertex nearest to it. Then at most ``max_influences`` bones
/// per vertex, normalized.
///
/// - ``body_positions`` ``(Vb, 3)``, ``body_triangles`` ``(Tb, 3)``, ``body_influences``
///   (:class:`Influences` of the ``Vb`` vertices; each vertex's weights are normalized first);
/// - ``cloth_positions`` ``(Vc, 3)``, ``cloth_triangles`` ``(Tc, 3)``, in the body's space;
/// - ``max_distance`` (default: 5 % of the clothing's bounding-box diagonal, as the paper),
///   ``max_angle`` (default 30), ``flipped_normals`` (also match opposite normals, default
///   False), ``smoothing`` passes over the filled vertices (default 0), ``max_influences``
///   (default 4), ``progress`` as in :func:`automatic_weights`.
///
/// Returns ``(influences, report)``: :class:`Influences` over the body's bones, and a dict with
/// ``matched`` (``(Vc,)`` bool), ``matched_count``, ``inpainted``, ``from_nearest`` (vertices of
/// loose parts with no match), ``max_distance`` (the threshold used) and ``iterations``.
#[pyfunction]
#[pyo3(signature = (body_positions, body_triangles, body_influences, cloth_positions, cloth_triangles, *,
    max_distance = None, max_angle = None, flipped_normals = None, smoothing = None, max_influences = None, progress = None))]
#[allow(clippy::too_many_arguments)]
fn transfer_weights<'py>(
    body_positions: &Bound<'py, PyAny>,
    body_triangles: &Bound<'py, PyAny>,
    body_influences: &Bound<'py, PyAny>,
    cloth_positions: &Bound<'py, PyAny>,
    cloth_triangles: &Bound<'py, PyAny>,
    max_distance: Option<&Bound<'py, PyAny>>,
    max_angle: Option<&Bound<'py, PyAny>>,
    flipped_normals: Option<&Bound<'py, PyAny>>,
    smoothing: Option<&Bound<'py, PyAny>>,
    max_influences: Option<&Bound<'py, PyAny>>,
    progress: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    guard(|| {
        let py = body_positions.py();
        let request = TransferRequest::new(
            body_positions,
            body_triangles,
            body_influences,
            cloth_positions,
            cloth_triangles,
            max_distance,
            max_angle,
            flipped_normals,
            smoothing,
            max_influences,
        )?;
        let result = with_progress(py, progress, "transfer_weights", |p| request.run(p))?;
        transfer_output(py, &result)
    })
}

/// `transfer_weights`' arguments, checked and owned (a job's thread takes them).
struct TransferRequest {
    body_positions: Vec<[f32; 3]>,
    body_triangles: Vec<[u32; 3]>,
    body_influences: Influences,
    cloth_positions: Vec<[f32; 3]>,
    cloth_triangles: Vec<[u32; 3]>,
    options: TransferOptions,
}

impl TransferRequest {
    #[allow(clippy::too_many_arguments)]
    fn new(
        body_positions: &Bound<'_, PyAny>,
        body_triangles: &Bound<'_, PyAny>,
        body_influences: &Bound<'_, PyAny>,
        cloth_positions: &Bound<'_, PyAny>,
        cloth_triangles: &Bound<'_, PyAny>,
        max_distance: Option<&Bound<'_, PyAny>>,
        max_angle: Option<&Bound<'_, PyAny>>,
        flipped_normals: Option<&Bound<'_, PyAny>>,
        smoothing: Option<&Bound<'_, PyAny>>,
        max_influences: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let defaults = TransferOptions::default();
        let max_distance = match max_distance {
            Some(d) if !d.is_none() => Some(args::float_in(d, "max_distance", 0.0, f32::MAX)?),
            _ => None,
        };
        let max_angle = args::or(max_angle, defaults.max_angle, |o| args::float_in(o, "max_angle", 0.0, 180.0))?;
        let flipped_normals = args::or(flipped_normals, false, |o| args::boolean(o, "flipped_normals"))?;
        let smoothing = args::or(smoothing, 0, |o| args::int(o, "smoothing", 0, 1000))? as u32;
        let max_influences = args::or(max_influences, defaults.max_influences as i64, |o| {
            args::int(o, "max_influences", 1, weights::MAX_WEIGHT_INFLUENCES as i64)
        })? as usize;
        let infl = body_influences
            .cast::<PyInfluences>()
            .map_err(|_| PyTypeError::new_err("body_influences must be a dqskin.Influences (the body's weights)"))?;
        let infl = &infl.get().0;
        let bp = arrays::readonly::<f32>(body_positions, "body_positions", &[None, Some(3)], &["V"])?;
        if bp.shape()[0] != infl.vertex_count() {
            return Err(PyValueError::new_err(format!(
                "body_positions has {} vertices but body_influences has {}: they must be the same body",
                bp.shape()[0],
                infl.vertex_count()
            )));
        }
        let bt = named_triangle_indices(body_triangles, "body_triangles")?;
        let cp = arrays::readonly::<f32>(cloth_positions, "cloth_positions", &[None, Some(3)], &["V"])?;
        let ct = named_triangle_indices(cloth_triangles, "cloth_triangles")?;
        Ok(Self {
            body_positions: as_points(bp.as_slice()?).to_vec(),
            body_triangles: bt,
            body_influences: infl.clone(),
            cloth_positions: as_points(cp.as_slice()?).to_vec(),
            cloth_triangles: ct,
            options: TransferOptions { max_distance, max_angle, flipped_normals, smoothing, max_influences },
        })
    }

    fn run(&self, progress: &mut dyn FnMut(usize, usize) -> bool) -> Result<Transferred, WeightsError> {
        weights::transfer_weights(
            &self.body_positions,
            &self.body_triangles,
            &self.body_influences,
            &self.cloth_positions,
            &self.cloth_triangles,
            &self.options,
            progress,
        )
    }
}

/// `(influences, report)` as `transfer_weights` returns them.
fn transfer_output<'py>(py: Python<'py>, result: &Transferred) -> PyResult<Bound<'py, PyTuple>> {
    let report = PyDict::new(py);
    let matched_count = result.matched.iter().filter(|&&m| m).count();
    report.set_item("matched", PyArray1::from_vec(py, result.matched.clone()))?;
    report.set_item("matched_count", matched_count)?;
    report.set_item("inpainted", result.inpainted)?;
    report.set_item("from_nearest", result.from_nearest)?;
    report.set_item("max_distance", result.max_distance)?;
    report.set_item("iterations", result.iterations)?;
    let influences = Bound::new(py, PyInfluences::wrap(result.influences.clone()))?;
    PyTuple::new(py, [influences.into_any(), report.into_any()])
}

/// A weights job's result and how it becomes Python objects.
struct WeightsFinish<T: Send + 'static> {
    task: Arc<Task<T>>,
    what: &'static str,
    convert: for<'py> fn(Python<'py>, &T) -> PyResult<Bound<'py, PyTuple>>,
}

impl<T: Send + Sync + 'static> Finish for WeightsFinish<T> {
    type Output = T;

    fn task(&self) -> &Task<T> {
        &self.task
    }

    fn what(&self) -> &str {
        self.what
    }

    fn convert<'py>(&self, py: Python<'py>, result: &T) -> PyResult<Bound<'py, PyAny>> {
        (self.convert)(py, result).map(Bound::into_any)
    }
}

/// Starts `run` as a job named `what` whose result `convert` turns into the function's tuple.
fn weights_job<T: Send + Sync + 'static>(
    what: &'static str,
    run: impl FnOnce(&mut dyn FnMut(usize, usize) -> bool) -> Result<T, WeightsError> + Send + 'static,
    convert: for<'py> fn(Python<'py>, &T) -> PyResult<Bound<'py, PyTuple>>,
) -> PyResult<PyJob> {
    let task =
        Task::spawn("dqskin weights", move |reports| match run(&mut |done, total| reports.progress(done, total)) {
            Ok(result) => Outcome::Done(result),
            Err(WeightsError::Cancelled) => Outcome::Cancelled,
            Err(e) => Outcome::Failed(e.to_string()),
        })?;
    Ok(PyJob::new(WeightsFinish { task, what, convert }))
}

/// :func:`automatic_weights` as a :class:`Job` (the same arguments but ``progress``), started
/// at once on a thread of dqskin's own that never runs Python nor holds the GIL. The arguments'
/// types and shapes are checked now and the arrays copied; what the computation itself refuses
/// (a triangle out of range, a resolution that needs too much memory) is raised by ``result()``,
/// as the function raises it.
#[pyfunction]
#[pyo3(signature = (positions, triangles, heads, tails, *, resolution = None, falloff = None, max_influences = None,
    smoothing = None, mirror = None))]
#[allow(clippy::too_many_arguments)]
fn automatic_weights_job(
    positions: &Bound<'_, PyAny>,
    triangles: &Bound<'_, PyAny>,
    heads: &Bound<'_, PyAny>,
    tails: &Bound<'_, PyAny>,
    resolution: Option<&Bound<'_, PyAny>>,
    falloff: Option<&Bound<'_, PyAny>>,
    max_influences: Option<&Bound<'_, PyAny>>,
    smoothing: Option<&Bound<'_, PyAny>>,
    mirror: Option<&Bound<'_, PyAny>>,
) -> PyResult<PyJob> {
    guard(|| {
        let request = AutoRequest::new(
            positions,
            triangles,
            heads,
            tails,
            resolution,
            falloff,
            max_influences,
            smoothing,
            mirror,
        )?;
        weights_job("automatic_weights", move |p| request.run(p), auto_output)
    })
}

/// :func:`transfer_weights` as a :class:`Job` (the same arguments but ``progress``), as
/// :func:`automatic_weights_job` is to :func:`automatic_weights`.
#[pyfunction]
#[pyo3(signature = (body_positions, body_triangles, body_influences, cloth_positions, cloth_triangles, *,
    max_distance = None, max_angle = None, flipped_normals = None, smoothing = None, max_influences = None))]
#[allow(clippy::too_many_arguments)]
fn transfer_weights_job(
    body_positions: &Bound<'_, PyAny>,
    body_triangles: &Bound<'_, PyAny>,
    body_influences: &Bound<'_, PyAny>,
    cloth_positions: &Bound<'_, PyAny>,
    cloth_triangles: &Bound<'_, PyAny>,
    max_distance: Option<&Bound<'_, PyAny>>,
    max_angle: Option<&Bound<'_, PyAny>>,
    flipped_normals: Option<&Bound<'_, PyAny>>,
    smoothing: Option<&Bound<'_, PyAny>>,
    max_influences: Option<&Bound<'_, PyAny>>,
) -> PyResult<PyJob> {
    guard(|| {
        let request = TransferRequest::new(
            body_positions,
            body_triangles,
            body_influences,
            cloth_positions,
            cloth_triangles,
            max_distance,
            max_angle,
            flipped_normals,
            smoothing,
            max_influences,
        )?;
        weights_job("transfer_weights", move |p| request.run(p), transfer_output)
    })
}

/// The name of the bone on the other side (``hand.L`` → ``hand.R``, ``L_hand`` → ``R_hand``,
/// ``LeftHand`` → ``RightHand``), or ``None`` for a name without a side.
#[pyfunction]
fn mirrored_bone_name(name: &Bound<'_, PyAny>) -> PyResult<Option<String>> {
    guard(|| Ok(weights::mirrored_name(&args::string(name, "name")?)))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(automatic_weights, m)?)?;
    m.add_function(wrap_pyfunction!(transfer_weights, m)?)?;
    m.add_function(wrap_pyfunction!(automatic_weights_job, m)?)?;
    m.add_function(wrap_pyfunction!(transfer_weights_job, m)?)?;
    m.add_function(wrap_pyfunction!(mirrored_bone_name, m)?)?;
    Ok(())
}

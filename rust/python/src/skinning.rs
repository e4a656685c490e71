//! The `Influences` class (validated once, reused every frame), the centers-of-rotation
//! precompute, B-Bone matrices and mesh measurements; the array helpers `skin()` shares
//! (`job.rs`).

use dqskin_core::glam::Mat4;
use std::sync::Mutex;

use dqskin_core::{CenterSums, Centers, Influences, SkinError};
use numpy::{PyArray1, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;

use crate::args;
use crate::arrays::{self, mat4_from_row_major};
use crate::guard;

pub(crate) fn skin_error(e: SkinError) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// Per-vertex bone influences in CSR form, validated once and reused for every frame.
///
/// Vertex ``v`` has the pairs ``(bones[i], weights[i])`` for ``i`` in
/// ``offsets[v]:offsets[v+1]``, in the given order (dual quaternion skinning chooses signs in
/// this order, as Blender does with a vertex's stored groups). ``offsets`` has ``V+1`` entries
/// starting at 0; bones are below ``bone_count``; weights are finite and ≥ 0 and need not sum
/// to one. Index arrays may have any integer dtype; ``weights`` must be float32.
#[pyclass(name = "Influences", module = "dqskin", frozen, weakref)]
pub struct PyInfluences(pub Influences, Mutex<Option<CenterSums>>);

impl PyInfluences {
    pub fn wrap(influences: Influences) -> Self {
        Self(influences, Mutex::new(None))
    }

    /// What an update of the centers computed from these weights kept for the next one (taken:
    /// an update replaces it).
    pub(crate) fn take_center_sums(&self) -> Option<CenterSums> {
        self.1.lock().unwrap_or_else(|p| p.into_inner()).take()
    }

    pub(crate) fn keep_center_sums(&self, sums: CenterSums) {
        *self.1.lock().unwrap_or_else(|p| p.into_inner()) = Some(sums);
    }
}

#[pymethods]
impl PyInfluences {
    #[new]
    fn new(
        offsets: &Bound<'_, PyAny>,
        bones: &Bound<'_, PyAny>,
        weights: &Bound<'_, PyAny>,
        bone_count: &Bound<'_, PyAny>,
    ) -> PyResult<Self> {
        guard(|| {
            let bone_count = args::int(bone_count, "bone_count", 0, u32::MAX as i64)? as usize;
            let offsets = arrays::indices(offsets, "offsets")?;
            let bones = arrays::indices(bones, "bones")?;
            let w = arrays::readonly::<f32>(weights, "weights", &[None], &["N"])?;
            let w = w.as_slice()?;
            Influences::from_csr(&offsets, &bones, w, bone_count).map(Self::wrap).map_err(skin_error)
        })
    }

    /// From dense ``(V, K)`` arrays, as glTF stores joints and weights: every vertex lists ``K``
    /// bones; pairs with zero weight are dropped (they never change the result).
    #[staticmethod]
    fn from_dense(
        bones: &Bound<'_, PyAny>,
        weights: &Bound<'_, PyAny>,
        bone_count: &Bound<'_, PyAny>,
    ) -> PyResult<Self> {
        guard(|| {
            let bone_count = args::int(bone_count, "bone_count", 0, u32::MAX as i64)? as usize;
            let w = arrays::readonly::<f32>(weights, "weights", &[None, None], &["V", "K"])?;
            let (v, k) = (w.shape()[0], w.shape()[1]);
            let shape = arrays::as_numpy(bones, "bones", "integers")?.shape();
            if shape != [v, k] {
                return Err(PyValueError::new_err(format!(
                    "bones must have the same shape as weights ({v}, {k}), got {shape:?}"
                )));
            }
            let b = arrays::index_array(bones, "bones", &[Some(v), Some(k)], &[])?;
            Influences::from_dense(&b, w.as_slice()?, v, k, bone_count).map(Self::wrap).map_err(skin_error)
        })
    }

    /// The influences Blender's Armature modifier uses this frame, with bone envelopes and
    /// B-Bones.
    ///
    /// ``self`` holds the vertex-group influences (every group mapped to a deforming bone, zero
    /// weights included, in stored order). ``positions`` ``(V, 3)`` float32 are the coordinates
    /// reaching the modifier, taken to armature space by ``premat``. A vertex uses its groups
    /// (with ``use_vertex_groups`` and at least one group), else every envelope that reaches it
    /// (with ``use_envelopes``). The result's bone indices run over the expanded bone list: the
    /// ``B`` bones, then for each B-Bone in order its ``segments + 1`` joints.
    ///
    /// - ``pose``: a :class:`PoseData` of the same ``B`` bones (``dqskin.memory.PoseMemory.read``): the
    ///   envelopes, B-Bones and their mappings (Straight or Curved, as Blender's) from it.
    /// - Or arrays: ``envelopes`` ``(B, 11)`` float32, one row per bone in Blender's pose-bone
    ///   order: head xyz, tail xyz (``Bone.head_local``, ``tail_local``), head radius, tail
    ///   radius, envelope distance, envelope weight, and 1 where the bone multiplies its vertex
    ///   group by the envelope; ``bbone_segments`` ``(B,)`` integers, the segment count of each
    ///   bone (0 or 1 for ordinary bones), with ``rest`` ``(B, 4, 4)`` rest matrices and
    ///   ``lengths`` ``(B,)`` bone lengths (see ``bbone_segment_matrices`` for the joints).
    ///   Segments are found with Blender's Straight mapping, except for the bones in
    ///   ``bbone_mapping``: ``{bone index: (index (V,) int32, blend (V,) float32)}`` computed
    ///   elsewhere (``PoseBone.bbone_segment_index``); a negative index falls back to the
    ///   Straight mapping for that vertex.
    #[pyo3(signature = (positions, premat = None, *, pose = None, envelopes = None, use_vertex_groups = None,
        use_envelopes = None, bbone_segments = None, rest = None, lengths = None, bbone_mapping = None))]
    #[allow(clippy::too_many_arguments)]
    fn effective(
        &self,
        positions: &Bound<'_, PyAny>,
        premat: Option<&Bound<'_, PyAny>>,
        pose: Option<&Bound<'_, PyAny>>,
        envelopes: Option<&Bound<'_, PyAny>>,
        use_vertex_groups: Option<&Bound<'_, PyAny>>,
        use_envelopes: Option<&Bound<'_, PyAny>>,
        bbone_segments: Option<&Bound<'_, PyAny>>,
        rest: Option<&Bound<'_, PyAny>>,
        lengths: Option<&Bound<'_, PyAny>>,
        bbone_mapping: Option<&Bound<'_, pyo3::types::PyDict>>,
    ) -> PyResult<Self> {
        guard(|| {
            let a = crate::armature::EffectiveArgs {
                positions,
                premat,
                pose,
                envelopes,
                use_vertex_groups,
                use_envelopes,
                bbone_segments,
                rest,
                lengths,
                bbone_mapping,
            };
            crate::armature::effective(&self.0, a)
        })
    }

    /// Number of vertices.
    #[getter]
    fn vertex_count(&self) -> usize {
        self.0.vertex_count()
    }

    /// Number of bones the indices refer to.
    #[getter]
    fn bone_count(&self) -> usize {
        self.0.bone_count()
    }

    /// The largest number of influences of any vertex.
    #[getter]
    fn max_per_vertex(&self) -> usize {
        self.0.max_per_vertex()
    }

    /// Bytes these influences hold (their lane-ordered copy for the kernels, the offsets, and
    /// what an Optimized Centers update kept for the next one), for memory accounting.
    #[getter]
    fn nbytes(&self) -> usize {
        let kept = self.1.lock().unwrap_or_else(|p| p.into_inner()).as_ref().map_or(0, CenterSums::heap_bytes);
        self.0.heap_bytes() + kept
    }

    /// Total number of ``(bone, weight)`` pairs.
    fn __len__(&self) -> usize {
        self.0.len()
    }

    /// A copy of the offsets (``uint32``, ``V+1``).
    #[getter]
    fn offsets<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u32>> {
        PyArray1::from_vec(py, self.0.offsets())
    }

    /// A copy of the bone indices (``uint32``).
    #[getter]
    fn bones<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u32>> {
        let v: Vec<u32> = self.0.entries().iter().map(|e| e.bone).collect();
        PyArray1::from_vec(py, v)
    }

    /// A copy of the weights (``float32``).
    #[getter]
    fn weights<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        let v: Vec<f32> = self.0.entries().iter().map(|e| e.weight).collect();
        PyArray1::from_vec(py, v)
    }

    fn __repr__(&self) -> String {
        format!(
            "Influences(vertex_count={}, bone_count={}, pairs={}, max_per_vertex={})",
            self.0.vertex_count(),
            self.0.bone_count(),
            self.0.len(),
            self.0.max_per_vertex()
        )
    }
}

/// The deform and rest matrices of a B-Bone's segment joints, as Blender builds them for the
/// Armature modifier: ``deform_a = channel · rest · P_a · R_a⁻¹ · rest⁻¹`` and rest
/// ``normalize(rest · R_a)``, from the bone's ``matrix_channel`` and ``matrix_local`` and its
/// joints' ``bbone_segment_matrix(a)`` / ``bbone_segment_matrix(a, rest=True)`` (``(N+1, 4, 4)``
/// each). Returns ``(deform, rest)``, both ``(N+1, 4, 4)`` float32.
#[pyfunction]
fn bbone_segment_matrices<'py>(
    channel: &Bound<'py, PyAny>,
    rest: &Bound<'py, PyAny>,
    pose_joints: &Bound<'py, PyAny>,
    rest_joints: &Bound<'py, PyAny>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    guard(|| {
        let py = channel.py();
        let (c, _) = arrays::small(channel, "channel", &[Some(4), Some(4)], &[])?;
        let (r, _) = arrays::small(rest, "rest", &[Some(4), Some(4)], &[])?;
        let (p, pd) = arrays::small(pose_joints, "pose_joints", &[None, Some(4), Some(4)], &["N+1"])?;
        let (rj, rd) = arrays::small(rest_joints, "rest_joints", &[None, Some(4), Some(4)], &["N+1"])?;
        if pd[0] != rd[0] {
            return Err(PyValueError::new_err(format!(
                "pose_joints has {} matrices but rest_joints has {}",
                pd[0], rd[0]
            )));
        }
        let to = |d: &[f32]| d.chunks_exact(16).map(mat4_from_row_major).collect::<Vec<_>>();
        let m = dqskin_core::skin::bbone_segment_matrices(
            mat4_from_row_major(&c),
            mat4_from_row_major(&r),
            &to(&p),
            &to(&rj),
        );
        let n = m.len();
        let flat = |f: fn(&(Mat4, Mat4)) -> Mat4| -> Vec<f32> {
            m.iter().flat_map(|x| arrays::mat4_to_row_major(&f(x))).collect()
        };
        Ok((
            PyArray1::from_vec(py, flat(|x| x.0)).reshape([n, 4, 4])?.into_any(),
            PyArray1::from_vec(py, flat(|x| x.1)).reshape([n, 4, 4])?.into_any(),
        ))
    })
}

pub(crate) fn matrices(obj: &Bound<'_, PyAny>, name: &str, count: Option<usize>) -> PyResult<Vec<Mat4>> {
    let a = arrays::readonly::<f32>(obj, name, &[count, Some(4), Some(4)], &["B"])?;
    let data = a.as_slice()?;
    arrays::check_finite(name, data)?;
    Ok(data.chunks_exact(16).map(mat4_from_row_major).collect())
}

pub(crate) fn space(obj: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Option<Mat4>> {
    match obj {
        None => Ok(None),
        Some(o) if o.is_none() => Ok(None),
        Some(o) => {
            let (m, _) = arrays::small(o, name, &[Some(4), Some(4)], &[])?;
            Ok(Some(mat4_from_row_major(&m)))
        }
    }
}

/// ``(T, 3)`` integer triangles as vertex indices (range checked by the core).
pub(crate) fn triangle_indices(triangles: &Bound<'_, PyAny>) -> PyResult<Vec<[u32; 3]>> {
    named_triangle_indices(triangles, "triangles")
}

/// [`triangle_indices`] of the argument `name`.
pub(crate) fn named_triangle_indices(triangles: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<[u32; 3]>> {
    let flat = arrays::index_array(triangles, name, &[None, Some(3)], &["T"])?;
    Ok(flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

pub(crate) fn as_points(flat: &[f32]) -> &[[f32; 3]] {
    let (chunks, rest) = flat.as_chunks::<3>();
    debug_assert!(rest.is_empty());
    chunks
}

pub(crate) fn as_points_mut(flat: &mut [f32]) -> &mut [[f32; 3]] {
    let (chunks, rest) = flat.as_chunks_mut::<3>();
    debug_assert!(rest.is_empty());
    chunks
}

/// ``points`` ``(N, 3)`` float32 transformed by the affine 4×4 ``matrix`` (row-major), as a new
/// array.
#[pyfunction]
fn transform_points<'py>(matrix: &Bound<'py, PyAny>, points: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    guard(|| {
        let py = points.py();
        let m = space(Some(matrix), "matrix")?
            .ok_or_else(|| PyTypeError::new_err("matrix must be a 4×4 array of numbers, got None"))?;
        if let Some(problem) = dqskin_core::skin::affine_problem(&m) {
            return Err(PyValueError::new_err(format!("matrix {problem}")));
        }
        let p = arrays::readonly::<f32>(points, "points", &[None, Some(3)], &["N"])?;
        let src = as_points(p.as_slice()?);
        let out: Vec<f32> = py.detach(|| {
            src.iter().flat_map(|c| m.transform_point3(dqskin_core::glam::Vec3::from_array(*c)).to_array()).collect()
        });
        Ok(PyArray1::from_vec(py, out).reshape([src.len(), 3])?.into_any())
    })
}

/// Enclosed volume of a closed, consistently oriented triangle mesh: ``positions`` ``(V, 3)``
/// float32, ``triangles`` ``(T, 3)`` integers.
#[pyfunction]
fn mesh_volume(positions: &Bound<'_, PyAny>, triangles: &Bound<'_, PyAny>) -> PyResult<f64> {
    guard(|| {
        let pos = arrays::readonly::<f32>(positions, "positions", &[None, Some(3)], &["V"])?;
        let tris = triangle_indices(triangles)?;
        dqskin_core::rigs::mesh_volume(as_points(pos.as_slice()?), &tris).map_err(skin_error)
    })
}

/// Area of a planar polygon, ``points`` ``(N, 3)`` float32 in order.
#[pyfunction]
fn polygon_area(points: &Bound<'_, PyAny>) -> PyResult<f64> {
    guard(|| {
        let p = arrays::readonly::<f32>(points, "points", &[None, Some(3)], &["N"])?;
        Ok(dqskin_core::rigs::polygon_area(as_points(p.as_slice()?)))
    })
}

/// Centers of rotation of a rest mesh (Le & Hodgins, SIGGRAPH 2016) for
/// ``skin(..., method='centers_of_rotation', centers=...)``: a ``(V, 3)`` float32 array.
///
/// - ``positions``: ``(V, 3)`` float32 rest positions (the mesh space ``skin`` gets them in);
/// - ``triangles``: ``(T, 3)`` integer vertex indices (split polygons into triangles first);
/// - ``influences``: the :class:`Influences` of the same ``V`` vertices; each vertex's weights
///   are normalized to sum 1 for the similarity (repeated bones added up);
/// - ``sigma``: the similarity width (0.1 in the paper), a finite number > 0;
/// - ``with_mask``: also return a ``(V,)`` bool array, True where the vertex has a center.
///
/// - ``progress``: called as ``progress(done, total)`` from the calling thread about a hundred
///   times; returning ``False`` stops the work with :class:`Cancelled`, and an exception it
///   raises stops it and is raised again.
/// - ``previous``: ``(influences, centers)``, the centers this function returned for the same
///   positions and triangles with other weights (``centers`` the array, or the ``(array, mask)``
///   pair ``with_mask`` gives): only the vertices the weight change reaches are computed again
///   (after a brush stroke, a small part of the mesh), with the result a full computation gives
///   bit for bit. The caller vouches that positions and triangles are the same.
///
/// A vertex without a center (fewer than two bones, or no triangle sharing two of them) gets its
/// own position, with which centers-of-rotation skinning is exactly linear blend skinning.
/// The GIL is released while it runs on dqskin's thread pool; Ctrl-C stops it
/// (``KeyboardInterrupt``).
#[pyfunction]
#[pyo3(signature = (positions, triangles, influences, sigma = None, *, with_mask = None, progress = None, previous = None))]
fn centers_of_rotation<'py>(
    positions: &Bound<'py, PyAny>,
    triangles: &Bound<'py, PyAny>,
    influences: &Bound<'py, PyAny>,
    sigma: Option<&Bound<'py, PyAny>>,
    with_mask: Option<&Bound<'py, PyAny>>,
    progress: Option<&Bound<'py, PyAny>>,
    previous: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    guard(|| {
        let py = positions.py();
        let CentersArgs { sigma, with_mask, influences, positions: pos, triangles: tris } =
            CentersArgs::read(positions, triangles, influences, sigma, with_mask)?;
        let after = influences.get();
        let infl = &after.0;
        let points = as_points(pos.as_slice()?);
        let mut previous = match previous {
            Some(p) if !p.is_none() => Some(previous_centers(p, points)?),
            _ => None,
        };
        let callback = crate::args::progress_callback(progress)?;
        // Between parts of the work the GIL is taken back: Ctrl-C, then the callback; between
        // the stages of the setup (before the callback's total is known), Ctrl-C only.
        let stopped: std::sync::Mutex<Option<PyErr>> = std::sync::Mutex::new(None);
        // Records why the computation stops; false, the answer that stops it.
        let stop = |e: PyErr| {
            *stopped.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
            false
        };
        let signalled = |py: Python<'_>| match py.check_signals() {
            Err(e) => !stop(e),
            Ok(()) => false,
        };
        let result = py.detach(|| {
            let mut progress = |done, total| {
                Python::attach(|py| {
                    if signalled(py) {
                        return false;
                    }
                    let Some(cb) = &callback else { return true };
                    match cb.bind(py).call1((done, total)) {
                        Ok(r) if r.is_instance_of::<pyo3::types::PyBool>() && !r.is_truthy().unwrap_or(true) => {
                            stop(Cancelled::new_err("centers_of_rotation was cancelled by its progress callback"))
                        }
                        Ok(_) => true,
                        Err(e) => stop(e),
                    }
                })
            };
            let mut interrupted = || Python::attach(signalled);
            match &mut previous {
                // Strokes follow one another: each update keeps per-pair sums in the new weights'
                // `Influences` for the next (the centers are the same bit for bit).
                Some((influences, centers, kept)) => {
                    let previous = dqskin_core::PreviousCenters { influences, centers };
                    dqskin_core::centers_of_rotation_update_keeping(
                        points,
                        &tris,
                        infl,
                        sigma,
                        previous,
                        kept.take(),
                        &mut progress,
                        &mut interrupted,
                    )
                    .map(|(centers, sums)| {
                        after.keep_center_sums(sums);
                        centers
                    })
                }
                None => dqskin_core::centers_of_rotation_interruptible(
                    points,
                    &tris,
                    infl,
                    sigma,
                    &mut progress,
                    &mut interrupted,
                ),
            }
        });
        if let Some(e) = stopped.into_inner().unwrap_or_else(|p| p.into_inner()) {
            return Err(e);
        }
        centers_output(py, &result.map_err(skin_error)?, with_mask)
    })
}

/// The arguments `centers_of_rotation` and `centers_of_rotation_job` share, read and checked.
pub(crate) struct CentersArgs<'py> {
    pub sigma: f32,
    pub with_mask: bool,
    pub influences: Bound<'py, PyInfluences>,
    /// `(V, 3)` float32, one row per vertex of `influences`.
    pub positions: numpy::PyReadonlyArrayDyn<'py, f32>,
    pub triangles: Vec<[u32; 3]>,
}

impl<'py> CentersArgs<'py> {
    pub(crate) fn read(
        positions: &Bound<'py, PyAny>,
        triangles: &Bound<'py, PyAny>,
        influences: &Bound<'py, PyAny>,
        sigma: Option<&Bound<'py, PyAny>>,
        with_mask: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Self> {
        let sigma = args::or(sigma, dqskin_core::skin::DEFAULT_SIGMA, |o| args::float(o, "sigma"))?;
        let with_mask = args::or(with_mask, false, |o| args::boolean(o, "with_mask"))?;
        let influences = influences.cast::<PyInfluences>().map_err(|_| {
            PyTypeError::new_err("influences must be a dqskin.Influences (the weights of the same vertices)")
        })?;
        let v = influences.get().0.vertex_count();
        let positions = crate::job::sized_by_influences(
            positions,
            v,
            "vertices",
            arrays::readonly::<f32>(positions, "positions", &[Some(v), Some(3)], &["V"]),
        )?;
        let triangles = triangle_indices(triangles)?;
        Ok(Self { sigma, with_mask, influences: influences.clone(), positions, triangles })
    }
}

/// The centers as `centers_of_rotation` returns them: a `(V, 3)` float32 array, with the `(V,)`
/// bool mask if `with_mask`.
pub(crate) fn centers_output<'py>(py: Python<'py>, centers: &Centers, with_mask: bool) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<f32> = centers.centers.iter().flatten().copied().collect();
    let array = PyArray1::from_vec(py, flat).reshape([centers.centers.len(), 3])?.into_any();
    if with_mask {
        let mask = PyArray1::from_vec(py, centers.has_center.clone()).into_any();
        Ok(pyo3::types::PyTuple::new(py, [array, mask])?.into_any())
    } else {
        Ok(array)
    }
}

/// `previous=(influences, centers)` read: the influences and the centers (with their mask, or
/// the mask found from the rows holding their own vertex's position).
/// The `(influences, centers)` of `previous`, and what the update that made them kept (taken
/// from that `Influences`: see `keep_center_sums`).
pub(crate) fn previous_centers(
    previous: &Bound<'_, PyAny>,
    points: &[[f32; 3]],
) -> PyResult<(Influences, Centers, Option<CenterSums>)> {
    let bad = || {
        PyTypeError::new_err(
            "previous must be (influences, centers): the dqskin.Influences and the array (or (array, mask)) centers_of_rotation returned for them",
        )
    };
    let (influences, centers): (Bound<'_, PyAny>, Bound<'_, PyAny>) = previous.extract().map_err(|_| bad())?;
    let before = influences.cast::<PyInfluences>().map_err(|_| bad())?.get();
    let influences = before.0.clone();
    let v = points.len();
    let (array, mask) = match centers.extract::<(Bound<'_, PyAny>, Bound<'_, PyAny>)>() {
        Ok((a, m)) => (a, Some(m)),
        Err(_) => (centers, None),
    };
    let array = arrays::readonly::<f32>(&array, "previous centers", &[Some(v), Some(3)], &["V"])?;
    let rows: Vec<[f32; 3]> = as_points(array.as_slice()?).to_vec();
    let has_center = match mask {
        Some(m) => {
            let m = arrays::readonly::<bool>(&m, "previous mask", &[Some(v)], &["V"])?;
            m.as_slice()?.to_vec()
        }
        None => rows.iter().zip(points).map(|(c, p)| c != p).collect(),
    };
    let kept = before.take_center_sums();
    Ok((influences, Centers { centers: rows, has_center }, kept))
}

pyo3::create_exception!(
    dqskin,
    Cancelled,
    pyo3::exceptions::PyException,
    "A long computation stopped because its progress callback returned False."
);

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("Cancelled", m.py().get_type::<Cancelled>())?;
    m.add_function(wrap_pyfunction!(centers_of_rotation, m)?)?;
    m.add_class::<PyInfluences>()?;
    m.add_function(wrap_pyfunction!(bbone_segment_matrices, m)?)?;
    m.add_function(wrap_pyfunction!(transform_points, m)?)?;
    m.add_function(wrap_pyfunction!(mesh_volume, m)?)?;
    m.add_function(wrap_pyfunction!(polygon_area, m)?)?;
    Ok(())
}

//! Skinning: the `Influences` class (validated once, reused every frame) and `skin()`.

use dqskin_core::glam::Mat4;
use dqskin_core::{Influences, Method, Pose, SkinError, SkinOptions};
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
#[pyclass(name = "Influences", module = "dqskin", frozen)]
pub struct PyInfluences(pub Influences);

#[pymethods]
impl PyInfluences {
    #[new]
    fn new(offsets: &Bound<'_, PyAny>, bones: &Bound<'_, PyAny>, weights: &Bound<'_, PyAny>, bone_count: &Bound<'_, PyAny>) -> PyResult<Self> {
        guard(|| {
            let bone_count = args::int(bone_count, "bone_count", 0, u32::MAX as i64)? as usize;
            let offsets = arrays::indices(offsets, "offsets")?;
            let bones = arrays::indices(bones, "bones")?;
            let w = arrays::readonly::<f32>(weights, "weights", &[None], &["N"])?;
            let w = w.as_slice()?;
            Influences::from_csr(&offsets, &bones, w, bone_count).map(Self).map_err(skin_error)
        })
    }

    /// From dense ``(V, K)`` arrays, as glTF stores joints and weights: every vertex lists ``K``
    /// bones; pairs with zero weight are dropped (they never change the result).
    #[staticmethod]
    fn from_dense(bones: &Bound<'_, PyAny>, weights: &Bound<'_, PyAny>, bone_count: &Bound<'_, PyAny>) -> PyResult<Self> {
        guard(|| {
            let bone_count = args::int(bone_count, "bone_count", 0, u32::MAX as i64)? as usize;
            let w = arrays::readonly::<f32>(weights, "weights", &[None, None], &["V", "K"])?;
            let (v, k) = (w.shape()[0], w.shape()[1]);
            if k > dqskin_core::MAX_INFLUENCES_PER_VERTEX {
                return Err(PyValueError::new_err(format!(
                    "weights has {k} influences per vertex; at most {} are supported",
                    dqskin_core::MAX_INFLUENCES_PER_VERTEX
                )));
            }
            let b_arr = bones.cast::<numpy::PyUntypedArray>().map_err(|_| {
                let ty = bones.get_type().name().map(|n| n.to_string()).unwrap_or_default();
                PyTypeError::new_err(format!("bones must be a numpy array of integers, got {ty}"))
            })?;
            if b_arr.shape() != [v, k] {
                return Err(PyValueError::new_err(format!(
                    "bones must have the same shape as weights ({v}, {k}), got {:?}",
                    b_arr.shape()
                )));
            }
            let np = bones.py().import("numpy")?;
            let flat = np.call_method1("ravel", (bones,))?;
            let b = arrays::indices(&flat, "bones")?;
            let wv = w.as_slice()?;
            let mut offsets = Vec::with_capacity(v + 1);
            let (mut ob, mut ow) = (Vec::new(), Vec::new());
            offsets.push(0u32);
            for row in 0..v {
                for c in 0..k {
                    let i = row * k + c;
                    if wv[i] != 0.0 {
                        ob.push(b[i]);
                        ow.push(wv[i]);
                    }
                }
                offsets.push(u32::try_from(ob.len()).map_err(|_| PyValueError::new_err("weights: too many influences"))?);
            }
            Influences::from_csr(&offsets, &ob, &ow, bone_count).map(Self).map_err(skin_error)
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
    /// - ``pose``: a :class:`PoseData` of the same ``B`` bones (``_PoseMemory.read``): the
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
            let a = crate::armature::EffectiveArgs { positions, premat, pose, envelopes, use_vertex_groups, use_envelopes, bbone_segments, rest, lengths, bbone_mapping };
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

    /// Total number of ``(bone, weight)`` pairs.
    fn __len__(&self) -> usize {
        self.0.len()
    }

    /// A copy of the offsets (``uint32``, ``V+1``).
    #[getter]
    fn offsets<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u32>> {
        PyArray1::from_slice(py, self.0.offsets())
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
            return Err(PyValueError::new_err(format!("pose_joints has {} matrices but rest_joints has {}", pd[0], rd[0])));
        }
        let to = |d: &[f32]| d.chunks_exact(16).map(mat4_from_row_major).collect::<Vec<_>>();
        let m = dqskin_core::skin::bbone_segment_matrices(mat4_from_row_major(&c), mat4_from_row_major(&r), &to(&p), &to(&rj));
        let n = m.len();
        let flat = |f: fn(&(Mat4, Mat4)) -> Mat4| -> Vec<f32> { m.iter().flat_map(|x| arrays::mat4_to_row_major(&f(x))).collect() };
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

const CENTERS_OF_ROTATION: u8 = 3;

fn parse_method(method: &str) -> PyResult<u8> {
    match method.to_ascii_lowercase().as_str() {
        "linear" | "lbs" => Ok(0),
        "dual_quaternion" | "dqs" => Ok(1),
        "blend" => Ok(2),
        "centers_of_rotation" | "cor" => Ok(CENTERS_OF_ROTATION),
        _ => Err(PyValueError::new_err(format!(
            "method must be 'linear', 'dual_quaternion', 'blend' or 'centers_of_rotation', got {method:?}"
        ))),
    }
}

/// The per-vertex centers `skin` needs for ``method='centers_of_rotation'`` (and refuses
/// otherwise).
fn centers_arg<'py>(centers: Option<&Bound<'py, PyAny>>, kind: u8, v: usize) -> PyResult<Option<numpy::PyReadonlyArrayDyn<'py, f32>>> {
    let given = centers.filter(|c| !c.is_none());
    match (given, kind) {
        (Some(c), CENTERS_OF_ROTATION) => {
            let a = arrays::readonly::<f32>(c, "centers", &[Some(v), Some(3)], &["V"])?;
            arrays::check_finite("centers", a.as_slice()?)?;
            Ok(Some(a))
        }
        (None, CENTERS_OF_ROTATION) => Err(PyValueError::new_err(
            "centers is required for method='centers_of_rotation': the (V, 3) float32 array from dqskin.centers_of_rotation()",
        )),
        (Some(_), _) => Err(PyValueError::new_err("centers is only used with method='centers_of_rotation'")),
        (None, _) => Ok(None),
    }
}

/// ``(T, 3)`` integer triangles as vertex indices (range checked by the caller).
fn triangle_indices(triangles: &Bound<'_, PyAny>) -> PyResult<Vec<[u32; 3]>> {
    let np = triangles.py().import("numpy")?;
    let tri = triangles.cast::<numpy::PyUntypedArray>().map_err(|_| {
        let ty = triangles.get_type().name().map(|n| n.to_string()).unwrap_or_default();
        PyTypeError::new_err(format!("triangles must be a numpy array of integers, got {ty}"))
    })?;
    let shape: Vec<usize> = tri.shape().to_vec();
    if shape.len() != 2 || shape[1] != 3 {
        return Err(PyValueError::new_err(format!("triangles must have shape (T, 3), got {shape:?}")));
    }
    let flat = arrays::indices(&np.call_method1("ravel", (triangles,))?, "triangles")?;
    Ok(flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// Skins ``positions`` (``(V, 3)`` float32) and returns the result (``out`` if given).
///
/// - ``influences``: an :class:`Influences` for the same ``V`` vertices.
/// - ``deform``: ``(B, 4, 4)`` float32, each bone's posed matrix times the inverse of its rest
///   matrix in armature space (Blender's ``PoseBone.matrix_channel``), row-major.
/// - ``rest``: ``(B, 4, 4)`` float32 rest matrices (``Bone.matrix_local``), required for
///   ``'dual_quaternion'`` and ``'blend'`` (Blender's scale path depends on them).
/// - ``method``: ``'linear'`` (Preserve Volume off), ``'dual_quaternion'`` (on), ``'blend'``:
///   ``(1−α)·linear + α·dual_quaternion`` with ``α = blend_factor · blend[v]`` (or
///   ``blend_factor`` alone without ``blend``); all in ``[0, 1]``; or
///   ``'centers_of_rotation'`` (Le & Hodgins 2016) with ``centers``, the ``(V, 3)`` float32
///   array from :func:`centers_of_rotation` (needs ``rest``).
/// - ``premat``/``postmat``: 4×4 mesh→armature and armature→mesh transforms (identity if None).
/// - ``mask``: ``(V,)`` float32 per-vertex strength in ``[0, 1]``; 0 leaves a vertex unchanged.
/// - ``out``: optional ``(V, 3)`` float32 C-contiguous buffer that does not overlap the inputs.
///
/// The GIL is released while the kernel runs on dqskin's thread pool.
#[pyfunction]
#[pyo3(signature = (positions, influences, deform, rest = None, *, method = None,
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
        let py = positions.py();
        let method = args::or(method, "dual_quaternion".to_string(), |o| args::string(o, "method"))?;
        let method = method.as_str();
        let blend_factor = args::or(blend_factor, 1.0, |o| args::float(o, "blend_factor"))?;
        let kind = parse_method(method)?;
        let infl = influences.cast::<PyInfluences>().map_err(|_| {
            PyTypeError::new_err("influences must be a dqskin.Influences (build one from CSR arrays once and reuse it)")
        })?;
        let infl = &infl.get().0;
        let v = infl.vertex_count();
        let pos = arrays::readonly::<f32>(positions, "positions", &[Some(v), Some(3)], &["V"])?;
        let deform = matrices(deform, "deform", Some(infl.bone_count()))?;
        let rest = match rest {
            Some(r) if !r.is_none() => Some(matrices(r, "rest", Some(deform.len()))?),
            _ => None,
        };
        if kind != 0 && rest.is_none() {
            return Err(PyValueError::new_err(format!(
                "rest is required for method={method:?}: the (B, 4, 4) rest matrices (Bone.matrix_local)"
            )));
        }
        let pose = Pose::new(&deform, rest.as_deref()).map_err(skin_error)?;
        let premat = space(premat, "premat")?;
        let postmat = space(postmat, "postmat")?;
        let mask = match mask {
            Some(m) if !m.is_none() => Some(arrays::readonly::<f32>(m, "mask", &[Some(v)], &["V"])?),
            _ => None,
        };
        let blend = match blend {
            Some(b) if !b.is_none() => Some(arrays::readonly::<f32>(b, "blend", &[Some(v)], &["V"])?),
            _ => None,
        };
        if kind != 2 && blend.is_some() {
            return Err(PyValueError::new_err("blend is only used with method='blend'"));
        }
        let centers = centers_arg(centers, kind, v)?;
        let out_arr = match out {
            Some(o) if !o.is_none() => o.clone(),
            _ => numpy::PyArray2::<f32>::zeros(py, [v, 3], false).into_any(),
        };
        let mut out_rw = arrays::readwrite::<f32>(&out_arr, "out", &[Some(v), Some(3)], &["V"])?;
        let pos_slice = as_points(pos.as_slice()?);
        let mask_slice = match &mask {
            Some(m) => Some(m.as_slice()?),
            None => None,
        };
        let blend_slice = match &blend {
            Some(b) => Some(b.as_slice()?),
            None => None,
        };
        let out_slice = as_points_mut(out_rw.as_slice_mut()?);
        let method = match (kind, &centers) {
            (0, _) => Method::Linear,
            (1, _) => Method::DualQuaternion,
            (CENTERS_OF_ROTATION, Some(c)) => Method::CentersOfRotation { centers: as_points(c.as_slice()?) },
            _ => Method::Blend { amount: blend_slice, factor: blend_factor },
        };
        let options = SkinOptions { premat, postmat, mask: mask_slice };
        py.detach(|| dqskin_core::skin(method, pos_slice, infl, &pose, &options, out_slice))
            .map_err(skin_error)?;
        drop(out_rw);
        Ok(out_arr)
    })
}

/// Skins many meshes in one call, in parallel across meshes: for scenes with many small
/// characters. ``jobs``: a list of tuples ``(positions, influences, deform, rest, method,
/// premat, postmat, mask, blend, blend_factor, out)`` with the arguments of :func:`skin` (``out``
/// required), optionally followed by ``centers`` (a twelfth item, for
/// ``method='centers_of_rotation'``). Returns one entry per job: None, or the error message of a job that failed (its
/// ``out`` untouched). Arguments that are not arrays of the right kind raise at once, naming
/// the job.
#[pyfunction]
fn skin_many<'py>(py: Python<'py>, jobs: &Bound<'py, PyAny>) -> PyResult<Vec<Option<String>>> {
    guard(|| {
        let jobs = jobs.cast::<pyo3::types::PyList>().map_err(|_| {
            let ty = jobs.get_type().name().map(|n| n.to_string()).unwrap_or_default();
            PyTypeError::new_err(format!("jobs must be a list of tuples, got {ty}"))
        })?;
        struct Held<'py> {
            kind: u8,
            positions: numpy::PyReadonlyArrayDyn<'py, f32>,
            influences: Bound<'py, PyInfluences>,
            deform: Vec<Mat4>,
            rest: Option<Vec<Mat4>>,
            premat: Option<Mat4>,
            postmat: Option<Mat4>,
            mask: Option<numpy::PyReadonlyArrayDyn<'py, f32>>,
            blend: Option<numpy::PyReadonlyArrayDyn<'py, f32>>,
            blend_factor: f32,
            out: numpy::PyReadwriteArrayDyn<'py, f32>,
            centers: Option<numpy::PyReadonlyArrayDyn<'py, f32>>,
        }
        let mut held = Vec::with_capacity(jobs.len());
        for (i, item) in jobs.iter().enumerate() {
            let at = |e: PyErr| -> PyErr {
                let msg = e.value(py).to_string();
                if e.is_instance_of::<PyTypeError>(py) {
                    PyTypeError::new_err(format!("jobs[{i}]: {msg}"))
                } else {
                    PyValueError::new_err(format!("jobs[{i}]: {msg}"))
                }
            };
            let t = item.cast::<pyo3::types::PyTuple>().map_err(|_| {
                PyTypeError::new_err(format!("jobs[{i}] must be a tuple (positions, influences, deform, rest, method, premat, postmat, mask, blend, blend_factor, out[, centers])"))
            })?;
            if t.len() != 11 && t.len() != 12 {
                return Err(PyValueError::new_err(format!("jobs[{i}] must have 11 items (12 with centers), got {}", t.len())));
            }
            let influences = t.get_item(1)?.cast_into::<PyInfluences>().map_err(|_| {
                PyTypeError::new_err(format!("jobs[{i}]: influences must be a dqskin.Influences"))
            })?;
            let (v, b) = (influences.get().0.vertex_count(), influences.get().0.bone_count());
            let method = args::string(&t.get_item(4)?, "method").map_err(at)?;
            let kind = parse_method(&method).map_err(at)?;
            let positions = arrays::readonly::<f32>(&t.get_item(0)?, "positions", &[Some(v), Some(3)], &["V"]).map_err(at)?;
            let deform = matrices(&t.get_item(2)?, "deform", Some(b)).map_err(at)?;
            let rest_obj = t.get_item(3)?;
            let rest = if rest_obj.is_none() { None } else { Some(matrices(&rest_obj, "rest", Some(b)).map_err(at)?) };
            let premat = space(Some(&t.get_item(5)?), "premat").map_err(at)?;
            let postmat = space(Some(&t.get_item(6)?), "postmat").map_err(at)?;
            let opt = |k: usize, name: &str| -> PyResult<Option<numpy::PyReadonlyArrayDyn<'py, f32>>> {
                let o = t.get_item(k)?;
                if o.is_none() { Ok(None) } else { arrays::readonly::<f32>(&o, name, &[Some(v)], &["V"]).map(Some).map_err(at) }
            };
            let mask = opt(7, "mask")?;
            let blend = opt(8, "blend")?;
            let blend_factor = args::float(&t.get_item(9)?, "blend_factor").map_err(at)?;
            let centers_obj = if t.len() == 12 { Some(t.get_item(11)?) } else { None };
            let centers = centers_arg(centers_obj.as_ref(), kind, v).map_err(at)?;
            let out = arrays::readwrite::<f32>(&t.get_item(10)?, "out", &[Some(v), Some(3)], &["V"]).map_err(at)?;
            held.push(Held { kind, positions, influences, deform, rest, premat, postmat, mask, blend, blend_factor, out, centers });
        }
        let mut many = Vec::with_capacity(held.len());
        for h in held.iter_mut() {
            let mask = match &h.mask { Some(m) => Some(m.as_slice()?), None => None };
            let blend = match &h.blend { Some(m) => Some(m.as_slice()?), None => None };
            let method = match (h.kind, &h.centers) {
                (0, _) => Method::Linear,
                (1, _) => Method::DualQuaternion,
                (CENTERS_OF_ROTATION, Some(c)) => Method::CentersOfRotation { centers: as_points(c.as_slice()?) },
                _ => Method::Blend { amount: blend, factor: h.blend_factor },
            };
            many.push(dqskin_core::ManyJob {
                method,
                positions: as_points(h.positions.as_slice()?),
                influences: &h.influences.get().0,
                deform: &h.deform,
                rest: h.rest.as_deref(),
                options: SkinOptions { premat: h.premat, postmat: h.postmat, mask },
                out: as_points_mut(h.out.as_slice_mut()?),
            });
        }
        let results = py.detach(|| dqskin_core::skin_many(&mut many));
        Ok(results.into_iter().map(|r| r.err().map(|e| e.to_string())).collect())
    })
}

fn as_points(flat: &[f32]) -> &[[f32; 3]] {
    let (chunks, rest) = flat.as_chunks::<3>();
    debug_assert!(rest.is_empty());
    chunks
}

fn as_points_mut(flat: &mut [f32]) -> &mut [[f32; 3]] {
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
        let n = pos.shape()[0];
        if let Some((t, &v)) = tris.iter().enumerate().find_map(|(t, tri)| tri.iter().find(|&&v| v as usize >= n).map(|v| (t, v))) {
            let k = tris[t].iter().position(|&x| x == v).unwrap_or(0);
            return Err(PyValueError::new_err(format!(
                "triangles contains vertex index {v} (flat index {}) but there are {n} positions",
                3 * t + k
            )));
        }
        Ok(dqskin_core::rigs::mesh_volume(as_points(pos.as_slice()?), &tris))
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
///
/// A vertex without a center (fewer than two bones, or no triangle sharing two of them) gets its
/// own position, with which centers-of-rotation skinning is exactly linear blend skinning.
/// The GIL is released while it runs on dqskin's thread pool; Ctrl-C stops it
/// (``KeyboardInterrupt``).
#[pyfunction]
#[pyo3(signature = (positions, triangles, influences, sigma = None, *, with_mask = None, progress = None))]
fn centers_of_rotation<'py>(
    positions: &Bound<'py, PyAny>,
    triangles: &Bound<'py, PyAny>,
    influences: &Bound<'py, PyAny>,
    sigma: Option<&Bound<'py, PyAny>>,
    with_mask: Option<&Bound<'py, PyAny>>,
    progress: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    guard(|| {
        let py = positions.py();
        let sigma = args::or(sigma, dqskin_core::skin::DEFAULT_SIGMA, |o| args::float(o, "sigma"))?;
        let with_mask = args::or(with_mask, false, |o| args::boolean(o, "with_mask"))?;
        let infl = influences.cast::<PyInfluences>().map_err(|_| {
            PyTypeError::new_err("influences must be a dqskin.Influences (the weights of the same vertices)")
        })?;
        let infl = &infl.get().0;
        let v = infl.vertex_count();
        let pos = arrays::readonly::<f32>(positions, "positions", &[Some(v), Some(3)], &["V"])?;
        let tris = triangle_indices(triangles)?;
        let points = as_points(pos.as_slice()?);
        let callback = match progress {
            Some(p) if !p.is_none() => {
                if !p.is_callable() {
                    let ty = p.get_type().name().map(|n| n.to_string()).unwrap_or_default();
                    return Err(PyTypeError::new_err(format!("progress must be callable as progress(done, total), got {ty}")));
                }
                Some(p.clone().unbind())
            }
            _ => None,
        };
        // Between parts of the work the GIL is taken back: Ctrl-C, then the callback.
        let mut stopped: Option<PyErr> = None;
        let result = py.detach(|| {
            dqskin_core::centers_of_rotation_with_progress(points, &tris, infl, sigma, &mut |done, total| {
                Python::attach(|py| {
                    if let Err(e) = py.check_signals() {
                        stopped = Some(e);
                        return false;
                    }
                    let Some(cb) = &callback else { return true };
                    match cb.bind(py).call1((done, total)) {
                        Ok(r) if r.is_instance_of::<pyo3::types::PyBool>() && !r.is_truthy().unwrap_or(true) => {
                            stopped = Some(Cancelled::new_err("centers_of_rotation was cancelled by its progress callback"));
                            false
                        }
                        Ok(_) => true,
                        Err(e) => {
                            stopped = Some(e);
                            false
                        }
                    }
                })
            })
        });
        if let Some(e) = stopped {
            return Err(e);
        }
        let centers = result.map_err(skin_error)?;
        let flat: Vec<f32> = centers.centers.iter().flatten().copied().collect();
        let array = PyArray1::from_vec(py, flat).reshape([v, 3])?.into_any();
        if with_mask {
            let mask = PyArray1::from_vec(py, centers.has_center).into_any();
            Ok(pyo3::types::PyTuple::new(py, [array, mask])?.into_any())
        } else {
            Ok(array)
        }
    })
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
    m.add_function(wrap_pyfunction!(skin, m)?)?;
    m.add_function(wrap_pyfunction!(skin_many, m)?)?;
    m.add_function(wrap_pyfunction!(bbone_segment_matrices, m)?)?;
    m.add_function(wrap_pyfunction!(transform_points, m)?)?;
    m.add_function(wrap_pyfunction!(mesh_volume, m)?)?;
    m.add_function(wrap_pyfunction!(polygon_area, m)?)?;
    Ok(())
}

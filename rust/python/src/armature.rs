//! Armature poses from Blender's memory (`dqskin.memory.PoseMemory`, `PoseData`) and the per-frame
//! influences that use them (`Influences.effective`).

use dqskin_blend::{read_channel_matrices, read_pose, PoseLayout, ReadError, ReadHints};
use dqskin_core::glam::Mat4;
use dqskin_core::skin::ArmaturePose;
use dqskin_core::{Envelope, Influences};
use numpy::{PyArray1, PyArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::args;
use crate::arrays::{self, mat4_to_row_major};
use crate::blender::layout_of;
use crate::guard;
use crate::kept::KeptByAddress;
use crate::skinning::{matrices, skin_error, space, PyInfluences};

/// Reads armature poses straight from the memory of the running Blender: the channel matrices,
/// the bones' rest data and envelopes, and Blender's own B-Bone cache (joint matrices and the
/// Curved mapping's boundaries).
///
/// Built from the bytes of any uncompressed ``.blend`` file that this Blender wrote (its SDNA
/// describes the structs in memory). Internal to the DQ Skin extension.
#[pyclass(name = "PoseMemory", module = "dqskin.memory", frozen)]
pub struct PyPoseMemory {
    layout: PoseLayout,
    /// Each armature object's channel count (by address) as Blender's Python API last gave it. A
    /// read walks the channels against it and asks the API again only where they disagree: the
    /// API counts by visiting every pose bone (12 µs for a Rigify rig's 706, every frame). And
    /// where its last read went, prefetched before the next one ([`ReadHints`]).
    kept: KeptByAddress<Kept>,
}

/// What a reader keeps of an armature between reads.
struct Kept {
    count: usize,
    hints: ReadHints,
}

/// Armature objects a reader keeps counts and hints of at most (addresses of removed ones are
/// forgotten when it is full).
const KEPT_ARMATURES: usize = 1024;

#[pymethods]
impl PyPoseMemory {
    #[new]
    fn new(blend_file: &Bound<'_, PyAny>) -> PyResult<Self> {
        guard(|| {
            layout_of(blend_file, PoseLayout::new)
                .map(|layout| Self { layout, kept: KeptByAddress::new(KEPT_ARMATURES) })
        })
    }

    /// The pose of ``armature``, a ``bpy.types.Object`` of type ``'ARMATURE'`` with a pose
    /// (evaluated, ``armature.evaluated_get(depsgraph)``, for this frame's B-Bone shapes).
    fn read(&self, armature: &Bound<'_, PyAny>) -> PyResult<PyPoseData> {
        guard(|| {
            // SAFETY: the address is `Object.as_pointer()` of a live armature object (checked
            // by `armature_address` to be a `bpy.types.Object` of type ARMATURE with a pose), and
            // the walk stops at a count Blender's API gave for it (see `counted`). The
            // extension reads it from a handler or operator, while Blender does not evaluate, or
            // from the feed's driver inside an evaluation, which Blender runs after every
            // operation writing what is read (the driver's variables order it after each bound
            // bone and each B-Bone's segments: `routes.feed_drivers.order_after_bones`); nothing else
            // writes a pose during an evaluation. See `read_pose`; the extension checks the first
            // read of a session against Blender's own data (`blender.memory_check`).
            let read =
                self.counted(armature, |ptr, count, hints| unsafe { read_pose(&self.layout, ptr, count, hints) })?;
            ArmaturePose::from_bones(read.deforms, read.bones)
                .map(PyPoseData)
                .map_err(|e| PyValueError::new_err(format!("armature: {e}")))
        })
    }

    /// ``(N, 4, 4)`` float32, row-major: every pose bone's ``matrix_channel`` of ``armature``
    /// (as :meth:`read`), in ``pose.bones`` order; the rest of the pose is not read.
    fn channel_matrices<'py>(&self, armature: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        guard(|| {
            // SAFETY: as for `read`.
            let matrices = self.counted(armature, |ptr, count, hints| unsafe {
                read_channel_matrices(&self.layout, ptr, count, hints)
            })?;
            matrices_array(armature.py(), &matrices)
        })
    }
}

impl PyPoseMemory {
    /// `read(address, channel count)` of `armature`, with the count this reader kept for it;
    /// where that read fails (the channels or bones walked disagree with the count: bones added
    /// or removed, or another armature at a removed one's address), read again with the count
    /// Blender's API gives now.
    fn counted<T>(
        &self,
        armature: &Bound<'_, PyAny>,
        read: impl Fn(usize, usize, &mut ReadHints) -> Result<T, ReadError>,
    ) -> PyResult<T> {
        let ptr = armature_address(armature)?;
        // (The hints taken out for the read: a reader on another thread reads without them meanwhile.)
        let (count, mut hints) = self.kept.with(ptr, |k| match k {
            Some(k) => (Some(k.count), std::mem::take(&mut k.hints)),
            None => (None, ReadHints::default()),
        });
        let (found, count) = match count.map(|count| (read(ptr, count, &mut hints), count)) {
            Some((Err(_), _)) | None => {
                let count = channel_count(armature)?;
                (read(ptr, count, &mut hints), count)
            }
            Some(done) => done,
        };
        self.kept.put(ptr, Kept { count, hints });
        found.map_err(|e| PyValueError::new_err(format!("armature: {e}")))
    }
}

/// The address of ``armature``, checked to be a ``bpy.types.Object`` of type ``'ARMATURE'``
/// with a pose.
fn armature_address(armature: &Bound<'_, PyAny>) -> PyResult<usize> {
    let py = armature.py();
    crate::blender::require_bpy_type(py, armature, "Object", "armature")?;
    let kind: String = armature.getattr("type")?.extract()?;
    if kind != "ARMATURE" {
        return Err(PyValueError::new_err(format!("armature must be an armature object, got one of type {kind}")));
    }
    if armature.getattr("pose")?.is_none() {
        return Err(PyValueError::new_err("armature has no pose"));
    }
    armature.call_method0("as_pointer")?.extract()
}

/// ``len(armature.pose.bones)``.
fn channel_count(armature: &Bound<'_, PyAny>) -> PyResult<usize> {
    armature.getattr("pose")?.getattr("bones")?.len()
}

/// One frame of an armature's pose as the Armature modifier deforms with it (from
/// ``dqskin.memory.PoseMemory.read``). Its *bones* are the deforming pose bones in ``pose.bones`` order;
/// the *expanded* bone list adds each B-Bone's ``segments + 1`` joints after them, in bone order.
#[pyclass(name = "PoseData", module = "dqskin", frozen)]
pub struct PyPoseData(pub ArmaturePose);

fn matrices_array<'py>(py: Python<'py>, m: &[Mat4]) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<f32> = m.iter().flat_map(mat4_to_row_major).collect();
    Ok(PyArray1::from_vec(py, flat).reshape([m.len(), 4, 4])?.into_any())
}

#[pymethods]
impl PyPoseData {
    /// The bones' names.
    #[getter]
    fn names(&self) -> Vec<String> {
        self.0.bones().map(|c| c.name.clone()).collect()
    }

    /// Each bone's index in ``pose.bones`` (``int64``).
    #[getter]
    fn bone_indices<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        PyArray1::from_iter(py, self.0.bone_indices().iter().map(|&i| i as i64))
    }

    #[getter]
    fn bone_count(&self) -> usize {
        self.0.bone_count()
    }

    #[getter]
    fn expanded_bone_count(&self) -> usize {
        self.0.expanded_bone_count()
    }

    /// ``(E, 4, 4)`` float32 deform matrices of the expanded bone list (row-major): each bone's
    /// ``matrix_channel``, then the B-Bones' joints as Blender's cache has them.
    #[getter]
    fn deform<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        matrices_array(py, &self.0.deform_matrices())
    }

    /// ``(E, 4, 4)`` float32 rest matrices of the expanded bone list: each bone's
    /// ``matrix_local``, then each joint's orthonormal rest basis.
    #[getter]
    fn rest<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        matrices_array(py, &self.0.rest_matrices())
    }

    /// ``(B, 11)`` float32 envelope rows (the layout ``Influences.effective`` takes).
    #[getter]
    fn envelopes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let e = self.0.envelopes();
        let flat: Vec<f32> = e.iter().flat_map(envelope_row).collect();
        Ok(PyArray1::from_vec(py, flat).reshape([e.len(), 11])?.into_any())
    }

    /// Each bone's segment count as it deforms (``int64``): ``N`` for a B-Bone, 1 otherwise.
    #[getter]
    fn segments<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        PyArray1::from_iter(py, self.0.segments().into_iter().map(i64::from))
    }

    /// A digest of everything the influences depend on besides the vertices (names, order,
    /// deform flags, rest matrices, envelopes, B-Bone settings and rest shapes).
    #[getter]
    fn binding_signature(&self) -> u64 {
        self.0.binding_signature()
    }

    /// A digest of the expanded deform matrices.
    #[getter]
    fn pose_signature(&self) -> u64 {
        self.0.pose_signature()
    }

    fn __repr__(&self) -> String {
        format!("PoseData(bone_count={}, expanded_bone_count={})", self.0.bone_count(), self.0.expanded_bone_count())
    }
}

fn envelope_row(e: &Envelope) -> [f32; 11] {
    let (h, t) = (e.head, e.tail);
    [
        h.x,
        h.y,
        h.z,
        t.x,
        t.y,
        t.z,
        e.head_radius,
        e.tail_radius,
        e.distance,
        e.weight,
        f32::from(u8::from(e.multiply_groups)),
    ]
}

fn envelope_from_row(r: &[f32]) -> Envelope {
    Envelope {
        head: dqskin_core::glam::Vec3::new(r[0], r[1], r[2]),
        tail: dqskin_core::glam::Vec3::new(r[3], r[4], r[5]),
        head_radius: r[6],
        tail_radius: r[7],
        distance: r[8],
        weight: r[9],
        multiply_groups: r[10] != 0.0,
    }
}

/// The arguments of `Influences.effective` (see its documentation in `skinning.rs`).
pub struct EffectiveArgs<'a, 'py> {
    pub positions: &'a Bound<'py, PyAny>,
    pub premat: Option<&'a Bound<'py, PyAny>>,
    pub pose: Option<&'a Bound<'py, PyAny>>,
    pub envelopes: Option<&'a Bound<'py, PyAny>>,
    pub use_vertex_groups: Option<&'a Bound<'py, PyAny>>,
    pub use_envelopes: Option<&'a Bound<'py, PyAny>>,
    pub bbone_segments: Option<&'a Bound<'py, PyAny>>,
    pub rest: Option<&'a Bound<'py, PyAny>>,
    pub lengths: Option<&'a Bound<'py, PyAny>>,
    pub bbone_mapping: Option<&'a Bound<'py, PyDict>>,
}

fn given(obj: Option<&Bound<'_, PyAny>>) -> bool {
    obj.is_some_and(|o| !o.is_none())
}

/// `Influences.effective`: this frame's influences from `groups` with envelopes and B-Bones,
/// from a `PoseData` or from arrays.
pub fn effective(groups: &Influences, a: EffectiveArgs<'_, '_>) -> PyResult<PyInfluences> {
    let py = a.positions.py();
    let use_vertex_groups = args::or(a.use_vertex_groups, true, |o| args::boolean(o, "use_vertex_groups"))?;
    let use_envelopes = args::or(a.use_envelopes, false, |o| args::boolean(o, "use_envelopes"))?;
    let (v, b) = (groups.vertex_count(), groups.bone_count());
    let premat = space(a.premat, "premat")?;
    if let Some(pose) = a.pose.filter(|p| !p.is_none()) {
        let pose = pose.cast::<PyPoseData>().map_err(|_| {
            let ty = pose.get_type().name().map(|n| n.to_string()).unwrap_or_default();
            PyTypeError::new_err(format!(
                "pose must be a dqskin.PoseData (from dqskin.memory.PoseMemory.read), got {ty}"
            ))
        })?;
        let arrays_too = [
            ("envelopes", a.envelopes),
            ("bbone_segments", a.bbone_segments),
            ("rest", a.rest),
            ("lengths", a.lengths),
        ];
        if let Some((name, _)) = arrays_too.iter().find(|(_, o)| given(*o)) {
            return Err(PyValueError::new_err(format!("{name} is taken from pose: give one or the other")));
        }
        if a.bbone_mapping.is_some_and(|d| !d.is_empty()) {
            return Err(PyValueError::new_err("bbone_mapping is taken from pose: give one or the other"));
        }
        let pos = arrays::readonly::<f32>(a.positions, "positions", &[Some(v), Some(3)], &["V"])?;
        let points = pos.as_slice()?.as_chunks::<3>().0;
        let pose = &pose.get().0;
        return py
            .detach(|| pose.effective(groups, points, premat, use_vertex_groups, use_envelopes))
            .map(PyInfluences::wrap)
            .map_err(|e| PyValueError::new_err(format!("pose: {e}")));
    }
    let mut mapped: Vec<(usize, Vec<i32>, Vec<f32>)> = Vec::new();
    if let Some(d) = a.bbone_mapping {
        for (key, value) in d.iter() {
            let bone = args::int(&key, "bbone_mapping key", 0, u32::MAX as i64)? as usize;
            let (idx, blend): (Bound<'_, PyAny>, Bound<'_, PyAny>) = value
                .extract()
                .map_err(|_| PyTypeError::new_err("bbone_mapping values must be (index, blend) pairs of arrays"))?;
            let idx = arrays::readonly::<i32>(&idx, "bbone_mapping index", &[Some(v)], &["V"])?.as_slice()?.to_vec();
            let blend =
                arrays::readonly::<f32>(&blend, "bbone_mapping blend", &[Some(v)], &["V"])?.as_slice()?.to_vec();
            if bone >= b {
                return Err(PyValueError::new_err(format!("bbone_mapping has bone {bone}, but there are {b} bones")));
            }
            mapped.push((bone, idx, blend));
        }
    }
    let pos = arrays::readonly::<f32>(a.positions, "positions", &[Some(v), Some(3)], &["V"])?;
    let envelopes = match a.envelopes {
        Some(e) if !e.is_none() => {
            let env = arrays::readonly::<f32>(e, "envelopes", &[Some(b), Some(11)], &["B"])?;
            let data = env.as_slice()?;
            arrays::check_finite("envelopes", data)?;
            Some(data.chunks_exact(11).map(envelope_from_row).collect::<Vec<_>>())
        }
        _ => None,
    };
    let given_mappings: Vec<(usize, &[i32], &[f32])> =
        mapped.iter().map(|(bone, i, f)| (*bone, i.as_slice(), f.as_slice())).collect();
    let (bbones, expanded) = match a.bbone_segments {
        Some(seg) if !seg.is_none() => {
            let segments = arrays::indices(seg, "bbone_segments")?;
            if segments.len() != b {
                return Err(PyValueError::new_err(format!(
                    "bbone_segments must have {b} entries, got {}",
                    segments.len()
                )));
            }
            let rest = a.rest.ok_or_else(|| PyValueError::new_err("rest is required with bbone_segments"))?;
            let rest = matrices(rest, "rest", Some(b))?;
            let lengths = a.lengths.ok_or_else(|| PyValueError::new_err("lengths is required with bbone_segments"))?;
            let (lengths, _) = arrays::small(lengths, "lengths", &[Some(b)], &["B"])?;
            dqskin_core::skin::bbones_from_rest(&segments, &rest, &lengths, &given_mappings)
        }
        _ => (Vec::new(), b),
    };
    let what = dqskin_core::Effective {
        envelopes: envelopes.as_deref(),
        use_vertex_groups,
        use_envelopes,
        bbones: &bbones,
        expanded_bone_count: expanded,
    };
    let points = pos.as_slice()?.as_chunks::<3>().0;
    py.detach(|| groups.effective(points, premat, &what)).map(PyInfluences::wrap).map_err(skin_error)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyPoseMemory>()?;
    m.add_class::<PyPoseData>()?;
    Ok(())
}

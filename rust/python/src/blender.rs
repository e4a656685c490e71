//! Helpers for the Blender extension: fast reads of Blender's own data and the small pieces of
//! Blender's math that come before skinning (shape keys, the armature spaces). Not Blender
//! specific in their math; the memory reader is the only code that knows Blender's layout.

use dqskin_blend::{read_deform_verts, MeshLayout, Sdna};
use dqskin_core::shape_keys::{self, KeyBlock};
use dqskin_core::{DeformGroups, Influences};
use numpy::{PyArray1, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyList, PyTuple};

use crate::arrays::{self, mat4_from_row_major, mat4_to_row_major};
use crate::guard;
use crate::skinning::{skin_error, PyInfluences};

/// Reads vertex-group weights of meshes straight from the memory of the running Blender.
///
/// Built from the bytes of any uncompressed ``.blend`` file that this Blender wrote (e.g.
/// ``bpy.data.libraries.write(path, set())``): its SDNA describes the structs in memory.
/// Internal to the DQ Skin extension: a wrong pointer crashes the process.
#[pyclass(name = "_MeshMemory", module = "dqskin", frozen)]
pub struct PyMeshMemory(MeshLayout);

#[pymethods]
impl PyMeshMemory {
    #[new]
    fn new(blend_file: &Bound<'_, PyBytes>) -> PyResult<Self> {
        guard(|| {
            let sdna = Sdna::from_blend_file(blend_file.as_bytes()).map_err(|e| PyValueError::new_err(format!("blend_file: {e}")))?;
            MeshLayout::new(&sdna).map(Self).map_err(|e| PyValueError::new_err(format!("blend_file: {e}")))
        })
    }

    /// ``(offsets, groups, weights)`` (``uint32``, ``uint32``, ``float32``): the weights of the
    /// ``Mesh`` at ``mesh_pointer`` (``Mesh.as_pointer()``) in CSR form and stored order, or
    /// ``None`` if it has no vertex-group data. ``vertex_count`` must be ``len(mesh.vertices)``.
    fn deform_verts<'py>(&self, py: Python<'py>, mesh_pointer: u64, vertex_count: i64) -> PyResult<Option<Bound<'py, PyTuple>>> {
        guard(|| {
            let n = usize::try_from(vertex_count).map_err(|_| PyValueError::new_err("vertex_count must be ≥ 0"))?;
            let ptr = usize::try_from(mesh_pointer).map_err(|_| PyValueError::new_err("mesh_pointer is out of range"))?;
            // SAFETY: the extension passes `Mesh.as_pointer()` of a live mesh from a handler or
            // operator, while Blender is not evaluating (see `read_deform_verts`).
            let read = unsafe { read_deform_verts(&self.0, ptr, n) }.map_err(|e| PyValueError::new_err(format!("mesh_pointer: {e}")))?;
            match read {
                None => Ok(None),
                Some(d) => Ok(Some(PyTuple::new(
                    py,
                    [
                        PyArray1::from_vec(py, d.offsets).into_any(),
                        PyArray1::from_vec(py, d.groups).into_any(),
                        PyArray1::from_vec(py, d.weights).into_any(),
                    ],
                )?)),
            }
        })
    }
}

fn groups_arg<'py>(
    offsets: &Bound<'py, PyAny>,
    groups: &Bound<'py, PyAny>,
    weights: &Bound<'py, PyAny>,
) -> PyResult<(numpy::PyReadonlyArrayDyn<'py, u32>, numpy::PyReadonlyArrayDyn<'py, u32>, numpy::PyReadonlyArrayDyn<'py, f32>)> {
    Ok((
        arrays::readonly::<u32>(offsets, "offsets", &[None], &["V+1"])?,
        arrays::readonly::<u32>(groups, "groups", &[None], &["N"])?,
        arrays::readonly::<f32>(weights, "weights", &[None], &["N"])?,
    ))
}

/// Influences from vertex groups as Blender's Armature modifier maps them: ``offsets``,
/// ``groups`` (``uint32``) and ``weights`` (``float32``) in CSR form (``_MeshMemory``), and
/// ``group_to_bone``: for each vertex group index, the bone index or -1.
#[pyfunction]
fn influences_from_deform_groups(
    offsets: &Bound<'_, PyAny>,
    groups: &Bound<'_, PyAny>,
    weights: &Bound<'_, PyAny>,
    group_to_bone: &Bound<'_, PyAny>,
    bone_count: i64,
) -> PyResult<PyInfluences> {
    guard(|| {
        let bone_count = usize::try_from(bone_count).map_err(|_| PyValueError::new_err("bone_count must be ≥ 0"))?;
        let (o, g, w) = groups_arg(offsets, groups, weights)?;
        let map = arrays::readonly::<i32>(group_to_bone, "group_to_bone", &[None], &["G"])?;
        let map: Vec<Option<u32>> = map.as_slice()?.iter().map(|&b| u32::try_from(b).ok()).collect();
        let dg = DeformGroups { offsets: o.as_slice()?, groups: g.as_slice()?, weights: w.as_slice()? };
        let py = offsets.py();
        py.detach(|| Influences::from_deform_groups(dg, &map, bone_count)).map(PyInfluences).map_err(skin_error)
    })
}

/// Each vertex's weight in vertex group ``group`` (0 outside it), ``(V,)`` float32.
#[pyfunction]
fn deform_group_weights<'py>(
    offsets: &Bound<'py, PyAny>,
    groups: &Bound<'py, PyAny>,
    weights: &Bound<'py, PyAny>,
    group: i64,
) -> PyResult<Bound<'py, PyArray1<f32>>> {
    guard(|| {
        let group = u32::try_from(group).map_err(|_| PyValueError::new_err("group must be a vertex group index ≥ 0"))?;
        let (o, g, w) = groups_arg(offsets, groups, weights)?;
        let dg = DeformGroups { offsets: o.as_slice()?, groups: g.as_slice()?, weights: w.as_slice()? };
        let v = dqskin_core::deform_group_weights(dg, group).map_err(skin_error)?;
        Ok(PyArray1::from_vec(offsets.py(), v))
    })
}

/// The coordinates shape keys give a mesh before its modifiers, into ``out`` ``(V, 3)``
/// float32, exactly as Blender mixes relative keys.
///
/// ``keys``: one ``(data, relative_to, value, muted, weights)`` per key block in order:
/// ``data`` ``(N, 3)`` float32, ``relative_to`` the index of its relative key, ``value``,
/// ``muted``, ``weights`` ``(N,)`` float32 of its vertex group or None. ``reference``: the
/// basis key's index. ``shown``: with Shape Key Lock, the index of the key shown alone.
#[pyfunction]
#[pyo3(signature = (keys, reference, out, shown = None))]
fn shape_key_mix(keys: &Bound<'_, PyList>, reference: i64, out: &Bound<'_, PyAny>, shown: Option<i64>) -> PyResult<()> {
    guard(|| {
        let reference = usize::try_from(reference).map_err(|_| PyValueError::new_err("reference must be ≥ 0"))?;
        let mut held = Vec::with_capacity(keys.len());
        for (i, item) in keys.iter().enumerate() {
            let t = item.cast::<PyTuple>().map_err(|_| PyTypeError::new_err(format!("keys[{i}] must be a tuple (data, relative_to, value, muted, weights)")))?;
            if t.len() != 5 {
                return Err(PyValueError::new_err(format!("keys[{i}] must have 5 items, got {}", t.len())));
            }
            let data = arrays::readonly::<f32>(&t.get_item(0)?, "keys[i].data", &[None, Some(3)], &["N"])?;
            let relative: i64 = t.get_item(1)?.extract().map_err(|_| PyTypeError::new_err(format!("keys[{i}].relative_to must be an integer")))?;
            let value: f32 = t.get_item(2)?.extract().map_err(|_| PyTypeError::new_err(format!("keys[{i}].value must be a number")))?;
            let muted: bool = t.get_item(3)?.extract().map_err(|_| PyTypeError::new_err(format!("keys[{i}].muted must be a bool")))?;
            let w = t.get_item(4)?;
            let weights = if w.is_none() { None } else { Some(arrays::readonly::<f32>(&w, "keys[i].weights", &[Some(data.shape()[0])], &["N"])?) };
            if !value.is_finite() {
                return Err(PyValueError::new_err(format!("keys[{i}].value is not finite")));
            }
            held.push((data, usize::try_from(relative).unwrap_or(usize::MAX), value, muted, weights));
        }
        let blocks = held
            .iter()
            .map(|(d, r, v, m, w)| {
                Ok(KeyBlock {
                    data: as_points(d.as_slice()?),
                    relative_to: *r,
                    value: *v,
                    muted: *m,
                    weights: match w {
                        Some(w) => Some(w.as_slice()?),
                        None => None,
                    },
                })
            })
            .collect::<PyResult<Vec<_>>>()?;
        let mut o = arrays::readwrite::<f32>(out, "out", &[None, Some(3)], &["V"])?;
        let o = as_points_mut(o.as_slice_mut()?);
        let r = match shown {
            Some(s) => shape_keys::mix_locked(&blocks, reference, usize::try_from(s).unwrap_or(usize::MAX), o),
            None => shape_keys::mix_relative(&blocks, reference, o),
        };
        r.map_err(|e| PyValueError::new_err(format!("keys: {e}")))
    })
}

/// ``(premat, postmat)`` of Blender's Armature modifier from the mesh object's and the
/// armature object's world matrices (row-major 4×4): ``postmat = inverse(object) · armature``,
/// ``premat = inverse(postmat)``, in single precision as Blender computes them.
#[pyfunction]
fn armature_spaces<'py>(py: Python<'py>, object_world: &Bound<'py, PyAny>, armature_world: &Bound<'py, PyAny>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    guard(|| {
        let (o, _) = arrays::small(object_world, "object_world", &[Some(4), Some(4)], &[])?;
        let (a, _) = arrays::small(armature_world, "armature_world", &[Some(4), Some(4)], &[])?;
        let (o, a) = (mat4_from_row_major(&o), mat4_from_row_major(&a));
        if o.determinant() == 0.0 || !o.determinant().is_finite() {
            return Err(PyValueError::new_err("object_world is not invertible (zero scale?)"));
        }
        let (pre, post) = dqskin_core::armature_spaces(o, a);
        if !pre.is_finite() || !post.is_finite() {
            return Err(PyValueError::new_err("armature_world is not invertible (zero scale?)"));
        }
        let m = |m| -> PyResult<Bound<'py, PyAny>> { Ok(PyArray1::from_slice(py, &mat4_to_row_major(&m)).reshape([4, 4])?.into_any()) };
        Ok((m(pre)?, m(post)?))
    })
}

fn as_points(flat: &[f32]) -> &[[f32; 3]] {
    flat.as_chunks::<3>().0
}

fn as_points_mut(flat: &mut [f32]) -> &mut [[f32; 3]] {
    flat.as_chunks_mut::<3>().0
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyMeshMemory>()?;
    m.add_function(wrap_pyfunction!(influences_from_deform_groups, m)?)?;
    m.add_function(wrap_pyfunction!(deform_group_weights, m)?)?;
    m.add_function(wrap_pyfunction!(shape_key_mix, m)?)?;
    m.add_function(wrap_pyfunction!(armature_spaces, m)?)?;
    Ok(())
}

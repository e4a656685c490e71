//! Helpers for the Blender extension: fast reads of Blender's own data and the small pieces of
//! Blender's math that come before skinning (shape keys, the armature spaces). Not Blender
//! specific in their math; the memory reader is the only code that knows Blender's layout.

use dqskin_blend::{positions_in_memory, read_deform_verts, read_positions, DnaError, MeshLayout, Sdna};
use dqskin_core::digest::Digest;
use dqskin_core::shape_keys::{self, KeyBlock};
use dqskin_core::{DeformGroups, Influences};
use numpy::{PyArray1, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyBytes, PyList, PyTuple};

use crate::args;
use crate::arrays::{self, mat4_from_row_major, mat4_to_row_major};
use crate::guard;
use crate::skinning::{skin_error, PyInfluences};

/// Reads vertex-group weights of meshes straight from the memory of the running Blender.
///
/// Built from the bytes of any uncompressed ``.blend`` file that this Blender wrote (e.g.
/// ``bpy.data.libraries.write(path, set())``): its SDNA describes the structs in memory.
/// Internal to the DQ Skin extension: a wrong pointer crashes the process.
#[pyclass(name = "MeshMemory", module = "dqskin.memory", frozen)]
pub struct PyMeshMemory(MeshLayout);

#[pymethods]
impl PyMeshMemory {
    #[new]
    fn new(blend_file: &Bound<'_, PyAny>) -> PyResult<Self> {
        guard(|| layout_of(blend_file, MeshLayout::new).map(Self))
    }

    /// ``(V, 3)`` float32: the vertex positions of ``mesh`` (a ``bpy.types.Mesh``), or ``None``
    /// if this Blender keeps them where the reader does not look. Unlike Blender's Python API,
    /// reading does not make a mesh that shares its positions with copies take its own.
    fn positions<'py>(&self, py: Python<'py>, mesh: &Bound<'py, PyAny>) -> PyResult<Option<Bound<'py, PyAny>>> {
        guard(|| {
            let (ptr, n) = mesh_pointer(py, mesh)?;
            let out = numpy::PyArray2::<f32>::zeros(py, [n, 3], false);
            let copied = {
                let mut rw = out.readwrite();
                let flat = rw.as_slice_mut()?;
                // SAFETY: as for `deform_verts`.
                unsafe { read_positions(&self.0, ptr, as_points_mut(flat)) }
                    .map_err(|e| PyValueError::new_err(format!("mesh_pointer: {e}")))?
            };
            Ok(copied.then(|| out.into_any()))
        })
    }

    /// A :class:`MeshPositions` of ``mesh`` (an original ``bpy.types.Mesh``): its positions
    /// where Blender keeps them, read by the kernel on every run without a copy; or ``None`` if
    /// this Blender keeps them where the reader does not look.
    fn positions_in_place(&self, py: Python<'_>, mesh: &Bound<'_, PyAny>) -> PyResult<Option<PyMeshPositions>> {
        guard(|| {
            let (ptr, n) = mesh_pointer(py, mesh)?;
            if !in_blend_data(py, mesh, ptr)? {
                // (An evaluated mesh is made and freed by each evaluation: not a mesh to keep.)
                return Err(PyValueError::new_err("mesh must be an original mesh of bpy.data, not an evaluated copy"));
            }
            // SAFETY: as for `deform_verts`; the slice is not kept.
            let found = unsafe { positions_in_memory(&self.0, ptr, n) }
                .map_err(|e| PyValueError::new_err(format!("mesh_pointer: {e}")))?;
            Ok(found.map(|_| PyMeshPositions { layout: self.0, mesh: mesh.clone().unbind(), vertices: n }))
        })
    }

    /// ``(offsets, groups, weights)`` (``uint32``, ``uint32``, ``float32``): the weights of
    /// ``mesh`` (a ``bpy.types.Mesh``) in CSR form and stored order, or ``None`` if it has no
    /// vertex-group data.
    fn deform_verts<'py>(&self, py: Python<'py>, mesh: &Bound<'py, PyAny>) -> PyResult<Option<Bound<'py, PyTuple>>> {
        guard(|| {
            let (ptr, n) = mesh_pointer(py, mesh)?;
            // SAFETY: the extension passes `Mesh.as_pointer()` of a live mesh from a handler or
            // operator, while Blender is not evaluating (see `read_deform_verts`).
            let read = unsafe { read_deform_verts(&self.0, ptr, n) }
                .map_err(|e| PyValueError::new_err(format!("mesh_pointer: {e}")))?;
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

/// A mesh's vertex positions where Blender keeps them (``MeshMemory.positions_in_place``): a
/// :class:`dqskin.SkinJob` given one as ``positions`` reads Blender's own array when it runs,
/// instead of a copy kept beside it. The mesh is found again on every run (``as_pointer``): a
/// mesh removed since, or one whose vertex count changed, makes that run's entry of
/// :func:`dqskin.skin_many` an error, never a read of freed memory.
#[pyclass(name = "MeshPositions", module = "dqskin.memory", frozen)]
pub struct PyMeshPositions {
    layout: MeshLayout,
    mesh: Py<PyAny>,
    vertices: usize,
}

impl PyMeshPositions {
    /// The vertex count the mesh had when this was made.
    pub(crate) fn vertex_count(&self) -> usize {
        self.vertices
    }

    /// The positions as they are now, for one call.
    ///
    /// # Safety
    /// The caller uses the slice only while Blender frees, reallocates and writes none of this
    /// mesh's data: during a call made from a handler, an operator or a driver of Blender's
    /// evaluation (the evaluation writes evaluated copies only; edit mode writes the mesh when
    /// it is left, from an operator). Python threads other than the caller's must not change
    /// meshes meanwhile, which Blender's API forbids anyway.
    pub(crate) unsafe fn resolve<'a>(&self, py: Python<'_>) -> PyResult<&'a [[f32; 3]]> {
        let mesh = self.mesh.bind(py);
        let name = || mesh.getattr("name").map(|n| n.to_string()).unwrap_or_default();
        let ptr: usize = match mesh.call_method0("as_pointer") {
            Ok(p) => p.extract()?,
            Err(_) => return Err(PyValueError::new_err("positions: the mesh was removed")),
        };
        // SAFETY: the mesh is live (Blender invalidates the Python object of a freed ID, so
        // `as_pointer` just succeeded on a live one), original (checked when made), and unchanged
        // while the slice is used (caller).
        match unsafe { positions_in_memory(&self.layout, ptr, self.vertices) } {
            Ok(Some(found)) => Ok(found),
            Ok(None) => Err(PyValueError::new_err(format!("positions: the mesh '{}' has no position layer", name()))),
            Err(e) => Err(PyValueError::new_err(format!("positions: the mesh '{}': {e}", name()))),
        }
    }
}

#[pymethods]
impl PyMeshPositions {
    /// The mesh (``bpy.types.Mesh``).
    #[getter]
    fn mesh(&self, py: Python<'_>) -> Py<PyAny> {
        self.mesh.clone_ref(py)
    }

    /// The vertex count the mesh had when this was made (its positions must keep it).
    fn __len__(&self) -> usize {
        self.vertices
    }

    /// A ``(V, 3)`` float32 copy of the positions as they are now.
    fn read<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        guard(|| {
            // SAFETY: used only within this call, made from Python while Blender waits on it.
            let found = unsafe { self.resolve(py) }?;
            let out = numpy::PyArray2::<f32>::zeros(py, [found.len(), 3], false);
            out.readwrite().as_slice_mut()?.copy_from_slice(found.as_flattened());
            Ok(out.into_any())
        })
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let name = self.mesh.bind(py).getattr("name").map(|n| n.to_string()).unwrap_or_else(|_| "<removed>".into());
        format!("MeshPositions(mesh={name:?}, vertices={})", self.vertices)
    }
}

/// 16 bytes that change whenever ``positions`` do (``(V, 3)`` float32, or a
/// :class:`dqskin.memory.MeshPositions`, read as it is now): compared instead of a copy kept to
/// compare with. The same positions give the same bytes either way.
#[pyfunction]
fn positions_digest<'py>(py: Python<'py>, positions: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyBytes>> {
    guard(|| {
        let digest = if let Ok(handle) = positions.cast::<PyMeshPositions>() {
            // SAFETY: used only within this call, made from Python while Blender waits on it.
            let found = unsafe { handle.get().resolve(py) }?;
            digest_of(found.as_flattened())
        } else {
            let a = arrays::readonly::<f32>(positions, "positions", &[None, Some(3)], &["V"])?;
            digest_of(a.as_slice()?)
        };
        Ok(PyBytes::new(py, &digest))
    })
}

/// Two fast digests with different seeds over the values' bits and their count
/// (`dqskin_core::digest`: only ever compared with an earlier one, nothing adversarial).
fn digest_of(values: &[f32]) -> [u8; 16] {
    two_digests(|h| h.floats(values))
}

/// Two fast digests with different seeds over `bytes` and their count.
pub(crate) fn digest_of_bytes(bytes: &[u8]) -> [u8; 16] {
    two_digests(|h| h.bytes(bytes))
}

/// 16 bytes: two digests, seeded 0 and 1, of what `feed` writes.
fn two_digests(feed: impl Fn(&mut Digest)) -> [u8; 16] {
    let mut out = [0u8; 16];
    for (seed, part) in out.chunks_exact_mut(8).enumerate() {
        let mut h = Digest::seeded(seed as u64);
        feed(&mut h);
        part.copy_from_slice(&h.finish().to_le_bytes());
    }
    out
}

/// Refuses `obj` (the argument `arg`) unless it is a real `bpy.types.<type_name>`: the memory
/// readers take addresses from Blender itself, never from the caller.
pub(crate) fn require_bpy_type(py: Python<'_>, obj: &Bound<'_, PyAny>, type_name: &str, arg: &str) -> PyResult<()> {
    let is_one = match bpy_types(py) {
        Some(types) => match types.bind(py).getattr(type_name) {
            Ok(t) => obj.is_instance(&t)?,
            Err(_) => false,
        },
        None => false, // not inside Blender
    };
    if !is_one {
        let ty = obj.get_type().name().map(|n| n.to_string()).unwrap_or_default();
        return Err(PyTypeError::new_err(format!("{arg} must be a bpy.types.{type_name}, got {ty}")));
    }
    Ok(())
}

/// `bpy.types`, imported once (the readers check every object they are given, a crowd's
/// characters on every frame), or None outside Blender.
fn bpy_types(py: Python<'_>) -> Option<&Py<PyAny>> {
    static TYPES: PyOnceLock<Py<PyAny>> = PyOnceLock::new();
    if let Some(types) = TYPES.get(py) {
        return Some(types);
    }
    let types = py.import("bpy").and_then(|bpy| bpy.getattr("types")).ok()?;
    Some(TYPES.get_or_init(py, || types.unbind()))
}

/// Whether `mesh` (at `ptr`) is the mesh of `bpy.data.meshes` of its name and library.
fn in_blend_data(py: Python<'_>, mesh: &Bound<'_, PyAny>, ptr: usize) -> PyResult<bool> {
    let name = mesh.getattr("name")?;
    let library = mesh.getattr("library")?;
    let path = if library.is_none() { library } else { library.getattr("filepath")? };
    let found = py.import("bpy")?.getattr("data")?.getattr("meshes")?.call_method1("get", ((name, path),))?;
    Ok(!found.is_none() && found.call_method0("as_pointer")?.extract::<usize>()? == ptr)
}

/// The address and vertex count of `mesh`, a real Blender mesh.
fn mesh_pointer(py: Python<'_>, mesh: &Bound<'_, PyAny>) -> PyResult<(usize, usize)> {
    require_bpy_type(py, mesh, "Mesh", "mesh")?;
    let ptr: usize = mesh.call_method0("as_pointer")?.extract()?;
    let n: usize = mesh.getattr("vertices")?.len()?;
    Ok((ptr, n))
}

/// A memory reader's layout, built by `build` from the SDNA of `blend_file` (the bytes of a
/// `.blend` file this Blender wrote); what is missing or wrong is a `ValueError` naming it.
pub(crate) fn layout_of<L>(
    blend_file: &Bound<'_, PyAny>,
    build: impl FnOnce(&Sdna) -> Result<L, DnaError>,
) -> PyResult<L> {
    build(&sdna_of(blend_file)?).map_err(|e| PyValueError::new_err(format!("blend_file: {e}")))
}

/// The SDNA of `blend_file`, the bytes of a `.blend` file.
fn sdna_of(blend_file: &Bound<'_, PyAny>) -> PyResult<Sdna> {
    let bytes = blend_file.cast::<PyBytes>().map_err(|_| {
        let ty = blend_file.get_type().name().map(|n| n.to_string()).unwrap_or_default();
        PyTypeError::new_err(format!("blend_file must be the bytes of a .blend file, got {ty}"))
    })?;
    Sdna::from_blend_file(bytes.as_bytes()).map_err(|e| PyValueError::new_err(format!("blend_file: {e}")))
}

fn groups_arg<'py>(
    offsets: &Bound<'py, PyAny>,
    groups: &Bound<'py, PyAny>,
    weights: &Bound<'py, PyAny>,
) -> PyResult<(
    numpy::PyReadonlyArrayDyn<'py, u32>,
    numpy::PyReadonlyArrayDyn<'py, u32>,
    numpy::PyReadonlyArrayDyn<'py, f32>,
)> {
    Ok((
        arrays::readonly::<u32>(offsets, "offsets", &[None], &["V+1"])?,
        arrays::readonly::<u32>(groups, "groups", &[None], &["N"])?,
        arrays::readonly::<f32>(weights, "weights", &[None], &["N"])?,
    ))
}

/// Influences from vertex groups as Blender's Armature modifier maps them: ``offsets``,
/// ``groups`` (``uint32``) and ``weights`` (``float32``) in CSR form (``dqskin.memory.MeshMemory``), and
/// ``group_to_bone``: for each vertex group index, the bone index or -1.
#[pyfunction]
fn influences_from_deform_groups(
    offsets: &Bound<'_, PyAny>,
    groups: &Bound<'_, PyAny>,
    weights: &Bound<'_, PyAny>,
    group_to_bone: &Bound<'_, PyAny>,
    bone_count: &Bound<'_, PyAny>,
) -> PyResult<PyInfluences> {
    guard(|| {
        let bone_count = args::int(bone_count, "bone_count", 0, u32::MAX as i64)? as usize;
        let (o, g, w) = groups_arg(offsets, groups, weights)?;
        let map = arrays::readonly::<i32>(group_to_bone, "group_to_bone", &[None], &["G"])?;
        let map: Vec<Option<u32>> = map.as_slice()?.iter().map(|&b| u32::try_from(b).ok()).collect();
        if let Some(g) = map.iter().position(|b| b.is_some_and(|b| b as usize >= bone_count)) {
            return Err(PyValueError::new_err(format!(
                "group_to_bone[{g}] = {} is not below bone_count = {bone_count}",
                map[g].unwrap()
            )));
        }
        let dg = DeformGroups { offsets: o.as_slice()?, groups: g.as_slice()?, weights: w.as_slice()? };
        let py = offsets.py();
        py.detach(|| Influences::from_deform_groups(dg, &map, bone_count)).map(PyInfluences::wrap).map_err(skin_error)
    })
}

/// Each vertex's weight in vertex group ``group`` (0 outside it), ``(V,)`` float32.
#[pyfunction]
fn deform_group_weights<'py>(
    offsets: &Bound<'py, PyAny>,
    groups: &Bound<'py, PyAny>,
    weights: &Bound<'py, PyAny>,
    group: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray1<f32>>> {
    guard(|| {
        let group = args::int(group, "group", 0, u32::MAX as i64)? as u32;
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
fn shape_key_mix(
    keys: &Bound<'_, PyAny>,
    reference: &Bound<'_, PyAny>,
    out: &Bound<'_, PyAny>,
    shown: Option<&Bound<'_, PyAny>>,
) -> PyResult<()> {
    guard(|| {
        let keys = keys.cast::<PyList>().map_err(|_| {
            PyTypeError::new_err("keys must be a list of (data, relative_to, value, muted, weights) tuples")
        })?;
        let reference = args::int(reference, "reference", 0, i32::MAX as i64)? as usize;
        let shown = match shown {
            Some(s) if !s.is_none() => Some(args::int(s, "shown", 0, i32::MAX as i64)?),
            _ => None,
        };
        let mut held = Vec::with_capacity(keys.len());
        for (i, item) in keys.iter().enumerate() {
            let t = item.cast::<PyTuple>().map_err(|_| {
                PyTypeError::new_err(format!("keys[{i}] must be a tuple (data, relative_to, value, muted, weights)"))
            })?;
            if t.len() != 5 {
                return Err(PyValueError::new_err(format!("keys[{i}] must have 5 items, got {}", t.len())));
            }
            let data = arrays::readonly::<f32>(&t.get_item(0)?, "keys[i].data", &[None, Some(3)], &["N"])?;
            let relative = args::int(&t.get_item(1)?, &format!("keys[{i}].relative_to"), -1, i32::MAX as i64)?;
            let value = args::float(&t.get_item(2)?, &format!("keys[{i}].value"))?;
            let muted = args::boolean(&t.get_item(3)?, &format!("keys[{i}].muted"))?;
            let w = t.get_item(4)?;
            let weights = if w.is_none() {
                None
            } else {
                Some(arrays::readonly::<f32>(&w, "keys[i].weights", &[Some(data.shape()[0])], &["N"])?)
            };
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
            Some(s) => shape_keys::mix_locked(&blocks, reference, s as usize, o),
            None => shape_keys::mix_relative(&blocks, reference, o),
        };
        r.map_err(|e| PyValueError::new_err(format!("keys: {e}")))
    })
}

/// ``(premat, postmat)`` of Blender's Armature modifier from the mesh object's and the
/// armature object's world matrices (row-major 4×4): ``postmat = inverse(object) · armature``,
/// ``premat = inverse(postmat)``, in single precision as Blender computes them.
#[pyfunction]
fn armature_spaces<'py>(
    py: Python<'py>,
    object_world: &Bound<'py, PyAny>,
    armature_world: &Bound<'py, PyAny>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
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
        let m = |m| -> PyResult<Bound<'py, PyAny>> {
            Ok(PyArray1::from_slice(py, &mat4_to_row_major(&m)).reshape([4, 4])?.into_any())
        };
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
    m.add_class::<PyMeshPositions>()?;
    m.add_function(wrap_pyfunction!(positions_digest, m)?)?;
    m.add_function(wrap_pyfunction!(influences_from_deform_groups, m)?)?;
    m.add_function(wrap_pyfunction!(deform_group_weights, m)?)?;
    m.add_function(wrap_pyfunction!(shape_key_mix, m)?)?;
    m.add_function(wrap_pyfunction!(armature_spaces, m)?)?;
    Ok(())
}

//! `dqskin.memory.ObjectStateMemory`: what decides whether a DQ Skin object's fed frame stands,
//! read from Blender's memory in one call (`dqskin_blend::read_object_state`).

use std::cell::RefCell;

use dqskin_blend::{describe_object, read_object_state, ObjectStateLayout, PropertyValue, StateHints};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};

use crate::blender::{digest_of_bytes, layout_of, require_bpy_type};
use crate::guard;
use crate::kept::KeptByAddress;

thread_local! {
    /// The buffer a state is read into (no allocation per call once it has grown).
    static SCRATCH: RefCell<Vec<u8>> = const { RefCell::new(Vec::new()) };
}

/// Reads, for a ``bpy.types.Object``, its mode, its modifier stack (each modifier's type,
/// switches, flags, id and name; a Geometry Nodes modifier's node group and inputs; an
/// Armature modifier's settings), the mode of the objects those point to, and its mesh's
/// vertex-group names: a state of a few kilobytes a character, kept as its 16-byte digest (as
/// `positions_digest` keeps positions) and only compared with an earlier one of the same object.
///
/// Built from the bytes of any uncompressed ``.blend`` file that this Blender wrote (its SDNA
/// describes the structs in memory). Internal to the DQ Skin extension.
#[pyclass(name = "ObjectStateMemory", module = "dqskin.memory", frozen)]
pub struct PyObjectStateMemory {
    layout: ObjectStateLayout,
    /// Where the last read of each object (by address) went, prefetched before the next one
    /// ([`StateHints`]: the frame handler reads each character once a frame, right after
    /// Blender's evaluation has moved what it walks out of the caches).
    kept: KeptByAddress<StateHints>,
}

/// Objects a reader keeps hints of at most.
const KEPT_OBJECTS: usize = 4096;

#[pymethods]
impl PyObjectStateMemory {
    #[new]
    fn new(blend_file: &Bound<'_, PyAny>) -> PyResult<Self> {
        guard(|| {
            layout_of(blend_file, ObjectStateLayout::new)
                .map(|layout| Self { layout, kept: KeptByAddress::new(KEPT_OBJECTS) })
        })
    }

    /// The digest of the state of ``obj`` (a ``bpy.types.Object``): 16 bytes.
    fn digest<'py>(&self, obj: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyBytes>> {
        guard(|| Ok(PyBytes::new(obj.py(), &self.read(obj)?)))
    }

    /// Whether the state of ``obj`` has the digest ``previous`` (from :meth:`digest`).
    fn unchanged(&self, obj: &Bound<'_, PyAny>, previous: &[u8]) -> PyResult<bool> {
        guard(|| Ok(self.read(obj)?.as_slice() == previous))
    }

    /// The same reads as values, for the check against Blender's Python API: ``{"mode": int,
    /// "vertex_groups": [str], "modifiers": [{"type": int, "mode": int, "name": str,
    /// "node_group": int, "inputs": {name: value}, "object": int}]}`` (addresses as ints; a
    /// group of properties as a dict; an array by its length).
    fn describe<'py>(&self, obj: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyDict>> {
        guard(|| {
            let py = obj.py();
            let ptr = object_pointer(obj)?;
            // SAFETY: as in `read`.
            let s = unsafe { describe_object(&self.layout, ptr) }
                .map_err(|e| PyValueError::new_err(format!("obj: {e}")))?;
            let modifiers = PyList::empty(py);
            for m in &s.modifiers {
                let d = PyDict::new(py);
                d.set_item("inputs", properties(py, &m.inputs)?)?;
                d.set_item("type", m.kind)?;
                d.set_item("mode", m.mode)?;
                d.set_item("name", text(&m.name))?;
                d.set_item("node_group", m.node_group)?;
                d.set_item("object", m.object)?;
                modifiers.append(d)?;
            }
            let out = PyDict::new(py);
            out.set_item("mode", s.mode)?;
            out.set_item("vertex_groups", s.vertex_groups.iter().map(|g| text(g)).collect::<Vec<_>>())?;
            out.set_item("modifiers", modifiers)?;
            Ok(out)
        })
    }
}

/// ID properties as a dict (a group as a dict of its own).
fn properties<'py>(py: Python<'py>, props: &[(Vec<u8>, PropertyValue)]) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    for (name, value) in props {
        let v: Bound<'_, PyAny> = match value {
            PropertyValue::Int(i) => i.into_pyobject(py)?.into_any(),
            PropertyValue::Float(f) => f.into_pyobject(py)?.into_any(),
            PropertyValue::Double(f) => f.into_pyobject(py)?.into_any(),
            PropertyValue::Bool(b) => b.into_pyobject(py)?.to_owned().into_any(),
            PropertyValue::String(b) => text(b.strip_suffix(&[0]).unwrap_or(b)).into_pyobject(py)?.into_any(),
            PropertyValue::Id(p) | PropertyValue::Array(p) => p.into_pyobject(py)?.into_any(),
            PropertyValue::Group(inner) => properties(py, inner)?.into_any(),
        };
        out.set_item(text(name), v)?;
    }
    Ok(out)
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

impl PyObjectStateMemory {
    /// The digest of the state of `obj`.
    fn read(&self, obj: &Bound<'_, PyAny>) -> PyResult<[u8; 16]> {
        let ptr = object_pointer(obj)?;
        // (Taken out for the read: a reader on another thread reads without them meanwhile.)
        let mut hints = self.kept.with(ptr, |h| h.map(std::mem::take).unwrap_or_default());
        let digest = SCRATCH.with_borrow_mut(|state| {
            // SAFETY: the address is `Object.as_pointer()` of a live object (checked above to be
            // a `bpy.types.Object`; a removed one raises there). The extension reads it from its
            // frame handler, while Blender does not evaluate or edit anything; every pointer
            // followed is one Blender keeps valid (its lists, and ID pointers, which it clears
            // or remaps when the data-block goes). The extension checks the first read of a
            // session against Blender's own data (`blender.memory_check`).
            unsafe { read_object_state(&self.layout, ptr, state, &mut hints) }
                .map_err(|e| PyValueError::new_err(format!("obj: {e}")))?;
            Ok(digest_of_bytes(state))
        });
        self.kept.put(ptr, hints);
        digest
    }
}

/// The address of ``obj``, checked to be a ``bpy.types.Object``.
fn object_pointer(obj: &Bound<'_, PyAny>) -> PyResult<usize> {
    require_bpy_type(obj.py(), obj, "Object", "obj")?;
    obj.call_method0("as_pointer")?.extract()
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyObjectStateMemory>()
}

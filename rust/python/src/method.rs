//! `dqskin.Method`: the skinning methods, one enum for every layer (the strings of `skin()`, the
//! labels of the Blender menu), and the one place that turns a method into the core's.

use dqskin_core::Method;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyString;

/// A skinning method: ``Method.LINEAR`` (Blender's Preserve Volume off),
/// ``Method.DUAL_QUATERNION`` (on), ``Method.BLEND`` (a per-vertex mix of the two) or
/// ``Method.CENTERS_OF_ROTATION`` (Le & Hodgins 2016, "Optimized Centers" in Blender).
///
/// ``Method(value)`` looks one up from its name as :func:`skin` takes it (``'linear'``,
/// ``'dual_quaternion'``, ``'blend'``, ``'centers_of_rotation'``, in any case, or the short
/// ``'lbs'``, ``'dqs'``, ``'cor'``) or from its :attr:`label`.
#[pyclass(name = "Method", module = "dqskin", eq, frozen, hash)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PyMethod {
    #[pyo3(name = "LINEAR")]
    Linear,
    #[pyo3(name = "DUAL_QUATERNION")]
    DualQuaternion,
    #[pyo3(name = "BLEND")]
    Blend,
    #[pyo3(name = "CENTERS_OF_ROTATION")]
    CentersOfRotation,
}

const ALL: [PyMethod; 4] = [PyMethod::Linear, PyMethod::DualQuaternion, PyMethod::Blend, PyMethod::CentersOfRotation];

impl PyMethod {
    /// The name `skin()` takes, then the short alias if there is one.
    fn names(self) -> &'static [&'static str] {
        match self {
            Self::Linear => &["linear", "lbs"],
            Self::DualQuaternion => &["dual_quaternion", "dqs"],
            Self::Blend => &["blend"],
            Self::CentersOfRotation => &["centers_of_rotation", "cor"],
        }
    }

    /// The name `skin()` takes (for messages).
    pub fn key(self) -> &'static str {
        self.names()[0]
    }

    fn label_text(self) -> &'static str {
        match self {
            Self::Linear => "Linear",
            Self::DualQuaternion => "Dual Quaternion",
            Self::Blend => "Blend",
            Self::CentersOfRotation => "Optimized Centers",
        }
    }

    /// A `Method`, a name or a label; errors name the argument `name`.
    pub fn from_arg(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Self> {
        if let Ok(m) = obj.cast::<PyMethod>() {
            return Ok(*m.get());
        }
        let Ok(text) = obj.cast::<PyString>() else {
            let ty = obj.get_type().name().map(|n| n.to_string()).unwrap_or_default();
            return Err(PyTypeError::new_err(format!("{name} must be a dqskin.Method or a string, got {ty}")));
        };
        let text = text.to_string_lossy();
        let folded = text.to_lowercase();
        ALL.into_iter()
            .find(|m| m.names().contains(&folded.as_str()) || m.label_text().to_lowercase() == folded)
            .ok_or_else(|| {
                let names: Vec<String> = ALL.iter().map(|m| format!("'{}'", m.key())).collect();
                let labels: Vec<String> = ALL.iter().map(|m| format!("'{}'", m.label_text())).collect();
                PyValueError::new_err(format!(
                    "{name} must be a dqskin.Method, one of {} (or 'lbs', 'dqs', 'cor') or a label ({}), got '{text}'",
                    names.join(", "),
                    labels.join(", "),
                ))
            })
    }

    /// The core's method with its per-vertex data. `centers` is required for
    /// `CENTERS_OF_ROTATION` (the caller checks it; without, the core refuses the empty list).
    pub fn core<'a>(self, blend: Option<&'a [f32]>, blend_factor: f32, centers: Option<&'a [[f32; 3]]>) -> Method<'a> {
        match self {
            Self::Linear => Method::Linear,
            Self::DualQuaternion => Method::DualQuaternion,
            Self::Blend => Method::Blend { amount: blend, factor: blend_factor },
            Self::CentersOfRotation => Method::CentersOfRotation { centers: centers.unwrap_or(&[]) },
        }
    }
}

#[pymethods]
impl PyMethod {
    #[new]
    fn new(value: &Bound<'_, PyAny>) -> PyResult<Self> {
        crate::guard(|| Self::from_arg(value, "value"))
    }

    /// The name an artist sees in Blender's menu: "Linear", "Dual Quaternion", "Blend",
    /// "Optimized Centers".
    #[getter]
    fn label(&self) -> &'static str {
        self.label_text()
    }

    /// The member's name: "LINEAR", "DUAL_QUATERNION", "BLEND", "CENTERS_OF_ROTATION" (what
    /// the Blender operators and the command line take).
    #[getter]
    fn name(&self) -> &'static str {
        match self {
            Self::Linear => "LINEAR",
            Self::DualQuaternion => "DUAL_QUATERNION",
            Self::Blend => "BLEND",
            Self::CentersOfRotation => "CENTERS_OF_ROTATION",
        }
    }

    /// Every method, in the order of Blender's menu.
    #[staticmethod]
    fn members() -> Vec<PyMethod> {
        ALL.to_vec()
    }
}

//! Skin weights: automatic weights from an armature's bones (geodesic voxel binding) and weight
//! transfer from a skinned body to clothing (closest-point matching and weight inpainting).
//!
//! - [`automatic_weights`] (Dionne & de Lasa, "Geodesic Voxel Binding for Production Character
//!   Meshes", SCA 2013): the rest mesh is voxelized (`voxels.rs`: its surface, and the interior
//!   as everything a flood fill from outside cannot reach, so open, intersecting and multi-part
//!   meshes all work), each bone's geodesic distance through that solid is found for the few
//!   nearest bones of every voxel (`geodesic.rs`), and each vertex's weights follow from its
//!   distances by the paper's falloff (`falloff.rs`). Optional smoothing over the mesh
//!   (`smooth.rs`) and mirroring by bone name (`mirror.rs`). A vertex that no bone reaches
//!   takes its nearest bones in straight lines: no vertex is ever left without weights.
//! - [`transfer_weights`] (Abdrashitov et al., "Robust Skin Weights Transfer via Weight
//!   Inpainting", SIGGRAPH Asia 2023): each clothing vertex takes the body's weights at its
//!   closest surface point when that point is near enough and faces the same way
//!   (`closest.rs`, `transfer.rs`); the others are filled by minimizing a Laplacian energy
//!   with the matched ones fixed (`laplacian.rs`, `solve.rs`); a loose part with no match
//!   takes the weights of the nearest matched point.
//!
//! Both return [`Influences`] whose vertices have at most `max_influences` bones, with weights
//! that sum to one.

mod automatic;
mod closest;
mod envelope;
mod falloff;
mod geodesic;
mod laplacian;
mod mesh;
mod mirror;
mod smooth;
mod solve;
mod sparse;
mod transfer;
mod voxels;

#[cfg(test)]
mod tests;

pub use automatic::{automatic_weights, AutoOptions, AutoWeights, Bone};
pub use mirror::{mirror_bone_map, mirrored_name};
pub use transfer::{transfer_weights, TransferOptions, Transferred};

/// The most influences per vertex the weighting functions make.
pub const MAX_WEIGHT_INFLUENCES: usize = 16;
/// The most bones automatic weights accept (bone indices are stored in 16 bits per voxel).
pub const MAX_WEIGHT_BONES: usize = u16::MAX as usize;
/// Voxel resolutions offered: the longest side of the mesh's bounding box in voxels.
pub const MIN_RESOLUTION: usize = 16;
pub const MAX_RESOLUTION: usize = 512;
pub const DEFAULT_RESOLUTION: usize = 128;
/// The most memory automatic weights may take (the voxel grid, the distances kept per voxel and
/// the queue); a resolution that would need more is refused before anything large is allocated.
pub const MEMORY_BUDGET: usize = 1 << 30;

/// Why weights could not be computed.
#[derive(Clone, Debug, PartialEq)]
pub enum WeightsError {
    /// An array has the wrong length.
    LengthMismatch { what: &'static str, expected: usize, got: usize },
    /// A point has a NaN or infinite coordinate.
    NotFinite { what: &'static str, index: usize },
    /// A triangle refers to a vertex that does not exist.
    InvalidTriangle { what: &'static str, index: usize, vertex: u32, vertex_count: usize },
    /// An option is outside its range.
    OutOfRange { what: &'static str, value: f64, min: f64, max: f64 },
    /// There is no bone to weight to.
    NoBones,
    /// More bones than [`MAX_WEIGHT_BONES`].
    TooManyBones { count: usize },
    /// The voxel grid at this resolution would need more than [`MEMORY_BUDGET`].
    TooMuchMemory { resolution: usize, needed: usize },
    /// The body has no weights to transfer.
    NoSourceWeights,
    /// The body has no triangles to find closest points on.
    NoSurface,
    /// The progress callback asked to stop.
    Cancelled,
}

impl core::fmt::Display for WeightsError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            WeightsError::LengthMismatch { what, expected, got } => {
                write!(f, "{what}: expected {expected} entries, got {got}")
            }
            WeightsError::NotFinite { what, index } => write!(f, "{what}[{index}] has a NaN or infinite coordinate"),
            WeightsError::InvalidTriangle { what, index, vertex, vertex_count } => {
                // (`body_triangles` index `body_positions`, and so on.)
                let positions = what.replace("triangles", "positions");
                write!(f, "{what}[{index}] refers to vertex {vertex}, but {positions} has {vertex_count} points")
            }
            WeightsError::OutOfRange { what, value, min, max } => {
                write!(f, "{what} must be between {min} and {max}, got {value}")
            }
            WeightsError::NoBones => write!(f, "there are no bones to weight the mesh to"),
            WeightsError::TooManyBones { count } => {
                write!(f, "{count} bones: automatic weights take at most {MAX_WEIGHT_BONES}")
            }
            WeightsError::TooMuchMemory { resolution, needed } => write!(
                f,
                "resolution {resolution} would need {} MB for this mesh (at most {} MB): choose a lower resolution",
                needed >> 20,
                MEMORY_BUDGET >> 20
            ),
            WeightsError::NoSourceWeights => {
                write!(f, "the body has no weights to transfer (no vertex has a weight above 0)")
            }
            WeightsError::NoSurface => {
                write!(f, "body_triangles is empty (the body has no faces): weights are transferred from the closest points of its surface")
            }
            WeightsError::Cancelled => write!(f, "cancelled"),
        }
    }
}

impl std::error::Error for WeightsError {}

/// Progress of a long computation: `progress(done, total)` on the calling thread; `false` stops
/// it with [`WeightsError::Cancelled`].
pub type Progress<'a> = &'a mut dyn FnMut(usize, usize) -> bool;

pub(crate) fn check_points(what: &'static str, points: &[[f32; 3]]) -> Result<(), WeightsError> {
    match points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        Some(index) => Err(WeightsError::NotFinite { what, index }),
        None => Ok(()),
    }
}

pub(crate) fn check_triangles(
    what: &'static str,
    triangles: &[[u32; 3]],
    vertex_count: usize,
) -> Result<(), WeightsError> {
    for (index, t) in triangles.iter().enumerate() {
        if let Some(&vertex) = t.iter().find(|&&v| v as usize >= vertex_count) {
            return Err(WeightsError::InvalidTriangle { what, index, vertex, vertex_count });
        }
    }
    Ok(())
}

pub(crate) fn check_range(what: &'static str, value: f64, min: f64, max: f64) -> Result<(), WeightsError> {
    if (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(WeightsError::OutOfRange { what, value, min, max })
    }
}

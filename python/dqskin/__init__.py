"""dqskin: dual-quaternion skinning and rigid-transform blending on numpy arrays.

The math runs in a Rust core (multithreaded, GIL released); this package is its Python face.

Conventions
-----------
- float32 everywhere; large arrays (positions, weights, outputs) must be C-contiguous float32
  numpy arrays and are used without copying.
- Quaternions are ``(w, x, y, z)``; dual quaternions are ``(8,)`` arrays
  ``[rw, rx, ry, rz, dw, dx, dy, dz]`` (real part, then dual part).
- Matrices are row-major 4x4 with the translation in the last column, as numpy and Blender's
  ``mathutils`` write them.

Skinning matches Blender's Armature modifier: ``Method.LINEAR`` (``method='linear'``) is Preserve
Volume off, ``Method.DUAL_QUATERNION`` (``'dual_quaternion'``) is Preserve Volume on, and
``Method.BLEND`` (``'blend'``) mixes the two per vertex. ``Method.CENTERS_OF_ROTATION``
(``'centers_of_rotation'``) skins with optimized centers of rotation (Le & Hodgins 2016),
precomputed once per mesh by :func:`centers_of_rotation`. Many meshes are skinned in one call by
:func:`skin_many` from a :class:`SkinJob` each.

Skin weights: :func:`automatic_weights` binds a rest mesh to bones (geodesic voxel binding,
never leaving a vertex unweighted) and :func:`transfer_weights` carries a body's weights to
clothing (closest-point matching and inpainting).
"""

from ._dqskin import (  # noqa: F401
    MAX_BONES,
    MAX_INFLUENCES_PER_VERTEX,
    Cancelled,
    DualQuat,
    Influences,
    Job,
    Method,
    PoseData,
    Screw,
    SkinJob,
    TwistCylinder,
    __version__,
    _panic_for_tests,  # noqa: F401  (tests check panics become RuntimeError)
    _panicking_job_for_tests,  # noqa: F401  (and in a job's thread too)
    angular_speeds,
    armature_spaces,
    automatic_weights,
    automatic_weights_job,
    bbone_segment_matrices,
    centers_of_rotation,
    centers_of_rotation_job,
    continuous_signs,
    curvature_energy,
    deform_group_weights,
    dib,
    dlb,
    dual_quats_from_matrices,
    forward_kinematics,
    get_num_threads,
    influences_from_deform_groups,
    kernel_copies,
    matrices_from_dual_quats,
    mesh_volume,
    mirrored_bone_name,
    polygon_area,
    sample_rotations,
    sample_transforms,
    sclerp,
    set_num_threads,
    shape_key_mix,
    skin,
    skin_many,
    slerp,
    spring,
    squad,
    squad_control_points,
    transfer_weights,
    transfer_weights_job,
    transform_points,
)

__all__ = [
    "MAX_BONES",
    "MAX_INFLUENCES_PER_VERTEX",
    "angular_speeds",
    "continuous_signs",
    "curvature_energy",
    "deform_group_weights",
    "sample_rotations",
    "sample_transforms",
    "spring",
    "Cancelled",
    "DualQuat",
    "Influences",
    "Job",
    "Method",
    "Screw",
    "SkinJob",
    "TwistCylinder",
    "__version__",
    "armature_spaces",
    "automatic_weights",
    "automatic_weights_job",
    "bbone_segment_matrices",
    "centers_of_rotation",
    "centers_of_rotation_job",
    "dib",
    "dlb",
    "dual_quats_from_matrices",
    "forward_kinematics",
    "get_num_threads",
    "influences_from_deform_groups",
    "kernel_copies",
    "matrices_from_dual_quats",
    "mesh_volume",
    "mirrored_bone_name",
    "polygon_area",
    "sclerp",
    "set_num_threads",
    "shape_key_mix",
    "skin",
    "skin_many",
    "slerp",
    "squad",
    "squad_control_points",
    "transform_points",
    "transfer_weights",
    "transfer_weights_job",
]

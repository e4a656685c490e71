"""Type stubs for the compiled core of dqskin (see the package docstring for conventions)."""

from collections.abc import Callable, Sequence
from typing import Any, Literal, SupportsFloat, TypedDict, final, overload

import numpy as np
import numpy.typing as npt

__version__: str
MAX_INFLUENCES_PER_VERTEX: int  # more influences on one vertex are refused (ValueError)
MAX_BONES: int  # influences referring to more bones are refused (ValueError)

F32Array = npt.NDArray[np.float32]
IntArray = npt.NDArray[np.integer]
ArrayLike = npt.ArrayLike | Sequence[float]
Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]

def set_num_threads(threads: int) -> None:
    """Sets the number of worker threads the kernels use (at least 1)."""

def get_num_threads() -> int:
    """The number of worker threads the kernels use (default: DQSKIN_NUM_THREADS or all cores)."""

def kernel_copies() -> list[tuple[str, str, str | None]]:
    """Which compiled copy of the kernels (``"avx2"``, ``"avx512"``, ``"neon"``, ``"baseline"``,
    or on x86-64 ``"avx2-noprefetch"`` or ``"avx512-noprefetch"``, whose batches do not ask the
    memory for their inputs ahead) runs each kernel variant in this process, per size of job
    (``"cached"``: fewer than 65,536 vertices, else ``"streamed"``): ``(variant, size, copy)``,
    ``copy`` None while the variant's first calls of that size still measure the copies.
    ``DQSKIN_SIMD`` forces one copy."""

@final
class Screw:
    """Rotation by ``angle`` about the line (``axis``, ``moment``) plus translation ``pitch`` along it."""

    axis: Vec3
    moment: Vec3
    angle: float
    pitch: float
    def __init__(self, axis: Vec3, moment: Vec3, angle: float, pitch: float) -> None: ...
    def point(self) -> Vec3:
        """The point of the axis closest to the origin."""

@final
class DualQuat:
    """A dual quaternion ``real + ε·dual``; unit ones are rigid transforms."""

    def __init__(self, real: ArrayLike | None = None, dual: ArrayLike | None = None) -> None: ...
    @staticmethod
    def identity() -> DualQuat: ...
    @staticmethod
    def from_rotation_translation(rotation: ArrayLike, translation: ArrayLike | None = None) -> DualQuat: ...
    @staticmethod
    def from_translation(translation: ArrayLike) -> DualQuat: ...
    @staticmethod
    def from_matrix(matrix: ArrayLike, check: bool = True, tolerance: float = 1e-5) -> DualQuat:
        """From a rigid 4x4 matrix; ``check`` rejects scale, shear, reflection, non-affine rows."""
    @staticmethod
    def from_screw(screw: Screw) -> DualQuat: ...
    @property
    def real(self) -> Quat: ...
    @property
    def dual(self) -> Quat: ...
    @property
    def rotation(self) -> Quat: ...
    @property
    def translation(self) -> Vec3: ...
    def to_array(self) -> F32Array:
        """``[rw, rx, ry, rz, dw, dx, dy, dz]`` as float32."""
    def to_matrix(self) -> F32Array:
        """Row-major 4x4 float32."""
    def conjugate(self) -> DualQuat: ...
    def dual_conjugate(self) -> DualQuat: ...
    def full_conjugate(self) -> DualQuat: ...
    def norm(self) -> tuple[float, float]:
        """The dual-number norm ``(real, dual)``."""
    def is_unit(self, tolerance: float = 1e-5) -> bool: ...
    def normalized(self) -> DualQuat: ...
    def inverse(self) -> DualQuat: ...
    def shortest(self) -> DualQuat: ...
    def log(self) -> DualQuat: ...
    def exp(self) -> DualQuat: ...
    def pow(self, t: float) -> DualQuat: ...
    def __pow__(self, t: float, modulo: None = None) -> DualQuat: ...
    def screw(self) -> Screw: ...
    def transform_point(self, point: ArrayLike) -> Vec3: ...
    def transform_points(self, points: F32Array) -> F32Array: ...
    @overload
    def __mul__(self, other: DualQuat) -> DualQuat: ...
    @overload
    def __mul__(self, other: SupportsFloat) -> DualQuat: ...
    def __rmul__(self, other: float) -> DualQuat: ...
    def __add__(self, other: DualQuat) -> DualQuat: ...
    def __sub__(self, other: DualQuat) -> DualQuat: ...
    def __neg__(self) -> DualQuat: ...
    def __eq__(self, other: object) -> bool: ...

def dual_quats_from_matrices(matrices: F32Array, check: bool = True, tolerance: float = 1e-5) -> F32Array:
    """``(N, 4, 4)`` rigid matrices to ``(N, 8)`` unit dual quaternions."""

def matrices_from_dual_quats(dual_quats: F32Array) -> F32Array:
    """``(N, 8)`` dual quaternions to ``(N, 4, 4)`` rigid matrices."""

@overload
def sclerp(a: ArrayLike, b: ArrayLike, t: float) -> F32Array: ...
@overload
def sclerp(a: ArrayLike, b: ArrayLike, t: ArrayLike) -> F32Array:
    """Screw linear interpolation (shortest path, constant speed); ``(8,)`` or ``(T, 8)``."""

def dlb(transforms: ArrayLike, weights: ArrayLike) -> F32Array:
    """Dual quaternion linear blending of ``(N, 8)`` transforms; returns ``(8,)``."""

def dib(transforms: ArrayLike, weights: ArrayLike, precision: float = 1e-6, max_iterations: int = 32) -> tuple[F32Array, int, bool]:
    """Dual quaternion iterative blending; returns ``(blend, iterations, converged)``."""

@overload
def slerp(q0: ArrayLike, q1: ArrayLike, t: float) -> F32Array: ...
@overload
def slerp(q0: ArrayLike, q1: ArrayLike, t: ArrayLike) -> F32Array:
    """Shortest-arc spherical linear interpolation of ``(w, x, y, z)`` rotations."""

@overload
def squad(keys: ArrayLike, u: float) -> F32Array: ...
@overload
def squad(keys: ArrayLike, u: ArrayLike) -> F32Array:
    """Shoemake's Squad through ``(K, 4)`` keys at ``u`` in ``[0, K-1]``."""

def squad_control_points(keys: ArrayLike) -> F32Array:
    """Squad's inner control points, ``(K, 4)``."""

def forward_kinematics(parents: ArrayLike, locals: ArrayLike) -> F32Array:
    """Global ``(B, 8)`` transforms from local ones; ``parents[i] < 0`` marks a root."""

@final
class Influences:
    """Per-vertex bone influences (CSR), validated once and reused every frame."""

    def __init__(self, offsets: IntArray, bones: IntArray, weights: F32Array, bone_count: int) -> None: ...
    @staticmethod
    def from_dense(bones: IntArray, weights: F32Array, bone_count: int) -> Influences:
        """From ``(V, K)`` arrays (as glTF stores joints and weights); zero weights dropped."""
    def effective(
        self,
        positions: F32Array,
        premat: ArrayLike | None = None,
        *,
        pose: PoseData | None = None,
        envelopes: F32Array | None = None,
        use_vertex_groups: bool = True,
        use_envelopes: bool = False,
        bbone_segments: IntArray | None = None,
        rest: F32Array | None = None,
        lengths: ArrayLike | None = None,
        bbone_mapping: dict[int, tuple[npt.NDArray[np.int32], F32Array]] | None = None,
    ) -> Influences:
        """This frame's influences with envelopes and B-Bones over the expanded bone list: from
        ``pose`` (envelopes, B-Bones, Straight and Curved mappings as Blender's), or from the
        arrays ``envelopes`` ``(B, 11)``, ``bbone_segments``, ``rest``, ``lengths`` and
        ``bbone_mapping``."""
    @property
    def vertex_count(self) -> int: ...
    @property
    def bone_count(self) -> int: ...
    @property
    def max_per_vertex(self) -> int: ...
    @property
    def nbytes(self) -> int:
        """Bytes these influences hold (their lane-ordered copy for the kernels, the offsets, and
        what an Optimized Centers update kept for the next one), for memory accounting."""
    @property
    def offsets(self) -> npt.NDArray[np.uint32]: ...
    @property
    def bones(self) -> npt.NDArray[np.uint32]: ...
    @property
    def weights(self) -> F32Array: ...
    def __len__(self) -> int: ...

@final
class Method:
    """A skinning method; ``Method(value)`` looks one up from its name in :func:`skin`
    (``'linear'``, ``'dual_quaternion'``, ``'blend'``, ``'centers_of_rotation'``, any case, or
    ``'lbs'``, ``'dqs'``, ``'cor'``) or from its label."""

    LINEAR: Method  # Blender's Preserve Volume off
    DUAL_QUATERNION: Method  # Preserve Volume on
    BLEND: Method  # a per-vertex mix of the two
    CENTERS_OF_ROTATION: Method  # Le & Hodgins 2016 ("Optimized Centers" in Blender)
    def __init__(self, value: Method | str) -> None: ...
    @property
    def label(self) -> str:
        """The name in Blender's menu: "Linear", "Dual Quaternion", "Blend", "Optimized Centers"."""
    @property
    def name(self) -> str:
        """The member's name ("LINEAR", ...), what Blender's operators and the command line take."""
    @staticmethod
    def members() -> list[Method]:
        """Every method, in the order of Blender's menu."""
    def __eq__(self, other: object) -> bool: ...
    def __hash__(self) -> int: ...

MethodName = (
    Method
    | Literal[
        "linear",
        "dual_quaternion",
        "blend",
        "centers_of_rotation",
        "LINEAR",
        "DUAL_QUATERNION",
        "BLEND",
        "CENTERS_OF_ROTATION",
        "lbs",
        "dqs",
        "cor",
        "Linear",
        "Dual Quaternion",
        "Blend",
        "Optimized Centers",
    ]
)

def skin(
    positions: F32Array,
    influences: Influences,
    deform: F32Array,
    rest: F32Array | None,
    *,
    method: MethodName = Method.DUAL_QUATERNION,
    blend: F32Array | None = None,
    blend_factor: float = 1.0,
    premat: ArrayLike | None = None,
    postmat: ArrayLike | None = None,
    mask: F32Array | None = None,
    out: F32Array | None = None,
    centers: F32Array | None = None,
) -> F32Array:
    """Skins ``(V, 3)`` positions exactly as Blender's Armature modifier (or with centers of
    rotation, ``Method.CENTERS_OF_ROTATION`` with ``centers`` from :func:`centers_of_rotation`);
    returns ``out``. ``deform`` is ``(B, 4, 4)``: each bone's posed matrix times the inverse of its
    rest matrix (Blender's ``PoseBone.matrix_channel``). ``rest`` is ``(B, 4, 4)``
    (``Bone.matrix_local``) and must be given; it may be None only with ``method='linear'``.
    ``method`` is a :class:`Method` or its name (strings are looked up as ``Method(value)``).
    ``blend`` (``(V,)``, with ``method='blend'``) and ``blend_factor`` give each vertex's share of
    Dual Quaternion; ``premat``/``postmat`` are the mesh-to-armature and armature-to-mesh
    transforms (identity if None); ``mask`` ``(V,)`` scales each vertex's deformation; ``out`` is
    a ``(V, 3)`` float32 buffer to write (allocated if None)."""

@final
class SkinJob:
    """One mesh's skinning for :func:`skin_many`: the arguments of :func:`skin`, checked when
    built (``out`` allocated if not given); arrays are kept by reference and read when the job
    runs. ``positions``, ``deform``, ``premat`` and ``postmat`` can be replaced per frame."""

    def __init__(
        self,
        positions: F32Array,
        influences: Influences,
        deform: F32Array,
        rest: F32Array | None,
        *,
        method: MethodName = Method.DUAL_QUATERNION,
        blend: F32Array | None = None,
        blend_factor: float = 1.0,
        premat: ArrayLike | None = None,
        postmat: ArrayLike | None = None,
        mask: F32Array | None = None,
        out: F32Array | None = None,
        centers: F32Array | None = None,
    ) -> None: ...
    positions: F32Array
    deform: F32Array
    premat: ArrayLike | None
    postmat: ArrayLike | None
    out: F32Array | None
    """Where the result is written: a writable, C-contiguous ``(V, 3)`` float32 array (None between
    runs keeps no array; a job without one is refused when it runs)."""
    @property
    def method(self) -> Method: ...
    @property
    def influences(self) -> Influences: ...
    @property
    def rest(self) -> F32Array | None: ...
    @property
    def mask(self) -> F32Array | None: ...
    @property
    def blend(self) -> F32Array | None: ...
    @property
    def blend_factor(self) -> float: ...
    @property
    def centers(self) -> F32Array | None: ...

def skin_many(jobs: Sequence[SkinJob], *, share_from: int | None = None) -> list[str | None]:
    """Runs the jobs at once, in parallel across meshes; returns None or the error message per
    job (a failed job's ``out`` is untouched). Below ``share_from`` vertices over all the jobs
    the calling thread runs them alone (None: the work is always shared with the pool)."""

@overload
def centers_of_rotation(
    positions: F32Array,
    triangles: IntArray,
    influences: Influences,
    sigma: float = 0.1,
    *,
    with_mask: Literal[False] = False,
    progress: Callable[[int, int], bool | None] | None = None,
    previous: tuple[Influences, F32Array | tuple[F32Array, npt.NDArray[np.bool_]]] | None = None,
) -> F32Array: ...
@overload
def centers_of_rotation(
    positions: F32Array,
    triangles: IntArray,
    influences: Influences,
    sigma: float = 0.1,
    *,
    with_mask: Literal[True],
    progress: Callable[[int, int], bool | None] | None = None,
    previous: tuple[Influences, F32Array | tuple[F32Array, npt.NDArray[np.bool_]]] | None = None,
) -> tuple[F32Array, npt.NDArray[np.bool_]]: ...
@overload
def centers_of_rotation(
    positions: F32Array,
    triangles: IntArray,
    influences: Influences,
    sigma: float = 0.1,
    *,
    with_mask: bool,
    progress: Callable[[int, int], bool | None] | None = None,
    previous: tuple[Influences, F32Array | tuple[F32Array, npt.NDArray[np.bool_]]] | None = None,
) -> F32Array | tuple[F32Array, npt.NDArray[np.bool_]]:
    """Centers of rotation of a rest mesh (Le & Hodgins 2016), ``(V, 3)`` float32; a vertex
    without a center gets its own position (skinned exactly like LBS). With ``with_mask=True``
    also a ``(V,)`` bool array, True where the vertex has a center. ``progress(done, total)`` is
    called about a hundred times; returning False raises :class:`Cancelled`. ``previous``:
    ``(influences, centers)`` returned before for the same positions and triangles with other
    weights: only what the weight change reaches is computed again (the same result, bit for
    bit). Such an update also keeps, inside ``influences``, the per-pair sums of what it
    computed, and the next update given ``(influences, centers)`` as ``previous`` takes them
    (then only the bone pairs whose triangles the new change altered are summed again): strokes
    that follow one another get faster. They are held until then, a few tens of bytes per
    bone pair of each distinct weight vector computed; a full computation keeps nothing."""

class Cancelled(Exception):
    """A long computation stopped because its progress callback returned False."""

class AutomaticWeightsReport(TypedDict):
    unreached: int
    outside_bones: npt.NDArray[np.uint32]
    grid: tuple[int, int, int]
    solid_voxels: int

def automatic_weights(
    positions: F32Array,
    triangles: IntArray,
    heads: F32Array,
    tails: F32Array,
    *,
    resolution: int = 128,
    falloff: float = 0.2,
    max_influences: int = 4,
    smoothing: int = 0,
    mirror: Sequence[str] | None = None,
    progress: Callable[[int, int], bool | None] | None = None,
) -> tuple[Influences, AutomaticWeightsReport]:
    """Automatic skin weights of a rest mesh for bones given as segments ``heads`` → ``tails``
    ``(B, 3)`` (geodesic voxel binding through a solid voxelization of the mesh); every vertex
    gets 1 to ``max_influences`` bones with weights summing to one. ``mirror``: the bones' names,
    to mirror across X = 0 by name. The report says how many vertices no bone reached (weighted
    to their nearest bones in straight lines) and which bones lie outside the mesh."""

class TransferReport(TypedDict):
    matched: npt.NDArray[np.bool_]
    matched_count: int
    inpainted: int
    from_nearest: int
    max_distance: float
    iterations: int

def transfer_weights(
    body_positions: F32Array,
    body_triangles: IntArray,
    body_influences: Influences,
    cloth_positions: F32Array,
    cloth_triangles: IntArray,
    *,
    max_distance: float | None = None,
    max_angle: float = 30.0,
    flipped_normals: bool = False,
    smoothing: int = 0,
    max_influences: int = 4,
    progress: Callable[[int, int], bool | None] | None = None,
) -> tuple[Influences, TransferReport]:
    """Transfers skin weights from a body to clothing (closest points within ``max_distance``,
    default 5 % of the clothing's bounding-box diagonal, and ``max_angle`` degrees; the rest
    filled by a Laplacian-energy solve; loose parts with no match take the nearest match)."""

class Job:
    """A long computation on a thread of dqskin's own that never runs Python nor holds the GIL
    (for hosts such as Blender, where a Python thread running beside the host's own code is a
    hazard), started by :func:`centers_of_rotation_job`, :func:`automatic_weights_job` or
    :func:`transfer_weights_job`. Dropping a running job cancels it."""

    @property
    def done(self) -> int: ...
    @property
    def total(self) -> int: ...
    @property
    def finished(self) -> bool: ...
    def cancel(self) -> None:
        """Stops the thread at its next step; ``result()`` then raises :class:`Cancelled`
        unless the work was already complete."""
    def wait(self, timeout: float | None = None) -> bool:
        """Waits until the thread ends or ``timeout`` seconds pass (Ctrl-C stops the wait, not
        the job); returns ``finished``."""
    def result(self) -> Any:
        """What the function would have returned, bit for bit (waits if needed); raises
        :class:`Cancelled` if the job was cancelled, ``ValueError`` if its inputs gave none."""

def centers_of_rotation_job(
    positions: F32Array,
    triangles: IntArray,
    influences: Influences,
    sigma: float = 0.1,
    *,
    with_mask: bool = False,
    previous: tuple[Influences, F32Array | tuple[F32Array, npt.NDArray[np.bool_]]] | None = None,
) -> Job:
    """:func:`centers_of_rotation` as a :class:`Job` (the same arguments but ``progress``; bad
    input raises here, the arrays are copied); an update (``previous``) hands what it kept to
    ``influences`` when ``result()`` is taken."""

def automatic_weights_job(
    positions: F32Array,
    triangles: IntArray,
    heads: F32Array,
    tails: F32Array,
    *,
    resolution: int = 128,
    falloff: float = 0.2,
    max_influences: int = 4,
    smoothing: int = 0,
    mirror: Sequence[str] | None = None,
) -> Job:
    """:func:`automatic_weights` as a :class:`Job` (the same arguments but ``progress``; types
    and shapes are checked here, what the computation refuses is raised by ``result()``)."""

def transfer_weights_job(
    body_positions: F32Array,
    body_triangles: IntArray,
    body_influences: Influences,
    cloth_positions: F32Array,
    cloth_triangles: IntArray,
    *,
    max_distance: float | None = None,
    max_angle: float = 30.0,
    flipped_normals: bool = False,
    smoothing: int = 0,
    max_influences: int = 4,
) -> Job:
    """:func:`transfer_weights` as a :class:`Job` (as :func:`automatic_weights_job`)."""

def mirrored_bone_name(name: str) -> str | None:
    """The bone name of the other side (``hand.L`` → ``hand.R``), or None."""

def bbone_segment_matrices(
    channel: ArrayLike, rest: ArrayLike, pose_joints: ArrayLike, rest_joints: ArrayLike
) -> tuple[F32Array, F32Array]:
    """Deform and rest matrices ``(N+1, 4, 4)`` of a B-Bone's segment joints, as Blender builds them."""

def transform_points(matrix: ArrayLike, points: F32Array) -> F32Array:
    """``(N, 3)`` points transformed by an affine 4x4 matrix."""

def mesh_volume(positions: F32Array, triangles: IntArray) -> float:
    """Enclosed volume of a closed, outward-oriented triangle mesh."""

def polygon_area(points: F32Array) -> float:
    """Area of a planar polygon given in order."""

@final
class TwistCylinder:
    """A two-bone cylinder along +Y for the candy-wrapper test."""

    def __init__(self, rings: int = 33, segments: int = 48, length: float = 4.0, radius: float = 0.5, blend_zone: float = 0.5) -> None: ...
    @property
    def positions(self) -> F32Array: ...
    @property
    def triangles(self) -> npt.NDArray[np.uint32]: ...
    @property
    def influences(self) -> Influences: ...
    @property
    def rest(self) -> F32Array: ...
    @property
    def rings(self) -> int: ...
    @property
    def segments(self) -> int: ...
    def twist(self, angle: float) -> F32Array:
        """Deform matrices ``(2, 4, 4)`` with the upper bone twisted by ``angle`` radians."""
    def ring(self, r: int) -> npt.NDArray[np.int64]: ...

def continuous_signs(keys: ArrayLike) -> tuple[F32Array, int]:
    """Keys ``(K, 4)`` made sign-continuous and normalized; returns ``(keys, flipped)``."""

def sample_rotations(times: ArrayLike, keys: ArrayLike, at: ArrayLike, method: Literal["slerp", "squad"] = "squad") -> F32Array:
    """Rotation keys at ``times`` sampled at ``at`` with Slerp or time-aware Squad; ``(T, 4)``."""

def sample_transforms(times: ArrayLike, keys: ArrayLike, at: ArrayLike) -> F32Array:
    """Transform keys ``(K, 8)`` sampled along piecewise ScLERP; ``(T, 8)``."""

def spring(
    times: ArrayLike, keys: ArrayLike, step: float = 1.0, levels: int = 3, iterations: int = 400, key_weight: float = 1.2
) -> F32Array:
    """Dam et al.'s curvature-minimizing Spring through the keys, every ``step``; ``(T, 4)``.

    At most 5,000,000 samples, 20 ``levels`` and 1,000,000 ``iterations`` per level (ValueError
    beyond); Ctrl-C stops it with KeyboardInterrupt."""

def angular_speeds(rotations: ArrayLike) -> F32Array:
    """Rotation angle (radians) between consecutive rotations; ``(T-1,)``."""

def curvature_energy(rotations: ArrayLike) -> float:
    """Summed squared discrete curvature of evenly spaced rotations."""

def _panic_for_tests() -> None: ...
def _panicking_job_for_tests() -> Job: ...
def influences_from_deform_groups(
    offsets: npt.NDArray[np.uint32],
    groups: npt.NDArray[np.uint32],
    weights: F32Array,
    group_to_bone: npt.NDArray[np.int32],
    bone_count: int,
) -> Influences:
    """Influences from vertex groups in CSR form (stored order), with each group index mapped to
    a bone index (or -1), as Blender's Armature modifier maps them."""

def deform_group_weights(offsets: npt.NDArray[np.uint32], groups: npt.NDArray[np.uint32], weights: F32Array, group: int) -> F32Array:
    """Each vertex's weight in one vertex group (0 outside it); ``(V,)``."""

def shape_key_mix(
    keys: list[tuple[F32Array, int, float, bool, F32Array | None]],
    reference: int,
    out: F32Array,
    shown: int | None = None,
) -> None:
    """Blender's relative shape-key mix into ``out`` ``(V, 3)``; keys are
    ``(data, relative_to, value, muted, weights)`` in block order; ``shown`` for Shape Key Lock."""

def armature_spaces(object_world: ArrayLike, armature_world: ArrayLike) -> tuple[F32Array, F32Array]:
    """``(premat, postmat)`` of the Armature modifier from the two world matrices."""

@final
class PoseData:
    """One frame of an armature's deforming bones (``pose.bones`` order) as the Armature
    modifier deforms with them; the expanded bone list adds each B-Bone's joints after them."""
    @property
    def names(self) -> list[str]: ...
    @property
    def bone_indices(self) -> npt.NDArray[np.int64]:
        """Each bone's index in ``pose.bones``."""
    @property
    def bone_count(self) -> int: ...
    @property
    def expanded_bone_count(self) -> int: ...
    @property
    def deform(self) -> F32Array:
        """``(E, 4, 4)``: each bone's ``matrix_channel``, then the B-Bones' joints (Blender's cache)."""
    @property
    def rest(self) -> F32Array:
        """``(E, 4, 4)``: each bone's ``matrix_local``, then each joint's orthonormal rest basis."""
    @property
    def envelopes(self) -> F32Array:
        """``(B, 11)`` envelope rows (as ``Influences.effective`` takes them)."""
    @property
    def segments(self) -> npt.NDArray[np.int64]:
        """Each bone's segment count as it deforms (1 for plain bones)."""
    @property
    def binding_signature(self) -> int:
        """Digest of what influences depend on besides the vertices."""
    @property
    def pose_signature(self) -> int:
        """Digest of the expanded deform matrices."""

"""A straightforward float64 numpy reference of Blender's Armature modifier for vertex groups.

Ported from the Rust reference (``rust/core/src/skin/tests.rs``, module ``reference``), itself
written from Blender's ``armature_deform.cc`` and ``math_rotation_c.cc``. It computes the scale
path the way Blender does (full scale matrices and ``add_weighted_dq_dq_pivot``), not the
shortcut dqskin's kernels take, and visits every vertex one at a time, so it is slow but easy to
check line by line against Blender.

Inputs are the same arrays dqskin takes (float32 is read exactly into float64):

- ``positions`` ``(V, 3)``; ``offsets`` ``(V+1,)``, ``bones``, ``weights``: CSR influences in
  the order Blender visits them;
- ``deform`` ``(B, 4, 4)``: Blender's ``matrix_channel`` = posed @ inv(rest), row-major;
- ``rest`` ``(B, 4, 4)``: ``Bone.matrix_local`` (needed for DQS);
- ``premat``/``postmat`` 4x4 (identity if None); ``mask`` ``(V,)`` (all 1 if None).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from dqmath import mat3_to_quat, qmul

# Blender's thresholds (armature_deform.cc / math_rotation_c.cc / math_matrix_c.cc).
CONTRIB_THRESHOLD = 0.0001  # a vertex moves only if its total weight is > this
ORTHONORMAL_TOLERANCE = 1e-5  # is_orthonormal_m3: dot products and squared lengths
SCALE_TOLERANCE_SQ = 1e-8  # mat4_to_dquat: |column lengths of M·B − 1|² above this → scale path


@dataclass
class BDq:
    """Blender's ``DualQuat``: ``quat`` and ``trans`` as (w, x, y, z), a scale matrix and weight."""

    quat: np.ndarray
    trans: np.ndarray
    scale: np.ndarray = field(default_factory=lambda: np.zeros((4, 4)))
    scale_weight: float = 0.0


@dataclass
class Stats:
    """What the reference did, so tests can check their data exercise the interesting paths."""

    sign_flips: int = 0  # DQS terms added with a negated weight
    scaled_bones: list = field(default_factory=list)  # bones that took the scale path
    moved: int = 0  # vertices with contrib > threshold (and mask != 0)


def mat4_to_quat(m):
    """Blender's ``mat4_to_quat``: normalize the columns, negate on a negative determinant,
    convert; ``w >= 0`` (the sign does not change any skinning result)."""
    m3 = np.array(m, dtype=np.float64)[:3, :3]
    norms = np.linalg.norm(m3, axis=0)
    m3 = np.where(norms > 0, m3 / np.where(norms > 0, norms, 1.0), 0.0)
    if np.linalg.det(m3) < 0:
        m3 = -m3
    return mat3_to_quat(m3)


def orthogonalize_y(m):
    """Blender's ``orthogonalize_m4(m, 1)``: keep the Y axis, rebuild X and Z with cross
    products, keep the column lengths and the translation."""
    m = np.array(m, dtype=np.float64)
    size = np.linalg.norm(m[:3, :3], axis=0)
    y = m[:3, 1] / np.linalg.norm(m[:3, 1])
    z = np.cross(m[:3, 0], y)
    z /= np.linalg.norm(z)
    x = np.cross(y, z)
    out = m.copy()
    out[:3, 0] = x * size[0]
    out[:3, 1] = y * size[1]
    out[:3, 2] = z * size[2]
    return out


def is_orthonormal(m3):
    """Blender's ``is_orthonormal_m3`` on the columns."""
    c = [m3[:, i] for i in range(3)]
    for i in range(3):
        for j in range(i):
            if abs(np.dot(c[i], c[j])) > ORTHONORMAL_TOLERANCE:
                return False
        if abs(np.dot(c[i], c[i]) - 1.0) > ORTHONORMAL_TOLERANCE:
            return False
    return True


def takes_scale_path(basemat, mat):
    """Whether ``mat4_to_dquat`` takes the scale path for this bone."""
    basemat = np.asarray(basemat, dtype=np.float64)
    mat = np.asarray(mat, dtype=np.float64)
    base_rs = mat @ basemat
    dscale = np.linalg.norm(base_rs[:3, :3], axis=0) - 1.0
    return not is_orthonormal(mat[:3, :3]) or np.linalg.det(mat) < 0 or float(np.dot(dscale, dscale)) > SCALE_TOLERANCE_SQ


def mat4_to_dquat(basemat, mat):
    """Blender's ``mat4_to_dquat(dq, basemat, mat)``."""
    basemat = np.asarray(basemat, dtype=np.float64)
    mat = np.asarray(mat, dtype=np.float64)
    base_rs = mat @ basemat
    if takes_scale_path(basemat, mat):
        basequat = mat4_to_quat(orthogonalize_y(base_rs))
        base_r = np.eye(4)
        base_r[:3, :3] = _quat_to_mat3_unit(basequat)
        base_r[:3, 3] = base_rs[:3, 3]
        baseinv = np.linalg.inv(basemat)
        r = base_r @ baseinv
        s = np.linalg.inv(base_r) @ base_rs
        scale = basemat @ s @ baseinv
        scale_weight = 1.0
    else:
        r = mat
        scale = np.zeros((4, 4))
        scale_weight = 0.0
    q = mat4_to_quat(r)
    t = r[:3, 3]
    # trans = ½·(0, t)·q
    trans = 0.5 * qmul(np.concatenate([[0.0], t]), q)
    return BDq(quat=q, trans=trans, scale=scale, scale_weight=scale_weight)


def _quat_to_mat3_unit(q):
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def add_weighted_dq_dq(dq_sum: BDq, dq: BDq, weight: float, stats: Stats | None = None):
    """Blender's ``add_weighted_dq_dq``: flip the weight when ``dq`` points away from the
    running sum (the first term is compared against zero and never flipped)."""
    if float(np.dot(dq.quat, dq_sum.quat)) < 0.0:
        w = -weight
        if stats is not None:
            stats.sign_flips += 1
    else:
        w = weight
    dq_sum.quat = dq_sum.quat + w * dq.quat
    dq_sum.trans = dq_sum.trans + w * dq.trans
    if dq.scale_weight != 0.0:
        dq_sum.scale = dq_sum.scale + dq.scale * weight
        dq_sum.scale_weight += weight


def add_weighted_dq_dq_pivot(dq_sum: BDq, dq: BDq, pivot, weight: float, stats: Stats | None = None):
    """Blender's ``add_weighted_dq_dq_pivot`` with ``compute_scale_matrix = false`` (the modifier
    passes no deform matrices): a scaled bone's translation gets ``dst = scale·pivot − pivot``
    (``trans += ½·q·(0, dst)``) and its scale matrix is dropped."""
    if dq.scale_weight != 0.0:
        dst = (dq.scale @ np.append(pivot, 1.0))[:3] - pivot
        trans = dq.trans + 0.5 * qmul(dq.quat, np.concatenate([[0.0], dst]))
        m = BDq(quat=dq.quat, trans=trans, scale=dq.scale, scale_weight=0.0)
        add_weighted_dq_dq(dq_sum, m, weight, stats)
    else:
        add_weighted_dq_dq(dq_sum, dq, weight, stats)


def mul_v3m3_dq(co, dq: BDq):
    """Blender's ``mul_v3m3_dq`` without the scale matrix: rotation by the unnormalized quat and
    translation from ``trans``, both divided by ``|quat|²``."""
    w, x, y, z = dq.quat
    t0, t1, t2, t3 = dq.trans
    m = np.array(
        [
            [w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), w * w + y * y - x * x - z * z, 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), w * w + z * z - x * x - y * y],
        ]
    )
    len2 = w * w + x * x + y * y + z * z
    t = np.array(
        [
            2 * (-t0 * x + w * t1 - t2 * z + y * t3),
            2 * (-t0 * y + t1 * z - x * t3 + w * t2),
            2 * (-t0 * z + x * t2 + w * t3 - t1 * y),
        ]
    )
    return (m @ co + t) / len2


def _affine(m):
    return np.eye(4) if m is None else np.asarray(m, dtype=np.float64)


def _point(m, p):
    return m[:3, :3] @ p + m[:3, 3]


def skin(
    positions,
    offsets,
    bones,
    weights,
    deform,
    rest=None,
    *,
    dqs: bool,
    premat=None,
    postmat=None,
    mask=None,
    stats: Stats | None = None,
):
    """Blender's ``armature_vert_task_with_dvert`` for vertex groups only; ``dqs`` picks
    Preserve Volume. Returns ``(V, 3)`` float64 mesh-space positions."""
    positions = np.asarray(positions, dtype=np.float64)
    offsets = np.asarray(offsets, dtype=np.int64)
    bones = np.asarray(bones, dtype=np.int64)
    weights = np.asarray(weights, dtype=np.float64)
    deform = np.asarray(deform, dtype=np.float64)
    premat = _affine(premat)
    postmat = _affine(postmat)
    if stats is None:
        stats = Stats()
    dq_bones = []
    if dqs:
        rest = np.asarray(rest, dtype=np.float64)
        dq_bones = [mat4_to_dquat(rest[b], deform[b]) for b in range(len(deform))]
        stats.scaled_bones = [b for b, d in enumerate(dq_bones) if d.scale_weight != 0.0]
    out = np.empty_like(positions)
    for v, p in enumerate(positions):
        a = 1.0 if mask is None else float(mask[v])
        if a == 0.0:
            out[v] = p  # copied as is, without the premat/postmat round trip
            continue
        co = _point(premat, p)
        contrib = 0.0
        vec = np.zeros(3)
        dq_sum = BDq(quat=np.zeros(4), trans=np.zeros(4))
        for i in range(offsets[v], offsets[v + 1]):
            w = float(weights[i])
            if w == 0.0:
                continue
            b = int(bones[i])
            if dqs:
                add_weighted_dq_dq_pivot(dq_sum, dq_bones[b], co, w, stats)
            else:
                vec += (_point(deform[b], co) - co) * w
            contrib += w
        if contrib > CONTRIB_THRESHOLD:
            stats.moved += 1
            if dqs:
                r = mul_v3m3_dq(co, dq_sum)
                co = co + (r - co) * a
            else:
                co = co + vec * (a / contrib)
        out[v] = _point(postmat, co)
    return out


def blend(positions, offsets, bones, weights, deform, rest, alpha, *, premat=None, postmat=None, mask=None):
    """``(1 − α)·LBS + α·DQS`` per vertex (``alpha`` is ``(V,)`` or a number)."""
    kw = dict(premat=premat, postmat=postmat, mask=mask)
    lbs = skin(positions, offsets, bones, weights, deform, rest, dqs=False, **kw)
    dq = skin(positions, offsets, bones, weights, deform, rest, dqs=True, **kw)
    alpha = np.broadcast_to(np.asarray(alpha, dtype=np.float64), (len(lbs),))[:, None]
    return (1.0 - alpha) * lbs + alpha * dq

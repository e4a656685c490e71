"""Small float64 numpy helpers for quaternions and dual quaternions, used by the reference and
the tests. They are written independently of dqskin so the tests can check dqskin against them.

Conventions are dqskin's: quaternions ``(w, x, y, z)``, dual quaternions ``(8,)``
``[rw, rx, ry, rz, dw, dx, dy, dz]``, matrices row-major 4x4 with the translation in ``m[:3, 3]``.
"""

from __future__ import annotations

import dqskin
import numpy as np

# ---------------------------------------------------------------------------------------------
# Quaternions


def qmul(a, b):
    """Hamilton product of ``(..., 4)`` quaternions."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def qconj(q):
    return np.asarray(q, dtype=np.float64) * np.array([1.0, -1.0, -1.0, -1.0])


def qnormalize(q):
    q = np.asarray(q, dtype=np.float64)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def quat_from_axis_angle(axis, angle):
    axis = np.asarray(axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])


def quat_to_mat3(q):
    """Rotation matrix of a (normalized here) quaternion."""
    w, x, y, z = qnormalize(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def mat3_to_quat(m):
    """Quaternion (w >= 0) of a proper rotation matrix (Shepperd's method, largest pivot)."""
    m = np.asarray(m, dtype=np.float64)
    tr = np.trace(m)
    cands = [tr, m[0, 0], m[1, 1], m[2, 2]]
    k = int(np.argmax(cands))
    if k == 0:
        s = 2.0 * np.sqrt(max(1.0 + tr, 0.0))
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif k == 1:
        s = 2.0 * np.sqrt(max(1.0 + m[0, 0] - m[1, 1] - m[2, 2], 0.0))
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif k == 2:
        s = 2.0 * np.sqrt(max(1.0 - m[0, 0] + m[1, 1] - m[2, 2], 0.0))
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(max(1.0 - m[0, 0] - m[1, 1] + m[2, 2], 0.0))
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    q = qnormalize(np.array(q))
    return -q if q[0] < 0 else q


def rotation_angle(q):
    """Rotation angle in [0, pi] of a quaternion, independent of its sign and length."""
    q = np.asarray(q, dtype=np.float64)
    return 2.0 * np.arctan2(np.linalg.norm(q[..., 1:4], axis=-1), np.abs(q[..., 0]))


def angle_between_quats(a, b):
    """Angle in [0, pi] of the rotation taking ``a`` to ``b`` (sign-independent)."""
    return rotation_angle(qmul(qconj(a), b))


def random_unit_quat(rng):
    while True:
        q = rng.normal(size=4)
        n = np.linalg.norm(q)
        if n > 0.1:
            return q / n


def random_axis(rng):
    while True:
        a = rng.normal(size=3)
        n = np.linalg.norm(a)
        if n > 0.1:
            return a / n


# ---------------------------------------------------------------------------------------------
# Dual quaternions (8,)


def dq_from_rt(q, t=(0.0, 0.0, 0.0)):
    """Rotation ``q`` (normalized here) followed by translation ``t``."""
    r = qnormalize(q)
    d = 0.5 * qmul(np.concatenate([[0.0], np.asarray(t, dtype=np.float64)]), r)
    return np.concatenate([r, d])


def dq_mul(a, b):
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return np.concatenate([qmul(a[:4], b[:4]), qmul(a[:4], b[4:]) + qmul(a[4:], b[:4])])


def dq_conj(a):
    a = np.asarray(a, dtype=np.float64)
    return np.concatenate([qconj(a[:4]), qconj(a[4:])])


def dq_normalize(a):
    """Divides by the dual-number norm."""
    a = np.asarray(a, dtype=np.float64)
    n = np.linalg.norm(a[:4])
    r, d = a[:4] / n, a[4:] / n
    return np.concatenate([r, d - r * np.dot(r, d)])


def dq_translation(a):
    a = dq_normalize(a)
    return 2.0 * qmul(a[4:], qconj(a[:4]))[1:]


def dq_to_matrix(a):
    a = dq_normalize(a)
    m = np.eye(4)
    m[:3, :3] = quat_to_mat3(a[:4])
    m[:3, 3] = dq_translation(a)
    return m


def matrix_to_dq(m):
    m = np.asarray(m, dtype=np.float64)
    return dq_from_rt(mat3_to_quat(m[:3, :3]), m[:3, 3])


def dq_transform_point(a, p):
    m = dq_to_matrix(a)
    return m[:3, :3] @ np.asarray(p, dtype=np.float64) + m[:3, 3]


def random_unit_dq(rng, max_translation=2.0, angle=None, axis=None):
    """A random rigid transform: random axis and angle (or the given ones), translation in a box."""
    if axis is None:
        axis = random_axis(rng)
    if angle is None:
        angle = rng.uniform(0.0, np.pi)
    q = quat_from_axis_angle(axis, angle)
    if rng.random() < 0.5:
        q = -q  # both signs of the same transform occur in the inputs
    t = rng.uniform(-max_translation, max_translation, size=3)
    return dq_from_rt(q, t)


def random_rigid_matrix(rng, max_translation=2.0):
    return dq_to_matrix(random_unit_dq(rng, max_translation))


def dq_distance(a, b):
    """Distance between two dual quaternions up to the overall sign (same transform)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return min(np.linalg.norm(a - b), np.linalg.norm(a + b))


def to_dualquat(a) -> dqskin.DualQuat:
    """A dqskin.DualQuat from an (8,) array."""
    a = np.asarray(a, dtype=np.float32)
    return dqskin.DualQuat(a[:4], a[4:])


def from_dualquat(d: dqskin.DualQuat) -> np.ndarray:
    return np.asarray(d.to_array(), dtype=np.float64)

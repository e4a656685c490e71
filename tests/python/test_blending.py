"""Rigid-transform interpolation and blending through the numpy API: ScLERP, DLB, DIB, Slerp,
Squad, forward kinematics, conversions and the DualQuat class, checked against float64 numpy
math (dqmath.py) and against the properties Kavan et al. 2006 and Dam et al. 1998 prove."""

from __future__ import annotations

import dqskin
import numpy as np
import pytest
from dqmath import (
    angle_between_quats,
    dq_distance,
    dq_from_rt,
    dq_mul,
    dq_to_matrix,
    dq_transform_point,
    dq_translation,
    from_dualquat,
    mat3_to_quat,
    qconj,
    qmul,
    qnormalize,
    quat_from_axis_angle,
    quat_to_mat3,
    random_axis,
    random_unit_dq,
    random_unit_quat,
    rotation_angle,
    to_dualquat,
)

SEEDS = [0, 1, 2]
F32 = np.float32

# Tolerances. dqskin works in float32 (unit round-off 6e-8); inputs here have rotations up to
# 180° and translations up to 2 units, so one float32 rounding of a component is ~1e-7.
# Endpoints, compositions and log/exp/pow round trips go through a handful of products,
# trigonometric functions and a normalization: observed errors are below 1e-6; 1e-5 leaves a
# 10x margin without hiding real mistakes (which show up as errors of 1e-3 and more).
DQ_TOL = 1e-5
# Angles measured from float32 results (atan2 of float32 components): observed below 1e-5 rad.
ANGLE_TOL = 5e-5
# Bi-invariance compares two float32 computations on inputs that were themselves multiplied in
# float32 (translations up to ~6 after composition), so the errors of both paths add up:
# observed below 1e-5.
INVARIANCE_TOL = 5e-5
# One or two float32 roundings of values of size ~1-2 (a normalization, a sign flip, a sum of two
# components, converting an exact input): ulp(2) = 2.4e-7, so 1e-6 allows a few of them.
ROUNDING_TOL = 1e-6
# Points and matrices with coordinates up to ~10 after a rotation and a translation in float32:
# a few ulps of 10 (ulp 1e-6).
POINT_TOL = 1e-5
# Norms of general (non-unit) dual quaternions with components ~N(0, 1): the real part is one
# float32 square root (1e-5 relative is generous); the dual part ⟨r, d⟩/|r| of a product
# involves sums of products that can cancel, so it gets 1e-4 relative.
NORM_REL_TOL = 1e-5
DUAL_NORM_REL_TOL = 1e-4
# The screw axis of a short stretch of ScLERP (t·angle down to 0.0025 rad) is a float32 vector
# divided by sin(t·angle/2): up to ~1e-7/0.0012 ≈ 1e-4 off. The moment multiplies that by
# translations of a few units; the pitch is a dot product with a translation.
AXIS_TOL = 1e-3
MOMENT_REL_TOL = 2e-3
PITCH_REL_TOL = 1e-4
# DIB's fixed point: with precision DIB_PRECISION the tangent-space mean (recomputed here with dqskin's
# own float32 log) is below ~1e-5 (observed ≤ 8e-6).
DIB_FIXED_POINT_TOL = 5e-5
DIB_PRECISION = 1e-5  # the precision passed to dib() in these tests
# Forward kinematics: a chain of up to 14 float32 products, ~1e-6 per link, relative to the
# largest entry (translations grow along the chain).
FK_REL_TOL = 1e-5
# DIB stops when its step is below its precision (1e-5 here), not at the exact blend, so two
# runs on transformed inputs may stop a step apart: a few times the precision.
DIB_INVARIANCE_TOL = 1e-4
# Kavan et al. 2006: the rotation angles of DLB and ScLERP of two transforms differ by less than
# 8.15° (the maximum, reached at a relative rotation of 180°, is 8.13°).
DLB_MAX_DEGREES = 8.15


def unit_dq32(rng, max_translation=2.0, angle=None):
    return random_unit_dq(rng, max_translation, angle=angle).astype(F32)


def screw_of(a):
    """Screw parameters of a dual quaternion array, on the shortest path."""
    return to_dualquat(a).shortest().screw()


def relative(a, b):
    """``conj(a)·b`` as a DualQuat built from arrays."""
    return to_dualquat(a).conjugate() * to_dualquat(b)


def assert_same_transform(got, want, tol=DQ_TOL):
    d = dq_distance(got, want)
    assert d <= tol, f"{np.asarray(got)} vs {np.asarray(want)}: distance {d:.3g}"


def pairs(seed, n=20):
    rng = np.random.default_rng(seed)
    return [(unit_dq32(rng), unit_dq32(rng)) for _ in range(n)]


# ---------------------------------------------------------------------------------------------
# ScLERP


@pytest.mark.parametrize("seed", SEEDS)
def test_sclerp_endpoints(seed):
    for a, b in pairs(seed):
        r0 = dqskin.sclerp(a, b, 0.0)
        r1 = dqskin.sclerp(a, b, 1.0)
        assert r0.dtype == F32 and r0.shape == (8,)
        assert_same_transform(r0, a)
        assert_same_transform(r1, b)


@pytest.mark.parametrize("seed", SEEDS)
def test_sclerp_constant_speed_fixed_screw(seed):
    ts = np.linspace(0.0, 1.0, 11)
    for a, b in pairs(seed):
        whole = relative(a, b).shortest().screw()
        assert whole.angle <= np.pi + ANGLE_TOL
        if not (0.05 < whole.angle < np.pi - 0.05):
            continue
        for t in ts:
            part = relative(a, dqskin.sclerp(a, b, float(t))).shortest().screw()
            assert part.angle == pytest.approx(t * whole.angle, abs=ANGLE_TOL)
            assert part.pitch == pytest.approx(t * whole.pitch, abs=PITCH_REL_TOL * (1 + abs(whole.pitch)))
            if t > 0.05:
                np.testing.assert_allclose(part.axis, whole.axis, atol=AXIS_TOL)
                np.testing.assert_allclose(part.moment, whole.moment, atol=MOMENT_REL_TOL * (1 + np.linalg.norm(whole.moment)))


@pytest.mark.parametrize("seed", SEEDS)
def test_sclerp_takes_the_shortest_path(seed):
    rng = np.random.default_rng(seed)
    for _ in range(20):
        a = unit_dq32(rng)
        b = unit_dq32(rng)
        # Make the real parts point into opposite hemispheres: the literal path p·(p*q)^t would
        # go the long way (more than 180°).
        if np.dot(a[:4], b[:4]) > 0:
            b = -b
        theta = angle_between_quats(a[:4], b[:4])  # shortest relative angle, in [0, π]
        for t in (0.25, 0.5, 0.75):
            r = dqskin.sclerp(a, b, t)
            travelled = angle_between_quats(a[:4], r[:4])
            assert travelled == pytest.approx(t * theta, abs=ANGLE_TOL), (theta, t)
            assert_same_transform(r, dqskin.sclerp(a, -b, t), ROUNDING_TOL)
    # A case where the long way is clearly different: 170° apart, half way is 85°, not 95°.
    a = dq_from_rt([1, 0, 0, 0], [0, 0, 0]).astype(F32)
    b = dq_from_rt(-quat_from_axis_angle([0, 1, 0], np.radians(170)), [1, 0, 0]).astype(F32)
    half = dqskin.sclerp(a, b, 0.5)
    assert rotation_angle(half[:4]) == pytest.approx(np.radians(85.0), abs=ANGLE_TOL)


@pytest.mark.parametrize("axis", [[0, 0, 1], [1, 0, 0], [0.3, -0.5, 0.8]])
def test_sclerp_at_exactly_half_a_turn_is_finite_and_rigid(axis):
    a = dq_from_rt([1, 0, 0, 0], [1.0, 0.0, 0.0]).astype(F32)
    b = np.concatenate([[0.0], np.asarray(axis) / np.linalg.norm(axis)])  # 180° about axis
    b = dq_from_rt(b, [0.0, 2.0, 0.5]).astype(F32)
    assert abs(np.dot(a[:4], b[:4])) == 0.0
    for t in (0.0, 0.25, 0.5, 0.75, 1.0):
        r = dqskin.sclerp(a, b, t)
        assert np.all(np.isfinite(r)), (t, r)
        assert np.linalg.norm(r[:4]) == pytest.approx(1.0, abs=ROUNDING_TOL)
        assert abs(np.dot(r[:4], r[4:])) < ROUNDING_TOL
        assert relative(a, r).shortest().screw().angle == pytest.approx(t * np.pi, abs=ANGLE_TOL)
    assert_same_transform(dqskin.sclerp(a, b, 1.0), b)


def test_sclerp_with_an_array_of_t():
    a, b = pairs(7, 1)[0]
    ts = np.linspace(0, 1, 9, dtype=F32)
    many = dqskin.sclerp(a, b, ts)
    assert many.shape == (9, 8) and many.dtype == F32
    for t, row in zip(ts, many):
        np.testing.assert_array_equal(row, dqskin.sclerp(a, b, float(t)))
    assert dqskin.sclerp(a, b, [0.0, 0.5]).shape == (2, 8)
    assert dqskin.sclerp(a, b, np.array([0.25, 0.5])).shape == (2, 8)  # float64 array works too
    assert dqskin.sclerp(a, b, np.zeros(0, F32)).shape == (0, 8)


def test_sclerp_with_a_one_element_array_of_t_returns_T_by_8():
    """The documented contract: an array of T numbers gives (T, 8), also for T = 1 (a list
    does; a numpy array of one element must too, whatever numpy allows converting to float)."""
    a, b = pairs(8, 1)[0]
    assert dqskin.sclerp(a, b, [0.5]).shape == (1, 8)
    shapes = {
        "sclerp": dqskin.sclerp(a, b, np.array([0.5], F32)).shape,
        "slerp": dqskin.slerp(a[:4], b[:4], np.array([0.5], F32)).shape,
        "squad": dqskin.squad(np.stack([a[:4], b[:4]]), np.array([0.5], F32)).shape,
    }
    assert shapes == {"sclerp": (1, 8), "slerp": (1, 4), "squad": (1, 4)}


@pytest.mark.parametrize("seed", SEEDS)
def test_sclerp_is_bi_invariant(seed):
    rng = np.random.default_rng(seed)
    for a, b in pairs(seed, 15):
        if angle_between_quats(a[:4], b[:4]) > np.pi - 0.02:
            continue  # both ways equally short: sign choice may legitimately differ
        c, d = unit_dq32(rng), unit_dq32(rng)
        t = float(rng.uniform())
        base = dqskin.sclerp(a, b, t)
        left = dqskin.sclerp(dq_mul(c, a).astype(F32), dq_mul(c, b).astype(F32), t)
        right = dqskin.sclerp(dq_mul(a, d).astype(F32), dq_mul(b, d).astype(F32), t)
        assert_same_transform(left, dq_mul(c, base), INVARIANCE_TOL)
        assert_same_transform(right, dq_mul(base, d), INVARIANCE_TOL)


# ---------------------------------------------------------------------------------------------
# DLB and DIB


def numpy_dlb(qs, w):
    """Σ wᵢ·qᵢ with signs aligned to the largest weight, divided by its dual-number norm."""
    qs = np.asarray(qs, dtype=np.float64)
    w = np.asarray(w, dtype=np.float64) / np.sum(w)
    ref = qs[int(np.argmax(w))][:4]
    s = sum((wi if np.dot(q[:4], ref) >= 0 else -wi) * q for q, wi in zip(qs, w))
    n = np.linalg.norm(s[:4])
    r, d = s[:4] / n, s[4:] / n
    return np.concatenate([r, d - r * np.dot(r, d)])


@pytest.mark.parametrize("seed", SEEDS)
def test_dlb_is_the_normalized_weighted_sum(seed):
    rng = np.random.default_rng(seed)
    for n in (1, 2, 3, 5, 8):
        qs = np.array([unit_dq32(rng) for _ in range(n)])
        w = rng.uniform(0.05, 2.0, n).astype(F32)
        got = dqskin.dlb(qs, w)
        assert got.shape == (8,) and got.dtype == F32
        assert_same_transform(got, numpy_dlb(qs, w), DQ_TOL)


@pytest.mark.parametrize("seed", SEEDS)
def test_dlb_is_bi_invariant(seed):
    rng = np.random.default_rng(seed)
    for n in (2, 3, 4, 6):
        qs = np.array([unit_dq32(rng) for _ in range(n)])
        w = rng.uniform(0.05, 1.0, n).astype(F32)
        c = unit_dq32(rng)
        base = dqskin.dlb(qs, w)
        left = dqskin.dlb(np.array([dq_mul(c, q) for q in qs], F32), w)
        right = dqskin.dlb(np.array([dq_mul(q, c) for q in qs], F32), w)
        assert_same_transform(left, dq_mul(c, base), INVARIANCE_TOL)
        assert_same_transform(right, dq_mul(base, c), INVARIANCE_TOL)


@pytest.mark.parametrize("seed", SEEDS)
def test_dlb_does_not_depend_on_input_signs_or_order(seed):
    rng = np.random.default_rng(seed)
    for n in (2, 3, 5):
        qs = np.array([unit_dq32(rng) for _ in range(n)])
        w = rng.uniform(0.05, 1.0, n).astype(F32)
        base = dqskin.dlb(qs, w)
        signs = np.where(rng.random(n) < 0.5, -1, 1).astype(F32)
        signs[0] = -signs[0]
        assert_same_transform(dqskin.dlb(qs * signs[:, None], w), base, ROUNDING_TOL)
        perm = rng.permutation(n)
        assert_same_transform(dqskin.dlb(qs[perm], w[perm]), base, DQ_TOL)
        # Unnormalized weights give the same blend.
        assert_same_transform(dqskin.dlb(qs, w * F32(7.0)), base, DQ_TOL)


def test_dlb_stays_within_kavans_bound_of_sclerp():
    rng = np.random.default_rng(42)
    worst = 0.0
    for _ in range(150):
        a, b = unit_dq32(rng), unit_dq32(rng)
        for t in np.linspace(0, 1, 9):
            d = dqskin.dlb(np.stack([a, b]), F32([1 - t, t]))
            s = dqskin.sclerp(a, b, float(t))
            diff = np.degrees(angle_between_quats(d[:4], s[:4]))
            worst = max(worst, diff)
            assert diff < DLB_MAX_DEGREES, (a, b, t, diff)
    # The bound is nearly reached when the relative rotation is close to 180°.
    a = dq_from_rt([1, 0, 0, 0]).astype(F32)
    b = dq_from_rt(quat_from_axis_angle(random_axis(rng), np.radians(179.5)), [1, 2, 3]).astype(F32)
    diffs = []
    for t in np.linspace(0, 1, 201):
        d = dqskin.dlb(np.stack([a, b]), F32([1 - t, t]))
        s = dqskin.sclerp(a, b, float(t))
        diffs.append(np.degrees(angle_between_quats(d[:4], s[:4])))
    assert max(diffs) < DLB_MAX_DEGREES
    # DLB of two rotations is normalized quaternion lerp: 8.13° at 180°, a bit less at 179.5°.
    assert max(diffs) > 7.8, max(diffs)
    assert worst > 1.0  # the random sweep did compare different curves


@pytest.mark.parametrize("seed", SEEDS)
def test_dib_of_two_transforms_is_sclerp_after_at_most_one_iteration(seed):
    rng = np.random.default_rng(seed)
    for a, b in pairs(seed, 15):
        if angle_between_quats(a[:4], b[:4]) > np.pi - 0.02:
            continue
        t = float(rng.uniform())
        blend, iterations, converged = dqskin.dib(np.stack([a, b]), F32([1 - t, t]))
        assert converged
        assert iterations <= 1, iterations
        assert_same_transform(blend, dqskin.sclerp(a, b, t), INVARIANCE_TOL)


def dib_inputs(rng, n):
    # Rotations up to 90° and translations up to 2: well inside the region where DIB converges.
    qs = np.array([unit_dq32(rng, 2.0, angle=rng.uniform(0, np.pi / 2)) for _ in range(n)])
    w = rng.uniform(0.05, 1.0, n).astype(F32)
    return qs, w


@pytest.mark.parametrize("n", [3, 4, 5, 6])
@pytest.mark.parametrize("seed", SEEDS)
def test_dib_converges_to_a_fixed_point_and_is_bi_invariant(seed, n):
    rng = np.random.default_rng(seed * 10 + n)
    qs, w = dib_inputs(rng, n)
    blend, iterations, converged = dqskin.dib(qs, w, DIB_PRECISION, 50)
    assert converged, iterations
    assert iterations < 50
    assert np.linalg.norm(blend[:4]) == pytest.approx(1.0, abs=ROUNDING_TOL)
    # Fixed point: the weighted mean of the inputs in the tangent space at the blend vanishes.
    B = to_dualquat(blend)
    wn = w.astype(np.float64) / w.sum()
    mean = sum(wi * from_dualquat((B.conjugate() * to_dualquat(q)).shortest().log()) for q, wi in zip(qs, wn))
    assert np.linalg.norm(mean) < DIB_FIXED_POINT_TOL, mean
    # ... which DLB alone generally is not (so this check can tell DIB from DLB).
    D = to_dualquat(dqskin.dlb(qs, w))
    dlb_mean = sum(wi * from_dualquat((D.conjugate() * to_dualquat(q)).shortest().log()) for q, wi in zip(qs, wn))
    assert np.linalg.norm(dlb_mean) > 2 * DIB_FIXED_POINT_TOL or iterations == 0
    c = unit_dq32(rng)
    left, _, ok_l = dqskin.dib(np.array([dq_mul(c, q) for q in qs], F32), w, DIB_PRECISION, 50)
    right, _, ok_r = dqskin.dib(np.array([dq_mul(q, c) for q in qs], F32), w, DIB_PRECISION, 50)
    assert ok_l and ok_r
    assert_same_transform(left, dq_mul(c, blend), DIB_INVARIANCE_TOL)
    assert_same_transform(right, dq_mul(blend, c), DIB_INVARIANCE_TOL)


def test_dib_reports_non_convergence_at_the_iteration_cap():
    qs = np.array([dq_from_rt(quat_from_axis_angle([0, 0, 1], 0.7 * i), [i, 0, 1]) for i in range(5)], F32)
    blend, iterations, converged = dqskin.dib(qs, np.ones(5, F32), precision=0.0, max_iterations=3)
    assert iterations == 3 and not converged
    assert np.linalg.norm(blend[:4]) == pytest.approx(1.0, abs=ROUNDING_TOL)


# ---------------------------------------------------------------------------------------------
# Slerp and Squad


def numpy_slerp(q0, q1, t):
    q0, q1 = qnormalize(q0), qnormalize(q1)
    if np.dot(q0, q1) < 0:
        q1 = -q1
    omega = np.arccos(np.clip(np.dot(q0, q1), -1, 1))
    if omega < 1e-8:
        return q0
    return (np.sin((1 - t) * omega) * q0 + np.sin(t * omega) * q1) / np.sin(omega)


@pytest.mark.parametrize("seed", SEEDS)
def test_slerp_endpoints_constant_speed_shortest_arc(seed):
    rng = np.random.default_rng(seed)
    for _ in range(20):
        q0, q1 = random_unit_quat(rng).astype(F32), random_unit_quat(rng).astype(F32)
        assert dq_distance(dqskin.slerp(q0, q1, 0.0), q0) < ROUNDING_TOL
        assert dq_distance(dqskin.slerp(q0, q1, 1.0), q1) < DQ_TOL
        theta = angle_between_quats(q0, q1)  # ≤ π: the short way
        ts = np.linspace(0, 1, 11)
        path = dqskin.slerp(q0, q1, ts)
        assert path.shape == (11, 4)
        steps = [angle_between_quats(path[i], path[i + 1]) for i in range(10)]
        np.testing.assert_allclose(steps, theta / 10, atol=ANGLE_TOL)
        travelled = [angle_between_quats(q0, p) for p in path]
        np.testing.assert_allclose(travelled, ts * theta, atol=ANGLE_TOL)
        for t, p in zip(ts, path):
            assert dq_distance(p, numpy_slerp(q0, q1, t)) < DQ_TOL
            assert dq_distance(p, dqskin.slerp(q0, -q1, float(t))) < ROUNDING_TOL
        # Unnormalized inputs are normalized.
        assert dq_distance(dqskin.slerp(3 * q0, 0.5 * q1, 0.3), path[3]) < DQ_TOL


def random_keys(rng, k):
    keys = [random_unit_quat(rng)]
    for _ in range(k - 1):
        step = quat_from_axis_angle(random_axis(rng), rng.uniform(0.3, 1.5))
        nxt = qmul(keys[-1], step)
        keys.append(-nxt if rng.random() < 0.5 else nxt)  # random signs: squad makes them continuous
    return np.array(keys, F32)


def rotation_vector(q_from, q_to):
    """Body-frame rotation vector (axis·angle) taking q_from to q_to, on the short way."""
    rel = qmul(qconj(q_from), q_to)
    if rel[0] < 0:
        rel = -rel
    n = np.linalg.norm(rel[1:])
    return np.zeros(3) if n == 0 else 2 * np.arctan2(n, rel[0]) * rel[1:] / n


def angular_velocity(curve, u, h, side):
    """Body-frame angular velocity at ``u`` from a one-sided, second-order finite difference
    (``side`` −1: from the left, +1: from the right) of the rotation vectors relative to
    ``curve(u)``: v'(0) ≈ ±(4·v(±h) − v(±2h))/(2h)."""
    q0 = curve(u)
    v1 = rotation_vector(q0, curve(u + side * h))
    v2 = rotation_vector(q0, curve(u + side * 2 * h))
    return side * (4 * v1 - v2) / (2 * h)


# The one-sided differences above have O(h²) truncation error and float32 noise of about
# 1e-7/h relative (u itself is rounded to float32 too): observed jumps ≤ 6e-4 for Squad. Squad's
# velocity jump at a key must stay below SQUAD_JUMP_TOL (relative); piecewise Slerp jumps by
# 0.4-1.7 on these keys, and the test checks that the measurement sees that.
FD_STEP = 2e-3
SQUAD_JUMP_TOL = 0.01


@pytest.mark.parametrize("seed", SEEDS)
def test_squad_interpolates_keys_with_continuous_angular_velocity(seed):
    rng = np.random.default_rng(seed)
    keys = random_keys(rng, 6)
    for i, k in enumerate(keys):
        assert dq_distance(dqskin.squad(keys, float(i)), k) < DQ_TOL
    us = np.linspace(0, 5, 51, dtype=F32)
    curve = dqskin.squad(keys, us)
    assert curve.shape == (51, 4)
    np.testing.assert_allclose(np.linalg.norm(curve, axis=1), 1.0, atol=ROUNDING_TOL)
    for i in range(0, 51, 10):
        assert dq_distance(curve[i], keys[i // 10]) < DQ_TOL

    squad = lambda u: dqskin.squad(keys, float(u)).astype(np.float64)  # noqa: E731

    def piecewise_slerp(u):
        i = min(int(np.floor(u)), len(keys) - 2)
        return dqskin.slerp(keys[i], keys[i + 1], float(u - i)).astype(np.float64)

    for i in range(1, len(keys) - 1):
        wl = angular_velocity(squad, i, FD_STEP, -1)
        wr = angular_velocity(squad, i, FD_STEP, +1)
        jump = np.linalg.norm(wl - wr) / max(np.linalg.norm(wl), np.linalg.norm(wr))
        assert jump < SQUAD_JUMP_TOL, (i, wl, wr)
        sl = angular_velocity(piecewise_slerp, i, FD_STEP, -1)
        sr = angular_velocity(piecewise_slerp, i, FD_STEP, +1)
        slerp_jump = np.linalg.norm(sl - sr) / max(np.linalg.norm(sl), np.linalg.norm(sr))
        # The same measurement does see a jump where there is one.
        assert slerp_jump > 10 * SQUAD_JUMP_TOL, (i, slerp_jump)


def test_squad_control_points_follow_dam_et_al():
    rng = np.random.default_rng(3)
    keys = random_keys(rng, 5).astype(np.float64)
    # sign-continuous, normalized keys
    for i in range(1, len(keys)):
        if np.dot(keys[i], keys[i - 1]) < 0:
            keys[i] = -keys[i]

    def qlog(q):
        v = q[1:]
        n = np.linalg.norm(v)
        return np.zeros(3) if n < 1e-12 else np.arctan2(n, q[0]) * v / n

    def qexp(v):
        h = np.linalg.norm(v)
        return np.concatenate([[np.cos(h)], np.sinc(h / np.pi) * v])

    want = [keys[0]]
    for i in range(1, len(keys) - 1):
        c = qconj(keys[i])
        s = qlog(qmul(c, keys[i + 1])) + qlog(qmul(c, keys[i - 1]))
        want.append(qmul(keys[i], qexp(-s / 4)))
    want.append(keys[-1])
    got = dqskin.squad_control_points(keys.astype(F32))
    assert got.shape == (5, 4)
    for g, w in zip(got, want):
        assert dq_distance(g, w) < DQ_TOL
    # Squad clamps u to the key range.
    assert dq_distance(dqskin.squad(keys.astype(F32), -1.0), keys[0]) < ROUNDING_TOL
    assert dq_distance(dqskin.squad(keys.astype(F32), 10.0), keys[-1]) < ROUNDING_TOL
    assert dq_distance(dqskin.squad(keys[:1].astype(F32), 0.7), keys[0]) < ROUNDING_TOL


# ---------------------------------------------------------------------------------------------
# Forward kinematics and conversions


@pytest.mark.parametrize("seed", SEEDS)
def test_forward_kinematics_matches_matrix_products_in_any_order(seed):
    rng = np.random.default_rng(seed)
    n = 14
    order = rng.permutation(n)  # parents come before children in `order`, not in index order
    parents = np.full(n, -1, dtype=np.int64)
    for k in range(1, n):
        if rng.random() < 0.85:
            parents[order[k]] = order[rng.integers(0, k)]
    parents[order[0]] = -1 - int(rng.integers(0, 3))  # any negative number is a root
    locals_ = np.array([unit_dq32(rng, 1.0) for _ in range(n)], F32)
    assert any(parents[i] > i for i in range(n)), "want some parents listed after their children"
    globals_ = dqskin.forward_kinematics(parents, locals_)
    assert globals_.shape == (n, 8) and globals_.dtype == F32
    local_m = dqskin.matrices_from_dual_quats(locals_).astype(np.float64)
    memo = {}

    def global_m(i):
        if i not in memo:
            memo[i] = local_m[i] if parents[i] < 0 else global_m(int(parents[i])) @ local_m[i]
        return memo[i]

    got = dqskin.matrices_from_dual_quats(globals_)
    for i in range(n):
        np.testing.assert_allclose(got[i], global_m(i), atol=FK_REL_TOL * (1 + np.abs(global_m(i)).max()))
        assert np.linalg.norm(globals_[i, :4]) == pytest.approx(1.0, abs=ROUNDING_TOL)
    # parents may be a list too
    np.testing.assert_array_equal(dqskin.forward_kinematics(parents.tolist(), locals_), globals_)


@pytest.mark.parametrize("seed", SEEDS)
def test_dual_quats_from_matrices_round_trip(seed):
    rng = np.random.default_rng(seed)
    mats = np.array([dq_to_matrix(random_unit_dq(rng)) for _ in range(32)], F32)
    dqs = dqskin.dual_quats_from_matrices(mats)
    assert dqs.shape == (32, 8) and dqs.dtype == F32
    back = dqskin.matrices_from_dual_quats(dqs)
    assert back.shape == (32, 4, 4) and back.dtype == F32
    np.testing.assert_allclose(back, mats, atol=POINT_TOL)
    for m, d in zip(mats, dqs):
        assert_same_transform(d, dq_from_rt(mat3_to_quat(m[:3, :3].astype(np.float64)), m[:3, 3]), DQ_TOL)
    again = dqskin.dual_quats_from_matrices(back)
    for a, b in zip(dqs, again):
        assert_same_transform(a, b, DQ_TOL)
    # Non-unit dual quaternions are normalized first.
    np.testing.assert_allclose(dqskin.matrices_from_dual_quats(dqs * F32(3.0)), back, atol=POINT_TOL)


# ---------------------------------------------------------------------------------------------
# The DualQuat class


def test_identity_and_defaults():
    i = dqskin.DualQuat.identity()
    assert i.real == (1.0, 0.0, 0.0, 0.0) and i.dual == (0.0, 0.0, 0.0, 0.0)
    assert dqskin.DualQuat() == i
    np.testing.assert_array_equal(i.to_matrix(), np.eye(4, dtype=F32))
    assert i.to_array().dtype == F32 and i.to_array().shape == (8,)
    assert i.transform_point([1, 2, 3]) == (1.0, 2.0, 3.0)
    assert i.is_unit()
    assert dqskin.DualQuat(real=[2, 0, 0, 0]) != i


@pytest.mark.parametrize("seed", SEEDS)
def test_from_rotation_translation_and_matrices(seed):
    rng = np.random.default_rng(seed)
    for _ in range(10):
        q = random_unit_quat(rng)
        t = rng.uniform(-3, 3, 3)
        d = dqskin.DualQuat.from_rotation_translation(q.astype(F32), t.astype(F32))
        assert d.is_unit()
        m = np.eye(4)
        m[:3, :3] = quat_to_mat3(q)
        m[:3, 3] = t
        np.testing.assert_allclose(d.to_matrix(), m, atol=POINT_TOL)
        np.testing.assert_allclose(d.translation, t, atol=POINT_TOL)
        assert dq_distance(d.rotation, q) < ROUNDING_TOL
        assert dq_distance(from_dualquat(d), dq_from_rt(q, t)) < ROUNDING_TOL
        # The quaternion is normalized here.
        d2 = dqskin.DualQuat.from_rotation_translation((5 * q).astype(F32), t.astype(F32))
        assert dq_distance(from_dualquat(d2), from_dualquat(d)) < ROUNDING_TOL
        # from_matrix is the inverse of to_matrix.
        assert dq_distance(from_dualquat(dqskin.DualQuat.from_matrix(m.astype(F32))), from_dualquat(d)) < DQ_TOL
        p = rng.uniform(-5, 5, 3)
        np.testing.assert_allclose(d.transform_point(p.astype(F32)), m[:3, :3] @ p + m[:3, 3], atol=POINT_TOL)
        pts = rng.uniform(-5, 5, (17, 3)).astype(F32)
        got = d.transform_points(pts)
        assert got.shape == (17, 3) and got.dtype == F32
        np.testing.assert_allclose(got, pts @ m[:3, :3].T + m[:3, 3], atol=POINT_TOL)
    assert dqskin.DualQuat.from_rotation_translation([1, 0, 0, 0]).translation == (0.0, 0.0, 0.0)
    tr = dqskin.DualQuat.from_translation([1.0, -2.0, 0.5])
    np.testing.assert_allclose(tr.translation, [1, -2, 0.5], atol=ROUNDING_TOL)
    np.testing.assert_allclose(tr.transform_point([0, 0, 0]), (1.0, -2.0, 0.5), atol=ROUNDING_TOL)


@pytest.mark.parametrize("seed", SEEDS)
def test_multiplication_is_composition(seed):
    rng = np.random.default_rng(seed)
    for _ in range(10):
        a, b = unit_dq32(rng), unit_dq32(rng)
        A, B = to_dualquat(a), to_dualquat(b)
        AB = A * B
        np.testing.assert_allclose(AB.to_matrix(), dq_to_matrix(a) @ dq_to_matrix(b), atol=POINT_TOL)
        assert dq_distance(from_dualquat(AB), dq_mul(a, b)) < ROUNDING_TOL
        p = rng.uniform(-2, 2, 3)
        np.testing.assert_allclose(AB.transform_point(p), A.transform_point(B.transform_point(p)), atol=POINT_TOL)
        # The conjugate of a unit dual quaternion is its inverse.
        for prod in (A * A.conjugate(), A.conjugate() * A):
            assert dq_distance(from_dualquat(prod), [1, 0, 0, 0, 0, 0, 0, 0]) < ROUNDING_TOL
        assert dq_distance(from_dualquat(A.inverse()), from_dualquat(A.conjugate())) < ROUNDING_TOL
        np.testing.assert_allclose(A.inverse().to_matrix(), np.linalg.inv(dq_to_matrix(a)), atol=POINT_TOL)
        # Scalars, sums and negation act on the eight components.
        np.testing.assert_array_equal(from_dualquat(A * 2.0), 2 * a)  # exact: times 2
        np.testing.assert_array_equal(from_dualquat(2.0 * A), 2 * a)
        np.testing.assert_allclose(from_dualquat(A + B), a.astype(np.float64) + b, atol=ROUNDING_TOL)
        np.testing.assert_allclose(from_dualquat(A - B), a.astype(np.float64) - b, atol=ROUNDING_TOL)
        np.testing.assert_array_equal(from_dualquat(-A), -a)
        assert A == to_dualquat(a) and A != B


def test_conjugates():
    a = np.float32([1, 2, 3, 4, 5, 6, 7, 8])
    A = to_dualquat(a)
    np.testing.assert_array_equal(A.conjugate().to_array(), [1, -2, -3, -4, 5, -6, -7, -8])
    np.testing.assert_array_equal(A.dual_conjugate().to_array(), [1, 2, 3, 4, -5, -6, -7, -8])
    np.testing.assert_array_equal(A.full_conjugate().to_array(), [1, -2, -3, -4, -5, 6, 7, 8])


@pytest.mark.parametrize("seed", SEEDS)
def test_norm_is_multiplicative_as_a_dual_number(seed):
    rng = np.random.default_rng(seed)
    for _ in range(10):
        a = rng.normal(size=8).astype(F32)  # general, non-unit dual quaternions
        b = rng.normal(size=8).astype(F32)
        A, B = to_dualquat(a), to_dualquat(b)
        ra, da = A.norm()
        rb, db = B.norm()
        assert ra == pytest.approx(np.linalg.norm(a[:4]), rel=NORM_REL_TOL)
        assert da == pytest.approx(np.dot(a[:4].astype(np.float64), a[4:]) / np.linalg.norm(a[:4]), rel=DUAL_NORM_REL_TOL, abs=ROUNDING_TOL)
        r, d = (A * B).norm()
        # (ra + ε da)(rb + ε db) = ra rb + ε (ra db + da rb)
        assert r == pytest.approx(ra * rb, rel=NORM_REL_TOL)
        assert d == pytest.approx(ra * db + da * rb, rel=DUAL_NORM_REL_TOL, abs=DUAL_NORM_REL_TOL * (1 + abs(ra * rb)))
        # normalized() divides by that norm: a unit dual quaternion, same transform.
        n = A.normalized()
        assert n.is_unit(ROUNDING_TOL)
        assert n.norm()[0] == pytest.approx(1.0, abs=ROUNDING_TOL) and abs(n.norm()[1]) < ROUNDING_TOL
        np.testing.assert_allclose(n.to_matrix(), A.to_matrix(), atol=POINT_TOL)
        assert not A.is_unit()


@pytest.mark.parametrize("seed", SEEDS)
def test_log_exp_pow(seed):
    rng = np.random.default_rng(seed)
    for _ in range(10):
        a = unit_dq32(rng)
        A = to_dualquat(a).shortest()
        assert A.real[0] >= 0
        L = A.log()
        assert L.real[0] == 0 and L.dual[0] == 0  # a pure dual quaternion
        assert dq_distance(from_dualquat(L.exp()), from_dualquat(A)) < DQ_TOL
        # log = screw axis · dual angle / 2
        s = A.screw()
        np.testing.assert_allclose(L.real[1:], np.asarray(s.axis) * s.angle / 2, atol=DQ_TOL)
        assert dq_distance(from_dualquat(A.pow(0.0)), [1, 0, 0, 0, 0, 0, 0, 0]) < ROUNDING_TOL
        assert dq_distance(from_dualquat(A.pow(1.0)), from_dualquat(A)) < DQ_TOL
        assert dq_distance(from_dualquat(A**1.0), from_dualquat(A)) < DQ_TOL
        half = A**0.5
        assert dq_distance(from_dualquat(half * half), from_dualquat(A)) < DQ_TOL
        assert rotation_angle(np.asarray(half.real)) == pytest.approx(s.angle / 2, abs=ANGLE_TOL)
        third = A.pow(1 / 3)
        assert dq_distance(from_dualquat(third * third * third), from_dualquat(A)) < DQ_TOL
    # Identity and pure translations go through log/exp smoothly.
    for d in (dqskin.DualQuat.identity(), dqskin.DualQuat.from_translation([1.0, 2.0, 3.0])):
        assert dq_distance(from_dualquat(d.log().exp()), from_dualquat(d)) < ROUNDING_TOL
    t = dqskin.DualQuat.from_translation([1.0, 2.0, 3.0])
    np.testing.assert_allclose(t.pow(0.5).translation, [0.5, 1.0, 1.5], atol=ROUNDING_TOL)


@pytest.mark.parametrize("seed", SEEDS)
def test_screw_round_trip(seed):
    rng = np.random.default_rng(seed)
    for _ in range(10):
        a = unit_dq32(rng)
        A = to_dualquat(a)
        s = A.screw()
        assert np.linalg.norm(s.axis) == pytest.approx(1.0, abs=ROUNDING_TOL)
        assert 0 <= s.angle <= 2 * np.pi + ROUNDING_TOL
        assert rotation_angle(a[:4]) == pytest.approx(min(s.angle, 2 * np.pi - s.angle), abs=ANGLE_TOL)
        # pitch is the translation along the axis; moment = point × axis.
        assert s.pitch == pytest.approx(np.dot(dq_translation(a), s.axis), abs=POINT_TOL)
        p = np.asarray(s.point())
        np.testing.assert_allclose(np.cross(p, s.axis), s.moment, atol=POINT_TOL)
        # The screw moves a point of its axis along the axis by `pitch`.
        np.testing.assert_allclose(dq_transform_point(a, p), p + s.pitch * np.asarray(s.axis), atol=POINT_TOL)
        back = dqskin.DualQuat.from_screw(s)
        assert dq_distance(from_dualquat(back), a) < DQ_TOL
        rebuilt = dqskin.DualQuat.from_screw(dqskin.Screw(s.axis, s.moment, s.angle, s.pitch))
        assert dq_distance(from_dualquat(rebuilt), a) < DQ_TOL
    # A pure translation: the axis is its direction.
    s = dqskin.DualQuat.from_translation([0.0, 3.0, 0.0]).screw()
    assert s.angle == 0.0 and s.pitch == pytest.approx(3.0, abs=ROUNDING_TOL)
    np.testing.assert_allclose(s.axis, [0, 1, 0], atol=ROUNDING_TOL)


def test_repr():
    r = repr(dqskin.DualQuat.from_rotation_translation([1, 0, 0, 0], [1, 2, 3]))
    assert r.startswith("DualQuat(real=(1.0, 0.0, 0.0, 0.0), dual=(") and r.endswith(")")
    s = repr(dqskin.DualQuat.identity().screw())
    assert s.startswith("Screw(axis=")
    assert "Influences(vertex_count=2" in repr(dqskin.Influences(np.array([0, 1, 1]), np.array([0]), F32([1]), 1))


def test_shortest_and_rotation():
    d = dqskin.DualQuat.from_rotation_translation([0.6, 0.8, 0, 0], [1, 0, 0])
    neg = -d
    assert neg.real[0] < 0 and neg.shortest() == d and d.shortest() == d
    np.testing.assert_array_equal(neg.to_matrix(), d.to_matrix())
    np.testing.assert_allclose(dqskin.DualQuat([0, 0, 0, 2]).rotation, [0, 0, 0, 1])

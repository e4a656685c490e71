"""Keyed tracks through the numpy API: Slerp/Squad sampling, ScLERP in-betweens, cleanup, Spring."""

from __future__ import annotations

import dqskin
import numpy as np
import pytest

F32 = np.float32


def axis_angle(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis]).astype(F32)


def qmul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


TIMES = F32([1, 11, 17, 31, 37])
KEYS = np.stack(
    [
        axis_angle([1, 0, 0], 0.0),
        axis_angle([1, 0, 0], 1.2),
        qmul(axis_angle([1, 0, 0], 1.2), axis_angle([0, 1, 0], 1.4)).astype(F32),
        qmul(axis_angle([0, 0, 1], -0.8), axis_angle([0, 1, 0], 0.6)).astype(F32),
        axis_angle([0, 0, 1], 0.9),
    ]
)


@pytest.mark.parametrize("method", ["slerp", "squad"])
def test_samples_pass_through_the_keys(method):
    got = dqskin.sample_rotations(TIMES, KEYS, TIMES, method=method)
    assert got.shape == (5, 4)
    np.testing.assert_allclose(np.abs(np.sum(got * KEYS, axis=1)), 1.0, atol=1e-6)


def test_slerp_segments_have_constant_angular_speed():
    # Every frame between two keys: speed constant to 1e-4 rad per frame (f32 round-off).
    at = np.arange(11, 18, dtype=F32)
    speeds = dqskin.angular_speeds(dqskin.sample_rotations(TIMES, KEYS, at, method="slerp"))
    assert np.ptp(speeds) < 1e-4, speeds


def test_squad_is_c1_in_time_and_slerp_is_not():
    def velocity_jump(method, t, h=0.02):
        """|one-sided angular speed before t − after t| in rad/frame, each Richardson-extrapolated
        (2·v(h) − v(2h)) since the acceleration jumps at keys."""

        def rot(x):
            return dqskin.sample_rotations(TIMES, KEYS, F32([x]), method=method)[0]

        def speed(a, b, dt):
            return dqskin.angular_speeds(np.stack([a, b]))[0] / dt

        left = 2 * speed(rot(t - h), rot(t), h) - speed(rot(t - 2 * h), rot(t), 2 * h)
        right = 2 * speed(rot(t), rot(t + h), h) - speed(rot(t), rot(t + 2 * h), 2 * h)
        return abs(left - right)

    # Tolerance: f32 round-off over 0.02-frame differences (~1e-5 rad / 0.02).
    for t in TIMES[1:-1]:
        assert velocity_jump("squad", float(t)) < 2e-3, t
    assert max(velocity_jump("slerp", float(t)) for t in TIMES[1:-1]) > 1e-2


def test_continuous_signs_removes_every_flip():
    keys = np.stack([axis_angle([0, 1, 0], 0.3 * i) for i in range(12)])
    keys[[2, 3, 7]] *= -1
    fixed, flipped = dqskin.continuous_signs(keys)
    assert flipped == 3
    assert np.all(np.sum(fixed[1:] * fixed[:-1], axis=1) >= 0)
    np.testing.assert_allclose(np.linalg.norm(fixed, axis=1), 1.0, atol=1e-6)


def test_screw_in_betweens_have_constant_speed():
    a = dqskin.DualQuat.identity().to_array()
    b = dqskin.DualQuat.from_rotation_translation(axis_angle([0, 0, 1], 1.5), [2.0, 0.0, 1.0]).to_array()
    at = np.linspace(0, 10, 21, dtype=F32)
    samples = dqskin.sample_transforms(F32([0, 10]), np.stack([a, b]), at)
    assert samples.shape == (21, 8)
    steps = [
        (dqskin.DualQuat(s[:4], s[4:]).conjugate() * dqskin.DualQuat(t[:4], t[4:])).shortest().screw()
        for s, t in zip(samples[:-1], samples[1:])
    ]
    angles = np.array([s.angle for s in steps])
    pitches = np.array([s.pitch for s in steps])
    assert np.ptp(angles) < 1e-4 and np.ptp(pitches) < 1e-4


def test_spring_keeps_keys_and_lowers_curvature_below_squad():
    samples = dqskin.spring(TIMES, KEYS, step=1.0, iterations=600)
    frames = np.arange(1, 38, dtype=F32)
    assert samples.shape == (37, 4)
    np.testing.assert_allclose(np.abs(np.sum(samples[(TIMES - 1).astype(int)] * KEYS, axis=1)), 1.0, atol=1e-6)
    squad = dqskin.sample_rotations(TIMES, KEYS, frames, method="squad")
    assert dqskin.curvature_energy(samples) < dqskin.curvature_energy(squad)


def test_bad_track_inputs_are_named():
    with pytest.raises(ValueError, match="times must increase strictly"):
        dqskin.sample_rotations(F32([0, 0]), KEYS[:2], F32([0]))
    with pytest.raises(ValueError, match="2 key times for 3 keys"):
        dqskin.sample_rotations(F32([0, 1]), KEYS[:3], F32([0]))
    with pytest.raises(ValueError, match="method must be"):
        dqskin.sample_rotations(TIMES, KEYS, F32([0]), method="cubic")
    with pytest.raises(ValueError, match="not on the sample grid"):
        dqskin.spring(TIMES, KEYS, step=4.0)
    with pytest.raises(ValueError, match="keys must have shape"):
        dqskin.sample_rotations(TIMES, KEYS[:, :3], F32([0]))
    with pytest.raises(ValueError, match="zero quaternion"):
        dqskin.continuous_signs(np.zeros((2, 4), F32))
    with pytest.raises(ValueError, match="zero real part"):
        dqskin.sample_transforms(F32([0, 1]), np.zeros((2, 8), F32), F32([0.5]))

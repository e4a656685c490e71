"""`dqskin.skin_many`: many meshes in one call, each exactly as `dqskin.skin` would skin it."""

from __future__ import annotations

import numpy as np
import pytest

import dqskin


def mesh(rng, v: int, bones: int, k: int = 4):
    positions = rng.normal(size=(v, 3)).astype(np.float32)
    influences = dqskin.Influences.from_dense(rng.integers(0, bones, (v, k)), rng.random((v, k), dtype=np.float32), bones)
    rest = np.tile(np.eye(4, dtype=np.float32), (bones, 1, 1))
    rest[:, :3, 3] = rng.normal(size=(bones, 3))
    deform = np.stack([dqskin.DualQuat.from_rotation_translation(q / np.linalg.norm(q), t).to_matrix()
                       for q, t in zip(rng.normal(size=(bones, 4)).astype(np.float32), rng.normal(size=(bones, 3)).astype(np.float32))])
    return positions, influences, np.ascontiguousarray(deform, np.float32), rest


@pytest.mark.parametrize("method", ["linear", "dual_quaternion", "blend"])
def test_each_job_equals_a_skin_call(method):
    rng = np.random.default_rng(5)
    jobs, want = [], []
    for v, bones in ((17, 3), (5000, 12), (40000, 30), (1, 1)):
        p, inf, d, r = mesh(rng, v, bones)
        premat = np.eye(4, dtype=np.float32)
        premat[:3, 3] = (0.5, -1.0, 2.0)
        postmat = np.linalg.inv(premat).astype(np.float32)
        mask = rng.random(v, dtype=np.float32)
        blend = rng.random(v, dtype=np.float32) if method == "blend" else None
        want.append(dqskin.skin(p, inf, d, r, method=method, premat=premat, postmat=postmat, mask=mask, blend=blend, blend_factor=0.7))
        jobs.append((p, inf, d, r, method, premat, postmat, mask, blend, 0.7, np.full((v, 3), 9.0, np.float32)))
    assert dqskin.skin_many(jobs) == [None] * len(jobs)
    for job, w in zip(jobs, want):
        np.testing.assert_array_equal(job[-1], w)


def test_a_failing_job_reports_its_error_and_leaves_its_out_alone():
    rng = np.random.default_rng(6)
    p, inf, d, r = mesh(rng, 100, 4)
    good = np.zeros((100, 3), np.float32)
    bad = np.full((100, 3), 3.0, np.float32)
    res = dqskin.skin_many([
        (p, inf, d, r, "linear", None, None, None, None, 1.0, good),
        (p, inf, d, None, "dual_quaternion", None, None, None, None, 1.0, bad),
    ])
    assert res[0] is None and "rest" in res[1]
    assert (bad == 3.0).all() and not (good == 0.0).all()


@pytest.mark.parametrize(
    "change, error, words",
    [
        (lambda j: (j[0].astype(np.float64),) + j[1:], TypeError, ["jobs[1]", "positions"]),
        (lambda j: j[:1] + ("not influences",) + j[2:], TypeError, ["jobs[1]", "influences"]),
        (lambda j: j[:4] + ("slerp",) + j[5:], ValueError, ["jobs[1]", "method"]),
        (lambda j: j[:10] + (np.empty((3, 3), np.float32),), ValueError, ["jobs[1]", "out"]),
        (lambda j: j[:10], ValueError, ["jobs[1]", "11 items"]),
        (lambda j: [1, 2], TypeError, ["jobs[1]", "tuple"]),
    ],
)
def test_bad_jobs_raise_naming_the_job_and_the_argument(change, error, words):
    rng = np.random.default_rng(7)
    p, inf, d, r = mesh(rng, 10, 2)
    job = (p, inf, d, r, "linear", None, None, None, None, 1.0, np.zeros((10, 3), np.float32))
    with pytest.raises(error) as e:
        dqskin.skin_many([job, change(job)])
    assert all(w in str(e.value) for w in words), str(e.value)


def test_the_same_out_twice_is_refused():
    rng = np.random.default_rng(8)
    p, inf, d, r = mesh(rng, 10, 2)
    out = np.zeros((10, 3), np.float32)
    job = (p, inf, d, r, "linear", None, None, None, None, 1.0, out)
    with pytest.raises(ValueError, match="jobs\\[1\\]"):
        dqskin.skin_many([job, job])

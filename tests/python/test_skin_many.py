"""`dqskin.SkinJob` and `dqskin.skin_many`: many meshes in one call, each exactly as `dqskin.skin`
would skin it; jobs checked when built and when their per-frame inputs are replaced."""

from __future__ import annotations

import dqskin
import dqskin.memory
import numpy as np
import pytest

F = np.float32


def mesh(rng, v: int, bones: int, k: int = 4):
    positions = rng.normal(size=(v, 3)).astype(F)
    influences = dqskin.Influences.from_dense(rng.integers(0, bones, (v, k)), rng.random((v, k), dtype=F), bones)
    rest = np.tile(np.eye(4, dtype=F), (bones, 1, 1))
    rest[:, :3, 3] = rng.normal(size=(bones, 3))
    return positions, influences, pose(rng, bones), rest


def pose(rng, bones: int) -> np.ndarray:
    deform = np.stack(
        [
            dqskin.DualQuat.from_rotation_translation(q / np.linalg.norm(q), t).to_matrix()
            for q, t in zip(rng.normal(size=(bones, 4)).astype(F), rng.normal(size=(bones, 3)).astype(F))
        ]
    )
    return np.ascontiguousarray(deform, F)


@pytest.mark.parametrize("method", ["linear", "dual_quaternion", "blend", dqskin.Method.BLEND])
def test_each_job_equals_a_skin_call(method):
    rng = np.random.default_rng(5)
    jobs, want = [], []
    for v, bones in ((17, 3), (5000, 12), (40000, 30), (1, 1)):
        p, inf, d, r = mesh(rng, v, bones)
        premat = np.eye(4, dtype=F)
        premat[:3, 3] = (0.5, -1.0, 2.0)
        postmat = np.linalg.inv(premat).astype(F)
        mask = rng.random(v, dtype=F)
        blend = rng.random(v, dtype=F) if dqskin.Method(method) == dqskin.Method.BLEND else None
        kw = dict(method=method, premat=premat, postmat=postmat, mask=mask, blend=blend, blend_factor=0.7)
        want.append(dqskin.skin(p, inf, d, r, **kw))
        jobs.append(dqskin.SkinJob(p, inf, d, r, out=np.full((v, 3), 9.0, F), **kw))
    assert dqskin.skin_many(jobs) == [None] * len(jobs)
    for job, w in zip(jobs, want):
        np.testing.assert_array_equal(job.out, w)
    assert dqskin.skin_many(tuple(jobs)) == [None] * len(jobs)  # any sequence
    assert dqskin.skin_many([]) == []


@pytest.mark.parametrize("method", ["linear", "dual_quaternion"])
def test_share_from_gives_the_same_bits_on_the_calling_thread_alone(method):
    """Below `share_from` vertices over all the jobs the calling thread runs them alone (the
    Rust pool's test checks which thread): every job as shared, in every chunk of a large one."""
    rng = np.random.default_rng(8)
    meshes = [mesh(rng, v, bones) for v, bones in ((40000, 30), (3000, 300), (17, 3))]
    total = sum(len(p) for p, *_ in meshes)
    results = {}
    for share_from in (None, 0, total, total + 1, 10**12):
        jobs = [dqskin.SkinJob(p, inf, d, r, method=method, out=np.full((len(p), 3), 9.0, F)) for p, inf, d, r in meshes]
        assert dqskin.skin_many(jobs, share_from=share_from) == [None] * len(jobs)
        results[share_from] = [j.out.copy() for j in jobs]
    for share_from, outs in results.items():
        for got, (p, inf, d, r) in zip(outs, meshes):
            np.testing.assert_array_equal(got, dqskin.skin(p, inf, d, r, method=method), err_msg=str(share_from))


@pytest.mark.parametrize("share_from, error", [(-1, ValueError), (1.5, TypeError), ("10", TypeError), (True, TypeError), ([1], TypeError)])
def test_a_bad_share_from_is_refused_naming_it(share_from, error):
    rng = np.random.default_rng(9)
    p, inf, d, r = mesh(rng, 10, 2)
    job = dqskin.SkinJob(p, inf, d, r, out=np.zeros((10, 3), F))
    with pytest.raises(error, match="share_from"):
        dqskin.skin_many([job], share_from=share_from)
    assert not job.out.any()


def test_a_job_keeps_its_arrays_and_allocates_out_when_not_given():
    rng = np.random.default_rng(4)
    p, inf, d, r = mesh(rng, 30, 3)
    out = np.zeros((30, 3), F)
    job = dqskin.SkinJob(p, inf, d, r, method="linear", out=out)
    assert job.positions is p and job.deform is d and job.rest is r and job.out is out and job.influences is inf
    assert job.method == dqskin.Method.LINEAR and job.premat is None and job.mask is None and job.blend_factor == 1.0
    own = dqskin.SkinJob(p, inf, d, r)
    assert own.out.shape == (30, 3) and own.out.dtype == F and own.method == dqskin.Method.DUAL_QUATERNION
    assert "vertices=30" in repr(own) and "DUAL_QUATERNION" in repr(own)
    p[:] += 1.0  # arrays are read when the job runs
    assert dqskin.skin_many([job]) == [None]
    np.testing.assert_array_equal(out, dqskin.skin(p, inf, d, r, method="linear"))


def test_the_per_frame_inputs_can_be_replaced_on_a_kept_job():
    rng = np.random.default_rng(9)
    p, inf, d, r = mesh(rng, 200, 5)
    job = dqskin.SkinJob(p, inf, d, r, method="dual_quaternion")
    for frame in range(3):
        p2 = (p + frame).astype(F)
        d2 = pose(rng, 5)
        premat = np.eye(4, dtype=F)
        premat[:3, 3] = frame
        job.positions, job.deform, job.premat, job.postmat = p2, d2, premat, None
        assert dqskin.skin_many([job]) == [None]
        np.testing.assert_array_equal(job.out, dqskin.skin(p2, inf, d2, r, premat=premat))
    assert job.positions is p2 and job.deform is d2 and job.premat is premat and job.postmat is None


@pytest.mark.parametrize(
    "attribute, value, error, words",
    [
        ("positions", np.zeros((7, 3), F), ValueError, ["positions", "(10, 3)"]),
        ("positions", np.zeros((10, 3)), TypeError, ["positions", "float32"]),
        ("positions", None, TypeError, ["positions"]),
        ("deform", np.zeros((3, 4, 4), F), ValueError, ["deform", "(2, 4, 4)"]),
        ("deform", np.full((2, 4, 4), np.nan, F), ValueError, ["deform", "NaN"]),
        ("premat", np.zeros((3, 3), F), ValueError, ["premat", "(4, 4)"]),
        ("postmat", "eye", TypeError, ["postmat"]),
        ("out", np.zeros((7, 3), F), ValueError, ["out", "(10, 3)"]),
        ("out", np.zeros((10, 3)), TypeError, ["out", "float32"]),
        ("out", np.zeros((10, 3), F)[::-1], ValueError, ["out", "contiguous"]),
        ("out", "buffer", TypeError, ["out"]),
    ],
)
def test_a_refused_replacement_names_the_argument_and_leaves_the_job(attribute, value, error, words):
    rng = np.random.default_rng(3)
    p, inf, d, r = mesh(rng, 10, 2)
    job = dqskin.SkinJob(p, inf, d, r)
    before = getattr(job, attribute)
    with pytest.raises(error) as e:
        setattr(job, attribute, value)
    assert all(w in str(e.value) for w in words), str(e.value)
    assert getattr(job, attribute) is before
    assert dqskin.skin_many([job]) == [None]


def test_only_the_per_frame_inputs_are_settable():
    rng = np.random.default_rng(3)
    p, inf, d, r = mesh(rng, 10, 2)
    job = dqskin.SkinJob(p, inf, d, r)
    for name in ("influences", "rest", "method", "mask", "blend", "blend_factor", "centers"):
        with pytest.raises(AttributeError):
            setattr(job, name, getattr(job, name))


def test_out_can_be_replaced_by_a_view_of_other_memory():
    """A job writes into whatever `out` names when it runs: a view of memory it does not own
    (the extension points it at Blender's own position array), then its own array again."""
    rng = np.random.default_rng(4)
    p, inf, d, r = mesh(rng, 50, 3)
    job = dqskin.SkinJob(p, inf, d, r, method="linear")
    own = job.out
    backing = np.zeros(50 * 3 + 8, F)
    view = backing[4:-4].reshape(50, 3)  # C-contiguous, inside a larger allocation
    job.out = view
    assert dqskin.skin_many([job]) == [None]
    np.testing.assert_array_equal(view, dqskin.skin(p, inf, d, r, method="linear"))
    assert not backing[:4].any() and not backing[-4:].any()
    assert not own.any()
    job.out = own
    assert dqskin.skin_many([job]) == [None]
    np.testing.assert_array_equal(own, view)
    with pytest.raises(ValueError, match="out"):
        job.out = p  # writing over an input is refused when it runs, or here
        dqskin.skin_many([job])


def test_a_job_can_keep_no_out_between_runs():
    """`out = None` drops the job's array (a caller that writes elsewhere each run keeps no
    buffer); run so, the job is refused naming it, and another `out` makes it run again."""
    rng = np.random.default_rng(5)
    p, inf, d, r = mesh(rng, 20, 2)
    job = dqskin.SkinJob(p, inf, d, r)
    job.out = None
    assert job.out is None
    with pytest.raises(ValueError, match=r"jobs\[0\]: out is not set"):
        dqskin.skin_many([job])
    job.out = np.empty((20, 3), F)
    assert dqskin.skin_many([job]) == [None]
    np.testing.assert_array_equal(job.out, dqskin.skin(p, inf, d, r))


def test_a_failing_job_reports_its_error_and_leaves_its_out_alone():
    rng = np.random.default_rng(6)
    p, inf, d, r = mesh(rng, 100, 4)
    good = np.zeros((100, 3), F)
    bad = np.full((100, 3), 3.0, F)
    mask = np.ones(100, F)
    jobs = [dqskin.SkinJob(p, inf, d, r, method="linear", out=good), dqskin.SkinJob(p, inf, d, r, mask=mask, out=bad)]
    mask[7] = 2.0  # in place after the job was built: the kernel's check reports it
    res = dqskin.skin_many(jobs)
    assert res[0] is None and "mask[7] = 2 is outside [0, 1]" in res[1]
    assert (bad == 3.0).all() and not (good == 0.0).all()


@pytest.mark.parametrize(
    "change, error, words",
    [
        (dict(positions=np.zeros((10, 3))), TypeError, ["positions", "float32"]),
        (dict(influences="not influences"), TypeError, ["influences", "dqskin.Influences"]),
        (dict(method="slerp"), ValueError, ["method", "slerp"]),
        (dict(method=2), TypeError, ["method"]),
        (dict(out=np.empty((3, 3), F)), ValueError, ["out", "(10, 3)"]),
        (dict(rest=None, method="dual_quaternion"), ValueError, ["rest is required"]),
        (dict(blend=np.ones(10, F)), ValueError, ["blend is only used"]),
        (dict(mask=np.ones(9, F)), ValueError, ["mask", "(10,)"]),
        (dict(blend_factor="half"), TypeError, ["blend_factor"]),
    ],
)
def test_bad_jobs_are_refused_when_built_naming_the_argument(change, error, words):
    rng = np.random.default_rng(7)
    p, inf, d, r = mesh(rng, 10, 2)
    kw = dict(positions=p, influences=inf, deform=d, rest=r, method="linear", out=np.zeros((10, 3), F)) | change
    with pytest.raises(error) as e:
        dqskin.SkinJob(**kw)
    assert all(w in str(e.value) for w in words), str(e.value)


@pytest.mark.parametrize(
    "jobs, error, words",
    [
        (lambda job: [job, (1, 2)], TypeError, ["jobs[1]", "dqskin.SkinJob", "tuple"]),
        (lambda job: job, TypeError, ["jobs", "list of dqskin.SkinJob"]),
        (lambda job: None, TypeError, ["jobs"]),
    ],
)
def test_skin_many_takes_jobs_only(jobs, error, words):
    rng = np.random.default_rng(7)
    p, inf, d, r = mesh(rng, 10, 2)
    with pytest.raises(error) as e:
        dqskin.skin_many(jobs(dqskin.SkinJob(p, inf, d, r)))
    assert all(w in str(e.value) for w in words), str(e.value)


def test_the_same_out_twice_is_refused_naming_the_job():
    rng = np.random.default_rng(8)
    p, inf, d, r = mesh(rng, 10, 2)
    out = np.zeros((10, 3), F)
    job = dqskin.SkinJob(p, inf, d, r, out=out)
    other = dqskin.SkinJob(p, inf, d, r, out=out)
    for jobs in ([job, job], [job, other]):
        with pytest.raises(ValueError, match=r"jobs\[1\]: out must not be"):
            dqskin.skin_many(jobs)
    assert (out == 0).all()


def test_an_array_reshaped_after_building_is_refused_when_run():
    rng = np.random.default_rng(8)
    p, inf, d, r = mesh(rng, 10, 2)
    job = dqskin.SkinJob(p, inf, d, r)
    p.shape = (30,)
    with pytest.raises(ValueError, match=r"jobs\[0\]: positions must have shape \(10, 3\)"):
        dqskin.skin_many([job])


def test_positions_digest_changes_with_any_bit_and_names_bad_input():
    """What the extension compares instead of a kept copy of a mesh's positions
    (`dqskin.memory.MeshPositions` is only made by the memory reader, inside Blender)."""
    digest = dqskin.memory.positions_digest
    rng = np.random.default_rng(3)
    p = rng.standard_normal((1000, 3)).astype(np.float32)
    d = digest(p)
    assert isinstance(d, bytes) and len(d) == 16 and digest(p.copy()) == d
    for i, j in ((0, 0), (517, 1), (999, 2)):
        q = p.copy()
        q[i, j] = np.nextafter(q[i, j], np.float32(np.inf))
        assert digest(q) != d
    assert digest(p[:999].copy()) != d and digest(np.zeros((0, 3), np.float32)) != digest(np.zeros((1, 3), np.float32))
    with pytest.raises(ValueError, match="positions"):
        digest(np.zeros((4, 2), np.float32))
    with pytest.raises(TypeError, match="positions"):
        digest(p.astype(np.float64))
    with pytest.raises(TypeError):
        dqskin.memory.MeshPositions()

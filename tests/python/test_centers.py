"""Skinning with optimized centers of rotation (Le & Hodgins, SIGGRAPH 2016):
``dqskin.centers_of_rotation`` against a float64 brute force of the paper's formula, and
``dqskin.skin(..., method='centers_of_rotation')`` against a float64 reference of the per-frame
formula (with the scale/shear phase dqskin documents), plus the method's properties and bad
input."""

from __future__ import annotations

import _thread
import threading
import time

import dqskin
import numpy as np
import pytest
from centers_meshes import dense_of, tube
from centers_reference import SIGMA, brute_force_centers, diagonal, reference_skin
from dqmath import quat_to_mat3, random_unit_quat

F = np.float32
# Centers: the paper's formula in float64 against dqskin's float64 sums stored as float32; the
# bound is what dqskin promises (its exp differs from the library's by < 1e-11 relative).
CENTER_TOL = 1e-5  # × bounding box diagonal
# Kernel: float32 against float64 on the same inputs, as in test_skinning.py (a few dozen
# dependent float32 operations on magnitudes up to ~10× the result).
REL_TOL = 5e-5


def check_centers(positions, triangles, influences, sigma=SIGMA):
    want, want_has = brute_force_centers(positions, triangles, influences, sigma)
    got, has = dqskin.centers_of_rotation(positions, triangles, influences, sigma, with_mask=True)
    assert got.dtype == np.float32 and got.shape == (len(positions), 3)
    assert has.dtype == np.bool_ and has.shape == (len(positions),)
    np.testing.assert_array_equal(has, want_has)
    assert np.all(np.linalg.norm(got[has] - want[has], axis=1) <= CENTER_TOL * diagonal(positions))
    np.testing.assert_array_equal(got[~has], positions[~has])
    return got, has


def random_rig(rest, rng, scaled=True):
    """Deform matrices (posed @ inv(rest)) with random rotations; some bones scaled or sheared."""
    deform = []
    for b, r in enumerate(rest):
        posed = np.eye(4)
        posed[:3, :3] = quat_to_mat3(random_unit_quat(rng))
        posed[:3, 3] = rng.normal(size=3)
        if scaled and b % 3 == 1:
            posed[:3, :3] = posed[:3, :3] @ np.diag(rng.uniform(0.5, 2.0, size=3))
        if scaled and b % 3 == 2:
            shear = np.eye(3)
            shear[0, 1] = 0.4
            posed[:3, :3] = posed[:3, :3] @ shear
        deform.append(posed @ np.linalg.inv(r))
    return np.asarray(deform, F)


def test_precompute_matches_the_brute_force():
    positions, tris, influences, _ = tube()
    centers, has = check_centers(positions, tris, influences)
    assert has.all()
    # Centers of a tube whose weights hardly vary around it lie near its axis.
    assert np.median(np.hypot(centers[:, 0], centers[:, 2])) < 0.1


def test_precompute_on_random_meshes_and_weights():
    rng = np.random.default_rng(5)
    for case in range(6):
        v, bones = 25, int(rng.integers(1, 5))
        positions = rng.normal(size=(v, 3)).astype(F)
        tris = rng.integers(0, v, size=(40, 3))
        counts = rng.integers(0, 4, size=v)
        offsets = np.concatenate([[0], np.cumsum(counts)])
        idx = rng.integers(0, bones, size=offsets[-1])
        w = np.where(rng.random(offsets[-1]) < 0.15, 0.0, rng.uniform(0, 2, offsets[-1])).astype(F)
        influences = dqskin.Influences(offsets, idx, w, bones)
        check_centers(positions, tris, influences, sigma=[0.1, 0.5, 0.04][case % 3])


def test_vertices_without_a_center_keep_their_position():
    cyl = dqskin.TwistCylinder(9, 12, 2.0, 0.5, 0.5)
    centers, has = check_centers(cyl.positions, cyl.triangles, cyl.influences)
    counts = np.diff(cyl.influences.offsets)
    np.testing.assert_array_equal(has, counts == 2)
    assert np.allclose(centers[has][:, [0, 2]], 0.0, atol=1e-5), "blended rings: centers on the axis"
    plain = dqskin.centers_of_rotation(cyl.positions, cyl.triangles, cyl.influences)
    np.testing.assert_array_equal(plain, centers)


def test_kernel_matches_the_reference_with_scaled_bones_spaces_and_mask():
    rng = np.random.default_rng(11)
    positions, tris, influences, rest = tube(rings=12, segments=10)
    centers = dqskin.centers_of_rotation(positions, tris, influences)
    deform = random_rig(rest, rng)
    premat = np.eye(4, dtype=F)
    premat[:3, :3] = quat_to_mat3(random_unit_quat(rng)) * 1.5
    premat[:3, 3] = [0.3, -1.0, 2.0]
    postmat = np.linalg.inv(premat).astype(F)
    mask = rng.random(len(positions)).astype(F)
    mask[::7] = 0.0
    got = dqskin.skin(
        positions, influences, deform, rest, method="centers_of_rotation", centers=centers, premat=premat, postmat=postmat, mask=mask
    )
    want = reference_skin(positions, centers, influences, deform, rest, premat=premat, postmat=postmat, mask=mask)
    err = np.linalg.norm(got - want, axis=1)
    assert np.all(err <= REL_TOL * (1 + np.linalg.norm(want, axis=1))), err.max()
    np.testing.assert_array_equal(got[::7], positions[::7])


def test_rows_without_a_center_are_lbs_and_translations_are_lbs():
    rng = np.random.default_rng(3)
    positions, tris, influences, rest = tube(rings=10, segments=8)
    deform = random_rig(rest, rng)
    cor = dqskin.skin(positions, influences, deform, rest, method="centers_of_rotation", centers=positions)
    lbs = dqskin.skin(positions, influences, deform, rest, method="linear")
    assert np.allclose(cor, lbs, rtol=0, atol=REL_TOL * (1 + np.abs(lbs).max()))
    shifts = np.tile(np.eye(4, dtype=F), (len(rest), 1, 1))
    shifts[:, :3, 3] = rng.normal(size=(len(rest), 3))
    centers = dqskin.centers_of_rotation(positions, tris, influences)
    cor = dqskin.skin(positions, influences, shifts, rest, method="cor", centers=centers)
    lbs = dqskin.skin(positions, influences, shifts, rest, method="lbs")
    assert np.allclose(cor, lbs, rtol=0, atol=1e-5)
    still = dqskin.skin(
        positions, influences, np.tile(np.eye(4, dtype=F), (len(rest), 1, 1)), rest, method="centers_of_rotation", centers=centers
    )
    assert np.allclose(still, positions, rtol=0, atol=1e-5)


def test_candy_wrapper_keeps_the_middle_cross_section():
    cyl = dqskin.TwistCylinder(21, 48, 4.0, 0.5, 0.5)
    centers = dqskin.centers_of_rotation(cyl.positions, cyl.triangles, cyl.influences)
    rest_area = dqskin.polygon_area(cyl.positions[cyl.ring(10)])
    deform = cyl.twist(np.pi)
    out = dqskin.skin(cyl.positions, cyl.influences, deform, cyl.rest, method="centers_of_rotation", centers=centers)
    lbs = dqskin.skin(cyl.positions, cyl.influences, deform, cyl.rest, method="linear")
    assert dqskin.polygon_area(out[cyl.ring(10)]) / rest_area >= 0.95
    assert dqskin.polygon_area(lbs[cyl.ring(10)]) / rest_area < 1e-6


def test_skin_many_takes_centers_in_a_job():
    rng = np.random.default_rng(8)
    positions, tris, influences, rest = tube(rings=10, segments=8)
    centers = dqskin.centers_of_rotation(positions, tris, influences)
    deform = random_rig(rest, rng, scaled=False)
    want = dqskin.skin(positions, influences, deform, rest, method="centers_of_rotation", centers=centers)
    cor = dqskin.SkinJob(positions, influences, deform, rest, method=dqskin.Method.CENTERS_OF_ROTATION, centers=centers)
    lbs = dqskin.SkinJob(positions, influences, deform, rest, method="linear")
    assert dqskin.skin_many([cor, lbs]) == [None, None]
    np.testing.assert_array_equal(cor.out, want)
    np.testing.assert_array_equal(lbs.out, dqskin.skin(positions, influences, deform, rest, method="linear"))
    with pytest.raises(ValueError, match=r"centers is required"):
        dqskin.SkinJob(positions, influences, deform, rest, method="cor")
    with pytest.raises(ValueError, match=r"centers is only used"):
        dqskin.SkinJob(positions, influences, deform, rest, method="linear", centers=centers)


@pytest.mark.parametrize(
    "kwargs, error, words",
    [
        (dict(sigma=0.0), ValueError, ["sigma"]),
        (dict(sigma=float("nan")), ValueError, ["sigma"]),
        (dict(sigma="wide"), TypeError, ["sigma"]),
        (dict(with_mask=1), TypeError, ["with_mask"]),
        (dict(triangles=np.array([[0, 1, 999]])), ValueError, ["triangles[0]", "999"]),
        (dict(triangles=np.array([[0, 1, -1]])), ValueError, ["triangles"]),
        (dict(triangles=np.zeros((2, 4), int)), ValueError, ["triangles", "(T, 3)"]),
        (dict(triangles=np.zeros((2, 3), F)), TypeError, ["triangles"]),
        (dict(positions=np.zeros((3, 3), F)), ValueError, ["positions"]),
        (dict(positions=np.zeros((100, 3))), TypeError, ["positions", "float32"]),
        (dict(positions=np.full((100, 3), np.nan, F)), ValueError, ["positions[0]"]),
        (dict(influences="weights"), TypeError, ["influences"]),
    ],
)
def test_bad_precompute_input(kwargs, error, words):
    cyl = dqskin.TwistCylinder(10, 10)
    args = dict(
        positions=cyl.positions[:100].copy(),
        triangles=cyl.triangles[:50],
        influences=dqskin.Influences(
            cyl.influences.offsets[:101],
            cyl.influences.bones[: cyl.influences.offsets[100]],
            cyl.influences.weights[: cyl.influences.offsets[100]],
            2,
        ),
    )
    args.update(kwargs)
    with pytest.raises(error) as e:
        dqskin.centers_of_rotation(**args)
    for w in words:
        assert w in str(e.value), str(e.value)


def test_bad_kernel_input_leaves_out_untouched():
    positions, tris, influences, rest = tube(rings=4, segments=8)
    deform = np.tile(np.eye(4, dtype=F), (len(rest), 1, 1))
    out = np.full_like(positions, 7.25)
    cases = [
        (dict(method="centers_of_rotation"), ValueError, "centers is required"),
        (dict(method="centers_of_rotation", centers=positions[:5]), ValueError, "centers"),
        (dict(method="centers_of_rotation", centers=positions.astype(np.float64)), TypeError, "centers"),
        (dict(method="centers_of_rotation", centers=np.full_like(positions, np.inf)), ValueError, "centers"),
        (dict(method="dual_quaternion", centers=positions), ValueError, "centers is only used"),
        (dict(method="centers_of_rotation", centers=positions, rest=None), ValueError, "rest"),
    ]
    for kw, error, word in cases:
        args = dict(rest=rest, out=out)
        args.update(kw)
        with pytest.raises(error, match=word):
            dqskin.skin(positions, influences, deform, **args)
        assert np.all(out == 7.25)


@pytest.mark.slow
def test_ctrl_c_stops_a_long_precompute():
    positions, tris, influences, _ = tube(rings=700, segments=48, bones=30, seed=2, length=30.0)
    start = time.perf_counter()
    dqskin.centers_of_rotation(
        positions[:2000],
        tris[:3000] % 2000,
        dqskin.Influences(
            influences.offsets[:2001], influences.bones[: influences.offsets[2000]], influences.weights[: influences.offsets[2000]], 30
        ),
    )
    small = time.perf_counter() - start
    # The interrupt (at 0.2 s) must come while the precompute runs: on a fast machine a longer
    # tube (the precompute's time grows with the vertices; 33,600 of them once took under 0.2 s).
    rings = 700
    while small * rings * 48 / 2000 < 0.6 and rings < 700 * 16:
        rings *= 2
    if rings != 700:
        positions, tris, influences, _ = tube(rings=rings, segments=48, bones=30, seed=2, length=30.0)
    timer = threading.Timer(0.2, _thread.interrupt_main)
    timer.start()
    start = time.perf_counter()
    try:
        with pytest.raises(KeyboardInterrupt):
            dqskin.centers_of_rotation(positions, tris, influences)
            # Finished before the interrupt all the same: let it arrive (a simulated interrupt
            # does not wake a long sleep, so short ones).
            for _ in range(500):
                time.sleep(0.01)
    finally:
        timer.cancel()
    assert time.perf_counter() - start < 0.2 + 1.0 + 20 * small


def test_progress_reports_and_cancels():
    positions, triangles, influences, _ = tube(rings=40, segments=24, bones=6)
    seen = []
    plain = dqskin.centers_of_rotation(positions, triangles, influences)
    got = dqskin.centers_of_rotation(positions, triangles, influences, progress=lambda d, t: seen.append((d, t)))
    np.testing.assert_array_equal(got, plain)  # watching does not change the result
    assert len(seen) >= 2 and seen[-1][0] == seen[-1][1] and all(t == seen[0][1] for _, t in seen)
    assert [d for d, _ in seen] == sorted(d for d, _ in seen)
    calls = []

    def stop_at_second(done, total):
        calls.append(done)
        return len(calls) < 2

    with pytest.raises(dqskin.Cancelled, match="cancelled by its progress callback"):
        dqskin.centers_of_rotation(positions, triangles, influences, progress=stop_at_second)
    assert len(calls) == 2  # stopped at once

    def fails(done, total):
        raise RuntimeError("from the callback")

    with pytest.raises(RuntimeError, match="from the callback"):
        dqskin.centers_of_rotation(positions, triangles, influences, progress=fails)
    with pytest.raises(TypeError, match="progress must be callable"):
        dqskin.centers_of_rotation(positions, triangles, influences, progress=3)


def test_strokes_that_follow_one_another_equal_the_full_precompute_and_compute_less():
    """`previous` chains strokes: each update equals a full computation bit for bit, and from
    the second stroke on it takes the per-pair sums the update before kept in its weights, so it
    sums less than the same update from weights that kept nothing (equal weights, a new object)."""
    positions, tris, first, _ = tube(rings=60, segments=24, bones=8)
    dense = dense_of(first)
    centers = dqskin.centers_of_rotation(positions, tris, first, with_mask=True)
    weights, influences = dense, first
    near = lambda at, r: np.linalg.norm(positions - positions[at], axis=1) < r  # noqa: E731
    for stroke, (at, radius, bone, value) in enumerate([(700, 0.5, 2, 0.5), (700, 0.5, 2, 0.8), (760, 0.4, 3, 0.3), (700, 0.5, 2, 0.5)]):
        painted = weights.copy()
        painted[near(at, radius), bone] = value
        after = dqskin.Influences.from_dense(np.tile(np.arange(8), (len(positions), 1)), painted.astype(F), 8)
        full = dqskin.centers_of_rotation(positions, tris, after, with_mask=True)
        work = {}

        def counting(name, work=work):
            def report(done, total):
                work[name] = total

            return report

        fresh = dqskin.Influences.from_dense(np.tile(np.arange(8), (len(positions), 1)), weights.astype(F), 8)
        plain = dqskin.centers_of_rotation(positions, tris, after, with_mask=True, previous=(fresh, centers), progress=counting("plain"))
        got = dqskin.centers_of_rotation(positions, tris, after, with_mask=True, previous=(influences, centers), progress=counting("kept"))
        for name, result in (("without kept sums", plain), ("with them", got)):
            np.testing.assert_array_equal(result[0], full[0], err_msg=f"stroke {stroke} {name}")
            np.testing.assert_array_equal(result[1], full[1], err_msg=f"stroke {stroke} {name}")
        if stroke > 0:
            assert work["kept"] < work["plain"], (stroke, work)
        # What an update keeps shows in the memory the new weights account for.
        # (At least an 8-bit bone and a 32-bit weight a pair, and a 4-bit count a vertex: eight
        # bones, and every vertex here has at most 15 influences.)
        assert after.nbytes > fresh.nbytes >= 5 * len(fresh) + (fresh.vertex_count + 1) // 2
        weights, influences, centers = painted, after, got

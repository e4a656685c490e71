"""``dqskin.centers_of_rotation_job``: the centers of rotation computed on a thread of dqskin's own that runs
no Python (what Blender's add-on uses for large meshes), against ``centers_of_rotation``."""

from __future__ import annotations

import _thread
import gc
import threading
import time

import dqskin
import numpy as np
import pytest
from centers_meshes import dense_of, tube
from native_threads import threads_named, wait_until_none_named


def test_the_job_gives_what_centers_of_rotation_gives_bit_for_bit_and_runs_no_python_thread():
    positions, triangles, influences, _ = tube(rings=40, segments=24, bones=6)
    want, want_mask = dqskin.centers_of_rotation(positions, triangles, influences, with_mask=True)
    python_threads = threading.active_count()
    job = dqskin.centers_of_rotation_job(positions, triangles, influences)
    assert threading.active_count() == python_threads
    assert job.wait(timeout=30)
    assert job.finished and job.done == job.total > 1
    np.testing.assert_array_equal(job.result(), want)
    np.testing.assert_array_equal(job.result(), want)  # again: the result stays
    got, mask = dqskin.centers_of_rotation_job(positions, triangles, influences, with_mask=True).result()
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(mask, want_mask)
    wait_until_none_named("dqskin centers")


def test_the_inputs_are_copied_at_the_start():
    positions, triangles, influences, _ = tube(rings=30, segments=16, bones=5)
    want = dqskin.centers_of_rotation(positions, triangles, influences)
    mine = positions.copy()
    job = dqskin.centers_of_rotation_job(mine, triangles.copy(), influences, 0.1)
    mine[:] = 0.0  # the caller's array changes while the job runs
    np.testing.assert_array_equal(job.result(), want)


def test_an_update_equals_the_full_computation_and_keeps_its_sums_for_the_next():
    positions, tris, first, _ = tube(rings=60, segments=24, bones=8)
    weights = dense_of(first)
    centers = dqskin.centers_of_rotation(positions, tris, first, with_mask=True)
    influences = first
    near = lambda at, r: np.linalg.norm(positions - positions[at], axis=1) < r  # noqa: E731
    for stroke, (at, radius, bone, value) in enumerate([(700, 0.5, 2, 0.5), (760, 0.4, 3, 0.3)]):
        painted = weights.copy()
        painted[near(at, radius), bone] = value
        after = dqskin.Influences.from_dense(np.tile(np.arange(8), (len(positions), 1)), painted.astype(np.float32), 8)
        full = dqskin.centers_of_rotation(positions, tris, after, with_mask=True)
        bare = after.nbytes
        job = dqskin.centers_of_rotation_job(positions, tris, after, with_mask=True, previous=(influences, centers))
        got = job.result()
        np.testing.assert_array_equal(got[0], full[0], err_msg=f"stroke {stroke}")
        np.testing.assert_array_equal(got[1], full[1], err_msg=f"stroke {stroke}")
        assert after.nbytes > bare  # result() handed what the update kept to the new weights
        weights, influences, centers = painted, after, got


def test_cancel_stops_the_thread_at_once_and_result_says_so():
    positions, triangles, influences, _ = tube(rings=700, segments=48, bones=30, seed=2, length=30.0)
    job = dqskin.centers_of_rotation_job(positions, triangles, influences)
    job.cancel()
    start = time.perf_counter()
    assert job.wait(timeout=10)
    assert time.perf_counter() - start < 1.0
    with pytest.raises(dqskin.Cancelled, match="cancelled"):
        job.result()
    wait_until_none_named("dqskin centers")


def test_a_job_dropped_while_running_stops_its_thread():
    positions, triangles, influences, _ = tube(rings=700, segments=48, bones=30, seed=2, length=30.0)
    job = dqskin.centers_of_rotation_job(positions, triangles, influences)
    del job
    gc.collect()
    wait_until_none_named("dqskin centers", 2.0)
    small = tube(rings=10, segments=8, bones=3)
    assert dqskin.centers_of_rotation_job(*small[:3]).result().shape == (80, 3)  # and the next one works


def test_ctrl_c_stops_the_wait_not_the_job():
    positions, triangles, influences, _ = tube(rings=700, segments=48, bones=30, seed=2, length=30.0)
    job = dqskin.centers_of_rotation_job(positions, triangles, influences)
    timer = threading.Timer(0.05, _thread.interrupt_main)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            job.wait()
            for _ in range(500):  # finished before the interrupt all the same: let it arrive
                time.sleep(0.01)
    finally:
        timer.cancel()
    job.cancel()
    assert job.wait(timeout=10)


@pytest.mark.parametrize(
    "kwargs, error, words",
    [
        (dict(sigma=0.0), ValueError, ["sigma"]),
        (dict(sigma=float("nan")), ValueError, ["sigma"]),
        (dict(sigma="wide"), TypeError, ["sigma"]),
        (dict(with_mask=1), TypeError, ["with_mask"]),
        (dict(triangles=np.array([[0, 1, 999]])), ValueError, ["triangles[0]", "999"]),
        (dict(triangles=np.array([[0, 1, -1]])), ValueError, ["triangles"]),
        (dict(triangles=np.zeros((2, 3), np.float32)), TypeError, ["triangles"]),
        (dict(positions=np.zeros((3, 3), np.float32)), ValueError, ["positions"]),
        (dict(positions=np.zeros((80, 3))), TypeError, ["positions", "float32"]),
        (dict(positions=np.full((80, 3), np.nan, np.float32)), ValueError, ["positions[0]"]),
        (dict(influences="weights"), TypeError, ["influences"]),
        (dict(previous="centers"), TypeError, ["previous"]),
        (dict(previous=(None, None)), TypeError, ["previous"]),
    ],
)
def test_bad_input_is_refused_at_the_start(kwargs, error, words):
    positions, triangles, influences, _ = tube(rings=10, segments=8, bones=3)
    args = dict(positions=positions, triangles=triangles, influences=influences)
    args.update(kwargs)
    wait_until_none_named("dqskin centers")  # the threads of earlier tests' jobs have ended
    before = threads_named("dqskin centers")
    with pytest.raises(error) as e:
        dqskin.centers_of_rotation_job(**args)
    for w in words:
        assert w in str(e.value), str(e.value)
    assert threads_named("dqskin centers") == before  # no thread started


def test_previous_of_other_vertices_is_refused_at_the_start():
    positions, triangles, influences, _ = tube(rings=10, segments=8, bones=3)
    other = tube(rings=12, segments=8, bones=3)
    centers = dqskin.centers_of_rotation(*other[:3])
    with pytest.raises(ValueError, match="previous"):
        dqskin.centers_of_rotation_job(positions, triangles, influences, previous=(other[2], centers))


@pytest.mark.parametrize("timeout, error", [(-1.0, ValueError), (float("nan"), ValueError), (float("inf"), ValueError), ("1", TypeError)])
def test_bad_timeouts_are_refused(timeout, error):
    job = dqskin.centers_of_rotation_job(*tube(rings=10, segments=8, bones=3)[:3])
    with pytest.raises(error, match="timeout"):
        job.wait(timeout)
    assert job.wait(timeout=30)


def test_a_panic_in_a_jobs_thread_is_a_runtime_error_from_result():
    job = dqskin._panicking_job_for_tests()
    assert job.wait(timeout=30) and job.finished
    with pytest.raises(BaseException) as info:
        job.result()
    exc = info.value
    assert isinstance(exc, RuntimeError) and type(exc).__name__ != "PanicException", type(exc).__mro__
    assert "internal error in dqskin" in str(exc) and "deliberate panic" in str(exc)
    assert dqskin.centers_of_rotation_job(*tube(rings=10, segments=8, bones=3)[:3]).result().shape == (80, 3)

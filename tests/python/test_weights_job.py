"""``dqskin.automatic_weights_job`` and ``transfer_weights_job``: automatic weights and weight transfer on a thread of dqskin's own that
runs no Python (what Blender's add-on uses), against the functions themselves."""

from __future__ import annotations

import gc
import threading
import time

import dqskin
import numpy as np
import pytest
from centers_meshes import tube
from native_threads import threads_named, wait_until_none_named


def chain(bones=4, length=3.0):
    """Bones along the tube's axis (Y), head to tail."""
    y = np.linspace(0.0, length, bones + 1, dtype=np.float32)
    heads = np.stack([np.zeros(bones), y[:-1], np.zeros(bones)], axis=1).astype(np.float32)
    tails = np.stack([np.zeros(bones), y[1:], np.zeros(bones)], axis=1).astype(np.float32)
    return heads, tails


def same_result(a, b) -> None:
    (ia, ra), (ib, rb) = a, b
    for name in ("offsets", "bones", "weights"):
        np.testing.assert_array_equal(getattr(ia, name), getattr(ib, name))
    assert ra.keys() == rb.keys()
    for k in ra:
        np.testing.assert_array_equal(ra[k], rb[k])


def test_automatic_weights_job_gives_what_the_function_gives_and_runs_no_python_thread():
    positions, triangles, _, _ = tube(rings=30, segments=16)
    heads, tails = chain()
    want = dqskin.automatic_weights(positions, triangles, heads, tails, resolution=48, max_influences=3)
    python_threads = threading.active_count()
    job = dqskin.automatic_weights_job(positions, triangles, heads, tails, resolution=48, max_influences=3)
    assert threading.active_count() == python_threads
    assert job.wait(timeout=60) and job.finished and job.done == job.total
    same_result(job.result(), want)
    same_result(job.result(), want)  # again: the result stays
    wait_until_none_named("dqskin weights")


def test_transfer_weights_job_gives_what_the_function_gives():
    positions, triangles, influences, _ = tube(rings=30, segments=16)
    cloth = positions * np.array([1.1, 1.0, 1.1], np.float32)
    want = dqskin.transfer_weights(positions, triangles, influences, cloth, triangles, max_influences=3)
    job = dqskin.transfer_weights_job(positions, triangles, influences, cloth, triangles, max_influences=3)
    same_result(job.result(), want)


def test_the_inputs_are_copied_at_the_start():
    positions, triangles, _, _ = tube(rings=30, segments=16)
    heads, tails = chain()
    want = dqskin.automatic_weights(positions, triangles, heads, tails, resolution=32)
    mine = positions.copy()
    job = dqskin.automatic_weights_job(mine, triangles, heads, tails, resolution=32)
    mine[:] = 0.0
    same_result(job.result(), want)


def test_cancel_stops_the_thread_and_result_says_so():
    positions, triangles, _, _ = tube(rings=200, segments=48)
    heads, tails = chain()
    job = dqskin.automatic_weights_job(positions, triangles, heads, tails, resolution=512)
    job.cancel()
    start = time.perf_counter()
    assert job.wait(timeout=30)
    assert time.perf_counter() - start < 2.0
    with pytest.raises(dqskin.Cancelled, match="automatic_weights was cancelled"):
        job.result()
    wait_until_none_named("dqskin weights")


def test_a_job_dropped_while_running_stops_its_thread():
    positions, triangles, _, _ = tube(rings=200, segments=48)
    heads, tails = chain()
    job = dqskin.automatic_weights_job(positions, triangles, heads, tails, resolution=512)
    del job
    gc.collect()
    wait_until_none_named("dqskin weights", 5.0)


def test_bad_types_are_refused_at_the_start_and_what_the_computation_refuses_by_result():
    positions, triangles, _, _ = tube(rings=10, segments=8)
    heads, tails = chain()
    wait_until_none_named("dqskin weights")  # the threads of earlier tests' jobs have ended
    before = threads_named("dqskin weights")
    with pytest.raises(TypeError, match="positions"):
        dqskin.automatic_weights_job(positions.astype(np.float64), triangles, heads, tails)
    with pytest.raises(ValueError, match="resolution"):
        dqskin.automatic_weights_job(positions, triangles, heads, tails, resolution=4)
    with pytest.raises(TypeError, match="body_influences"):
        dqskin.transfer_weights_job(positions, triangles, "weights", positions, triangles)
    assert threads_named("dqskin weights") == before  # no thread started
    bad = triangles.copy()
    bad[0, 0] = 10_000
    with pytest.raises(ValueError, match="triangles") as direct:
        dqskin.automatic_weights(positions, bad, heads, tails)
    job = dqskin.automatic_weights_job(positions, bad, heads, tails)
    with pytest.raises(ValueError, match="triangles") as late:
        job.result()
    assert str(late.value) == str(direct.value)


@pytest.mark.parametrize("timeout, error", [(-1.0, ValueError), (float("nan"), ValueError), (1e30, ValueError), ("1", TypeError)])
def test_bad_timeouts_are_refused(timeout, error):
    positions, triangles, _, _ = tube(rings=10, segments=8)
    job = dqskin.automatic_weights_job(positions, triangles, *chain(), resolution=16)
    with pytest.raises(error, match="timeout"):
        job.wait(timeout)
    assert job.wait(timeout=60)

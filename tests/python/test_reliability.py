"""The attacks of the reliability issue, each answered by a clear error naming the argument,
fast, with nothing left behind (threads, memory, panics)."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import dqskin
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


def threads_now() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("Threads:"):
            return int(line.split()[1])
    return 0


@pytest.mark.slow
@pytest.mark.parametrize("n", [10**6, 2**31, 10**40])
def test_absurd_thread_counts_are_refused_before_any_thread_starts(n):
    before = dqskin.get_num_threads()  # the pool exists
    before_threads = threads_now()
    with pytest.raises(ValueError, match=r"threads must be between 1 and \d+"):
        dqskin.set_num_threads(n)
    assert threads_now() <= before_threads
    assert dqskin.get_num_threads() == before
    # Later calls run at full speed (no thousands of spinning threads).
    cyl = dqskin.TwistCylinder()
    t = time.perf_counter()
    for _ in range(20):
        dqskin.skin(cyl.positions, cyl.influences, cyl.twist(1.0), cyl.rest, method="dual_quaternion")
    assert time.perf_counter() - t < 2.0


def test_a_sane_thread_count_still_works():
    before = dqskin.get_num_threads()
    try:
        dqskin.set_num_threads(3)
        assert dqskin.get_num_threads() == 3
    finally:
        dqskin.set_num_threads(before)


@pytest.mark.parametrize(
    "kw, name", [({"rings": 10**6, "segments": 10**6}, "rings × segments"), ({"rings": 10**12}, "rings"), ({"segments": 2**63}, "segments")]
)
def test_huge_cylinders_are_refused_before_allocating(kw, name):
    t = time.perf_counter()
    with pytest.raises(ValueError, match=name):
        dqskin.TwistCylinder(**kw)
    assert time.perf_counter() - t < 0.5


def test_no_panic_reaches_python():
    with pytest.raises(TypeError, match="matrix"):
        dqskin.transform_points(None, np.zeros((2, 3), np.float32))
    keys = np.array([[1, 0, 0, 0], [0, 1, 0, 0]], np.float32)
    for times in ([-1e38, 1e38], [0.0, 3e38]):
        with pytest.raises(ValueError, match="too many samples"):
            dqskin.spring(np.array(times, np.float32), keys)


def test_spring_iterations_are_bounded():
    keys = np.array([[1, 0, 0, 0], [0, 1, 0, 0]], np.float32)
    with pytest.raises(ValueError, match=r"iterations must be between 0 and 1000000, got 1000000000"):
        dqskin.spring(np.array([0.0, 4.0], np.float32), keys, iterations=10**9)


SPRING = """
import numpy as np, dqskin, sys
times = np.arange(0, 200, 10, dtype=np.float32)
keys = np.tile(np.array([[1, 0, 0, 0], [0, 1, 0, 0]], np.float32), (10, 1))
print("started", flush=True)
try:
    dqskin.spring(times, keys, iterations=10**6)  # the most allowed: minutes of work
except KeyboardInterrupt:
    print("interrupted", flush=True)
    sys.exit(3)
"""


@pytest.mark.slow
def test_a_long_spring_stops_on_ctrl_c():
    p = subprocess.Popen([sys.executable, "-c", SPRING], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "started"
    time.sleep(0.5)
    p.send_signal(signal.SIGINT)
    t = time.perf_counter()
    out, _ = p.communicate(timeout=10)
    assert time.perf_counter() - t < 1.0
    assert p.returncode == 3 and "interrupted" in out


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: dqskin.slerp(np.array([1, 0, 0, 0], np.complex64), [1, 0, 0, 0], 0.5), "q0"),
        (lambda: dqskin.sclerp(np.array([1, 0, 0, 0, 0, 0, 0, 1j]), [1, 0, 0, 0, 0, 0, 0, 0], 0.5), "a"),
        (lambda: dqskin.dlb(np.eye(8, dtype=np.float32)[:2], np.array([1, 1j])), "weights"),
        (lambda: dqskin.DualQuat.from_matrix(np.eye(4) * (1 + 0j)), "matrix"),
        (lambda: dqskin.DualQuat(np.complex128(1)), "real"),
        (lambda: dqskin.slerp([1, 0, 0, 0], [1, 0, 0, 0], np.complex64(0.5)), "t"),
    ],
)
def test_complex_numbers_are_refused_not_cut_to_their_real_part(call, name):
    with pytest.raises(TypeError, match=rf"\b{name}\b.*(complex|real)"):
        call()


def test_one_vertex_with_ten_million_influences_is_refused():
    n = 10**7
    t = time.perf_counter()
    with pytest.raises(ValueError, match=r"vertex 0 has 10000000 influences; at most 4096"):
        dqskin.Influences(np.array([0, n]), np.zeros(n, np.uint32), np.ones(n, np.float32), 1)
    assert time.perf_counter() - t < 5.0


def test_bone_counts_beyond_the_kernels_addressing_are_refused():
    # The kernels keep each influence's bone index in 16 bits.
    assert dqskin.MAX_BONES == 2**16
    one = (np.array([0, 1]), np.array([dqskin.MAX_BONES - 1], np.uint32), np.ones(1, np.float32))
    assert dqskin.Influences(*one, dqskin.MAX_BONES).bone_count == dqskin.MAX_BONES
    with pytest.raises(ValueError, match=r"bone_count is 65537; at most 65536 bones"):
        dqskin.Influences(*one, dqskin.MAX_BONES + 1)


def test_4096_influences_sum_within_the_stated_error():
    k = dqskin.MAX_INFLUENCES_PER_VERTEX
    assert k == 4096
    rng = np.random.default_rng(1)
    w = rng.random(k, dtype=np.float32)
    inf = dqskin.Influences(np.array([0, k]), np.zeros(k, np.uint32), w, 1)
    deform = np.eye(4, dtype=np.float32)[None]
    deform[0, :3, 3] = (1.0, 2.0, 3.0)
    p = np.array([[0.5, 0.5, 0.5]], np.float32)
    got = dqskin.skin(p, inf, deform, np.eye(4, dtype=np.float32)[None], method="linear")
    np.testing.assert_allclose(got, p + [[1.0, 2.0, 3.0]], rtol=3e-4)


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: dqskin.Influences.from_dense([[0, 1]], np.ones((1, 2), np.float32), 2), "bones"),
        (lambda: dqskin.Influences.from_dense(None, np.ones((1, 2), np.float32), 2), "bones"),
        (lambda: dqskin.Influences.from_dense(np.zeros((1, 2), int), [[1.0, 1.0]], 2), "weights"),
        (lambda: dqskin.mesh_volume(np.zeros((3, 3), np.float32), [[0, 1, 2]]), "triangles"),
        (lambda: dqskin.mesh_volume(np.zeros((3, 3), np.float32), None), "triangles"),
        (lambda: dqskin.mesh_volume(None, np.zeros((1, 3), int)), "positions"),
        (lambda: dqskin.forward_kinematics("abc", np.zeros((1, 8), np.float32)), "parents"),
    ],
)
def test_lists_and_none_get_a_type_error_naming_the_argument(call, name):
    with pytest.raises(TypeError, match=rf"\b{name}\b"):
        call()


@pytest.mark.parametrize("value", [10**30, -(10**30), 2**64])
def test_huge_integers_are_value_errors_not_overflow_errors(value):
    for call, name in (
        (lambda: dqskin.Influences(np.array([0, 0]), np.zeros(0, int), np.zeros(0, np.float32), value), "bone_count"),
        (lambda: dqskin.TwistCylinder(rings=value), "rings"),
        (lambda: dqskin.TwistCylinder().ring(value), "r"),
        (lambda: dqskin.dib(np.eye(8, dtype=np.float32)[:2], np.ones(2, np.float32), max_iterations=value), "max_iterations"),
        (lambda: dqskin.set_num_threads(value), "threads"),
        (lambda: dqskin.spring(np.array([0, 1], np.float32), np.eye(4, dtype=np.float32)[:2], levels=value), "levels"),
    ):
        with pytest.raises(ValueError, match=rf"\b{name}\b"):
            call()


@pytest.mark.parametrize("value", [True, np.True_, 2.0, np.float32(2), "2"])
def test_counts_must_be_integers_not_bools_or_floats(value):
    for call, name in (
        (lambda: dqskin.TwistCylinder(rings=value), "rings"),
        (lambda: dqskin.set_num_threads(value), "threads"),
        (lambda: dqskin.dib(np.eye(8, dtype=np.float32)[:2], np.ones(2, np.float32), max_iterations=value), "max_iterations"),
    ):
        with pytest.raises(TypeError, match=rf"\b{name} must be an integer"):
            call()


def test_misaligned_arrays_are_refused_with_the_argument_named():
    buf = np.zeros(3 * 10 * 4 + 1, np.uint8)
    unaligned = np.frombuffer(buf.data, dtype=np.float32, count=30, offset=1).reshape(10, 3)
    assert not unaligned.flags.aligned
    inf = dqskin.Influences.from_dense(np.zeros((10, 1), int), np.ones((10, 1), np.float32), 1)
    with pytest.raises(ValueError, match=r"positions is not aligned"):
        dqskin.skin(unaligned, inf, np.eye(4, dtype=np.float32)[None], None, method="linear")

"""PC2 files against the format's specification (header, counts, sample rate, layout)."""

from __future__ import annotations

import os
import signal
import struct
import subprocess
import sys
import time

import numpy as np
import pytest
from dqskin import pc2


def test_layout_follows_the_specification(tmp_path):
    samples = np.arange(4 * 5 * 3, dtype=np.float32).reshape(4, 5, 3)
    path = tmp_path / "a.pc2"
    header = pc2.write(path, samples, start_frame=7.0, sample_rate=0.5)
    raw = path.read_bytes()
    assert raw[:12] == b"POINTCACHE2\0"
    assert struct.unpack("<iiffi", raw[12:32]) == (1, 5, 7.0, 0.5, 4)
    assert len(raw) == 32 + 4 * 5 * 12
    np.testing.assert_array_equal(np.frombuffer(raw[32:], "<f4").reshape(4, 5, 3), samples)
    assert (header.points, header.samples, header.end_frame) == (5, 4, 8.5)
    h, back = pc2.read(path)
    assert h == header
    np.testing.assert_array_equal(back, samples)


def test_merge_joins_consecutive_chunks(tmp_path):
    data = np.random.default_rng(0).normal(size=(10, 6, 3)).astype(np.float32)
    pc2.write(tmp_path / "b.pc2", data[4:], start_frame=5)
    pc2.write(tmp_path / "a.pc2", data[:4], start_frame=1)
    header = pc2.merge([tmp_path / "b.pc2", tmp_path / "a.pc2"], tmp_path / "all.pc2")
    assert (header.start_frame, header.samples) == (1.0, 10)
    np.testing.assert_array_equal(pc2.read(tmp_path / "all.pc2")[1], data)


def test_merge_refuses_gaps_overlaps_and_mismatches(tmp_path):
    d = np.zeros((3, 4, 3), np.float32)
    pc2.write(tmp_path / "a.pc2", d, start_frame=1)
    pc2.write(tmp_path / "gap.pc2", d, start_frame=6)
    pc2.write(tmp_path / "overlap.pc2", d, start_frame=3)
    pc2.write(tmp_path / "other.pc2", np.zeros((3, 5, 3), np.float32), start_frame=4)
    for bad, message in (("gap.pc2", "a gap"), ("overlap.pc2", "an overlap"), ("other.pc2", "points")):
        with pytest.raises(pc2.PC2Error, match=message):
            pc2.merge([tmp_path / "a.pc2", tmp_path / bad], tmp_path / "out.pc2")
        assert not (tmp_path / "out.pc2").exists()


def test_bad_files_and_interrupted_writes(tmp_path):
    (tmp_path / "junk.pc2").write_bytes(b"not a cache at all, but long enough" * 2)
    with pytest.raises(pc2.PC2Error, match="bad signature"):
        pc2.read_header(tmp_path / "junk.pc2")
    pc2.write(tmp_path / "short.pc2", np.zeros((2, 3, 3), np.float32), 1)
    (tmp_path / "short.pc2").write_bytes((tmp_path / "short.pc2").read_bytes()[:-4])
    with pytest.raises(pc2.PC2Error, match="header promises"):
        pc2.read_header(tmp_path / "short.pc2")
    with pytest.raises(RuntimeError):
        with pc2.Writer(tmp_path / "partial.pc2", 3, 1) as w:
            w.add(np.zeros((3, 3)))
            raise RuntimeError("interrupted")
    assert not (tmp_path / "partial.pc2").exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
    with pytest.raises(pc2.PC2Error, match="shape"):
        with pc2.Writer(tmp_path / "wrong.pc2", 3, 1) as w:
            w.add(np.zeros((4, 3)))


# -- defensive reading and recognisable temporaries ------------------------------------------------


def raw_pc2(path, points, start, rate, samples, data_floats=None):
    with open(path, "wb") as f:
        f.write(pc2.HEADER.pack(pc2.MAGIC, 1, points, start, rate, samples))
        if data_floats is None:
            data_floats = points * samples * 3
        f.write(np.zeros(max(data_floats, 0), "<f4").tobytes())


@pytest.mark.parametrize(
    "points, start, rate, samples, words",
    [
        (3, 1.0, float("nan"), 2, "sample rate"),
        (3, 1.0, 0.0, 2, "sample rate"),
        (3, 1.0, -1.0, 2, "sample rate"),
        (3, float("nan"), 1.0, 2, "start frame"),
        (3, float("inf"), 1.0, 2, "start frame"),
        (0, 1.0, 1.0, 2**31 - 1, "at least one point"),
        (-1, 1.0, 1.0, 2, "at least one point"),
    ],
)
def test_headers_that_make_no_sense_are_refused(tmp_path, points, start, rate, samples, words):
    path = tmp_path / "bad.pc2"
    raw_pc2(path, points, start, rate, samples, data_floats=0 if points <= 0 else None)
    with pytest.raises(pc2.PC2Error, match=words):
        pc2.read_header(path)


def test_merging_a_zero_point_file_fails_at_once_and_leaves_nothing(tmp_path):
    good = tmp_path / "a.pc2"
    pc2.write(good, np.zeros((2, 3, 3), np.float32), 1.0)
    bad = tmp_path / "b.pc2"
    raw_pc2(bad, 0, 3.0, 1.0, 2**31 - 1, data_floats=0)
    out = tmp_path / "out.pc2"
    t = time.perf_counter()
    with pytest.raises(pc2.PC2Error):
        pc2.merge([good, bad], out)
    assert time.perf_counter() - t < 1.0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.pc2", "b.pc2"]


def test_sizes_are_checked_against_the_file_before_reading(tmp_path):
    path = tmp_path / "short.pc2"
    raw_pc2(path, 1000, 1.0, 1.0, 2**31 - 1, data_floats=30)
    with pytest.raises(pc2.PC2Error, match="promises"):
        pc2.read(path)


def test_temporaries_of_dead_processes_are_removed_by_the_next_write(tmp_path):
    out = tmp_path / "cache.pc2"
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    stale = tmp_path / f".cache.pc2.dqskin-{int(dead.stdout)}.tmp"
    stale.write_bytes(b"x" * 100)
    mine = tmp_path / f".cache.pc2.dqskin-{os.getppid()}.tmp"  # a live process: kept
    mine.write_bytes(b"y")
    other = tmp_path / ".other.pc2.dqskin-1.tmp"  # another output: kept
    other.write_bytes(b"z")
    pc2.write(out, np.zeros((1, 2, 3), np.float32), 1.0)
    assert not stale.exists() and mine.exists() and other.exists() and out.exists()


# -- signals: the temporary goes on Ctrl-C and SIGTERM too ------------------------------------------

WRITING = """
import signal, sys, time
import numpy as np
from dqskin import pc2

if sys.argv[2] == "default-action":
    signal.signal(signal.SIGINT, signal.SIG_DFL)
with pc2.Writer(sys.argv[1], 1000, 1.0) as w:
    w.add(np.zeros((1000, 3)))
    print("writing", flush=True)
    while True:
        w.add(np.ones((1000, 3)))
        time.sleep(0.001)
"""


@pytest.mark.parametrize(
    "signum, handler",
    [(signal.SIGTERM, "default-action"), (signal.SIGINT, "default-action"), (signal.SIGINT, "KeyboardInterrupt")],
    ids=["SIGTERM", "SIGINT-default-action", "SIGINT-KeyboardInterrupt"],
)
@pytest.mark.slow
def test_a_writer_signalled_mid_write_leaves_nothing(tmp_path, signum, handler):
    out = tmp_path / "cache.pc2"
    p = subprocess.Popen([sys.executable, "-c", WRITING, str(out), handler], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "writing", p.stderr.read()
        assert [f.name for f in tmp_path.iterdir()] == [f".cache.pc2.dqskin-{p.pid}.tmp"]
        time.sleep(0.05)
        p.send_signal(signum)
        p.wait(timeout=10)
    finally:
        p.kill()
    assert p.returncode == -signum, p.stderr.read()  # ended by the signal, as without a writer
    assert list(tmp_path.iterdir()) == []


CHAINED = """
import signal, sys
import numpy as np
from dqskin import pc2

got = []
def record(signum, frame):
    got.append(signum)
for sig in (signal.SIGINT, signal.SIGTERM):
    signal.signal(sig, record)
with pc2.Writer(sys.argv[1], 10, 1.0) as w:
    for sig in (signal.SIGINT, signal.SIGTERM):
        w.add(np.zeros((10, 3)))
        signal.raise_signal(sig)
assert got == [signal.SIGINT, signal.SIGTERM], got
assert signal.getsignal(signal.SIGINT) is record and signal.getsignal(signal.SIGTERM) is record
print(pc2.read_header(sys.argv[1]).samples)
"""


@pytest.mark.slow
def test_a_previous_handler_that_returns_lets_the_write_finish_and_is_restored(tmp_path):
    out = tmp_path / "cache.pc2"
    run = subprocess.run([sys.executable, "-c", CHAINED, str(out)], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "2"
    assert [f.name for f in tmp_path.iterdir()] == ["cache.pc2"]


def test_handlers_are_restored_when_the_last_writer_closes(tmp_path):
    before = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    with pc2.Writer(tmp_path / "a.pc2", 2, 1.0) as a:
        assert signal.getsignal(signal.SIGTERM) is not before[signal.SIGTERM]
        with pc2.Writer(tmp_path / "b.pc2", 2, 1.0) as b:
            b.add(np.zeros((2, 3)))
        assert signal.getsignal(signal.SIGTERM) is not before[signal.SIGTERM]  # a is still open
        a.add(np.zeros((2, 3)))
    assert {sig: signal.getsignal(sig) for sig in before} == before
    with pytest.raises(KeyboardInterrupt):
        with pc2.Writer(tmp_path / "c.pc2", 2, 1.0):
            signal.raise_signal(signal.SIGINT)  # Python's handler: KeyboardInterrupt
    assert {sig: signal.getsignal(sig) for sig in before} == before
    assert sorted(f.name for f in tmp_path.iterdir()) == ["a.pc2", "b.pc2"]


def test_a_write_stopped_by_a_signal_refuses_to_go_on(tmp_path):
    with pytest.raises(pc2.PC2Error, match="stopped by SIGINT"):  # the block's end refuses
        with pc2.Writer(tmp_path / "a.pc2", 2, 1.0) as w:
            try:
                signal.raise_signal(signal.SIGINT)
            except KeyboardInterrupt:
                pass  # caught inside the block: the temporary is gone, so the write cannot finish
            with pytest.raises(pc2.PC2Error, match="stopped by SIGINT"):
                w.add(np.zeros((2, 3)))
    assert list(tmp_path.iterdir()) == []


def test_merge_interrupted_at_any_python_call_raises_keyboardinterrupt_and_leaves_nothing(tmp_path):
    # Python runs a signal's handler at the next Python-level call, wherever that lands. A
    # profile hook runs SIGINT's handler at the n-th call event of a merge, for every n the merge
    # has: the caller must always see KeyboardInterrupt (np.fromfile once turned it into a
    # TypeError), no temporary left behind, and either no output or the whole merge (when the
    # signal comes after the file was renamed into place).
    chunks = []
    for i in range(2):
        path = tmp_path / f"c{i}.pc2"
        pc2.write(path, np.full((3, 4, 3), i, np.float32), 1 + 3 * i)
        chunks.append(path)
    out = tmp_path / "all.pc2"

    def merge_interrupted_at(n):
        """Returns how many calls the merge made, or where the handler ran if it returned."""
        seen, where = 0, None

        def hook(frame, event, arg):
            nonlocal seen, where
            if event == "return" and frame.f_code is pc2.merge.__code__:
                sys.setprofile(None)  # the merge is over: not the test's own calls
            elif event in ("call", "c_call"):
                seen += 1
                if seen == n:
                    where = (frame.f_code.co_name, frame.f_back.f_code.co_name, event, arg)
                    signal.getsignal(signal.SIGINT)(signal.SIGINT, frame)

        sys.setprofile(hook)
        try:
            pc2.merge(chunks, out)
        finally:
            sys.setprofile(None)
        assert where is None, f"the handler ran at call {n} ({where}) and the merge still returned"
        return seen

    handler = signal.getsignal(signal.SIGINT)
    merge_interrupted_at(0)  # n=0 never fires; the first merge's calls include one-time caching
    whole = out.read_bytes()
    out.unlink()
    calls = merge_interrupted_at(0)
    assert calls > 20
    out.unlink()
    kept = 0
    for n in range(1, calls + 1):
        with pytest.raises(KeyboardInterrupt):
            merge_interrupted_at(n)
        left = sorted(p.name for p in tmp_path.iterdir())
        if left == ["all.pc2", "c0.pc2", "c1.pc2"]:
            assert out.read_bytes() == whole, f"call {n}"
            out.unlink()
            kept += 1
        else:
            assert left == ["c0.pc2", "c1.pc2"], f"call {n}"
        # Only writers the signal discarded may linger (a signal on the entry of __exit__ raises
        # before its cleanup); the next writer forgets them and restores the handler.
        assert all(w._interrupted for w in pc2._open), f"call {n}"
    assert kept < calls // 4  # most interruptions come before the rename
    assert merge_interrupted_at(0) == calls
    assert out.read_bytes() == whole
    assert signal.getsignal(signal.SIGINT) is handler and not pc2._open

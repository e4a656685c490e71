"""PC2 files against the format's specification (header, counts, sample rate, layout)."""

from __future__ import annotations

import struct

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

"""The Mesh Cache carrier's file (`routes.pointcache`): the kernel writes the file's own memory,
and the feed's check that a frame is in the file (`PointCache.holds`) is true only for that
memory while the file is at its path; a deleted file is made again by `write`."""

from __future__ import annotations

import os
from pathlib import Path

import addon_modules
import numpy as np
import pytest

pointcache = addon_modules.load("routes", "pointcache")


def _positions_in(path: Path) -> np.ndarray:
    return np.fromfile(path, np.float32, offset=pointcache.HEADER_SIZE).reshape(-1, 3)


@pytest.mark.skipif(not pointcache.MAPPED, reason="files are mapped on POSIX only")
def test_the_file_holds_what_the_kernel_wrote_into_its_memory_until_it_is_deleted(tmp_path):
    path = tmp_path / "dqskin-test.pc2"
    cache = pointcache.PointCache(str(path))
    try:
        buffer = cache.buffer(5)
        buffer[:] = np.arange(15, dtype=np.float32).reshape(5, 3)
        assert cache.holds(buffer)
        assert np.array_equal(_positions_in(path), buffer)
        # Another array of the same values is not in the file: it must be written.
        assert not cache.holds(buffer.copy())

        os.unlink(path)
        assert not cache.holds(buffer)  # (the mapping still reads, but Mesh Cache reads by path)
        cache.write(buffer)
        assert path.exists() and np.array_equal(_positions_in(path), buffer)
        new = cache.buffer(5)
        assert new is not buffer and cache.holds(new) and not cache.holds(buffer)
    finally:
        cache.close()


def test_an_unmapped_file_never_holds_an_array(tmp_path, monkeypatch):
    monkeypatch.setattr(pointcache, "MAPPED", False)
    path = tmp_path / "dqskin-test.pc2"
    cache = pointcache.PointCache(str(path))
    try:
        buffer = cache.buffer(4)
        buffer[:] = 1.5
        assert not cache.holds(buffer)  # (its own array: the file has it only once written)
        cache.write(buffer)
        assert np.array_equal(_positions_in(path), buffer)
    finally:
        cache.close()

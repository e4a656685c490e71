# SPDX-License-Identifier: GPL-3.0-or-later
"""The point-cache files a Mesh Cache carrier reads (`cache_route`): one PC2 frame each, kept
open and mapped into memory, the kernel writing the positions in place; in memory-backed storage
where there is one (`/dev/shm`), else in the temporary folder; made again if something deletes
it."""

from __future__ import annotations

import mmap
import os
import struct
import tempfile

import numpy as np

HEADER = b"POINTCACHE2\0"
HEADER_SIZE = len(HEADER) + 20  # and the version, point count, start frame, sample rate, frame count
# Mapped files on POSIX only: Windows cannot delete or replace a file while it is mapped.
MAPPED = os.name == "posix"


def folder() -> str:
    return "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else tempfile.gettempdir()


def is_ours(path: str) -> bool:
    """Whether `path` names a file of this kind (any process's)."""
    return os.path.basename(path).startswith("dqskin-") and path.endswith(".pc2")


class PointCache:
    """One PC2 file holding one frame of `points` positions. Where the system can map it into
    memory (POSIX), its positions are an array (`buffer`) that the kernel writes directly, so
    that no copy of them is kept in the process: the file is the output."""

    def __init__(self, path: str):
        self.path = path
        self._open()

    def _open(self) -> None:
        self.file = open(self.path, "w+b", buffering=0)  # kept open; closed by `close`
        self.points = -1  # the point count its header says
        self._map = None
        self._positions: np.ndarray | None = None  # the file's mapping, or (not mapped) an array of ours

    def _ready(self, n: int) -> None:
        """The file exists at its path (made again if something deleted it: Mesh Cache reads
        by name) and holds `n` points."""
        if os.fstat(self.file.fileno()).st_nlink == 0:
            self.file.close()
            self._open()
        if n == self.points:
            return
        if self._map is not None:
            # A new file rather than this one resized: arrays still viewing the old mapping
            # (a following modifier's input) must never reach past its end.
            self.close()
            self._open()
        fd = self.file.fileno()
        os.pwrite(fd, HEADER + struct.pack("<iiffi", 1, n, 0.0, 1.0, 1), 0)
        self.file.truncate(HEADER_SIZE + 12 * n)
        self.points = n
        self._positions = None
        if MAPPED:
            self._map = mmap.mmap(fd, HEADER_SIZE + 12 * n)
            self._positions = np.frombuffer(self._map, np.float32, 3 * n, HEADER_SIZE).reshape(n, 3)

    def buffer(self, n: int) -> np.ndarray:
        """A `(n, 3)` float32 array for this frame's positions: the file's own where it is mapped
        (a new one after the file was made again), else an array `write` copies to the file."""
        self._ready(n)
        if self._positions is None:  # (not mapped: an array of ours, written by `write`)
            self._positions = np.empty((n, 3), np.float32)
        return self._positions

    def holds(self, positions: np.ndarray) -> bool:
        """Whether `positions` are in the file already: the kernel wrote them into its mapping,
        and the file is still at its path (one `fstat`, as `write` checks)."""
        return positions is self._positions and self._map is not None and os.fstat(self.file.fileno()).st_nlink != 0

    def is_buffer(self, positions: np.ndarray) -> bool:
        """Whether `positions` is the current file's own array."""
        return positions is self._positions and self._positions is not None

    def write(self, positions: np.ndarray) -> None:
        self._ready(len(positions))
        if self._map is not None:
            if positions is not self._positions:
                self._positions[:] = positions
            return  # (the kernel wrote the file)
        # Every frame, only the positions: one write of the array's own memory.
        os.pwrite(self.file.fileno(), np.ascontiguousarray(positions, np.float32).data.cast("B"), HEADER_SIZE)

    def close(self) -> None:
        # The mapping is not closed here: arrays may still view it (it goes with the last).
        self._map = self._positions = None
        try:
            self.file.close()
            os.unlink(self.path)
        except OSError:
            pass


def is_mapped(positions: np.ndarray | None) -> bool:
    """Whether `positions` views a point-cache file's memory."""
    base = getattr(positions, "base", None)
    while isinstance(base, np.ndarray):
        base = base.base
    if isinstance(base, memoryview):
        base = base.obj
    return isinstance(base, mmap.mmap)

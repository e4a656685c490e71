# SPDX-License-Identifier: GPL-3.0-or-later
"""The point-cache files a Mesh Cache carrier reads (`cache_route`): one PC2 frame each, kept
open and rewritten in place, in memory-backed storage where there is one (`/dev/shm`), else in
the temporary folder; made again if something deletes it."""

from __future__ import annotations

import os
import struct
import tempfile

import numpy as np

HEADER = b"POINTCACHE2\0"
HEADER_SIZE = len(HEADER) + 20  # and the version, point count, start frame, sample rate, frame count


def folder() -> str:
    return "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else tempfile.gettempdir()


def is_ours(path: str) -> bool:
    """Whether `path` names a file of this kind (any process's)."""
    return os.path.basename(path).startswith("dqskin-") and path.endswith(".pc2")


class PointCache:
    """One PC2 file holding one frame of `points` positions."""

    def __init__(self, path: str):
        self.path = path
        self.points = -1  # the point count its header says
        self.file = open(path, "w+b", buffering=0)  # kept open; closed by `close`

    def write(self, positions: np.ndarray) -> None:
        n = len(positions)
        fd = self.file.fileno()
        if os.fstat(fd).st_nlink == 0:  # (a cleaner removed it: Mesh Cache reads by name)
            self.file.close()
            self.file, self.points = open(self.path, "w+b", buffering=0), -1
            fd = self.file.fileno()
        if n != self.points:
            header = HEADER + struct.pack("<iiffi", 1, n, 0.0, 1.0, 1)
            os.pwrite(fd, header, 0)
            self.file.truncate(HEADER_SIZE + 12 * n)
            self.points = n
        # Every frame, only the positions: one write of the array's own memory.
        os.pwrite(fd, np.ascontiguousarray(positions, np.float32).data.cast("B"), HEADER_SIZE)

    def close(self) -> None:
        try:
            self.file.close()
            os.unlink(self.path)
        except OSError:
            pass

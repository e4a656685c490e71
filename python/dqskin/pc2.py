"""PC2 point caches, the format Blender's Mesh Cache modifier reads (and 3ds Max writes).

Layout (little-endian): the 12 bytes ``POINTCACHE2\\0``, int32 version (1), int32 number of
points, float32 start frame, float32 sample rate (frames between samples), int32 number of
samples, then ``samples × points × 3`` float32 coordinates.

Files are written to a temporary file beside the target and renamed into place when complete,
so a failed or interrupted bake never leaves a partial cache under the final name. Temporary
files are named ``.NAME.dqskin-PID.tmp``. Ctrl-C (SIGINT) and SIGTERM remove them too (see
`Writer`); one left by a killed process (SIGKILL cannot be caught) is removed by the next write
of the same file.

Reading is defensive: every count is checked against the file's length before anything is
allocated or looped over, and the frame numbers must be finite (the sample rate positive).
"""

from __future__ import annotations

import math
import os
import signal
import struct
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

MAGIC = b"POINTCACHE2\0"
HEADER = struct.Struct("<12siiffi")


class PC2Error(ValueError):
    """A file that is not a PC2 cache, or caches that cannot be combined."""


@dataclass(frozen=True)
class Header:
    points: int
    start_frame: float
    sample_rate: float
    samples: int

    @property
    def end_frame(self) -> float:
        return self.start_frame + self.sample_rate * max(self.samples - 1, 0)


def read_header(path) -> Header:
    with open(path, "rb") as f:
        raw = f.read(HEADER.size)
    if len(raw) < HEADER.size:
        raise PC2Error(f"{path}: too short for a PC2 header")
    magic, version, points, start, rate, samples = HEADER.unpack(raw)
    if magic != MAGIC:
        raise PC2Error(f"{path}: not a PC2 file (bad signature)")
    if version != 1:
        raise PC2Error(f"{path}: unsupported PC2 version {version}")
    if points <= 0 or samples < 0:
        raise PC2Error(f"{path}: {points} points and {samples} samples (a cache needs at least one point)")
    if not (math.isfinite(start) and math.isfinite(rate) and rate > 0):
        raise PC2Error(f"{path}: start frame {start} and sample rate {rate} (both must be finite, the rate positive)")
    size = os.path.getsize(path)
    expected = HEADER.size + points * samples * 12
    if size != expected:
        raise PC2Error(f"{path}: {size} bytes, but the header promises {expected}")
    return Header(points, start, rate, samples)


def read(path) -> tuple[Header, np.ndarray]:
    """The header and the samples as a ``(samples, points, 3)`` float32 array."""
    header = read_header(path)
    data = np.fromfile(path, dtype="<f4", offset=HEADER.size)
    return header, data.reshape(header.samples, header.points, 3)


class Writer:
    """Streams samples into a PC2 file: ``with Writer(path, points, start) as w: w.add(xyz)``.

    The file appears under ``path`` only when the ``with`` block ends without an exception.

    Signals: while a writer opened in the main thread is open, it handles SIGINT and SIGTERM
    (Python delivers signals to the main thread only) and passes each on to the handler that
    was there before. If that handler raises (``KeyboardInterrupt``, a batch command's own
    interruption), the temporary file is removed and the exception goes on; if it returns, the
    write goes on too; if there was none (the default action: the process ends, as SIGTERM
    does in plain Python), the temporary file is removed and the process then ends by the same
    signal. The previous handlers are restored when the last open writer closes. Ignored
    signals and handlers installed outside Python (``signal.getsignal`` gives None) are left
    alone; such a process leaves its temporary to the next write of the same file.
    """

    def __init__(self, path, points: int, start_frame: float, sample_rate: float = 1.0):
        if points <= 0:
            raise PC2Error("points must be at least 1")
        if not (math.isfinite(start_frame) and math.isfinite(sample_rate) and sample_rate > 0):
            raise PC2Error("start_frame must be finite and sample_rate finite and positive")
        self.path = Path(path)
        self.points = int(points)
        self.header = (float(start_frame), float(sample_rate))
        self.samples = 0
        self._file = None
        self._tmp = None
        self._interrupted = None  # the signal that discarded the temporary

    def __enter__(self) -> Writer:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(self.path)
        self._tmp = temporary_path(self.path)
        try:
            _watch(self)  # inside: a signal arriving in it still unwatches
            self._file = open(self._tmp, "xb")
            self._file.write(HEADER.pack(MAGIC, 1, self.points, *self.header, 0))
        except BaseException:
            self._discard()
            _unwatch(self)
            raise
        return self

    def add(self, positions) -> None:
        a = np.ascontiguousarray(positions, dtype="<f4")
        if a.shape != (self.points, 3):
            raise PC2Error(f"a sample must have shape ({self.points}, 3), got {a.shape}")
        self._check_open()
        self._file.write(a.tobytes())
        self.samples += 1

    def add_many(self, samples) -> None:
        """Several samples ``(n, points, 3)`` in one write."""
        a = np.ascontiguousarray(samples, dtype="<f4")
        if a.ndim != 3 or a.shape[1:] != (self.points, 3):
            raise PC2Error(f"samples must have shape (n, {self.points}, 3), got {a.shape}")
        self._check_open()
        self._file.write(a.tobytes())
        self.samples += a.shape[0]

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            if exc_type is None:
                self._check_open()
                self._file.seek(0)
                self._file.write(HEADER.pack(MAGIC, 1, self.points, *self.header, self.samples))
                self._file.flush()
                os.fsync(self._file.fileno())
                self._file.close()
                os.replace(self._tmp, self.path)
        finally:
            self._discard()
            _unwatch(self)

    def _check_open(self) -> None:
        if self._interrupted is not None:
            raise PC2Error(f"{self.path}: the write was stopped by {signal.Signals(self._interrupted).name}; nothing was written")

    def _discard(self) -> None:
        """Closes and removes the temporary file (nothing if it is gone already)."""
        if self._file is not None:
            self._file.close()
        self._remove_temporary()

    def _remove_temporary(self) -> None:
        # Also while the file is open (a signal can come inside a write, where closing it would
        # be a reentrant call): POSIX unlinks an open file; Windows refuses, and the close in
        # `__exit__` removes it then.
        if self._tmp is not None:
            try:
                self._tmp.unlink(missing_ok=True)
            except OSError:
                pass


# Writers open in the main thread, and the handler each signal had before the first of them.
_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_open: list[Writer] = []
_previous: dict[int, object] = {}


def _on_signal(signum, frame) -> None:
    previous = _previous.get(signum, signal.SIG_DFL)
    if callable(previous):
        try:
            previous(signum, frame)
        except BaseException:
            _discard_open(signum)
            raise
        return
    _discard_open(signum)  # the default action ends the process without unwinding
    signal.signal(signum, signal.SIG_DFL)
    signal.raise_signal(signum)


def _discard_open(signum: int) -> None:
    for writer in _open:
        writer._interrupted = signum
        writer._remove_temporary()


def _forget_discarded() -> None:
    # A signal that lands on the very entry of `Writer.__exit__` raises before its cleanup runs:
    # the handler already removed that writer's temporary; drop the writer here, at the next
    # writer's start or end, so the handlers are still restored.
    for w in [w for w in _open if w._interrupted is not None]:
        _open.remove(w)
        if w._file is not None:
            w._file.close()


def _watch(writer: Writer) -> None:
    if threading.current_thread() is not threading.main_thread():
        return
    _forget_discarded()
    _open.append(writer)
    for sig in _SIGNALS:
        current = signal.getsignal(sig)
        if current is _on_signal or current is None or current == signal.SIG_IGN:
            continue
        _previous[sig] = current
        signal.signal(sig, _on_signal)


def _unwatch(writer: Writer) -> None:
    if writer not in _open:
        return
    _open.remove(writer)
    _forget_discarded()
    if _open:
        return
    for sig, previous in list(_previous.items()):
        if signal.getsignal(sig) is _on_signal:  # not if someone replaced it meanwhile
            signal.signal(sig, previous)
        del _previous[sig]


def temporary_path(path) -> Path:
    """Where a file is written before it is renamed to `path`: recognisable (and this
    process's), so that one left behind by a killed run can be cleaned up."""
    path = Path(path)
    return path.with_name(f".{path.name}.dqskin-{os.getpid()}.tmp")


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


def remove_stale_temporaries(path) -> list[Path]:
    """Removes temporary files for `path` left by processes that no longer run; returns them."""
    path = Path(path)
    removed = []
    prefix, suffix = f".{path.name}.dqskin-", ".tmp"
    try:
        entries = list(path.parent.iterdir())
    except OSError:
        return removed
    for p in entries:
        name = p.name
        if not (name.startswith(prefix) and name.endswith(suffix)):
            continue
        pid_text = name[len(prefix) : -len(suffix)]
        if pid_text.isdigit() and not _alive(int(pid_text)):
            try:
                p.unlink()
                removed.append(p)
            except OSError:
                pass
    return removed


def write(path, samples, start_frame: float, sample_rate: float = 1.0) -> Header:
    """Writes ``(samples, points, 3)`` positions; returns the header written."""
    samples = np.asarray(samples)
    if samples.ndim != 3 or samples.shape[2] != 3:
        raise PC2Error(f"samples must have shape (samples, points, 3), got {samples.shape}")
    with Writer(path, samples.shape[1], start_frame, sample_rate) as w:
        for s in samples:
            w.add(s)
    return read_header(path)


def merge(paths, out) -> Header:
    """Joins caches of consecutive frame ranges (e.g. a farm's chunks) into one, in frame order.
    They must have the same point count and sample rate and follow each other without gaps or
    overlaps."""
    if not paths:
        raise PC2Error("nothing to merge")
    headers = sorted(((read_header(p), p) for p in paths), key=lambda hp: hp[0].start_frame)
    first = headers[0][0]
    for (prev, pp), (cur, cp) in zip(headers, headers[1:]):
        if cur.points != first.points:
            raise PC2Error(f"{cp} has {cur.points} points, {headers[0][1]} has {first.points}")
        if abs(cur.sample_rate - first.sample_rate) > 1e-6:
            raise PC2Error(f"{cp} has sample rate {cur.sample_rate}, {headers[0][1]} has {first.sample_rate}")
        expected = prev.start_frame + prev.samples * prev.sample_rate
        if abs(cur.start_frame - expected) > 1e-4:
            kind = "a gap" if cur.start_frame > expected else "an overlap"
            raise PC2Error(f"{pp} ends before frame {expected} but {cp} starts at {cur.start_frame}: {kind}")
    # In blocks of about MERGE_BLOCK bytes: memory stays flat, and a signal is handled between
    # blocks (one call reading or writing a whole chunk cannot be interrupted). Read with
    # readinto, not np.fromfile: fromfile runs os.PathLike's Python isinstance check on the file
    # object and turns a KeyboardInterrupt raised there into a TypeError.
    frame_bytes = first.points * 12
    per_block = max(1, MERGE_BLOCK // frame_bytes)
    block = np.empty((per_block, first.points, 3), "<f4")
    with Writer(out, first.points, first.start_frame, first.sample_rate) as w:
        for header, p in headers:
            with open(p, "rb") as f:
                f.seek(HEADER.size)
                for done in range(0, header.samples, per_block):
                    data = block[: min(per_block, header.samples - done)]
                    if f.readinto(memoryview(data).cast("B")) != data.nbytes:
                        raise PC2Error(f"{p} is shorter than its header says")
                    w.add_many(data)
    return read_header(out)


MERGE_BLOCK = 8 << 20

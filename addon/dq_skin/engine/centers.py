# SPDX-License-Identifier: GPL-3.0-or-later
"""Optimized Centers of Rotation for the modifier: the per-vertex centers (computed by the Rust
core from the rest mesh, its triangles and the weights) are computed once and kept, keyed by a
digest of exactly what they depend on:

- in memory, for every modifier and object that shares them (duplicates share a mesh);
- on disk, in the extension's user folder, so opening a file again does not recompute them
  (nothing is written into the user's file or mesh).

Small meshes are computed on the spot. Large ones, in an interactive session, on a thread of
the core's own (`dqskin.centers_of_rotation_job`: no Python runs there, since Blender runs its operators and
evaluation with the GIL released and a Python thread running then is a hazard), one at a time,
while the modifier says so and Blender's own deformation stands in; Blender's thread collects
the result (the timer, or whoever asks next); the panel shows the progress and can cancel. In
background mode (command line, render farms) they are computed on the spot with a progress
bar, stopping on Ctrl-C.

After a weight change (a brush stroke) on a mesh whose centers were computed before (the same
rest positions and triangles, `latest`), only what the change reaches is computed again (the
core's `previous`, the same result bit for bit): on the spot up to UPDATE_INLINE_VERTICES, else
in the background while the last centers keep showing (the panel says they are updating).
"""

from __future__ import annotations

import hashlib
import os
from collections import OrderedDict
from pathlib import Path

import numpy as np

import bpy

from .. import dqskin
from ..progress import Progress

SIGMA = 0.1  # the paper's default similarity width
# Up to this many vertices the centers are computed on the spot, even in the viewport (well
# under half a second on two cores).
INLINE_VERTICES = 30_000
# Up to this many vertices an update after a weight change is computed on the spot (a stroke
# reaches a part of the mesh: see docs/performance.md).
UPDATE_INLINE_VERTICES = 30_000
MEMORY_ENTRIES = 16
DISK_BYTES = 1 << 30  # the on-disk cache is trimmed to this, oldest first (the add-on's preferences change it)
POLL_SECONDS = 0.05  # how soon finished centers show (a stroke's update takes a few tenths)
FORMAT = 1  # bump when the centers' definition changes: old files are then ignored
MAX_RUNNING = 1  # computations at once: each already uses every core


class Cancelled(Exception):
    """The user cancelled the computation."""


class Job:
    """A computation on the core's thread (`native`, a `dqskin.centers_of_rotation_job`), or queued until
    another one ends (`native` None); its result is collected in Blender's thread, by the
    first of the timer or a caller asking whether it has `finished`."""

    def __init__(self, store: Centers, key: str, vertices: int, inputs: tuple, geometry: str, owners: set):
        self._store = store
        self.key = key
        self.vertices = vertices
        self.inputs = inputs  # (positions, triangles, influences, previous) until started
        self.geometry = geometry
        self.influences = inputs[2]
        self.owners = owners  # object names waiting for it (redrawn after)
        self.native = None
        self.cancelled = False
        self.error = ""
        self.collected = False

    @property
    def done(self) -> int:
        return self.native.done if self.native is not None else int(self.collected)

    @property
    def total(self) -> int:
        return self.native.total if self.native is not None else 1

    @property
    def fraction(self) -> float:
        return self.done / max(self.total, 1)

    @property
    def finished(self) -> bool:
        if not self.collected:
            self._store.pump()
        return self.collected


def in_background() -> bool:
    """No interactive session (command line, render farm): compute on the spot."""
    return bpy.app.background


def triangles_of(mesh) -> np.ndarray:
    """The mesh's triangles (Blender's own triangulation of its faces), `(T, 3)` uint32."""
    mesh.calc_loop_triangles()
    tris = np.empty(len(mesh.loop_triangles) * 3, np.uint32)
    mesh.loop_triangles.foreach_get("vertices", tris)
    return tris.reshape(-1, 3)


def key_of(positions: np.ndarray, triangles: np.ndarray, influences, sigma: float = SIGMA) -> str:
    """A digest of everything the centers depend on (rest positions, topology, weights, sigma)."""
    h = hashlib.blake2b(digest_size=20)
    h.update(f"dq_skin centers {FORMAT} {sigma!r} {len(positions)} {len(triangles)}".encode())
    for a in (positions, triangles, influences.offsets, influences.bones, influences.weights):
        h.update(np.ascontiguousarray(a).data)
    return h.hexdigest()


def geometry_of(positions: np.ndarray, triangles: np.ndarray) -> str:
    """A digest of the rest mesh the centers are computed on (positions and topology), whatever
    the weights: centers of the same geometry can be updated after a weight change."""
    h = hashlib.blake2b(digest_size=20)
    h.update(f"dq_skin geometry {len(positions)} {len(triangles)}".encode())
    for a in (positions, triangles):
        h.update(np.ascontiguousarray(a).data)
    return h.hexdigest()


def _folder() -> Path | None:
    try:
        return Path(bpy.utils.extension_path_user(__package__.rpartition(".")[0], path="centers", create=True))
    except (ValueError, OSError, AttributeError):
        return None  # not installed as an extension (or no writable user folder): memory only


def _trim(folder: Path, limit: int) -> None:
    """Removes the oldest centers of `folder` beyond `limit` bytes."""
    files = sorted(folder.glob("*.npy"), key=lambda p: p.stat().st_mtime, reverse=True)
    total = 0
    for p in files:
        total += p.stat().st_size
        if total > limit:
            p.unlink(missing_ok=True)


class Centers:
    """The centers computed in this session (an LRU in memory, backed by the user folder) and
    the computations running on the core's threads (owned by the session). `interrupted()`:
    whether Ctrl-C or SIGTERM stopped a batch command."""

    def __init__(self, interrupted=lambda: False):
        self._interrupted = interrupted
        self._memory: OrderedDict[str, np.ndarray] = OrderedDict()
        # Geometry digest -> (influences, centers) computed last for it (what an update starts from).
        self._latest: OrderedDict[str, tuple] = OrderedDict()
        self._jobs: dict[str, Job] = {}
        self.disk_bytes = DISK_BYTES  # the user folder's centers are trimmed to this, oldest first

    def set_disk_limit(self, limit: int) -> None:
        """Keeps at most `limit` bytes of centers in the user folder (trimmed now, and after
        every computation)."""
        self.disk_bytes = max(int(limit), 0)
        self.trim()

    def trim(self, folder: Path | None = None) -> None:
        """Trims the centers kept on disk (in `folder`, the user folder's by default) to the limit."""
        folder = folder if folder is not None else _folder()
        if folder is not None:
            try:
                _trim(Path(folder), self.disk_bytes)
            except OSError:
                pass  # a cache: trimming again later is enough

    def lookup(self, key: str, vertices: int) -> np.ndarray | None:
        """The centers for `key` if they were computed before (in this session or an earlier one)."""
        self.pump()
        got = self._memory.get(key)
        if got is not None:
            self._memory.move_to_end(key)
            return got
        folder = _folder()
        if folder is None:
            return None
        path = folder / f"{key}.npy"
        try:
            got = np.load(path, allow_pickle=False)
        except (OSError, ValueError):
            return None
        if got.dtype != np.float32 or got.shape != (vertices, 3):
            return None
        os.utime(path)  # recently used: trimmed last
        self._remember(key, got)
        return got

    def _remember(self, key: str, centers: np.ndarray) -> None:
        centers.setflags(write=False)
        self._memory[key] = centers
        self._memory.move_to_end(key)
        while len(self._memory) > MEMORY_ENTRIES:
            self._memory.popitem(last=False)

    def _store(self, key: str, centers: np.ndarray) -> None:
        self._remember(key, centers)
        folder = _folder()
        if folder is None:
            return
        tmp = folder / f".{key}.{os.getpid()}.tmp.npy"
        try:
            np.save(tmp, centers, allow_pickle=False)
            os.replace(tmp, folder / f"{key}.npy")
            _trim(folder, self.disk_bytes)
        except OSError:
            pass  # a cache: failing to keep it only costs a recomputation
        finally:
            if tmp.exists():
                tmp.unlink()

    def forget_memory(self) -> None:
        """Drops the centers kept in memory (the user folder's stay)."""
        self._memory.clear()
        self._latest.clear()

    def latest(self, geometry: str) -> tuple | None:
        """`(influences, centers)` computed or found last for this geometry in this session, or None."""
        return self._latest.get(geometry)

    def remember_latest(self, geometry: str, influences, centers: np.ndarray) -> None:
        self._latest[geometry] = (influences, centers)
        self._latest.move_to_end(geometry)
        while len(self._latest) > MEMORY_ENTRIES:
            self._latest.popitem(last=False)

    def compute(
        self,
        positions,
        triangles,
        influences,
        key: str,
        label: str = "",
        check=None,
        geometry: str = "",
        previous: tuple | None = None,
    ) -> np.ndarray:
        """Computes (and keeps) the centers now (`previous`: the `(influences, centers)` of the
        same geometry, of which only what the weight change reaches is computed again).
        `check()` may raise to stop (Ctrl-C on the command line)."""
        progress = Progress(None, 100, label) if label else None
        last = [0]

        def report(done: int, total: int) -> bool:
            if progress is not None:
                step = int(100 * done / max(total, 1))
                if step > last[0]:
                    progress.set(step)
                    last[0] = step
            if check is not None:
                check()
            return not self._interrupted()  # Ctrl-C or SIGTERM in a batch command

        try:
            centers = dqskin.centers_of_rotation(positions, triangles, influences, sigma=SIGMA, progress=report, previous=previous)
        except dqskin.Cancelled:
            raise Cancelled() from None
        finally:
            if progress is not None:
                progress.end()
        centers = np.ascontiguousarray(centers, np.float32)
        self._store(key, centers)
        if geometry:
            self.remember_latest(geometry, influences, centers)
        return centers

    def start(self, positions, triangles, influences, key: str, owner: str, geometry: str = "", previous: tuple | None = None) -> Job:
        """The background computation of `key` (queued if another one is running)."""
        job = self._jobs.get(key)
        if job is not None and not job.finished:
            job.owners.add(owner)
            return job
        inputs = (positions.copy(), triangles.copy(), influences, previous)
        job = self._jobs[key] = Job(self, key, len(positions), inputs, geometry, {owner})
        self.pump()
        if not bpy.app.timers.is_registered(self.poll):
            bpy.app.timers.register(self.poll, first_interval=POLL_SECONDS)
        return job

    def pump(self) -> None:
        """Collects what the core's threads finished and starts queued computations, at most
        MAX_RUNNING at a time (each uses every core). Blender's thread only."""
        for job in self._jobs.values():
            if job.native is not None and not job.collected and job.native.finished:
                self._collect(job)
        running = sum(1 for j in self._jobs.values() if j.native is not None and not j.collected)
        for job in self._jobs.values():
            if running >= MAX_RUNNING:
                break
            if job.native is None and not job.collected:
                self._launch(job)
                running += not job.collected

    def _launch(self, job: Job) -> None:
        positions, triangles, influences, previous = job.inputs
        job.inputs = None
        try:
            job.native = dqskin.centers_of_rotation_job(positions, triangles, influences, SIGMA, previous=previous)
        except (ValueError, TypeError, RuntimeError) as e:  # reported on the modifier
            job.error, job.collected = f"{type(e).__name__}: {e}", True

    def _collect(self, job: Job) -> None:
        try:
            if job.cancelled:  # as the artist asked, even if the thread had just finished
                raise dqskin.Cancelled()
            centers = np.ascontiguousarray(job.native.result(), np.float32)
        except dqskin.Cancelled:
            job.error = "cancelled"
        except Exception as e:  # reported on the modifier
            job.error = f"{type(e).__name__}: {e}"
        else:
            self._store(job.key, centers)
            if job.geometry:
                self.remember_latest(job.geometry, job.influences, centers)
        job.collected = True
        job.native = job.influences = None

    def running(self) -> list[Job]:
        self.pump()
        return [j for j in self._jobs.values() if not j.collected]

    def jobs(self) -> list[Job]:
        """Every computation started in this session, running or finished, oldest first."""
        self.pump()
        return list(self._jobs.values())

    def job_of(self, key: str) -> Job | None:
        self.pump()
        return self._jobs.get(key)

    def cancel(self, key: str) -> None:
        job = self._jobs.get(key)
        if job is None or job.collected:
            return
        job.cancelled = True
        if job.native is not None:
            job.native.cancel()  # collected as cancelled once its thread stops
        else:
            job.inputs, job.error, job.collected = None, "cancelled", True

    def close(self) -> None:
        """Stops every background computation (their threads end at their next step)."""
        for key in list(self._jobs):
            self.cancel(key)
        if bpy.app.timers.is_registered(self.poll):
            bpy.app.timers.unregister(self.poll)

    def poll(self):
        """While computations run: redraw their progress; when one ends, re-evaluate its objects."""
        self.pump()
        running = False
        for job in list(self._jobs.values()):
            if job.finished and job.owners:
                for name in job.owners:
                    obj = bpy.data.objects.get(name)
                    if obj is not None:
                        obj.update_tag()  # evaluates again: now with the centers (or the error)
                job.owners.clear()
            running |= not job.finished
        for window in getattr(bpy.context.window_manager, "windows", []):
            for area in window.screen.areas:
                if area.type in ("PROPERTIES", "VIEW_3D"):
                    area.tag_redraw()
        return POLL_SECONDS if running else None

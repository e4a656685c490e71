"""Timing in one Blender session: rounds alternating the variants of a scene (only one of them in
the depsgraph at a time), each a median; where DQ Skin's time of a frame goes; memory."""

from __future__ import annotations

import ctypes
import sys
import time

import numpy as np

import bpy

ADDON = "bl_ext.user_default.dq_skin"


def addon():
    return sys.modules[ADDON]


def steady_allocator() -> bool:
    """Keeps glibc's allocator from handing big blocks back to the system (its mmap threshold
    and heap trimming), so that a large array Blender frees and allocates again every frame
    does not page-fault afresh at random frames: without it, 250k vertices with Corrective
    Smooth took 48 or 63 ms a frame at random, with the Armature modifier and with DQ Skin
    alike. Blender's own Linux builds allocate with jemalloc
    (`build_files/cmake/config/blender_release.cmake`), which keeps freed blocks for reuse below
    8 MB and hands larger ones back at once; the `bpy` module cannot (`bpy_module.cmake`:
    jemalloc does not work when Python loads the module). Every variant of a run gets the same
    allocator; `bench/allocators.py` measures how the allocators move the 1M grid. Returns
    whether it applied (glibc)."""
    try:
        libc = ctypes.CDLL("libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    m_trim_threshold, m_mmap_max = -1, -4
    return bool(mallopt(m_trim_threshold, 1 << 30)) and bool(mallopt(m_mmap_max, 0))


def show_only(*objs) -> None:
    """Only `objs` of the scene's meshes in the depsgraph (the others hidden from the viewport)."""
    keep = set(objs)
    for o in bpy.context.scene.objects:
        if o.type == "MESH":
            o.hide_viewport = o not in keep
    bpy.context.view_layer.update()


def frames_ms(objs, frames, runs: int) -> float:
    """Median ms of a frame change until every object's evaluated mesh is there."""
    scene = bpy.context.scene
    times = []
    scene.frame_set(frames[-1])
    for k in range(runs):
        start = time.perf_counter()
        scene.frame_set(frames[k % len(frames)])
        dg = bpy.context.evaluated_depsgraph_get()
        for o in objs:
            o.evaluated_get(dg).data
        times.append(time.perf_counter() - start)
    return 1e3 * float(np.median(times))


def alternate(variants: dict, frames, rounds: int, per_round: int, hooks: dict | None = None) -> dict:
    """Rounds alternating the variants (name -> objects); `{name}_ms`, the median over all
    rounds. `hooks`: name -> (enter, leave), called around each of its rounds, outside the
    timing (a route forced, a prototype built)."""
    all_times = {k: [] for k in variants}
    hooks = hooks or {}
    for _ in range(rounds):
        for name, objs in variants.items():
            enter, leave = hooks.get(name, (None, None))
            if enter:
                enter()
            try:
                show_only(*objs)
                bpy.context.scene.frame_set(frames[0])  # settle after the switch
                bpy.context.scene.frame_set(frames[1])
                all_times[name].append(frames_ms(objs, frames, per_round))
            finally:
                if leave:
                    leave()
    return {f"{k}_ms": float(np.median(v)) for k, v in all_times.items()}


class Parts:
    """Where DQ Skin's time of a frame goes, per frame: the feed's skinning inside Blender's
    evaluation (`fed`: all of it; `fed_prepare`: reading pose, spaces and inputs; `kernel`;
    `file`: checking or writing the Mesh Cache carrier's file) and the frame handler after it
    (`handler`; `handler_checks`: whether each fed frame stands, by the kept check or the whole
    one). Each part times the functions it names (none calls another of the same part)."""

    PARTS = {
        "fed": (("SESSION.routes.feeds", "skin"),),
        "fed_prepare": (("engine.fed.FedFrame", "_prepare"),),
        "kernel": (("dqskin", "skin_many"),),
        "file": (("routes.cache_route.CacheRoute", "fed_done"),),
        "handler": (("engine.tracker.Tracker", "frame"),),
        "handler_checks": (("engine.playback", "fed_frame_stands_as_checked"), ("engine.playback", "fed_frame_stands")),
    }

    def __init__(self):
        self.saved = []
        self.totals = {k: 0.0 for k in self.PARTS}
        self.frames = 0

    def __enter__(self):
        for key, path, name in ((k, p, n) for k, functions in self.PARTS.items() for p, n in functions):
            owner = addon()
            for part in path.split("."):
                owner = getattr(owner, part)
            original = getattr(owner, name)
            self.saved.append((owner, name, original))

            def timed(*a, _original=original, _key=key, **k):
                t = time.perf_counter()
                try:
                    return _original(*a, **k)
                finally:
                    self.totals[_key] += time.perf_counter() - t

            setattr(owner, name, timed)
        return self

    def __exit__(self, *exc):
        for owner, name, original in reversed(self.saved):
            setattr(owner, name, original)
        self.saved.clear()

    def measure(self, objs, frames, runs: int) -> dict:
        """Per frame ms of each part over `runs` frame changes."""
        self.totals = {k: 0.0 for k in self.PARTS}
        frames_ms(objs, frames, runs)
        return {f"dq_skin_{k}_ms": 1e3 * v / runs for k, v in self.totals.items()}


def reevaluation_ms(template, runs: int = 40) -> float:
    """What Blender costs to evaluate the scene again after a change to one mesh nothing depends
    on: the least a second evaluation costs here (median ms of a tag and an update)."""
    mesh = template.data.copy()
    o = bpy.data.objects.new(f"{template.name} re-evaluation", mesh)
    bpy.context.scene.collection.objects.link(o)
    bpy.context.view_layer.update()
    ts = []
    for _ in range(runs):
        t = time.perf_counter()
        mesh.update_tag()
        bpy.context.view_layer.update()
        ts.append(time.perf_counter() - t)
    bpy.data.objects.remove(o)
    bpy.data.meshes.remove(mesh)
    bpy.context.view_layer.update()
    return 1e3 * float(np.median(ts))


def kernel_ms(obj, runs: int) -> dict:
    """`dqskin.skin_many` alone on the job DQ Skin last built for `obj` (its inputs, spaces and
    output), Linear and Dual Quaternion."""
    a = addon()
    mod = a.engine.context.dq_skin_modifiers(obj)[0]
    job = a.SESSION.state_of(obj, mod).output.job
    if job is None:  # handed over (the Armature modifier deforms): no kernel of ours runs
        return {}
    res = {}
    for method in ("linear", "dual_quaternion"):
        j = a.dqskin.SkinJob(
            job.positions, job.influences, job.deform, job.rest, method=method, premat=job.premat, postmat=job.postmat, mask=job.mask
        )
        ts = []
        for _ in range(runs):
            t = time.perf_counter()
            a.dqskin.skin_many([j])
            ts.append(time.perf_counter() - t)
        res[f"kernel_{method}_ms"] = 1e3 * float(np.median(ts))
    return res


def resident_bytes() -> int:
    """This process's resident memory (Linux), after a garbage collection."""
    import gc

    gc.collect()
    with open("/proc/self/statm") as f:
        pages = int(f.read().split()[1])
    import os

    return pages * os.sysconf("SC_PAGE_SIZE")


def timed_s(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t

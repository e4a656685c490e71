"""The memory DQ Skin adds, each case in fresh processes (a process that built other scenes
first reuses their freed memory, and its resident size would hide what DQ Skin keeps), three
of them, pooled (see `PROCESSES`).

The scene is built with Blender's Armature modifier and evaluated; then DQ Skin takes the
Armature modifier's place and plays eighteen frames. DQ Skin's extra memory is the growth of the
process's resident memory, measured after a garbage collection and `malloc_trim` (so that freed
memory does not count) after each frame, the median over the frames of every process kept and
the range reported (and, of it, the file-backed part: Blender's code paged in for the route's
modifiers, the same for any number of characters), plus the bytes
of the point-cache files it keeps in memory-backed storage that are not mapped into the process
(`/dev/shm` is memory too, though it is no process's). It is set against the payload: the bytes
of the meshes' positions (12 per vertex) and weights (8 per vertex-group entry). What DQ Skin
itself holds is itemized from its session: output buffers, copies of the rest positions,
influences (lane order and counts), point-cache files (mapped into the process or not)."""

from __future__ import annotations

import ctypes
import gc
import json
import os
import subprocess
import sys
from pathlib import Path

import bpy

from . import routes, scenes
from .compare import add_dq_skin, payload_bytes
from .timing import addon

CASES = {
    "crowd": ("200 CesiumMen (3,273 vertices each), Dual Quaternion", "DUAL_QUATERNION"),
    "crowd_own_weights": ("200 CesiumMen, each with weights of its own, Dual Quaternion", "DUAL_QUATERNION"),
    "grid_linear": ("Grid 1,000,000 vertices, 64 bones, Linear", "LINEAR"),
    "grid_dq": ("Grid 1,000,000 vertices, 64 bones, Dual Quaternion", "DUAL_QUATERNION"),
}
# Eighteen frames: what stays resident moves in steps of one array of positions between frames
# (Blender's evaluated copies), so the median needs enough of them to settle.
FRAMES = (3, 9, 15, 21, 27, 33, 39, 5, 12) * 2


def _libc():
    try:
        return ctypes.CDLL("libc.so.6")
    except OSError:
        return None


def resident_bytes() -> int:
    """Resident memory of this process after freed memory went back to the system (Linux)."""
    gc.collect()
    libc = _libc()
    if libc is not None and hasattr(libc, "malloc_trim"):
        libc.malloc_trim(0)
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def resident_shared_bytes() -> int:
    """The part of the resident memory that is mapped shared memory (a mapped file of
    `/dev/shm` counts there, and must not be counted twice)."""
    return _status_bytes("RssShmem")


def resident_file_bytes() -> int:
    """The part of the resident memory that is file-backed (code and data of the programs and
    libraries, paged in as they are first used: Blender's code for the route's modifiers, the
    same for any number of characters)."""
    return _status_bytes("RssFile")


def _status_bytes(field: str) -> int:
    """A size in `/proc/self/status` (Linux), 0 where the kernel does not give it."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024
    return 0


def cache_file_bytes() -> int:
    """Bytes this process's point-cache files occupy (allocated blocks, not their length)."""
    folder = addon().routes.pointcache.folder()
    prefix = f"dqskin-{os.getpid()}-"
    total = 0
    for entry in os.scandir(folder):
        if entry.name.startswith(prefix) and entry.name.endswith(".pc2"):
            total += entry.stat().st_blocks * 512
    return total


def held_by_dq_skin() -> dict:
    """What DQ Skin's session holds, by kind, in bytes (arrays and influences; the Python
    objects around them and Blender's own data are not itemized)."""
    a = addon()
    session = a.SESSION
    mapped = a.routes.pointcache.is_mapped
    held = {"output_buffers": 0, "influences": 0, "rest_copies": 0}
    seen: set[int] = set()
    for _key, st in session.states.items():
        if st.output.buffer is not None and not mapped(st.output.buffer):
            held["output_buffers"] += st.output.buffer.nbytes
        bound = st.binding.binding
        if bound is not None and id(bound.influences) not in seen:
            seen.add(id(bound.influences))
            held["influences"] += bound.influences.nbytes
    held["rest_copies"] = session.meshes.nbytes()
    held["cache_files"] = cache_file_bytes()
    return held


def _build(case: str):
    scenes.empty_scene()
    if case.startswith("crowd"):
        pairs = scenes.crowd(200)
        if case == "crowd_own_weights":
            # One weight changed per character: no two bind to the same influences.
            for k, (m, _) in enumerate(pairs):
                g = m.data.vertices[k].groups[0]
                m.vertex_groups[g.group].add([k], g.weight * 0.5, "REPLACE")
    else:
        pairs = [scenes.grid_rig(1_000_000)]
    meshes = [m for m, _ in pairs]
    method = CASES[case][1]
    for m in meshes:
        next(x for x in m.modifiers if x.type == "ARMATURE").use_deform_preserve_volume = method == "DUAL_QUATERNION"
    return meshes, method


def measure(case: str) -> dict:
    """In this process (a fresh one): the row of `case`."""
    meshes, method = _build(case)
    for f in (1, 2):
        bpy.context.scene.frame_set(f)
    before, shared_before, files_before = resident_bytes(), resident_shared_bytes(), cache_file_bytes()
    file_backed_before = resident_file_bytes()
    add_dq_skin(meshes, method)
    # What stays resident changes from frame to frame (an array of positions freed in one frame
    # and made in the next): measured after each frame, the median is the row's figure.
    growth, file_backed = [], []
    for f in FRAMES:
        bpy.context.scene.frame_set(f)
        growth.append(resident_bytes() - before)
        file_backed.append(resident_file_bytes() - file_backed_before)
    grown = _median(growth)
    held = held_by_dq_skin()
    # The files' bytes that are not already resident in this process as a mapping.
    unmapped_files = max(0, held["cache_files"] - files_before - (resident_shared_bytes() - shared_before))
    extra = grown + unmapped_files
    payload = payload_bytes(meshes)
    return {
        "case": f"memory: {CASES[case][0]}",
        "objects": len(meshes),
        "route": routes.route_of(meshes[0]),
        "payload_bytes": payload,
        "resident_growth_bytes": grown,
        "resident_growth_range_bytes": [min(growth), max(growth)],
        "resident_growth_per_frame_bytes": growth,
        "resident_file_growth_bytes": _median(file_backed),
        "unmapped_file_bytes": unmapped_files,
        "extra_bytes": extra,
        "extra_per_payload": extra / max(payload, 1),
        **{f"held_{k}_bytes": v for k, v in held.items()},
    }


def _median(values: list) -> int:
    return sorted(values)[len(values) // 2]


# Processes per case: which of Blender's evaluated copies stay resident differs from one process
# to the next as well as from frame to frame (the 1M grids: 60-96 MB), so the row pools them.
PROCESSES = 3


def run_fresh(case: str) -> dict:
    """`measure(case)` in `PROCESSES` new processes running this benchmark, one after the other:
    the row of the first, with the growth pooled over every frame of every process (median and
    range) and each process's median."""
    script = Path(__file__).resolve().parents[1] / "blender_bench.py"
    rows = []
    for _ in range(PROCESSES):
        done = subprocess.run([sys.executable, str(script), "--memory-case", case], capture_output=True, text=True, timeout=1800)
        lines = [ln for ln in done.stdout.splitlines() if ln.startswith("{")]
        if done.returncode != 0 or not lines:
            raise RuntimeError(f"memory case {case} failed ({done.returncode}):\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}")
        rows.append(json.loads(lines[-1]))
    row = dict(rows[0])
    pooled = [g for r in rows for g in r.pop("resident_growth_per_frame_bytes")]
    grown = _median(pooled)
    row.pop("resident_growth_per_frame_bytes", None)
    row["resident_growth_bytes"] = grown
    row["resident_growth_range_bytes"] = [min(pooled), max(pooled)]
    row["resident_growth_process_medians_bytes"] = [r["resident_growth_bytes"] for r in rows]
    row["resident_file_growth_bytes"] = _median([r["resident_file_growth_bytes"] for r in rows])
    row["extra_bytes"] = grown + row["unmapped_file_bytes"]
    row["extra_per_payload"] = row["extra_bytes"] / max(row["payload_bytes"], 1)
    return row

"""Automatic weights and weight transfer: the issue's speed and memory goals, measured.

- a 100,000-vertex creature of 160 bones (closed tubes around a branching skeleton that
  intersect at every joint, plus loose spheres) at the default resolution;
- the tests' Rigify character (its deforming bones; needs the bpy module) at the default resolution;
- peak memory at the highest resolution offered, in a process of its own;
- transfer to a 50,000-vertex garment (an open sleeve-like shell around the creature's trunk).

Each timing is the best of `--repeat` runs (default 3). The CPU, the thread count and the
command go with the figures (docs/performance.md).

Usage: python bench/weights_bench.py [--repeat N] [--skip-rigify] [--skip-memory]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

import dqskin
import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def tube(a: np.ndarray, b: np.ndarray, radius: float, rings: int, segments: int, capped: bool = True):
    """A tube from `a` to `b` (rings × segments vertices), closed by two fans when `capped`."""
    axis = b - a
    length = float(np.linalg.norm(axis))
    z = axis / length
    x = np.cross(z, [0.0, 0.0, 1.0] if abs(z[2]) < 0.9 else [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    t = np.linspace(0.0, 1.0, rings)
    phi = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    ring = np.cos(phi)[:, None] * x + np.sin(phi)[:, None] * y
    pos = (a + t[:, None, None] * axis + radius * ring[None]).reshape(-1, 3)
    tris = []
    for r in range(rings - 1):
        for s in range(segments):
            i0, i1 = r * segments + s, r * segments + (s + 1) % segments
            j0, j1 = i0 + segments, i1 + segments
            tris += [(i0, i1, j1), (i0, j1, j0)]
    if capped:
        first, last = len(pos), len(pos) + 1
        pos = np.vstack([pos, a, b])
        top = (rings - 1) * segments
        for s in range(segments):
            tris += [(first, (s + 1) % segments, s), (last, top + s, top + (s + 1) % segments)]
    return pos.astype(np.float32), np.asarray(tris, np.int64)


def sphere(center, radius: float, n: int = 12):
    """A UV sphere (a loose part: an eye)."""
    theta = np.linspace(0, np.pi, n)[1:-1]
    phi = np.linspace(0, 2 * np.pi, n, endpoint=False)
    pts = [np.array([0, 0, radius])]
    for th in theta:
        for ph in phi:
            pts.append(radius * np.array([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)]))
    pts.append(np.array([0, 0, -radius]))
    pos = np.asarray(pts) + center
    rows = len(theta)
    tris = []
    for s in range(n):
        tris.append((0, 1 + s, 1 + (s + 1) % n))
    for r in range(rows - 1):
        for s in range(n):
            i0, i1 = 1 + r * n + s, 1 + r * n + (s + 1) % n
            tris += [(i0, i1 + n, i1), (i0, i0 + n, i1 + n)]
    last = len(pos) - 1
    for s in range(n):
        tris.append((last, 1 + (rows - 1) * n + (s + 1) % n, 1 + (rows - 1) * n + s))
    return pos.astype(np.float32), np.asarray(tris, np.int64)


def merge(parts):
    positions, triangles, base = [], [], 0
    for pos, tris in parts:
        positions.append(pos)
        triangles.append(tris + base)
        base += len(pos)
    return np.vstack(positions), np.vstack(triangles).astype(np.int32)


def skeleton(bones: int, seed: int = 7):
    """A branching skeleton of `bones` segments: a trunk, limbs off it and chains off those."""
    rng = np.random.default_rng(seed)
    heads, tails = [np.zeros(3)], [np.array([0.0, 0.0, 0.3])]
    while len(heads) < bones:
        parent = int(rng.integers(len(heads)))
        start = tails[parent]
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        heads.append(start)
        tails.append(start + 0.25 * direction)
    return np.asarray(heads, np.float32), np.asarray(tails, np.float32)


def creature(vertices: int = 100_000, bones: int = 160):
    """Closed tubes around every bone (intersecting at the joints) and two loose spheres."""
    heads, tails = skeleton(bones)
    segments = 24
    rings = max(2, round((vertices - 2 * 110) / bones / segments))
    parts = [tube(h, t, 0.06, rings, segments) for h, t in zip(heads, tails)]
    parts += [sphere(tails[0] + [0.08, 0.05, 0.05], 0.02, 11), sphere(tails[0] + [-0.08, 0.05, 0.05], 0.02, 11)]
    positions, triangles = merge(parts)
    return positions, triangles, heads, tails


def garment(heads, tails, vertices: int = 50_000):
    """An open shell around the creature's first bones (a sleeve), a little outside their tubes."""
    chain = list(range(min(len(heads), 20)))
    segments = 40
    rings = max(2, vertices // (len(chain) * segments))
    parts = [tube(heads[i], tails[i], 0.07, rings, segments, capped=False) for i in chain]
    return merge(parts)


def best_of(repeat: int, run):
    times, result = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - t)
    return min(times), result


def check(influences, count: int, k: int) -> dict:
    """Every vertex weighted, sums 1, at most k bones."""
    offsets = np.asarray(influences.offsets, np.int64)
    per_vertex = np.diff(offsets)
    sums = np.add.reduceat(np.asarray(influences.weights, np.float64), offsets[:-1]) if len(offsets) > 1 else np.zeros(0)
    return {
        "vertices": count,
        "unweighted": int((per_vertex == 0).sum()),
        "most_bones": int(per_vertex.max()),
        "worst_sum_error": float(np.abs(sums - 1).max()),
        "ok": bool((per_vertex >= 1).all() and per_vertex.max() <= k and np.abs(sums - 1).max() < 1e-5),
    }


def rigify_case(repeat: int):
    """The tests' Rigify character (tests/blender/characters.py) through the bpy module."""
    sys.path.insert(0, str(ROOT / "tests" / "blender"))
    import characters

    import bpy  # noqa: F401  (the bpy module of the pinned Blender)

    body, rig = characters.rigify_character()
    mesh = body.data
    positions = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", positions)
    mesh.calc_loop_triangles()
    tris = np.empty(len(mesh.loop_triangles) * 3, np.int32)
    mesh.loop_triangles.foreach_get("vertices", tris)
    to_mesh = np.asarray(body.matrix_world.inverted() @ rig.matrix_world, np.float64)
    deform = [b for b in rig.data.bones if b.use_deform]

    def points(attr):
        p = np.asarray([list(getattr(b, attr)) for b in deform], np.float64)
        return (p @ to_mesh[:3, :3].T + to_mesh[:3, 3]).astype(np.float32)

    positions = positions.reshape(-1, 3)
    seconds, (inf, report) = best_of(
        repeat, lambda: dqskin.automatic_weights(positions, tris.reshape(-1, 3), points("head_local"), points("tail_local"))
    )
    return {
        "case": "Rigify character",
        "bones": len(deform),
        "seconds": seconds,
        "goal_seconds": 1.0,
        **check(inf, len(positions), 4),
        "unreached": report["unreached"],
    }


def memory_case() -> dict:
    """Peak resident memory of automatic weights at the highest resolution, in a fresh process."""
    code = (
        f"import resource, sys, json; sys.path.insert(0, {str(Path(__file__).parent)!r}); import weights_bench as w, dqskin;"
        "p, t, h, e = w.creature(); base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss;"
        "dqskin.automatic_weights(p, t, h, e, resolution=512);"
        "print(json.dumps([base, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss]))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    before, peak = json.loads(out.strip().splitlines()[-1])
    return {"case": "peak memory at resolution 512 (100k creature)", "peak_mb": peak / 1024, "before_mb": before / 1024, "goal_mb": 1024}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--skip-rigify", action="store_true")
    ap.add_argument("--skip-memory", action="store_true")
    args = ap.parse_args(argv)
    cpu = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name")), platform.processor())
    print(f"# {cpu}, {os.cpu_count()} CPUs, dqskin {dqskin.__version__}, {platform.python_version()}", flush=True)
    results = []

    positions, triangles, heads, tails = creature()
    seconds, (inf, report) = best_of(args.repeat, lambda: dqskin.automatic_weights(positions, triangles, heads, tails))
    results.append(
        {
            "case": "automatic weights, 100k creature",
            "bones": len(heads),
            "grid": report["grid"],
            "seconds": seconds,
            "goal_seconds": 3.0,
            **check(inf, len(positions), 4),
            "unreached": report["unreached"],
        }
    )
    print(json.dumps(results[-1]), flush=True)

    cloth_pos, cloth_tris = garment(heads, tails)
    seconds, (moved, treport) = best_of(args.repeat, lambda: dqskin.transfer_weights(positions, triangles, inf, cloth_pos, cloth_tris))
    results.append(
        {
            "case": "transfer to a 50k garment",
            "seconds": seconds,
            "goal_seconds": 1.0,
            "matched": treport["matched_count"],
            "inpainted": treport["inpainted"],
            **check(moved, len(cloth_pos), 4),
        }
    )
    print(json.dumps(results[-1]), flush=True)

    if not args.skip_rigify:
        results.append(rigify_case(args.repeat))
        print(json.dumps(results[-1]), flush=True)
    if not args.skip_memory:
        results.append(memory_case())
        print(json.dumps(results[-1]), flush=True)
    print(f"(peak memory of this process: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

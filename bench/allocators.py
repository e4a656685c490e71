"""A large grid, DQ Skin against Blender's Armature modifier, under each memory allocator.

Blender's own builds allocate with jemalloc; the `bpy` module cannot (Python loads it), so it
runs on glibc's allocator, and `blender_bench.py` sets glibc to keep its big blocks
(`timing.steady_allocator`). On a million vertices each frame copies 12 MB of positions in
Blender (the Armature modifier's own copy, and on DQ Skin's route the carrier's), and whether that
copy lands on memory the process already has, or page-faults on fresh memory, depends on the
allocator. This runs the same comparison in a fresh process per allocator, one after the other:
glibc as it comes, glibc kept steady, and jemalloc preloaded where its library is given. Each
process alternates the Armature modifier and DQ Skin in rounds, keeps each one's median frame,
and counts the minor page faults a frame. A benchmark, not a test; docs/performance.md has its
figures.

Usage: python bench/allocators.py [--vertices N] [--method LINEAR|DUAL_QUATERNION]
       [--rounds R] [--jemalloc PATH/libjemalloc.so.2]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MODES = ("glibc", "steady", "jemalloc")
CHILD_TIMEOUT_S = 900


def minor_faults() -> int:
    """This process's minor page faults so far (Linux)."""
    with open("/proc/self/stat") as f:
        return int(f.read().rsplit(")", 1)[1].split()[7])


def child(mode: str, vertices: int, method: str, rounds: int) -> dict:
    """One process's comparison (imports Blender here: the allocator is chosen before it)."""
    os.environ.setdefault("BLENDER_USER_RESOURCES", str(ROOT / ".blender_user"))
    sys.path.insert(0, str(ROOT / "bench"))
    from endtoend.timing import steady_allocator

    if mode == "steady" and not steady_allocator():
        raise SystemExit("allocators: the steady mode needs glibc")
    import numpy as np
    from endtoend import scenes
    from endtoend.compare import add_dq_skin
    from endtoend.timing import ADDON, frames_ms, show_only

    import bpy

    import addon_utils

    addon_utils.enable(ADDON, default_set=True)
    scenes.empty_scene()
    armature, _rig = scenes.grid_rig(vertices)
    for mod in armature.modifiers:
        if mod.type == "ARMATURE":
            mod.use_deform_preserve_volume = method == "DUAL_QUATERNION"
    dq_skin = scenes.copy_of(armature, "Grid DQ Skin")
    show_only(dq_skin)
    add_dq_skin([dq_skin], method)
    frames = [3, 9, 15, 21]
    times: dict[str, list[float]] = {"armature": [], "dq_skin": []}
    faults: dict[str, list[float]] = {"armature": [], "dq_skin": []}
    for _ in range(rounds):
        for name, obj in (("armature", armature), ("dq_skin", dq_skin)):
            show_only(obj)
            for f in frames:
                bpy.context.scene.frame_set(f)
            before, runs = minor_faults(), 40
            times[name].append(frames_ms([obj], frames, runs))
            faults[name].append((minor_faults() - before) / runs)
    return {
        "mode": mode,
        **{f"{k}_ms": float(np.median(v)) for k, v in times.items()},
        **{f"{k}_faults_per_frame": float(np.median(v)) for k, v in faults.items()},
    }


def run_mode(mode: str, args) -> dict:
    env = dict(os.environ)
    if mode == "jemalloc":
        env["LD_PRELOAD"] = str(args.jemalloc)
    command = [
        sys.executable,
        __file__,
        "--child",
        mode,
        "--vertices",
        str(args.vertices),
        "--method",
        args.method,
        "--rounds",
        str(args.rounds),
    ]
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=CHILD_TIMEOUT_S)
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode != 0 or not lines:
        raise SystemExit(f"allocators: the {mode} process failed (exit {done.returncode}):\n{done.stderr[-2000:]}")
    return json.loads(lines[-1])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vertices", type=int, default=1_000_000)
    parser.add_argument("--method", choices=("LINEAR", "DUAL_QUATERNION"), default="LINEAR")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--jemalloc", type=Path, help="jemalloc's shared library, preloaded in a third process")
    parser.add_argument("--child", choices=MODES, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.vertices < 1000 or args.rounds < 1:
        parser.error("--vertices must be at least 1000 and --rounds at least 1")
    if args.child:
        print(json.dumps(child(args.child, args.vertices, args.method, args.rounds)), flush=True)
        return 0
    if not sys.platform.startswith("linux"):
        parser.error("the allocators' comparison runs on Linux (glibc, /proc)")
    if args.jemalloc is not None and not args.jemalloc.is_file():
        parser.error(f"--jemalloc: no file {args.jemalloc}")
    modes = MODES if args.jemalloc is not None else MODES[:2]
    print(f"{args.vertices:,} vertices, {args.method}, {args.rounds} rounds a process")
    print("| Allocator | Armature modifier, ms a frame | DQ Skin | Ratio | Page faults a frame: Armature modifier / DQ Skin |")
    print("|---|---|---|---|---|")
    for mode in modes:  # (one process at a time)
        r = run_mode(mode, args)
        ratio = r["armature_ms"] / r["dq_skin_ms"]
        print(
            f"| {mode} | {r['armature_ms']:.2f} | {r['dq_skin_ms']:.2f} | {ratio:.2f}× | {r['armature_faults_per_frame']:.0f} / {r['dq_skin_faults_per_frame']:.0f} |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())

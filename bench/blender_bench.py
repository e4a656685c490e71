"""DQ Skin against Blender's Armature modifier, end to end, in one Blender session.

Every case builds the same scene several times, each object with its own copy of the mesh: with
the Armature modifier, without skinning, and with DQ Skin on the route it chooses and on each
route forced (`endtoend.routes`: the Mesh Cache carrier, the fed result object, the result
written after the first evaluation as before, and where Blender has them the Geometry Nodes
file-import nodes); on single characters also Blender's floors, and on them and the crowd the
chosen route with no Python of DQ Skin's per frame (`floor_route`). Only one of them is in the
depsgraph at a time; rounds alternate between them and each keeps its median. Every route is
checked to show DQ Skin's mesh before it is timed. The timing runs with glibc's allocator kept
from handing big blocks back to the system (`timing.steady_allocator`: without it a frame that
frees and allocates a large array page-faults afresh at random frames, whichever variant). A
benchmark, not a test: it prints a row per case and writes JSON (default:
target/bench-blender.json); docs/performance.md has the figures.

Cases (as in the issues): a 3k grid, CesiumMan, 200 CesiumMen (moving, and standing still), the
Rigify character holding its pose, grids of 250k and 1M vertices
(64 bones, 4 influences), 250k with Smooth and Corrective Smooth after the skinning modifier, a
100k grid on 16 B-Bones of 8 segments, the Rigify character of the tests (its skinning share:
each frame minus the rig alone's), Optimized Centers (precompute on the Rigify body and on a 52k
mesh, the update after a brush stroke), `dq_skin_add` to the first frame, a weight change, and
Rigify's Re-Generate Rig with DQ Skin characters on the rig; and the memory DQ Skin adds to 200
characters and to a million-vertex grid, each measured in a fresh process (`endtoend.memory`).

Usage: python bench/blender_bench.py [--out FILE] [--quick] [--only GROUP...]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
os.environ.setdefault("BLENDER_USER_RESOURCES", str(ROOT / ".blender_user"))

from endtoend import cases, memory  # noqa: E402
from endtoend.timing import ADDON, steady_allocator  # noqa: E402

import bpy  # noqa: E402  (after BLENDER_USER_RESOURCES)

import addon_utils  # noqa: E402  (importable once bpy is)

GROUPS = ("small", "cesium", "crowd", "still", "grid", "later", "bbones", "rigify", "centers", "binding", "weights", "regenerate", "memory")


def cpu_name() -> str:
    """The CPU's name, with its family and model where Linux gives them (a virtual machine's name
    may say only "AMD EPYC": the family and model tell its generation)."""
    fields = {}
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                key = key.strip()
                if key in ("model name", "cpu family", "model") and key not in fields:
                    fields[key] = value.strip()
                if not line.strip() and fields:
                    break  # (the first processor's block)
    except OSError:
        pass
    name = fields.get("model name") or platform.processor() or platform.machine()
    if "cpu family" in fields and "model" in fields:
        name += f" (family {fields['cpu family']}, model {fields['model']})"
    return name


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "target" / "bench-blender.json")
    parser.add_argument("--quick", action="store_true", help="smaller meshes, fewer rounds")
    parser.add_argument("--only", nargs="*", default=None, choices=GROUPS, metavar="GROUP", help=f"case groups: {', '.join(GROUPS)}")
    parser.add_argument("--memory-case", choices=sorted(memory.CASES), help=argparse.SUPPRESS)  # (run by the memory group)
    args = parser.parse_args()
    if addon_utils.enable(ADDON, default_set=True) is None:
        raise SystemExit("the DQ Skin extension is not installed: run make setup")
    if args.memory_case:
        print(json.dumps(memory.measure(args.memory_case)), flush=True)
        return 0
    steady = steady_allocator()  # (after the memory case: memory is measured as Blender allocates)
    only = set(args.only or GROUPS)
    q = args.quick
    big = [250_000] if q else [250_000, 1_000_000]
    rows = []

    def report(row):
        rows.append(row)
        print(json.dumps({k: (round(v, 3) if isinstance(v, float) else v) for k, v in row.items()}), flush=True)

    for method in ("LINEAR", "DUAL_QUATERNION"):
        if "small" in only:
            report(cases.case_grid(3_000, method, q))
        if "cesium" in only:
            report(cases.case_cesium(method, q))
        if "grid" in only:
            for n in big:
                report(cases.case_grid(n, method, q))
        if "rigify" in only:
            report(cases.case_rigify(method, q))
    if "crowd" in only:
        report(cases.case_crowd(50 if q else 200, q))
    if "still" in only:
        for row in cases.case_still(q):
            report(row)
    if "later" in only:
        for later in ("smooth5", "corrective5"):
            report(cases.case_grid(250_000, "DUAL_QUATERNION", q, later=later, routes_too=False))
        report(cases.case_crowd(50 if q else 200, q, later="corrective5"))
    if "bbones" in only:
        for method in ("LINEAR", "DUAL_QUATERNION"):
            report(cases.case_bbone_grid(100_000, method, q))
    if "centers" in only:
        for row in cases.case_centers(q):
            report(row)
    if "binding" in only:
        for n in big:
            report(cases.case_binding(n))
    if "weights" in only:
        report(cases.case_weights(250_000, q))
    if "regenerate" in only:
        report(cases.case_regenerate(q))
    if "memory" in only:
        for case in memory.CASES:
            report(memory.run_fresh(case))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    info = {"blender": bpy.app.version_string, "cpu": cpu_name(), "threads": os.cpu_count(), "steady_allocator": steady, "rows": rows}
    args.out.write_text(json.dumps(info, indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The tables of docs/performance.md, from the files `make bench` writes: the kernels
(target/bench-kernels.json, and target/bench-kernels-avx2.json on a CPU with AVX-512) and the
Blender benchmark (target/bench-blender.json). Prints Markdown; a missing file skips its tables.

Usage: python bench/report.py [--target DIR]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

ROUTES = ("cache", "node", "result", "import")
ROUTE_NAMES = {"cache": "Mesh Cache", "node": "result object", "result": "written after the frame", "handed over": "handed over"}
KERNELS = (
    ("LBS", "rigid", "Linear"),
    ("DQS", "rigid", "Dual Quaternion, rigid bones"),
    ("DQS", "scaled", "Dual Quaternion, scaled bones"),
    ("Blend", "rigid", "Blend"),
    ("CoR", "rigid", "Optimized Centers, rigid bones"),
    ("CoR", "scaled", "Optimized Centers, scaled bones"),
)


def ms(v) -> str:
    if v is None:
        return ""
    return f"{v:.3f}" if v < 1 else f"{v:.2f}" if v < 10 else f"{v:.1f}"


def ratio(v) -> str:
    return f"{v:.2f}×"


def mb(v) -> str:
    return f"{v / 1e6:.1f} MB"


def skinning_rows(rows: list) -> list:
    """The rows comparing frames with the Armature modifier (not the weight change's)."""
    return [r for r in rows if "armature_ms" in r and "speedup" in r]


def blender_table(rows: list) -> str:
    out = [
        "| Case, ms a frame | Armature modifier | No skinning | DQ Skin (route chosen) | Mesh Cache route | Result object route | Result written after the frame | Import PLY (prototype) | Frame, skinning share against the Armature modifier |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in skinning_rows(rows):
        route = ROUTE_NAMES.get(r["dq_skin_route"], r["dq_skin_route"])
        forced = [ms(r.get(f"route_{k}_ms")) for k in ROUTES]
        out.append(
            f"| {r['case']} | {ms(r['armature_ms'])} | {ms(r['none_ms'])} | {ms(r['dq_skin_ms'])} ({route}) | "
            + " | ".join(forced)
            + f" | {ratio(r['speedup'])}, {ratio(r['dq_skin_share_speedup'])} |"
        )
    return "\n".join(out)


def parts_table(rows: list) -> str:
    out = [
        "| Case, ms a frame | Armature's skinning share | Route with no Python of DQ Skin's (`floor_route`), above no skinning | The most that route allows: Armature modifier's frame ÷ `floor_route`'s | The most the route and the kernel as it ran allow, with no Python of DQ Skin's: Armature modifier's frame ÷ (`floor_route`'s + the kernel's) | Feed's driver: all (reading inputs; kernel; file) | Frame handler: all (checks) | Kernel alone, Linear / Dual Quaternion |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in skinning_rows(rows):
        if "dq_skin_fed_ms" not in r:
            continue
        floor = ms(r["floor_route_ms"] - r["none_ms"]) if "floor_route_ms" in r else ""
        ceiling = ratio(r["armature_ms"] / r["floor_route_ms"]) if "floor_route_ms" in r else ""
        # (What no amount of work on DQ Skin's Python could pass on this route and kernel.)
        kernel_ceiling = ratio(r["armature_ms"] / (r["floor_route_ms"] + r["dq_skin_kernel_ms"])) if "floor_route_ms" in r else ""
        alone = f"{ms(r['kernel_linear_ms'])} / {ms(r['kernel_dual_quaternion_ms'])}" if "kernel_linear_ms" in r else ""
        out.append(
            f"| {r['case']} | {ms(r['armature_share_ms'])} | {floor} | {ceiling} | {kernel_ceiling} | {ms(r['dq_skin_fed_ms'])} ({ms(r['dq_skin_fed_prepare_ms'])}; "
            f"{ms(r['dq_skin_kernel_ms'])}; {ms(r['dq_skin_file_ms'])}) | {ms(r['dq_skin_handler_ms'])} ({ms(r['dq_skin_handler_checks_ms'])}) | {alone} |"
        )
    return "\n".join(out)


def bound_table(rows: list, vertices_per_s: float) -> str:
    """The grids of 100k vertices and more: the most any kernel could reach on DQ Skin's route on
    this machine, the route's floor plus the kernel's bytes moved at the speed of the bandwidth
    reference (`vertices_per_s`: the kernels' benchmark, 4 influences as on the grids, from
    memory, every thread)."""
    out = [
        "| Case, ms a frame | Armature modifier | DQ Skin's route with no Python of DQ Skin's (`floor_route`) | A kernel moving its bytes at the bandwidth reference's speed | The most a kernel allows: Armature ÷ (floor + bytes) | DQ Skin | DQ Skin's share of that most |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in skinning_rows(rows):
        if not r["case"].startswith("grid") or r.get("later") or r.get("vertices", 0) < 100_000 or "floor_route_ms" not in r:
            continue
        bytes_ms = 1e3 * r["vertices"] / vertices_per_s
        most = r["armature_ms"] / (r["floor_route_ms"] + bytes_ms)
        reached = r["armature_ms"] / r["dq_skin_ms"]
        out.append(
            f"| {r['case']} | {ms(r['armature_ms'])} | {ms(r['floor_route_ms'])} | {ms(bytes_ms)} | {ratio(most)} | "
            f"{ms(r['dq_skin_ms'])} ({ratio(reached)}) | {100 * reached / most:.0f} % |"
        )
    return "\n".join(out)


def memory_speed(rows: list) -> float | None:
    """Vertices a second of the bandwidth reference from memory: the largest mesh, 4 influences,
    the most threads (the kernels' benchmark; the reference does no math, so any copy's file gives it)."""
    cases = [r for r in rows if r["influences"] == 4 and r["method"] == "LBS"]
    if not cases:
        return None
    r = max(cases, key=lambda r: (r["vertices"], r["threads"]))
    return r["vertices"] / r["reference_seconds"]


def floors_table(rows: list) -> str:
    out = [
        "| Case, ms a frame above no skinning | Armature modifier | Mesh Cache reading a fixed file (`floor_mesh_cache`) | The same, its driver calling Python (`floor_python_driver`) | Mesh Cache and DQ Skin's node group (`floor_carried`) | DQ Skin's route, no Python of DQ Skin's (`floor_route`) | DQ Skin |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in skinning_rows(rows):
        if "floor_mesh_cache_ms" not in r:
            continue
        above = [
            ms(r[k] - r["none_ms"])
            for k in ("armature_ms", "floor_mesh_cache_ms", "floor_python_driver_ms", "floor_carried_ms", "floor_route_ms", "dq_skin_ms")
        ]
        out.append(f"| {r['case']} | " + " | ".join(above) + " |")
    return "\n".join(out)


def memory_table(rows: list) -> str:
    out = [
        "| Case | Route | Payload | DQ Skin adds: median (range; each process's median) | Ratio | Of it file-backed (code paged in) | Held by DQ Skin: influences, rest positions copy, output buffers, point-cache files |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if not r.get("case", "").startswith("memory: "):
            continue
        lo, hi = r["resident_growth_range_bytes"]
        medians = ", ".join(f"{m / 1e6:.1f}" for m in r.get("resident_growth_process_medians_bytes", []))
        held = ", ".join(f"{r[f'held_{k}_bytes'] / 1e6:.2f}" for k in ("influences", "rest_copies", "output_buffers", "cache_files"))
        file_backed = mb(r["resident_file_growth_bytes"]) if "resident_file_growth_bytes" in r else "not measured"
        out.append(
            f"| {r['case'][len('memory: ') :]} | {ROUTE_NAMES.get(r['route'], r['route'])} | {mb(r['payload_bytes'])} | "
            f"{mb(r['extra_bytes'])} ({lo / 1e6:.1f}–{hi / 1e6:.1f}; {medians}) | **{ratio(r['extra_per_payload'])}** | {file_backed} | {held} MB |"
        )
    return "\n".join(out)


def other_rows(rows: list) -> str:
    out = []
    for r in rows:
        case = r.get("case", "")
        if case.startswith("Optimized Centers"):
            out.append(
                f"- {case}: precompute {r['precompute_s']:.2f} s, DQ Skin added to the first frame shown {r['add_and_first_frame_s']:.2f} s, "
                f"a weight stroke until it shows {r['stroke_update_s']:.2f} s mean, {r['stroke_update_max_s']:.2f} s worst ({len(r['stroke_vertices'])} strokes)"
            )
        elif case.startswith("still: "):
            out.append(
                f"- {case[len('still: ') :]}: a frame change {ms(r['armature_ms'])} ms with the Armature modifier, "
                f"{ms(r['dq_skin_ms'])} ms with DQ Skin (same mesh within {r['max_deviation']:.1e})"
            )
        elif case.startswith("dq_skin_add"):
            out.append(f"- {case}: {r['seconds']:.2f} s")
        elif case.startswith("weight change"):
            out.append(f"- {case}: Armature modifier {ms(r['armature_ms'])} ms, DQ Skin {ms(r['dq_skin_ms'])} ms")
        elif case.startswith("Rigify Re-Generate"):
            out.append(f"- {case}: {r['with_extension_s']:.1f} s with DQ Skin, {r['without_extension_s']:.1f} s without the extension")
    return "\n".join(out)


def kernel_table(copies: dict, vertices: int, influences: int) -> str:
    """Mverts/s and share of the bandwidth reference, per copy and thread count."""
    columns = [(copy, t) for t in (1, 2) for copy in copies]
    head = " | ".join(f"{copy.upper()}, {t} thread{'s' if t > 1 else ''}" for copy, t in columns)
    out = [f"| Kernel | {head} |", "|---|" + "---|" * len(columns)]

    def find(copy, t, method, pose):
        for r in copies[copy]:
            if (r["vertices"], r["influences"], r["threads"], r["method"], r["pose"]) == (vertices, influences, t, method, pose):
                return r
        return None

    for method, pose, name in KERNELS:
        cells = []
        for copy, t in columns:
            r = find(copy, t, method, pose)
            cells.append(f"{r['mverts_per_s']:.0f} ({100 * r['fraction_of_reference']:.0f} %)" if r else "")
        out.append(f"| {name} | " + " | ".join(cells) + " |")
    refs = []
    for copy, t in columns:
        plain, centers = find(copy, t, "LBS", "rigid"), find(copy, t, "CoR", "rigid")
        refs.append(
            f"{vertices / plain['reference_seconds'] / 1e6:.0f} ({vertices / centers['reference_seconds'] / 1e6:.0f})"
            if plain and centers
            else ""
        )
    out.append("| Bandwidth reference (with the centers) | " + " | ".join(refs) + " |")
    return "\n".join(out)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--target", default=str(Path(__file__).resolve().parent.parent / "target"))
    target = Path(parser.parse_args().target)
    copies = {}
    for name in ("bench-kernels.json", "bench-kernels-avx2.json"):
        path = target / name
        if path.exists():
            data = json.loads(path.read_text())
            copies[data["copy"]] = data["rows"]
            if data["copy"] == "chosen" and data.get("chosen"):  # (each variant's trial, per size of job: the "chosen" column)
                print(f"\nCopies the trials chose ({name}): " + ", ".join(f"{k} {v}" for k, v in data["chosen"].items()))
    if copies:
        sizes = sorted({(r["vertices"], r["influences"]) for rows in copies.values() for r in rows})
        for vertices, influences in sizes:
            print(f"\nKernels, {vertices:,} vertices, {influences} influences: Mverts/s (share of the bandwidth reference)\n")
            print(kernel_table(copies, vertices, influences))
    path = target / "bench-blender.json"
    if path.exists():
        data = json.loads(path.read_text())
        rows = data["rows"]
        print(f"\nBlender {data['blender']}, {data['cpu']}, {data['threads']} threads, steady allocator: {data['steady_allocator']}\n")
        for table in (blender_table, parts_table, floors_table, memory_table, other_rows):
            print(table(rows) + "\n")
        speed = memory_speed(copies[next(iter(copies))]) if copies else None
        if speed is not None:
            print(f"Large grids against this machine's memory ({speed / 1e6:.0f} Mverts/s):\n")
            print(bound_table(rows, speed) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

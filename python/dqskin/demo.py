"""The demo comparison: twist a two-bone cylinder and see how much volume each method keeps.

Run with ``python -m dqskin.demo`` (``make demo``). Linear blend skinning collapses the middle
of the cylinder as the twist grows (the "candy wrapper"); dual quaternion skinning keeps it.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

import dqskin

METHODS = (
    ("linear", {}),
    ("dual_quaternion", {}),
    ("blend", {"blend_factor": 0.5}),
)


def run(angles_deg: list[float], rings: int, segments: int) -> list[dict]:
    cyl = dqskin.TwistCylinder(rings=rings, segments=segments)
    rest_positions = cyl.positions
    triangles = cyl.triangles
    influences, rest = cyl.influences, cyl.rest
    middle = cyl.ring(cyl.rings // 2)
    rest_volume = dqskin.mesh_volume(rest_positions, triangles)
    rest_area = dqskin.polygon_area(rest_positions[middle])
    out = np.empty_like(rest_positions)
    rows = []
    for angle in angles_deg:
        deform = cyl.twist(math.radians(angle))
        row = {"twist_deg": angle}
        for name, extra in METHODS:
            dqskin.skin(rest_positions, influences, deform, rest, method=name, out=out, **extra)
            row[name] = {
                "volume": dqskin.mesh_volume(out, triangles) / rest_volume,
                "middle_area": dqskin.polygon_area(out[middle]) / rest_area,
            }
        rows.append(row)
    return rows


def timing(vertices: int) -> dict[str, float]:
    """Per-frame time of each method on a denser cylinder of about ``vertices`` vertices."""
    segments = 256
    rings = max(2, vertices // segments)
    cyl = dqskin.TwistCylinder(rings=rings, segments=segments)
    positions, influences, rest = cyl.positions, cyl.influences, cyl.rest
    deform = cyl.twist(math.radians(120))
    out = np.empty_like(positions)
    result = {"vertices": float(len(positions))}
    for name, extra in METHODS:
        dqskin.skin(positions, influences, deform, rest, method=name, out=out, **extra)
        runs = []
        for _ in range(7):
            start = time.perf_counter()
            dqskin.skin(positions, influences, deform, rest, method=name, out=out, **extra)
            runs.append(time.perf_counter() - start)
        result[name] = sorted(runs)[len(runs) // 2]
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rings", type=int, default=33)
    parser.add_argument("--segments", type=int, default=48)
    parser.add_argument("--timing-vertices", type=int, default=1_000_000)
    args = parser.parse_args(argv)

    angles = [0, 45, 90, 135, 150, 170, 180]
    print(f"dqskin {dqskin.__version__}: two-bone cylinder twisted about its axis ({args.rings} rings x {args.segments} segments)")
    print("Volume and middle cross-section kept, relative to rest:")
    header = f"{'twist':>6} | {'linear (LBS)':>19} | {'dual quaternion':>19} | {'blend 50%':>19}"
    print(header)
    print(f"{'':>6} | {'volume':>9} {'area':>9} | {'volume':>9} {'area':>9} | {'volume':>9} {'area':>9}")
    print("-" * len(header))
    for row in run(angles, args.rings, args.segments):
        cells = " | ".join(f"{row[m]['volume']:>9.3f} {row[m]['middle_area']:>9.3f}" for m, _ in METHODS)
        print(f"{row['twist_deg']:>5.0f}° | {cells}")

    t = timing(args.timing_vertices)
    print(f"\nPer-frame time on {int(t['vertices']):,} vertices, {dqskin.get_num_threads()} threads:")
    for name, _ in METHODS:
        print(f"  {name:<16} {t[name] * 1e3:8.2f} ms  ({t['vertices'] / t[name] / 1e6:7.1f} Mverts/s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

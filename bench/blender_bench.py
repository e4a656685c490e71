"""Per-frame cost of Blender's Armature modifier and of DQ Skin, in one Blender session on the
same meshes: CesiumMan subdivided to about 50k and 250k vertices, and a 1M-vertex synthetic rig.

For each mesh and method it measures
- end to end: a frame change (the pose changes) until the evaluated mesh is there, the
  depsgraph evaluation, DQ Skin's handler and its Geometry Nodes pass included;
- the kernel alone: one `dqskin.skin` call on the same inputs.
Writes the figures as JSON (default: target/bench-blender.json). A benchmark, not a test.

Usage: python bench/blender_bench.py [--out FILE] [--quick]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
os.environ.setdefault("BLENDER_USER_RESOURCES", str(ROOT / ".blender_user"))
sys.path.insert(0, str(ROOT / "tests" / "blender"))

import bpy  # noqa: E402  (after BLENDER_USER_RESOURCES)
import addon_utils  # noqa: E402  (importable once bpy is)


def evaluated(obj):
    dg = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(dg)
    return len(ev.data.vertices)


def subdivide_to(obj, target: int) -> None:
    """One subdivision with as many cuts as bring the mesh closest to `target` vertices (each cut
    level multiplies the faces by (cuts + 1)²)."""
    cuts = max(1, round((target / len(obj.data.vertices)) ** 0.5) - 1)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.mesh.subdivide(number_cuts=cuts)
    bpy.ops.object.mode_set(mode="OBJECT")


def cesium_man(target: int):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.import_scene.gltf(filepath=str(ROOT.parent / "shared" / "assets" / "CesiumMan.glb"))
    obj = next(o for o in bpy.data.objects if o.type == "MESH" and any(m.type == "ARMATURE" for m in o.modifiers))
    subdivide_to(obj, target)
    return obj, [2, 20]


def synthetic(target: int):
    from scenes import rig_tube

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    segments = 256
    obj, arm, mod = rig_tube(rings=max(2, target // segments), segments=segments, length=8.0, bones=16)
    for i, pb in enumerate(arm.pose.bones):
        pb.rotation_quaternion = (1, 0, 0, 0)
        pb.keyframe_insert("rotation_quaternion", frame=1)
        pb.rotation_quaternion = (0.9, 0.1 * (i % 3), 0.3, 0.1)
        pb.keyframe_insert("rotation_quaternion", frame=20)
    return obj, [2, 19]


def per_frame(frames, obj, runs: int) -> float:
    scene = bpy.context.scene
    times = []
    for k in range(runs + 1):
        f = frames[k % 2]
        start = time.perf_counter()
        scene.frame_set(f)
        evaluated(obj)
        if k:
            times.append(time.perf_counter() - start)
    return float(np.median(times))


def measure(name: str, obj, frames, runs: int, dq_skin) -> dict:
    arm_mod = next(m for m in obj.modifiers if m.type == "ARMATURE")
    row = {"mesh": name, "vertices": len(obj.data.vertices)}
    for pv in (False, True):
        arm_mod.use_deform_preserve_volume = pv
        row[f"armature_{'dqs' if pv else 'lbs'}_ms"] = 1e3 * per_frame(frames, obj, runs)
    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(object=obj, active_object=obj):
        bpy.ops.object.dq_skin_add(method="LINEAR")
    mod = next(m for m in obj.modifiers if m.type == "NODES")
    from bl_ext.user_default.dq_skin import nodes, operators, rig

    for method, item in (("lbs", "Linear"), ("dqs", "Dual Quaternion")):
        operators.set_input(mod, "Method", operators.menu_value(mod.node_group, item))
        bpy.context.scene.frame_set(frames[0])
        row[f"dq_skin_{method}_ms"] = 1e3 * per_frame(frames, obj, runs)
        # The kernel alone, on what the modifier used.
        st = dq_skin.modifier.state(obj, mod)
        assert not st.error, st.error
        positions = rig.mesh_positions(obj.data)
        arm = mod[nodes.socket_ids(mod.node_group)["Armature"]]
        matrices = rig.frame(st.binding, obj, arm)
        out = np.empty_like(positions)
        kernel = []
        for _ in range(runs):
            start = time.perf_counter()
            rig.skin(st.binding, obj, arm, positions, {"lbs": "linear", "dqs": "dual_quaternion"}[method], out=out, matrices=matrices)
            kernel.append(time.perf_counter() - start)
        row[f"kernel_{method}_ms"] = 1e3 * float(np.median(kernel))
    for method in ("lbs", "dqs"):
        row[f"ratio_{method}"] = row[f"dq_skin_{method}_ms"] / row[f"armature_{method}_ms"]
    return row


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "target" / "bench-blender.json")
    parser.add_argument("--quick", action="store_true", help="smaller meshes, fewer runs")
    args = parser.parse_args()
    dq_skin = addon_utils.enable("bl_ext.user_default.dq_skin", default_set=True)
    if dq_skin is None:
        raise SystemExit("the DQ Skin extension is not installed: run make setup")
    runs = 5 if args.quick else 15
    cases = [("CesiumMan 50k", lambda: cesium_man(50_000)), ("CesiumMan 250k", lambda: cesium_man(250_000)), ("synthetic 1M", lambda: synthetic(1_000_000))]
    if args.quick:
        cases = [("CesiumMan 50k", lambda: cesium_man(50_000))]
    rows = []
    print(f"{'mesh':<16} {'verts':>9} | {'Armature LBS':>12} {'DQ Skin LBS':>12} {'ratio':>6} | {'Armature DQS':>12} {'DQ Skin DQS':>12} {'ratio':>6} | {'kernel LBS':>10} {'kernel DQS':>10}")
    for name, build in cases:
        obj, frames = build()
        row = measure(name, obj, frames, runs, dq_skin)
        rows.append(row)
        print(
            f"{name:<16} {row['vertices']:>9} | {row['armature_lbs_ms']:>10.2f}ms {row['dq_skin_lbs_ms']:>10.2f}ms {row['ratio_lbs']:>6.2f} | "
            f"{row['armature_dqs_ms']:>10.2f}ms {row['dq_skin_dqs_ms']:>10.2f}ms {row['ratio_dqs']:>6.2f} | "
            f"{row['kernel_lbs_ms']:>8.2f}ms {row['kernel_dqs_ms']:>8.2f}ms"
        )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"blender": bpy.app.version_string, "threads": os.cpu_count(), "rows": rows}, indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The Blender part of `make demo`: CesiumMan with DQ Skin in place of its Armature modifier.

Imports CesiumMan, replaces its Armature modifier with DQ Skin (installed in `.blender_user/`),
plays the animation headless, and prints for each method the largest deviation from Blender's
own Armature modifier over all frames and the per-frame time of both.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
os.environ.setdefault("BLENDER_USER_RESOURCES", str(ROOT / ".blender_user"))

import bpy  # noqa: E402  (after BLENDER_USER_RESOURCES)

import addon_utils  # noqa: E402

ASSET = ROOT.parent / "shared" / "assets" / "CesiumMan.glb"


def positions(obj) -> np.ndarray:
    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    flat = np.empty(len(ev.data.vertices) * 3, np.float32)
    ev.data.attributes["position"].data.foreach_get("vector", flat)
    return flat.reshape(-1, 3)


def play(obj, frames) -> tuple[list[np.ndarray], float]:
    """Evaluated positions at each frame, and the median time of a frame change."""
    scene = bpy.context.scene
    out, times = [], []
    for f in frames:
        start = time.perf_counter()
        scene.frame_set(f)
        result = positions(obj)
        times.append(time.perf_counter() - start)
        out.append(result)
    return out, float(np.median(times))


def main() -> int:
    if addon_utils.enable("bl_ext.user_default.dq_skin", default_set=True) is None:
        raise SystemExit("DQ Skin is not installed in .blender_user: run make setup")
    if not ASSET.is_file():
        raise SystemExit(f"missing {ASSET}")
    from bl_ext.user_default.dq_skin.ops.modifiers import set_input

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.import_scene.gltf(filepath=str(ASSET))
    obj = next(o for o in bpy.data.objects if o.type == "MESH" and any(m.type == "ARMATURE" for m in o.modifiers))
    arm_mod = next(m for m in obj.modifiers if m.type == "ARMATURE")
    action = arm_mod.object.animation_data.action
    frames = list(range(int(action.frame_range[0]), int(action.frame_range[1]) + 1))

    # The built-in modifier's results first (same object, same frames).
    reference = {}
    for method, pv in (("Linear", False), ("Dual Quaternion", True)):
        arm_mod.use_deform_preserve_volume = pv
        reference[method] = play(obj, frames)

    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(object=obj, active_object=obj):
        bpy.ops.object.dq_skin_add(method="LINEAR")
    mod = next(m for m in obj.modifiers if m.type == "NODES")
    print(f"DQ Skin on {obj.name} ({len(obj.data.vertices)} vertices), {len(frames)} frames of {action.name}:")
    print(f"{'method':<16} {'max deviation':>14} {'of diagonal':>12} {'Armature':>10} {'DQ Skin':>10}")
    for method in ("Linear", "Dual Quaternion"):
        set_input(mod, "Method", method)
        ours, ours_time = play(obj, frames)
        theirs, theirs_time = reference[method]
        dev = max(float(np.abs(a - b).max()) for a, b in zip(ours, theirs))
        diag = max(float(np.linalg.norm(b.max(0) - b.min(0))) for b in theirs)
        print(f"{method:<16} {dev:>14.3e} {dev / diag:>12.2e} {theirs_time * 1e3:>8.2f}ms {ours_time * 1e3:>8.2f}ms")
    return 0


if __name__ == "__main__":
    code = main()
    # The bpy module frees the file's data from a C exit hook after Python has finalized, which on
    # Blender 4.2 crashes on DQ Skin's Python driver: end once everything is printed (as the tests'
    # `blender` stand-ins do).
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)

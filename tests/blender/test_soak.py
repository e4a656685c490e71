"""A soak: 10,000 frames of CesiumMan under DQ Skin, saved and reloaded every 1,000 frames.
Memory must stay flat, nothing the add-on makes may be left orphaned, and at the end the
character must still match Blender's Armature modifier."""

from __future__ import annotations

import gc
import os
from pathlib import Path

import pytest
from conftest import ASSETS
from dqtest import REL_TOL, action_frames, add_dq_skin, deviation, evaluated_positions, import_character, is_carrier, plain_twin

import bpy

FRAMES = 10_000
RELOAD_EVERY = 1_000
GROWTH_LIMIT = 5 * 2**20  # bytes of resident memory, from the first reload to the end


def resident_bytes() -> int:
    statm = Path("/proc/self/statm")
    if not statm.exists():
        pytest.skip("resident memory is read from /proc (Linux)")
    return int(statm.read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def our_outputs() -> list:
    """Where DQ Skin's positions go: result objects and carriers (one for the one character)."""
    results = [o.name for o in bpy.data.objects if o.get("dq_skin_result")]
    return results + [f"{o.name}: {m.name}" for o in bpy.data.objects for m in getattr(o, "modifiers", ()) if is_carrier(m)]


def orphans() -> list[str]:
    """Meshes and objects nobody uses: what a leaking result swap would leave behind."""
    return [d.name for d in (*bpy.data.meshes, *bpy.data.objects) if d.users == 0]


@pytest.mark.slow
def test_ten_thousand_frames_with_reloads(dq_skin, tmp_path):
    obj, _ = import_character(ASSETS / "CesiumMan.glb")
    add_dq_skin(obj, method="DUAL_QUATERNION")
    name = obj.name  # objects are new Python objects after each reload
    arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
    frames = list(action_frames(arm.animation_data.action))
    assert len(frames) > 20  # every soak frame must move the character
    path = tmp_path / "soak.blend"
    scene = bpy.context.scene
    baseline = None
    for i in range(FRAMES):
        scene.frame_set(frames[i % len(frames)])
        if (i + 1) % RELOAD_EVERY:
            continue
        assert not orphans(), f"after {i + 1} frames: {orphans()}"
        assert len(our_outputs()) == 1, our_outputs()
        bpy.ops.wm.save_as_mainfile(filepath=str(path))
        bpy.ops.wm.open_mainfile(filepath=str(path))
        scene = bpy.context.scene
        gc.collect()
        if baseline is None:  # the first reload warms every cache: measure growth from here
            baseline = resident_bytes()
    growth = resident_bytes() - baseline
    assert growth < GROWTH_LIMIT, f"resident memory grew {growth / 2**20:.1f} MB over {FRAMES} frames"

    obj = bpy.data.objects[name]
    reference = plain_twin(obj)
    worst = 0.0
    for frame in frames[:: max(1, len(frames) // 8)]:
        scene.frame_set(frame)
        worst = max(worst, deviation(evaluated_positions(obj), evaluated_positions(reference)))
    assert len(our_outputs()) == 1 and not orphans()
    assert len(dq_skin.SESSION.tracker.records) == 1
    assert worst <= REL_TOL, f"{worst:.3e} of the diagonal from the Armature modifier after the soak"
    print(f"\nsoak: {FRAMES} frames, resident growth {growth / 2**20:.2f} MB, deviation {worst:.2e}")

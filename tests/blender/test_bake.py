"""Baking DQ Skin to a PC2 cache played by Blender's Mesh Cache modifier."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from dqtest import add_dq_skin, assert_fed, evaluated_positions, import_character
from scenes import RIGS, make_rig

import bpy

PLAYBACK_TOL = 1e-6  # of the bounding-box diagonal: float32 positions stored and read back


@pytest.mark.parametrize("rig", RIGS)
def test_mesh_cache_playback_reproduces_the_live_result(dq_skin, assets, tmp_path, rig):
    from bl_ext.user_default.dq_skin.dqskin import pc2

    obj, arm_mod = import_character(assets / "CesiumMan.glb")
    make_rig(arm_mod.object, rig)  # B-Bones: the feed skins the live frames, the bake's own steps run the handler
    mod = add_dq_skin(obj, "DUAL_QUATERNION")
    if rig != "vertex groups":
        assert_fed(dq_skin, obj)
    action = arm_mod.object.animation_data.action
    start, end = (int(round(f)) for f in action.frame_range)
    scene = bpy.context.scene
    live = {}
    for f in range(start, end + 1):
        scene.frame_set(f)
        live[f] = evaluated_positions(obj)
    path = tmp_path / "cesium.pc2"
    with bpy.context.temp_override(object=obj, active_object=obj):
        result = bpy.ops.object.dq_skin_bake(filepath=str(path), frame_start=start, frame_end=end)
    assert result == {"FINISHED"}
    header = pc2.read_header(path)
    assert (header.points, header.start_frame, header.sample_rate, header.samples) == (len(obj.data.vertices), start, 1.0, end - start + 1)
    assert not mod.show_viewport and not mod.show_render
    cache = obj.modifiers["DQ Skin Cache"]
    assert cache.type == "MESH_CACHE" and list(obj.modifiers).index(cache) == list(obj.modifiers).index(mod) + 1
    worst = 0.0
    for f in list(range(start, end + 1))[::-1]:  # backwards too
        scene.frame_set(f)
        played = evaluated_positions(obj)
        diag = float(np.linalg.norm(live[f].max(0) - live[f].min(0)))
        worst = max(worst, float(np.abs(played - live[f]).max()) / diag)
    assert worst <= PLAYBACK_TOL, worst
    # Where the add-on is not installed (a render farm), the saved file plays the cache alone:
    # DQ Skin is off and so is its companion Armature modifier.
    mid = (start + end) // 2
    blend = tmp_path / "baked.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), copy=True)
    np.save(tmp_path / "expected.npy", live[mid])
    script = tmp_path / "farm.py"
    script.write_text(
        "import sys, bpy, numpy as np\n"
        f"bpy.ops.wm.open_mainfile(filepath={str(blend)!r})\n"
        f"bpy.context.scene.frame_set({mid})\n"
        f"o = bpy.data.objects[{obj.name!r}]\n"
        "m = o.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()\n"
        "a = np.empty(len(m.vertices) * 3, np.float32); m.vertices.foreach_get('co', a)\n"
        f"e = np.load({str(tmp_path / 'expected.npy')!r})\n"
        "print('DEV', float(np.abs(a.reshape(-1, 3) - e).max() / np.linalg.norm(e.max(0) - e.min(0))))\n"
    )
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "farm_user"))
    (tmp_path / "farm_user").mkdir()
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, env=env)
    dev = float(next(line.split()[1] for line in r.stdout.splitlines() if line.startswith("DEV")))
    assert dev <= PLAYBACK_TOL * 2, dev


def test_failed_bake_writes_nothing(dq_skin, tmp_path):
    from scenes import rig_tube

    obj, arm, arm_mod = rig_tube()
    mod = add_dq_skin(obj)
    arm_obj = arm
    bpy.context.view_layer.objects.active = arm_obj
    bpy.ops.object.mode_set(mode="EDIT")  # DQ Skin reports an error on every frame
    path = tmp_path / "never.pc2"
    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(object=obj, active_object=obj):
        with pytest.raises(RuntimeError, match="Bake failed, nothing written"):
            bpy.ops.object.dq_skin_bake(filepath=str(path), frame_start=1, frame_end=5)
    assert not path.exists()
    assert not list(tmp_path.iterdir())  # no temporary file left either
    assert "DQ Skin Cache" not in obj.modifiers
    assert mod.show_viewport


def test_bake_needs_a_dq_skin_modifier(dq_skin, tmp_path):
    from scenes import rig_tube

    obj, arm, arm_mod = rig_tube()
    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(object=obj, active_object=obj):
        with pytest.raises(RuntimeError, match="has no DQ Skin modifier"):
            bpy.ops.object.dq_skin_bake(filepath=str(tmp_path / "x.pc2"))

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


def two_armature_tube():
    """A tube deformed by two armatures (the lower half by one, the upper by the other), each
    replaced by its own DQ Skin: two DQ Skin modifiers, the second skinning the first's result."""
    from dqtest import animate
    from scenes import armature_chain, rig_tube

    obj, arm, mod = rig_tube(bones=2)
    arm2 = armature_chain("Rig2", 2, 4.0)
    for a, seed in ((arm, 0.0), (arm2, 0.9)):
        animate(a, seed)
    upper = obj.vertex_groups.new(name="Upper")
    for v in obj.data.vertices:
        upper.add([v.index], min(1.0, max(0.0, (v.co.z - 1.5) / 1.0)), "REPLACE")
    mod.vertex_group, mod.invert_vertex_group = "Upper", True
    second = obj.modifiers.new("Armature.001", "ARMATURE")
    second.object, second.vertex_group = arm2, "Upper"
    add_dq_skin(obj, "DUAL_QUATERNION")
    add_dq_skin(obj, "BLEND")
    return obj


def live_frames(obj, frames) -> dict:
    out = {}
    for f in frames:
        bpy.context.scene.frame_set(f)
        out[f] = evaluated_positions(obj)
    return out


def assert_plays(obj, live: dict) -> None:
    for f, expected in live.items():
        bpy.context.scene.frame_set(f)
        diag = float(np.linalg.norm(expected.max(0) - expected.min(0)))
        assert float(np.abs(evaluated_positions(obj) - expected).max()) / diag <= PLAYBACK_TOL, f"frame {f}"


def test_every_dq_skin_modifier_is_baked(dq_skin, tmp_path):
    """An object with two DQ Skins: the cache holds the full result (after the last DQ Skin),
    plays right after it, and every DQ Skin (with its companion) is off, so the baked file plays
    the same where the add-on is not installed."""
    obj = two_armature_tube()
    dq_mods = [m for m in obj.modifiers if m.name.startswith("DQ Skin") and m.type == "NODES"]
    assert len(dq_mods) == 2
    smooth = obj.modifiers.new("Smooth", "SMOOTH")  # after every DQ Skin: muted while baking only
    smooth.show_viewport = False
    live = live_frames(obj, range(1, 21))
    smooth.show_viewport = True
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.object.dq_skin_bake(filepath=str(tmp_path / "two.pc2"), frame_start=1, frame_end=20) == {"FINISHED"}
    names = [m.name for m in obj.modifiers]
    assert names.index("DQ Skin Cache") == names.index(dq_mods[-1].name) + 1
    for m in dq_mods:
        assert not m.show_viewport and not m.show_render, m.name
    for m in obj.modifiers:
        if m.type == "ARMATURE":
            assert not m.show_viewport and not m.show_render, f"{m.name}: a companion still deforms"
    assert smooth.show_viewport
    smooth.show_viewport = False
    assert_plays(obj, live)


def test_default_files_are_one_per_object_and_never_overwrite_others(dq_skin, tmp_path):
    """Without a file named, each object bakes to `<blend>_<object>.pc2` beside the blend file;
    two objects whose names clean up the same, or a file already there that is not the object's
    own bake, get a new name. Baking an object again writes its own file again."""
    from scenes import rig_tube

    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "shot.blend"))
    first, arm1, _ = rig_tube()
    first.name = "Body.L"
    second, arm2, _ = rig_tube()
    second.name = "Body_L"
    for obj, seed in ((first, 0.0), (second, 1.1)):
        from dqtest import animate

        animate(obj.modifiers["Armature"].object, seed)
        add_dq_skin(obj, "DUAL_QUATERNION")
    stranger = tmp_path / "shot_Body_L_2.pc2"
    stranger.write_bytes(b"not ours")
    live_first = live_frames(first, (4, 12))
    live_second = live_frames(second, (4, 12))
    played = {}
    for obj in (first, second):
        bpy.context.view_layer.objects.active = obj
        with bpy.context.temp_override(object=obj, active_object=obj):
            assert bpy.ops.object.dq_skin_bake(frame_start=1, frame_end=20) == {"FINISHED"}
        played[obj.name] = obj.modifiers["DQ Skin Cache"].filepath
    assert played == {"Body.L": "//shot_Body_L.pc2", "Body_L": "//shot_Body_L_3.pc2"}
    assert stranger.read_bytes() == b"not ours"
    assert_plays(first, live_first)
    assert_plays(second, live_second)
    # Again: the object's own bake is its default file.
    assert dq_skin.ops.bake.default_path(first) == "//shot_Body_L.pc2"
    # A duplicate plays the original's file: neither bakes over it by default any more.
    twin = first.copy()
    bpy.context.scene.collection.objects.link(twin)
    assert twin.modifiers["DQ Skin Cache"].filepath == "//shot_Body_L.pc2"
    assert dq_skin.ops.bake.default_path(first) == "//shot_Body_L_4.pc2"
    assert dq_skin.ops.bake.default_path(twin) == "//shot_Body_L_001.pc2"  # Body.L.001
    bpy.data.objects.remove(twin)
    third, _, _ = rig_tube()
    third.name = "Body L"
    assert dq_skin.ops.bake.default_path(third) == "//shot_Body_L_4.pc2"


def test_esc_cancels_the_modal_bake_leaving_nothing(dq_skin, tmp_path, monkeypatch):
    """The panel's bake runs modal: each timer event bakes frames for a moment (progress on the
    window manager), Esc goes through the operator's cancel: the temporary file is removed and
    nothing else is left changed. Run to its end, the same steps give the cache."""
    from types import SimpleNamespace

    from dqtest import animated_tube

    bake_module = dq_skin.ops.bake
    monkeypatch.setattr(bake_module, "STEP_SECONDS", 0.0)  # one frame per timer event
    op_class = bake_module.OBJECT_OT_dq_skin_bake
    obj, arm, _ = animated_tube()
    mod = add_dq_skin(obj, "DUAL_QUATERNION")
    smooth = obj.modifiers.new("Smooth", "SMOOTH")
    bpy.context.scene.frame_set(7)
    before = [(m.name, m.type, m.show_viewport, m.show_render) for m in obj.modifiers]
    timer = SimpleNamespace(type="TIMER", value="NOTHING")
    esc = SimpleNamespace(type="ESC", value="PRESS")

    class Run:
        """The operator's own modal and cancel methods, on a stand-in for the instance Blender
        makes (headless tests have no window to add a modal handler to)."""

        modal, cancel, _end_modal, _done = op_class.modal, op_class.cancel, op_class._end_modal, op_class._done
        disable_dq_skin = True
        _timer = None

        def __init__(self, path):
            self.reports = []
            self._baking = bake_module.Baking(bpy.context, obj, path, 1, 20)
            self._baking.start()

        def report(self, kind, text):
            self.reports.append((set(kind), text))

    run = Run(tmp_path / "cancelled.pc2")
    assert not smooth.show_viewport  # muted while baking
    for _ in range(3):
        assert run.modal(bpy.context, timer) == {"RUNNING_MODAL"}
    assert run._baking.frame == 4
    assert list(tmp_path.iterdir())  # the temporary file
    assert run.modal(bpy.context, esc) == {"CANCELLED"}
    assert run.reports == [({"WARNING"}, f"Bake of {obj.name} cancelled, nothing written")]
    assert not list(tmp_path.iterdir())
    assert [(m.name, m.type, m.show_viewport, m.show_render) for m in obj.modifiers] == before
    assert bpy.context.scene.frame_current == 7 and mod.show_viewport
    # Other events are swallowed; timer events bake to the end.
    run = Run(tmp_path / "done.pc2")
    assert run.modal(bpy.context, SimpleNamespace(type="MOUSEMOVE", value="NOTHING")) == {"RUNNING_MODAL"}
    results = [run.modal(bpy.context, timer) for _ in range(20)]
    assert results == [{"RUNNING_MODAL"}] * 19 + [{"FINISHED"}]
    assert [p.name for p in tmp_path.iterdir()] == ["done.pc2"]
    assert obj.modifiers["DQ Skin Cache"].filepath == str(tmp_path / "done.pc2") and not mod.show_viewport
    assert smooth.show_viewport and bpy.context.scene.frame_current == 7

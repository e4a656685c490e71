"""`preflight FILE` before a render farm: the objects that would render differently on a node
without the DQ Skin extension are named (exit code 3), and none is when every object would
render the same (0); checked against what a Blender without the extension really shows, and
through both entry points. The panel of such a modifier says so and how to render it anywhere."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from dqtest import add_dq_skin, draw_panel, evaluated_positions, import_character
from test_cli import both

import bpy

FRAME = 17


def save_character(dq_skin, assets, path, method: str, setup=None) -> np.ndarray:
    """CesiumMan with DQ Skin's `method` (and `setup(obj, mod)`) saved to `path`; returns what it
    shows at FRAME here, with the extension."""
    body, _ = import_character(assets / "CesiumMan.glb")
    mod = add_dq_skin(body, method)
    if setup is not None:
        setup(body, mod)
    bpy.context.scene.frame_set(FRAME)
    here = evaluated_positions(body)
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    return here


def without_the_extension(path, tmp_path) -> np.ndarray:
    """What the saved file shows at FRAME in a Blender without the extension."""
    empty = tmp_path / "no-extension"
    empty.mkdir(exist_ok=True)
    out = tmp_path / "elsewhere.npy"
    script = (
        "import bpy, numpy as np\n"
        f"bpy.ops.wm.open_mainfile(filepath={str(path)!r})\n"
        f"bpy.context.scene.frame_set({FRAME})\n"
        "o = bpy.data.objects['Cesium_Man']\n"
        "ev = o.evaluated_get(bpy.context.evaluated_depsgraph_get())\n"
        "co = np.empty(len(ev.data.vertices) * 3, np.float32)\n"
        "ev.data.attributes['position'].data.foreach_get('vector', co)\n"
        f"np.save({str(out)!r}, co.reshape(-1, 3))\n"
        "import os; os._exit(0)\n"
    )
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(empty))
    r = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return np.load(out)


def _size(p: np.ndarray) -> float:
    return float(np.linalg.norm(np.ptp(p, axis=0)))


def _blend_painted(obj, mod):
    from bl_ext.user_default.dq_skin.ops.modifiers import set_attribute

    g = obj.vertex_groups.new(name="Blend")
    g.add(list(range(0, len(obj.data.vertices), 2)), 0.25, "REPLACE")
    set_attribute(mod, "Blend Amount", "Blend")


def _baked(tmp_path):
    def setup(obj, mod):
        with bpy.context.temp_override(object=obj, active_object=obj):
            assert bpy.ops.object.dq_skin_bake(filepath=str(tmp_path / "body.pc2"), frame_start=1, frame_end=30) == {"FINISHED"}

    return setup


CASES = {
    # name: (method, setup, renders differently elsewhere)
    "Linear": ("LINEAR", None, False),
    "Dual Quaternion": ("DUAL_QUATERNION", None, False),
    "Blend with its defaults (all Dual Quaternion)": ("BLEND", None, False),
    "Blend painted": ("BLEND", _blend_painted, True),
    "Optimized Centers": ("CENTERS_OF_ROTATION", None, True),
    "Optimized Centers baked": ("CENTERS_OF_ROTATION", "baked", False),
}


@pytest.mark.parametrize("case", list(CASES))
def test_preflight_names_what_renders_differently_without_the_extension(dq_skin, assets, tmp_path, case):
    from test_cli import run

    method, setup, differs = CASES[case]
    if setup == "baked":
        setup = _baked(tmp_path)
    path = tmp_path / "shot.blend"
    here = save_character(dq_skin, assets, path, method, setup)
    # What the panel says (with the extension) before the file goes to the farm.
    bpy.ops.wm.open_mainfile(filepath=str(path))
    bpy.context.scene.frame_set(FRAME)
    lines = [line for line in draw_panel(dq_skin, bpy.data.objects["Cesium_Man"]) if "Without the DQ Skin extension" in line]
    assert bool(lines) == differs, lines
    assert all("bake it" in line for line in lines), lines
    elsewhere = without_the_extension(path, tmp_path)
    really_differs = float(np.abs(elsewhere - here).max()) / _size(here) > 1e-5
    assert really_differs == differs, f"without the extension it {'differs' if really_differs else 'is the same'}"
    r = run("preflight", str(path))
    if differs:
        assert r.returncode == 3, (r.returncode, r.stdout, r.stderr)
        assert "Cesium_Man" in r.stdout and "Preserve Volume" in r.stdout, r.stdout
    else:
        assert r.returncode == 0, (r.returncode, r.stdout, r.stderr)
        assert "renders the same" in r.stdout


@both
def test_preflight_through_both_entry_points_and_a_missing_bake(run, dq_skin, assets, tmp_path):
    path = tmp_path / "shot.blend"
    save_character(dq_skin, assets, path, "CENTERS_OF_ROTATION", _baked(tmp_path))
    r = run("preflight", str(path))
    assert r.returncode == 0, (r.stdout, r.stderr)
    (tmp_path / "body.pc2").unlink()  # the bake's file did not reach the farm
    r = run("preflight", str(path))
    assert r.returncode == 3 and "missing" in r.stdout, (r.stdout, r.stderr)
    r = run("preflight", str(tmp_path / "nothing.blend"))
    assert r.returncode == 1 and "no such file" in r.stderr


def test_preflight_needs_a_file(dq_skin):
    from test_cli import run

    r = run("preflight")
    assert r.returncode == 2 and "file" in r.stderr

"""The batch command line and the add-on under faults: corrupt inputs, unwritable outputs, real
signals (Ctrl-C, SIGTERM, SIGKILL) in the middle of long commands, an empty mesh, renames."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import ASSETS, USER

import bpy


def env():
    return dict(os.environ, BLENDER_USER_RESOURCES=str(USER))


def run(*args, timeout=600):
    return subprocess.run([sys.executable, "-m", "dqskin.blender", *args], capture_output=True, text=True, env=env(), timeout=timeout)


def one_line_failure(r, code=1):
    assert r.returncode == code, (r.returncode, r.stdout, r.stderr)
    # Blender's own lines ("Read blend", "Info:", 4.2's "Attempt to free nullptr pointer") aside,
    # exactly one line, ours.
    lines = [line for line in r.stderr.splitlines() if line.startswith("python -m dqskin.blender")]
    assert len(lines) == 1, r.stderr
    assert "Traceback" not in r.stderr and "Error:" not in r.stderr.replace(lines[0], ""), r.stderr
    return lines[0]


@pytest.mark.parametrize("suffix", [".blend", ".glb"])
def test_corrupt_input_is_one_line_and_exit_1(tmp_path, suffix):
    bad = tmp_path / f"broken{suffix}"
    bad.write_bytes(b"\x00garbage" * 1000)
    out = tmp_path / "out.blend"
    line = one_line_failure(run("apply", str(bad), "--out", str(out)))
    assert "cannot be read" in line and bad.name in line
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == [bad.name]


def test_unwritable_output_is_one_line_and_exit_1(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    line = one_line_failure(run("apply", str(ASSETS / "RiggedSimple.glb"), "--out", str(blocker / "out.blend")))
    assert "cannot be written" in line
    line = one_line_failure(
        run("bake", str(ASSETS / "CesiumMan.glb"), "--object", "Cesium_Man", "--frames", "1-3", "--out", str(blocker / "x.pc2"))
    )
    assert "x.pc2" in line or "file" in line


def start(*args):
    return subprocess.Popen(
        [sys.executable, "-m", "dqskin.blender", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env()
    )


def wait_for(predicate, timeout=120.0):
    t = time.perf_counter()
    while not predicate():
        if time.perf_counter() - t > timeout:
            raise AssertionError("timed out waiting")
        time.sleep(0.02)


def temporaries(folder: Path):
    return [p for p in folder.rglob("*") if ".dqskin-" in p.name]


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_bake_stops_on_signals_cleans_up_and_keeps_the_old_output(tmp_path, sig, code):
    out = tmp_path / "cache.pc2"
    out.write_bytes(b"previous bake")
    p = start("bake", str(ASSETS / "CesiumMan.glb"), "--object", "Cesium_Man", "--frames", "1-5000", "--out", str(out))
    wait_for(lambda: temporaries(tmp_path) or p.poll() is not None)
    assert p.poll() is None, p.communicate()
    time.sleep(0.3)
    p.send_signal(sig)
    t = time.perf_counter()
    _, err = p.communicate(timeout=30)
    assert time.perf_counter() - t < 1.0, "stopped within a second"
    assert p.returncode == code, err
    assert "interrupted" in err and "Traceback" not in err
    assert out.read_bytes() == b"previous bake"
    assert not temporaries(tmp_path)


def test_compare_stops_on_ctrl_c(tmp_path):
    p = start("compare", str(ASSETS / "CesiumMan.glb"), "--frames", "1-3000", "--no-render", "--out", str(tmp_path / "cmp"))
    time.sleep(6.0)  # loading, building the comparison scene, then frames
    assert p.poll() is None, p.communicate()
    p.send_signal(signal.SIGINT)
    t = time.perf_counter()
    _, err = p.communicate(timeout=30)
    assert time.perf_counter() - t < 1.0
    assert p.returncode == 130, err
    assert not (tmp_path / "cmp" / "report.json").exists() and not temporaries(tmp_path)


def crowd_file(path: Path, count: int = 40) -> None:
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.import_scene.gltf(filepath=str(ASSETS / "CesiumMan.glb"))
    src = next(o for o in bpy.data.objects if o.type == "MESH")
    for i in range(count):
        c = src.copy()
        c.location.x = i
        bpy.context.scene.collection.objects.link(c)
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)


def test_apply_stops_on_sigterm(tmp_path):
    src = tmp_path / "crowd.blend"
    crowd_file(src, count=150)
    out = tmp_path / "applied.blend"
    out.write_bytes(b"old")
    p = start("apply", str(src), "--out", str(out))
    time.sleep(1.5)
    if p.poll() is not None:
        pytest.skip("apply finished before the signal (machine too fast for this input)")
    p.send_signal(signal.SIGTERM)
    t = time.perf_counter()
    _, err = p.communicate(timeout=30)
    assert time.perf_counter() - t < 1.0
    assert p.returncode == 143, err
    assert out.read_bytes() == b"old" and not temporaries(tmp_path)


def test_merge_stops_on_ctrl_c(tmp_path):
    from dqskin import pc2

    chunks = []
    for i in range(6):
        path = tmp_path / f"c{i}.pc2"
        with pc2.Writer(path, 500_000, 1 + 20 * i) as w:
            w.add_many(np.zeros((20, 500_000, 3), np.float32))
        chunks.append(path)
    out = tmp_path / "all.pc2"
    p = subprocess.Popen(
        [sys.executable, "-m", "dqskin.blender", "merge", str(out), *map(str, chunks)], stderr=subprocess.PIPE, text=True, env=env()
    )
    wait_for(lambda: temporaries(tmp_path) or p.poll() is not None)
    if p.poll() is not None:
        pytest.skip("merge finished before the signal")
    p.send_signal(signal.SIGINT)
    t = time.perf_counter()
    _, err = p.communicate(timeout=30)
    assert time.perf_counter() - t < 1.0
    assert p.returncode == 130, err
    assert not out.exists() and not temporaries(tmp_path)


def test_sigkill_leaves_a_recognisable_temporary_that_the_next_run_removes(tmp_path):
    out = tmp_path / "cache.pc2"
    args = ("bake", str(ASSETS / "CesiumMan.glb"), "--object", "Cesium_Man", "--frames", "1-5000", "--out", str(out))
    p = start(*args)
    wait_for(lambda: temporaries(tmp_path) or p.poll() is not None)
    p.kill()
    p.communicate(timeout=30)
    left = temporaries(tmp_path)
    assert len(left) == 1 and left[0].name.startswith(".cache.pc2.dqskin-") and left[0].name.endswith(".tmp")
    r = run("bake", str(ASSETS / "CesiumMan.glb"), "--object", "Cesium_Man", "--frames", "1-4", "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert out.exists() and not temporaries(tmp_path)


# -- the add-on ---------------------------------------------------------------------------------


def test_an_empty_mesh_under_dq_skin_says_so(dq_skin):
    from dqtest import add_dq_skin, draw_panel
    from scenes import rig_tube

    obj, arm, _ = rig_tube()
    mod = add_dq_skin(obj)
    obj.data.clear_geometry()
    bpy.context.view_layer.update()
    bpy.context.scene.frame_set(3)
    st = dq_skin.SESSION.status_of(obj, mod)
    assert "no vertices" in st.message, st.message
    lines = draw_panel(dq_skin, obj)
    assert any("no vertices" in line for line in lines)
    assert len(obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data.vertices) == 0


def test_renaming_an_object_200_times_keeps_one_entry(dq_skin):
    from dqtest import add_dq_skin, is_carrier
    from scenes import rig_tube

    obj, arm, _ = rig_tube()
    add_dq_skin(obj)
    states = dq_skin.SESSION.states
    before = len(states)
    for i in range(200):
        obj.name = f"Renamed {i}"
        bpy.context.view_layer.update()
        bpy.context.scene.frame_set(1 + i % 5)
    assert len(states) == before
    assert len(dq_skin.SESSION.tracker.records) == 1
    outputs = [o for o in bpy.data.objects if o.get("dq_skin_result")] + [m for m in obj.modifiers if is_carrier(m)]
    assert len(outputs) == 1

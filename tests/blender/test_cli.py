"""The batch command line, run as users run it, through both entry points: a separate
`python -m dqskin.blender` process, and Blender's own `blender -b --command dq_skin` (the command
the extension registers, called as Blender calls it; see as_blender_command.py)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ASSETS, USER

ENTRY_POINTS = {
    "python -m dqskin.blender": [sys.executable, "-m", "dqskin.blender"],
    "blender --command dq_skin": [sys.executable, str(Path(__file__).with_name("as_blender_command.py"))],
}


def runner(entry):
    def run(*args, cwd=None):
        env = dict(os.environ, BLENDER_USER_RESOURCES=str(USER))
        return subprocess.run([*ENTRY_POINTS[entry], *args], capture_output=True, text=True, env=env, cwd=cwd, timeout=600)

    return run


run = runner("python -m dqskin.blender")
both = pytest.mark.parametrize("run", [runner(e) for e in ENTRY_POINTS], ids=list(ENTRY_POINTS))


@both
def test_bake_then_merge_chunks_like_a_farm(run, tmp_path):
    from dqskin import pc2

    whole = tmp_path / "whole.pc2"
    r = run("bake", str(ASSETS / "CesiumMan.glb"), "--object", "Cesium_Man", "--frames", "1-20", "--out", str(whole))
    assert r.returncode == 0, r.stderr
    chunks = []
    for a, b in ((1, 8), (9, 20)):
        chunk = tmp_path / f"chunk_{a}.pc2"
        r = run("bake", str(ASSETS / "CesiumMan.glb"), "--object", "Cesium_Man", "--frames", f"{a}-{b}", "--out", str(chunk))
        assert r.returncode == 0, r.stderr
        chunks.append(chunk)
    merged = tmp_path / "merged.pc2"
    r = run("merge", str(merged), *map(str, chunks[::-1]))
    assert r.returncode == 0, r.stderr
    hw, dw = pc2.read(whole)
    hm, dm = pc2.read(merged)
    assert hw == hm
    np.testing.assert_array_equal(dw, dm)


@both
def test_failures_exit_non_zero_with_one_line_and_write_nothing(run, tmp_path):
    out = tmp_path / "x.pc2"
    r = run("bake", str(ASSETS / "CesiumMan.glb"), "--object", "Nobody", "--out", str(out))
    assert r.returncode != 0 and "no mesh object named 'Nobody'" in r.stderr
    assert len(r.stderr.strip().splitlines()[-1]) < 200
    r = run("bake", str(tmp_path / "missing.glb"), "--object", "A", "--out", str(out))
    assert r.returncode != 0 and "no such file" in r.stderr
    r = run("bake", str(ASSETS / "CesiumMan.glb"), "--object", "Cesium_Man", "--frames", "9-3", "--out", str(out))
    assert r.returncode != 0 and "end is before the start" in r.stderr
    assert not out.exists()
    r = run("merge", str(tmp_path / "m.pc2"), str(tmp_path / "missing.pc2"))
    assert r.returncode != 0 and not (tmp_path / "m.pc2").exists()


@both
def test_apply_saves_a_file_with_dq_skin(run, tmp_path):
    out = tmp_path / "fox_dq.blend"
    r = run("apply", str(ASSETS / "Fox.glb"), "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert out.is_file() and "replaced 1 Armature modifier" in r.stdout
    check = tmp_path / "check.py"
    check.write_text(
        "import sys, bpy\n"
        f"bpy.ops.wm.open_mainfile(filepath={str(out)!r})\n"
        "o = next(o for o in bpy.data.objects if o.type == 'MESH' and any(m.type == 'ARMATURE' for m in o.modifiers))\n"
        "print('MODS', [m.type for m in o.modifiers], [m.show_viewport for m in o.modifiers])\n"
    )
    r = subprocess.run([sys.executable, str(check)], capture_output=True, text=True, timeout=300)
    # Saved for any Blender: DQ Skin first, its companion Armature modifier after it, active
    # (the add-on parks it when it loads the file; without the add-on it deforms the mesh).
    assert "MODS ['NODES', 'ARMATURE'] [True, True]" in r.stdout, r.stdout + r.stderr


def test_compare_writes_a_report_and_a_picture(tmp_path):
    out = tmp_path / "out"
    r = run(
        "compare",
        str(ASSETS / "RiggedFigure.glb"),
        "--frames",
        "1-10",
        "--out",
        str(out),
        "--width",
        "160",
        "--height",
        "90",
        "--samples",
        "1",
    )
    assert r.returncode == 0, r.stderr
    report = json.loads((out / "report.json").read_text())
    methods = report["rows"][0]["methods"]
    assert len(methods) == 6
    assert methods["DQ Skin Linear"]["max_deviation_from_armature_linear"] < 1e-5
    assert methods["DQ Skin Dual Quaternion"]["max_deviation_from_armature_preserve_volume"] < 1e-5
    assert "| DQ Skin Blend |" in (out / "report.md").read_text()
    assert (out / "comparison.png").stat().st_size > 0


@both
def test_compare_built_in_rigs(run, tmp_path):
    out = tmp_path / "rigs"
    r = run("compare", "--out", str(out), "--no-render")
    assert r.returncode == 0, r.stderr
    rows = json.loads((out / "report.json").read_text())["rows"]
    assert [row["mesh"] for row in rows] == ["Candy Wrapper Twist", "Elbow Bend", "Shoulder Raise"]


def test_both_entry_points_bake_the_same_cache(tmp_path):
    outs = []
    for entry in ENTRY_POINTS:
        out = tmp_path / f"{entry.split()[0]}.pc2"
        r = runner(entry)("bake", str(ASSETS / "CesiumMan.glb"), "--object", "Cesium_Man", "--frames", "1-5", "--out", str(out))
        assert r.returncode == 0, r.stderr
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]


@pytest.mark.parametrize("entry", list(ENTRY_POINTS))
def test_usage_errors_and_help_name_the_entry_point(entry):
    r = runner(entry)("bake", "x.glb")
    assert r.returncode == 2 and f"usage: {entry}" in r.stderr and "--object" in r.stderr
    r = runner(entry)("--help")
    assert r.returncode == 0 and "compare" in r.stdout and "merge" in r.stdout


def test_blender_command_refuses_user_resources(tmp_path):
    r = runner("blender --command dq_skin")("--user-resources", str(tmp_path), "merge", str(tmp_path / "a.pc2"), str(tmp_path / "b.pc2"))
    assert r.returncode == 1 and "--user-resources is for `python -m dqskin.blender`" in r.stderr


def test_long_commands_report_progress(tmp_path):
    r = run("apply", str(ASSETS / "Fox.glb"), "--out", str(tmp_path / "fox.blend"))
    assert r.returncode == 0 and "Adding DQ Skin to 1 object(s) [" in r.stderr and "2/2" in r.stderr, r.stderr
    r = run("compare", "--out", str(tmp_path / "c"), "--no-render", "--frames", "1-4")
    assert r.returncode == 0 and "Comparing 3 row(s) over 4 frame(s) [" in r.stderr, r.stderr


@pytest.mark.parametrize(
    "args, option",
    [
        (["compare", "--width", "0"], "--width"),
        (["compare", "--height", "-5"], "--height"),
        (["compare", "--width", "wide"], "--width"),
        (["compare", "--samples", "0"], "--samples"),
        (["compare", "--frames", "5-1"], "--frames"),
        (["compare", "--frames", "1-x"], "--frames"),
        (["bake", "shot.blend", "--object", "A", "--out", "x.pc2", "--frames", "1-99999999"], "--frames"),
    ],
    ids=lambda v: " ".join(v) if isinstance(v, list) else v,
)
def test_out_of_range_options_are_usage_errors_naming_the_option(args, option, tmp_path):
    r = run(*args, cwd=tmp_path)
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert f"error: argument {option}:" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert not list(tmp_path.iterdir())  # nothing rendered or written


def _apply(run, method: str, out: Path) -> Path:
    r = run("apply", str(ASSETS / "CesiumMan.glb"), "--method", method, "--out", str(out))
    assert r.returncode == 0, r.stderr
    return out


@both
@pytest.mark.parametrize("method", ["DUAL_QUATERNION", "CENTERS_OF_ROTATION"])
def test_bake_method_applies_to_an_object_that_has_dq_skin(run, method, tmp_path):
    """`bake --method M` on a file saved with DQ Skin (Linear) bakes M, as a bake of the object
    with DQ Skin set to M does, and leaves the file as it was (the command never saves it)."""
    linear = _apply(run, "LINEAR", tmp_path / "linear.blend")
    saved = linear.read_bytes()
    reference = _apply(run, method, tmp_path / "reference.blend")
    caches = {}
    for name, blend, extra in (("got", linear, ["--method", method]), ("reference", reference, []), ("linear", linear, [])):
        caches[name] = tmp_path / f"{name}.pc2"
        r = run("bake", str(blend), "--object", "Cesium_Man", "--frames", "1-6", *extra, "--out", str(caches[name]))
        assert r.returncode == 0, r.stderr
    assert caches["got"].read_bytes() == caches["reference"].read_bytes()
    assert caches["got"].read_bytes() != caches["linear"].read_bytes()
    assert linear.read_bytes() == saved


@pytest.mark.parametrize(
    "entry, option",
    [
        ("python -m dqskin.blender", ["--threads", "1"]),
        ("blender --command dq_skin", ["-t", "1"]),  # Blender's own option, before --command
        ("blender --command dq_skin", ["--threads", "1"]),
    ],
    ids=["launcher --threads", "blender -t", "blender --command dq_skin --threads"],
)
def test_threads_size_dq_skins_pool(entry, option, tmp_path):
    out = tmp_path / "one.pc2"
    args = ["bake", str(ASSETS / "CesiumMan.glb"), "--object", "Cesium_Man", "--frames", "1-3", "--out", str(out)]
    r = runner(entry)(*option, *args)
    assert r.returncode == 0 and "(1 thread)" in r.stdout, r.stdout + r.stderr
    r = runner(entry)(*args, "--threads", "2")  # after the command too
    assert r.returncode == 0 and "(2 threads)" in r.stdout, r.stdout + r.stderr
    r = runner(entry)("--threads", "0", *args)
    assert r.returncode == 2 and "argument --threads" in r.stderr, r.stderr


@pytest.fixture
def bodies(tmp_path):
    """`Body R.blend`: three CesiumMan meshes on their Armature modifiers, Body/L, Body R and
    Body_L (whose file name is Body/L's: `/` cannot be in one)."""
    import bpy

    for name in ("Body/L", "Body R", "Body_L"):
        bpy.ops.import_scene.gltf(filepath=str(ASSETS / "CesiumMan.glb"))
        bpy.data.objects["Cesium_Man"].name = name
    blend = tmp_path / "Body R.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), copy=True)
    return blend


@both
def test_bake_several_objects_one_file_each(run, bodies, tmp_path):
    objects = ["--object", "Body/L", "--object", "Body R"]
    single = {}
    for name, file_name in (("Body/L", "Body_L"), ("Body R", "Body R")):
        single[file_name] = tmp_path / f"single {file_name}.pc2"
        r = run("bake", str(bodies), "--object", name, "--frames", "1-4", "--out", str(single[file_name]))
        assert r.returncode == 0, r.stderr
    # Into a folder: FOLDER/NAME.pc2 (`/` in a name becomes `_`). Temporaries that a killed run
    # left there (a process that no longer runs) go first.
    folder = tmp_path / "caches"
    folder.mkdir()
    dead = 2**22 + 1  # above Linux's largest process id
    for stale in (f".Body_L.pc2.dqskin-{dead}.tmp", f"..Body_L.pc2.dqskin-{dead}.tmp.dqskin-{dead}.tmp"):
        (folder / stale).write_bytes(b"killed")
    r = run("bake", str(bodies), *objects, "--frames", "1-4", "--out", f"{folder}/")
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in folder.iterdir()) == ["Body R.pc2", "Body_L.pc2"]
    for name, path in single.items():
        assert (folder / f"{name}.pc2").read_bytes() == path.read_bytes(), name
    # A pattern.
    r = run("bake", str(bodies), *objects, "--frames", "1-4", "--out", str(tmp_path / "shot {object}.pc2"))
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "shot Body_L.pc2").read_bytes() == single["Body_L"].read_bytes()
    assert (tmp_path / "shot Body R.pc2").read_bytes() == single["Body R"].read_bytes()

    # Never two objects on one file, never a file the user did not name: nothing is written.
    saved = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    r = run("bake", str(bodies), *objects, "--frames", "1-4", "--out", str(tmp_path / "both.pc2"))
    assert r.returncode == 2 and "argument --out: several objects need a folder" in r.stderr, r.stderr
    r = run("bake", str(bodies), "--object", "Body/L", "--object", "Body_L", "--frames", "1-4", "--out", f"{folder}/")
    assert r.returncode == 1 and "would both be baked to" in r.stderr, r.stderr
    r = run("bake", str(bodies), "--object", "Body R", "--frames", "1-4", "--out", str(tmp_path / "{object}.blend"))
    assert r.returncode == 1 and "that is the input file" in r.stderr, r.stderr
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == saved


@both
def test_bake_reports_progress_in_logs(run, tmp_path):
    """Not on a terminal (a farm's log): a line, flushed, each tenth of the frames."""
    r = run("bake", str(ASSETS / "CesiumMan.glb"), "--object", "Cesium_Man", "--frames", "1-20", "--out", str(tmp_path / "c.pc2"))
    assert r.returncode == 0, r.stderr
    lines = [line for line in r.stderr.splitlines() if line.startswith("Baking Cesium_Man [")]
    assert [line.split("] ")[1].split()[0] for line in lines] == [f"{n}/20" for n in range(2, 21, 2)], r.stderr
    assert "\r" not in r.stderr


@both
def test_user_errors_in_bake_and_apply_name_the_problem(run, tmp_path):
    """Errors the user caused: exit 1, one line naming the problem, never a program error."""
    import bpy

    bpy.ops.import_scene.gltf(filepath=str(ASSETS / "CesiumMan.glb"))
    next(m for m in bpy.data.objects["Cesium_Man"].modifiers if m.type == "ARMATURE").object = None
    bpy.ops.mesh.primitive_cube_add()
    bpy.context.active_object.name = "Plain"
    unrigged = tmp_path / "unrigged.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(unrigged), copy=True)
    (tmp_path / "broken.blend").write_text("not a blend file")
    (tmp_path / "folder.blend").mkdir()
    (tmp_path / "a file").write_text("")
    glb = str(ASSETS / "CesiumMan.glb")
    cases = [
        (["bake", str(unrigged), "--object", "Cesium_Man"], "Cesium_Man: its Armature modifier 'Armature' has no armature object"),
        (["apply", str(unrigged)], "Cesium_Man: its Armature modifier 'Armature' has no armature object"),
        (["bake", str(unrigged), "--object", "Plain"], "Plain has neither a DQ Skin nor an Armature modifier"),
        (["bake", str(unrigged), "--object", "Armature"], "'Armature' is an armature object, not a mesh"),
        (["bake", str(unrigged), "--object", "Nobody"], "no mesh object named 'Nobody'"),
        (["bake", str(tmp_path / "broken.blend"), "--object", "A"], "broken.blend: cannot be read"),
        (["apply", str(tmp_path / "broken.blend")], "broken.blend: cannot be read"),
        (["bake", str(tmp_path / "folder.blend"), "--object", "A"], "folder.blend: not a file"),
        (
            ["bake", glb, "--object", "Cesium_Man", "--frames", "1-3", "--out", str(tmp_path / "a file" / "x.pc2")],
            "x.pc2: cannot be written",
        ),
        (["apply", glb, "--out", str(tmp_path / "a file" / "x.blend")], "x.blend: cannot be written"),
    ]
    for args, message in cases:
        if "--out" not in args:
            args = [*args, "--out", str(tmp_path / ("out.pc2" if args[0] == "bake" else "out.blend"))]
        r = run(*args)
        last = r.stderr.strip().splitlines()[-1]
        assert r.returncode == 1 and message in last, (args, r.stderr)
        assert last.startswith(("python -m dqskin.blender ", "blender --command dq_skin ")) and len(last) < 300, last
        assert "Traceback" not in r.stderr and "DQSKIN_DEBUG" not in r.stderr, r.stderr
    assert not list(tmp_path.glob("out.*")) and not list(tmp_path.glob(".*.tmp"))

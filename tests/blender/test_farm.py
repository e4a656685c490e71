"""The farm job templates, run for real on a Blender file: the Open Job Description template with
`openjd run` (every chunk of the bake step, then the merge step that depends on it), and the
Flamenco job type compiled by Node with Flamenco's authoring API (tests/farm/flamenco_compile.js),
its tasks then run in dependency order. Both merged caches must equal a single-run bake byte for
byte."""

from __future__ import annotations

import json
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from conftest import ASSETS, ROOT

import bpy

OPENJD_TEMPLATE = ROOT / "farm" / "dq-skin-bake.openjd.yaml"
FLAMENCO_JOB_TYPE = ROOT / "farm" / "dq-skin-bake.js"
OPENJD = Path(sys.executable).with_name("openjd")
COMMAND = f"{sys.executable} -m dqskin.blender"
OBJECT, FRAMES = "Cesium_Man", (1, 20)


@pytest.fixture(scope="module")
def shot(tmp_path_factory):
    """A .blend with CesiumMan on its Armature modifier, and the PC2 one bake of FRAMES writes."""
    folder = tmp_path_factory.mktemp("shot")
    blend = folder / "shot.blend"
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.import_scene.gltf(filepath=str(ASSETS / "CesiumMan.glb"))
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), copy=True)
    single = folder / "single.pc2"
    r = subprocess.run(
        [*COMMAND.split(), "bake", str(blend), "--object", OBJECT, "--frames", "{}-{}".format(*FRAMES), "--out", str(single)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr
    return blend, single.read_bytes()


def test_the_openjd_template_has_the_parameters_and_steps_a_studio_sets():
    template = yaml.safe_load(OPENJD_TEMPLATE.read_text())
    params = {p["name"]: p for p in template["parameterDefinitions"]}
    assert list(params) == ["BlendFile", "Object", "Frames", "ChunkSize", "Method", "Output", "DqSkinCommand"]
    assert params["DqSkinCommand"]["default"] == "blender -b --command dq_skin"
    steps = {s["name"]: s for s in template["steps"]}
    assert [d["dependsOn"] for d in steps["Merge"]["dependencies"]] == ["Bake"]
    r = subprocess.run([str(OPENJD), "check", str(OPENJD_TEMPLATE)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr


def test_openjd_run_bakes_every_chunk_and_merges_them_like_one_bake(shot, tmp_path):
    blend, single = shot
    out = tmp_path / "cache" / "body.pc2"
    # A chunk left from an earlier job with other frames: outside Frames, the merge must skip it.
    stale = out.with_name("body.pc2.chunks") / "40-48.pc2"
    stale.parent.mkdir(parents=True)
    stale.write_bytes(b"not this job's")
    params = {
        "BlendFile": str(blend),
        "Object": OBJECT,
        "Frames": "{}-{}".format(*FRAMES),
        "ChunkSize": "7",
        "Output": str(out),
        "DqSkinCommand": COMMAND,
    }
    r = subprocess.run(
        [
            str(OPENJD),
            "run",
            str(OPENJD_TEMPLATE),
            "--step",
            "Merge",
            "--run-dependencies",
            *[a for k, v in params.items() for a in ("-p", f"{k}={v}")],
        ],
        capture_output=True,
        text=True,
        timeout=1200,
        cwd=tmp_path,
    )
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-2000:]
    # OpenJD splits 20 frames into chunks of at most 7: three bake tasks, then the merge.
    assert "Chunks run: 4" in r.stdout, r.stdout[-2000:]
    for chunk in ("1-7", "8-14", "15-20"):
        assert f"baked {OBJECT} frames {chunk} to" in r.stdout, chunk
    assert out.read_bytes() == single
    assert not stale.parent.exists()  # the merge removes the chunks


def spaced(shot, tmp_path) -> tuple[Path, Path, str]:
    """The shot's file in a folder whose name has spaces, an output there, and a command whose
    program's path has spaces, quoted as the templates document: `"/a b/dq skin"` (a script that
    runs `python -m dqskin.blender`)."""
    folder = tmp_path / "my shots"
    folder.mkdir()
    blend = folder / "shot one.blend"
    shutil.copyfile(shot[0], blend)
    program = tmp_path / "bin dir" / "dq skin"
    program.parent.mkdir()
    program.write_text(f'#!/bin/sh\nexec {shlex.quote(sys.executable)} -m dqskin.blender "$@"\n')
    program.chmod(0o755)
    return blend, folder / "cache dir" / "body cache.pc2", f'"{program}"'


def run_openjd(params: dict, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [
            str(OPENJD),
            "run",
            str(OPENJD_TEMPLATE),
            "--step",
            "Merge",
            "--run-dependencies",
            *[a for k, v in params.items() for a in ("-p", f"{k}={v}")],
        ],
        capture_output=True,
        text=True,
        timeout=1200,
        cwd=cwd,
    )


def test_openjd_run_keeps_paths_with_spaces(shot, tmp_path):
    blend, out, command = spaced(shot, tmp_path)
    params = {
        "BlendFile": blend,
        "Object": OBJECT,
        "Frames": "{}-{}".format(*FRAMES),
        "ChunkSize": "10",
        "Output": out,
        "DqSkinCommand": command,
    }
    r = run_openjd(params, tmp_path)
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-2000:]
    assert out.read_bytes() == shot[1]
    assert sorted(p.name for p in out.parent.iterdir()) == ["body cache.pc2"]


COMMANDS = [
    "blender -b --command dq_skin",
    '"/opt/Blender 4.5/blender" -b --command dq_skin',
    "'/opt/Blender 4.5/blender'  -b\t--command dq_skin",
    "/opt/Blender\\ 4.5/blender -b --command dq_skin",
    '"C:\\Program Files\\Blender\\blender.exe" -b -c dq_skin',
    'python -m dqskin.blender --user-resources "/studio/blender user" --threads 2',
    "a''b '' \"say \\\"hi\\\"\" $HOME `x`",
]


def openjd_split(script: str, text: str) -> list[str]:
    """What an embedded script of the template makes of DqSkinCommand `text`."""
    split = script[script.index("split_command() {") : script.index('split_command "$1"\n')]
    r = subprocess.run(
        ["bash", "-c", f'set -euo pipefail\n{split}\nsplit_command "$1"\nprintf "%s\\0" "${{command[@]}}"', "-", text],
        capture_output=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    return r.stdout.decode().split("\0")[:-1]


@pytest.mark.parametrize("command", COMMANDS)
def test_both_templates_split_the_command_as_a_shell_does(command):
    words = shlex.split(command)
    for step in yaml.safe_load(OPENJD_TEMPLATE.read_text())["steps"]:
        assert openjd_split(step["script"]["embeddedFiles"][0]["data"], command) == words, step["name"]
    r = flamenco_graph(
        {
            "blendfile": "/my shots/a b.blend",
            "object": "Body",
            "frames": "1-2",
            "chunk_size": 4,
            "output": "/cache dir/b c.pc2",
            "dq_skin_command": command,
        }
    )
    assert r.returncode == 0, r.stderr
    bake = json.loads(r.stdout)["tasks"][0]["commands"][0]["parameters"]
    assert [bake["exe"], *bake["args"]] == [
        *words,
        "bake",
        "/my shots/a b.blend",
        "--object",
        "Body",
        "--frames",
        "1-2",
        "--method",
        "AUTO",
        "--out",
        "/cache dir/b c.pc2.chunks/1-2.pc2",
    ]


@pytest.mark.parametrize("command", ['"unclosed', "ends with \\", "  "])
def test_both_templates_refuse_a_command_they_cannot_split(command):
    for step in yaml.safe_load(OPENJD_TEMPLATE.read_text())["steps"]:
        script = step["script"]["embeddedFiles"][0]["data"]
        split = script[script.index("split_command() {") : script.index('split_command "$1"\n')]
        r = subprocess.run(
            ["bash", "-c", f'set -euo pipefail\n{split}\nsplit_command "$1"', "-", command], capture_output=True, text=True, timeout=60
        )
        assert r.returncode == 2 and "DqSkinCommand" in r.stderr, r.stderr
    r = flamenco_graph(
        {"blendfile": "a.blend", "object": "B", "frames": "1-2", "chunk_size": 4, "output": "o.pc2", "dq_skin_command": command}
    )
    assert r.returncode != 0 and "DQ Skin command" in r.stderr, r.stderr


def flamenco_graph(settings: dict) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["node", str(ROOT / "tests" / "farm" / "flamenco_compile.js"), str(FLAMENCO_JOB_TYPE), json.dumps(settings)],
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_the_flamenco_job_type_compiles_to_one_bake_per_chunk_and_a_merge_after_them():
    r = flamenco_graph({"blendfile": "/shots/a.blend", "object": "Body", "frames": "1-10", "chunk_size": 4, "output": "/cache/body.pc2"})
    assert r.returncode == 0, r.stderr
    graph = json.loads(r.stdout)
    assert graph["label"] == "DQ Skin Bake" and graph["settings"]["dq_skin_command"] == "{blender} -b --command dq_skin"
    tasks = {t["name"]: t for t in graph["tasks"]}
    # Flamenco's chunker writes the last two frames as "9,10": the bake gets the range 9-10.
    assert list(tasks) == ["bake-1-4", "bake-5-8", "bake-9-10", "merge"]
    bake = tasks["bake-9-10"]["commands"][0]
    assert bake["name"] == "exec" and bake["parameters"]["exe"] == "{blender}"
    assert bake["parameters"]["args"] == [
        "-b",
        "--command",
        "dq_skin",
        "bake",
        "/shots/a.blend",
        "--object",
        "Body",
        "--frames",
        "9-10",
        "--method",
        "AUTO",
        "--out",
        "/cache/body.pc2.chunks/9-10.pc2",
    ]
    merge = tasks["merge"]
    assert merge["dependencies"] == ["bake-1-4", "bake-5-8", "bake-9-10"]
    assert merge["commands"][0]["parameters"]["args"][3:] == [
        "merge",
        "/cache/body.pc2",
        *[f"/cache/body.pc2.chunks/{c}.pc2" for c in ("1-4", "5-8", "9-10")],
    ]
    # One frame left over is written "9" by the chunker: still a range for the bake.
    single = json.loads(
        flamenco_graph({"blendfile": "a.blend", "object": "B", "frames": "1..9", "chunk_size": 4, "output": "o.pc2"}).stdout
    )
    assert [t["name"] for t in single["tasks"]] == ["bake-1-4", "bake-5-8", "bake-9-9", "merge"]


@pytest.mark.parametrize("frames", ["1-5,8", "9-3", "", "frames"])
def test_the_flamenco_job_type_refuses_frames_that_are_not_one_range(frames):
    r = flamenco_graph({"blendfile": "a.blend", "object": "B", "frames": frames, "chunk_size": 4, "output": "o.pc2"})
    assert r.returncode != 0 and ("frames" in r.stderr), r.stderr


@pytest.mark.parametrize("paths", ["plain", "with spaces"])
def test_the_flamenco_tasks_run_in_order_give_the_single_bake(shot, tmp_path, paths):
    blend, single = shot
    out, command = tmp_path / "body.pc2", COMMAND
    if paths == "with spaces":
        blend, out, command = spaced(shot, tmp_path)
    r = flamenco_graph(
        {
            "blendfile": str(blend),
            "object": OBJECT,
            "frames": "{}-{}".format(*FRAMES),
            "chunk_size": 8,
            "output": str(out),
            "dq_skin_command": command,
        }
    )
    assert r.returncode == 0, r.stderr
    tasks = json.loads(r.stdout)["tasks"]
    done: set[str] = set()
    while len(done) < len(tasks):  # what the Manager does: a task once all it depends on is done
        task = next(t for t in tasks if t["name"] not in done and set(t["dependencies"]) <= done)
        for command in task["commands"]:
            p = command["parameters"]
            run = subprocess.run([p["exe"], *p["args"]], capture_output=True, text=True, timeout=600)
            assert run.returncode == 0, (task["name"], run.stderr)
        done.add(task["name"])
    assert [t["name"] for t in tasks] == ["bake-1-8", "bake-9-16", "bake-17-20", "merge"]
    assert out.read_bytes() == single

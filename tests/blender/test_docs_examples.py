"""Every example in the README and docs/ that needs Blender runs as written: the command lines
(`blender ... --command dq_skin|extension`, `python -m dqskin.blender`, `openjd run`) in bash, and
the Blender scripts with `blender -b --python`, through a user's shell (user_shell.py: the fake
`blender` and this Python on the PATH).

Each example runs in a folder of its own holding what the docs say it holds: `shot.blend` (a mesh
`Body` on an Armature modifier, animated over frames 1-24: CesiumMan), and the repository's
`dist/` and `farm/`. Commands that install extensions get a fresh Blender user folder; the
others use the tests' own, with DQ Skin installed. The numpy examples run in
tests/python/test_docs.py."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
import user_shell
from conftest import ASSETS, ROOT, USER

import bpy

PAGES = [ROOT / "README.md", *sorted(p for p in (ROOT / "docs").glob("*.md") if p.name != "performance-history.md")]
# A command line an example runs (an environment assignment may come first).
RUNS = re.compile(r"^(\w+=\S+ )*(blender |python -m dqskin\.blender |openjd )", re.M)


def blocks(language: str) -> list[tuple[str, int, str]]:
    """(page, index, code) of a language's fenced blocks in the pages, above any generated part."""
    found = []
    for page in PAGES:
        text = page.read_text().split("<!-- Generated below")[0]
        for i, code in enumerate(re.findall(rf"^```{language}\n(.*?)^```$", text, flags=re.S | re.M)):
            found.append((page.relative_to(ROOT).as_posix(), i, code))
    return found


# The examples run through the fake `blender` (fake_blender.py), which needs the user's
# preferences: Blender 4.2's bpy module crashes reading them, and crashes again as a command ends.
pytestmark = pytest.mark.skipif(bpy.app.version < (4, 3), reason="Blender 4.2's bpy module cannot run the fake blender")

SHELL_EXAMPLES = [b for b in blocks("sh") if RUNS.search(b[2])]
SCRIPT_EXAMPLES = [b for b in blocks("python") if "import bpy" in b[2]]


def example_id(example) -> str:
    page, index, _ = example
    return f"{page}-{index + 1}"


@pytest.fixture(scope="module")
def shot(tmp_path_factory) -> Path:
    """shot.blend: CesiumMan with its mesh named Body, frames 1-24."""
    folder = tmp_path_factory.mktemp("shot")
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.import_scene.gltf(filepath=str(ASSETS / "CesiumMan.glb"))
    bpy.data.objects["Cesium_Man"].name = "Body"
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, 24
    bpy.ops.wm.save_as_mainfile(filepath=str(folder / "shot.blend"), copy=True)
    return folder / "shot.blend"


def workspace(tmp_path: Path, shot: Path) -> Path:
    folder = tmp_path / "work"
    folder.mkdir()
    shutil.copyfile(shot, folder / "shot.blend")
    for name in ("dist", "farm"):
        (folder / name).symlink_to(ROOT / name)
    return folder


def test_the_docs_have_examples_of_each_kind():
    pages = {page for page, _, _ in SHELL_EXAMPLES}
    assert {"README.md", "docs/pipeline.md"} <= pages, pages
    assert SCRIPT_EXAMPLES, "the artist guide's script"


@pytest.mark.parametrize("example", SHELL_EXAMPLES, ids=example_id)
def test_every_command_line_example_runs_as_written(example, shot, tmp_path):
    page, index, code = example
    folder = workspace(tmp_path, shot)
    installs = "--command extension" in code
    user = user_shell.fresh_user_folder(tmp_path / "user") if installs else USER
    r = user_shell.run(code, folder, user, user_shell.bin_folder(tmp_path / "bin"))
    assert r.returncode == 0, f"{page}, shell example {index + 1}:\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    if "|| echo" in code:  # an example of a failure: the failure happened, and said so
        assert "exit code 1" in r.stdout and "Traceback" not in r.stderr, r.stdout + r.stderr


@pytest.mark.parametrize("example", SCRIPT_EXAMPLES, ids=example_id)
def test_every_blender_script_example_runs_as_written(example, shot, tmp_path):
    page, index, code = example
    folder = workspace(tmp_path, shot)
    (folder / "script.py").write_text(code)
    r = user_shell.run("blender -b --python script.py", folder, USER, user_shell.bin_folder(tmp_path / "bin"))
    assert r.returncode == 0, f"{page}, script example {index + 1}:\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"

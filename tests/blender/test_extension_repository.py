"""The extension repository `make setup` and `make repo` write into dist/: Blender adds it as a
remote repository by a file:// URL, installs DQ Skin from it, and upgrades DQ Skin when the
repository offers a newer version. Every step is Blender's own `extension` command, as a user or
a studio script runs it (user_shell.py)."""

from __future__ import annotations

import json
import shlex
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
import user_shell
from conftest import ASSETS, ROOT

import bpy

# Every test here adds a repository, which later commands find in the user's preferences: the
# fake `blender` cannot read them on Blender 4.2, whose bpy module crashes in wm.read_userpref.
pytestmark = [
    pytest.mark.skipif(bpy.app.version < (4, 3), reason="Blender 4.2's bpy module crashes reading the user's preferences"),
]

DIST = ROOT / "dist"
MANIFEST = ROOT / "addon" / "dq_skin" / "blender_manifest.toml"
REPOSITORY_ID = "studio"


def installed_version(user: Path) -> str | None:
    manifest = user / "extensions" / REPOSITORY_ID / "dq_skin" / "blender_manifest.toml"
    return tomllib.loads(manifest.read_text())["version"] if manifest.is_file() else None


def test_dist_is_a_repository_of_every_zip_it_holds():
    index = json.loads((DIST / "index.json").read_text())
    listed = sorted(entry["archive_url"] for entry in index["data"])
    assert listed == sorted(f"./{z.name}" for z in DIST.glob("*.zip")), "dist/index.json is stale: run make setup"
    version = tomllib.loads(MANIFEST.read_text())["version"]
    for entry in index["data"]:
        zip_path = DIST / entry["archive_url"].removeprefix("./")
        assert entry["id"] == "dq_skin" and entry["version"] == version
        assert entry["archive_size"] == zip_path.stat().st_size
        assert entry["platforms"] == [zip_path.stem.rsplit("-", 1)[1].replace("_", "-")]
        assert entry["python_versions"] == ["3"]  # the cp311-abi3 wheel: every CPython 3 Blender ships


def test_blender_installs_from_the_repository_and_upgrades_to_a_newer_version(tmp_path):
    version = tomllib.loads(MANIFEST.read_text())["version"]
    major, minor, patch = (int(part) for part in version.split("."))
    newer = f"{major}.{minor}.{patch + 1}"
    # The repository as a studio would host it: a copy of dist/'s index and zips.
    repository = tmp_path / "repository"
    repository.mkdir()
    for path in [DIST / "index.json", *DIST.glob("*.zip")]:
        shutil.copyfile(path, repository / path.name)
    user = user_shell.fresh_user_folder(tmp_path / "user")
    shell = user_shell.bin_folder(tmp_path / "bin")
    url = (repository / "index.json").as_uri()

    def blender(*args: str) -> subprocess.CompletedProcess:
        r = user_shell.run(" ".join(["blender", "--online-mode", "--command", "extension", *args]), tmp_path, user, shell)
        assert r.returncode == 0, r.stdout + r.stderr
        return r

    blender("repo-add", REPOSITORY_ID, "--url", url)
    blender("install", "dq_skin", "--sync", "--enable")
    assert installed_version(user) == version
    listed = blender("list").stdout
    assert "dq_skin [installed]" in listed, listed

    # A newer version published to the same address: this platform's zip rebuilt with the version
    # bumped in place of every zip (a repository offers one version), and the index written again.
    wheels = sorted((ROOT / "target" / "wheels").glob("linux-x64/dqskin-*.whl"))
    assert wheels, "no Linux wheel in target/wheels/linux-x64 (run make setup)"
    for old in repository.glob("*.zip"):
        old.unlink()
    for script, args in (
        ("build.py", [str(wheels[-1]), "--out", str(repository), "--version", newer]),
        ("repository.py", [str(repository)]),
    ):
        r = subprocess.run([sys.executable, str(ROOT / "addon" / script), *args], capture_output=True, text=True, timeout=600)
        assert r.returncode == 0, r.stdout + r.stderr
    assert [e["version"] for e in json.loads((repository / "index.json").read_text())["data"]] == [newer]

    r = blender("update", "--sync")
    assert installed_version(user) == newer, r.stdout + r.stderr
    # The upgraded extension is enabled and its command runs (the module its wheel installed).
    r = user_shell.run("blender --command dq_skin --help", tmp_path, user, shell)
    assert r.returncode == 0 and "bake DQ Skin to a PC2 cache" in r.stdout, r.stdout + r.stderr
    # The launcher finds it there too: `bl_ext.studio.dq_skin`, not the user_default one.
    r = user_shell.run("python -m dqskin.blender --help", tmp_path, user, shell)
    assert r.returncode == 0 and "bake DQ Skin to a PC2 cache" in r.stdout, r.stdout + r.stderr


@pytest.mark.skipif(
    bpy.app.version < (4, 3),
    reason="Blender 4.2's bpy module crashes in wm.read_userpref: the launcher finds DQ Skin in the repositories it starts with only",
)
def test_the_launcher_runs_dq_skin_installed_in_a_local_studio_repository(tmp_path):
    """A studio installs the zip into a repository of its own (not user_default): the launcher
    `python -m dqskin.blender` enables it from there, as Blender does."""
    zips = sorted(DIST.glob("dq_skin-*-linux_x64.zip"))
    assert zips, "no Linux zip in dist/ (run make setup)"
    user = user_shell.fresh_user_folder(tmp_path / "user")
    shell = user_shell.bin_folder(tmp_path / "bin")
    folder = tmp_path / "studio extensions"
    for command in (
        f"blender --command extension repo-add studio_local --name 'Studio' --directory {shlex.quote(str(folder))}",
        f"blender --command extension install-file -r studio_local -e {shlex.quote(str(zips[-1]))}",
    ):
        r = user_shell.run(command, tmp_path, user, shell)
        assert r.returncode == 0, r.stdout + r.stderr
    assert (folder / "dq_skin" / "blender_manifest.toml").is_file()
    assert not (user / "extensions" / "user_default" / "dq_skin").exists()
    out = tmp_path / "body.pc2"
    glb = shlex.quote(str(ASSETS / "CesiumMan.glb"))
    r = user_shell.run(
        f"python -m dqskin.blender bake {glb} --object Cesium_Man --frames 1-3 --out {shlex.quote(str(out))}", tmp_path, user, shell
    )
    assert r.returncode == 0 and "baked Cesium_Man frames 1-3" in r.stdout, r.stdout + r.stderr
    assert out.is_file()

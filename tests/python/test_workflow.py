"""The hosted-runner workflow (.github/workflows/platforms.yml) cannot run here: its syntax is
checked against the GitHub Actions workflow schema (check-jsonschema's vendored copy), and what it
runs against what the issue asks: native builds and `make test` on Windows and both Macs, with
Blender 4.2 LTS and the newest release, the zips kept as artifacts."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]
WORKFLOW = ROOT / ".github" / "workflows" / "platforms.yml"
sys.path.insert(0, str(ROOT / "tests"))
from run_blenders import VERSIONS  # noqa: E402  (the Blender releases the Linux tests cover)


def test_the_workflow_is_a_valid_github_actions_workflow():
    checker = Path(sys.executable).with_name("check-jsonschema")
    r = subprocess.run(
        [str(checker), "--builtin-schema", "vendor.github-workflows", str(WORKFLOW)], capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 0, r.stdout + r.stderr


def test_the_workflow_tests_every_platform_with_the_oldest_and_newest_blender():
    job = yaml.safe_load(WORKFLOW.read_text())["jobs"]["test"]
    matrix = job["strategy"]["matrix"]
    assert matrix["os"] == ["windows-latest", "macos-14", "macos-13"]
    platforms = {i["os"]: i["platform"] for i in matrix["include"] if "platform" in i}
    assert platforms == {"windows-latest": "windows-x64", "macos-14": "macos-arm64", "macos-13": "macos-x64"}
    lts = min(v for v in VERSIONS if v.startswith("4.2."))
    newest = max(VERSIONS, key=lambda v: tuple(map(int, v.split("."))))
    assert matrix["bpy"] == [lts, newest]
    runs = [s.get("run", "") for s in job["steps"]]
    assert any(r.startswith("make test PLATFORM=${{ matrix.platform }}") for r in runs)
    upload = next(s for s in job["steps"] if s.get("uses", "").startswith("actions/upload-artifact"))
    assert "dist/*.zip" in upload["with"]["path"]

"""A user's shell, for the tests that run commands exactly as the docs tell users to type them:
`blender` (fake_blender.py, with the `bpy` module: there is no Blender binary here) and `python`
(this virtual environment's) first on the PATH, and a Blender user folder of its own.

A fresh user folder has Blender's default online repository (extensions.blender.org) switched
off: these tests have no network, and Blender would try it on every `--sync`.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def bin_folder(folder: Path) -> Path:
    """`folder` with `blender` and `python` scripts that run the fake Blender and this Python."""
    folder.mkdir(parents=True, exist_ok=True)
    scripts = {
        "blender": f'#!/bin/sh\nexec "{sys.executable}" "{HERE / "fake_blender.py"}" "$@"\n',
        "python": f'#!/bin/sh\nexec "{sys.executable}" "$@"\n',
    }
    for name, text in scripts.items():
        path = folder / name
        path.write_text(text)
        path.chmod(0o755)
    return folder


def fresh_user_folder(folder: Path) -> Path:
    """An empty Blender user folder whose preferences have the online repository switched off."""
    folder.mkdir(parents=True, exist_ok=True)
    script = (
        "import bpy, os\n"
        "for repo in bpy.context.preferences.extensions.repos:\n"
        "    repo.enabled = repo.module != 'blender_org'\n"
        "bpy.ops.wm.save_userpref()\n"
        "os._exit(0)\n"
    )
    r = subprocess.run([sys.executable, "-c", script], env=environment(folder, None), capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    # The wheels' folder exists before any command starts with it on PYTHONPATH: Python would
    # otherwise remember at startup that the path holds nothing, and a wheel Blender installs
    # there later in the same process would not be found (Blender adds the folder to sys.path
    # itself only when it is not there yet).
    site_packages(folder).mkdir(parents=True, exist_ok=True)
    return folder


def site_packages(user: Path) -> Path:
    """Where Blender installs the wheels of the user folder's extensions."""
    return user / "extensions" / ".local" / "lib" / f"python{sys.version_info[0]}.{sys.version_info[1]}" / "site-packages"


def environment(user: Path, bin_dir: Path | None) -> dict[str, str]:
    """The environment of a command: the user folder, its extensions' wheels first on the path (as
    conftest.py does for the tests' own user folder: no other `dqskin` may be imported), and the
    shell's `blender`, `python` and this environment's programs first on the PATH."""
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(user), PYTHONPATH=str(site_packages(user)))
    if bin_dir is not None:
        # This virtual environment's programs too (`openjd`), as an activated one puts them.
        env["PATH"] = os.pathsep.join([str(bin_dir), str(Path(sys.executable).parent), env.get("PATH", "")])
    return env


def run(command: str, cwd: Path, user: Path, bin_dir: Path, timeout: float = 900) -> subprocess.CompletedProcess:
    """Runs shell text (one or more lines) in bash, stopping at the first failing line."""
    return subprocess.run(
        ["bash", "-e", "-o", "pipefail", "-c", command],
        cwd=cwd,
        env=environment(user, bin_dir),
        capture_output=True,
        text=True,
        timeout=timeout,
    )

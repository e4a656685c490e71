"""`make test-blenders`: the Blender tests on other Blender releases than the pinned one.

Each release gets its own virtual environment, `.venvs/bpy-VERSION/`, with its own CPython (3.11
up to Blender 5.0, 3.13 from 5.1) and its `bpy` wheel from PyPI, and the Linux extension zip
from `dist/` installed into its own Blender user folder (`.venvs/bpy-VERSION/user`), which puts
the zip's `dqskin` wheel into that folder's extension site-packages; then `tests/blender` runs
there, on that module, with DQSKIN_BLENDER_USER pointing at the folder. Usage: python tests/run_blenders.py [--full] [VERSION ...] (default: all of VERSIONS; --full runs
every file on every release).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# Release -> (CPython it needs, extra requirements). The pinned release (requirements-dev.txt)
# runs under `make test`. bpy 4.4.0 was built against NumPy 1 but lets pip pick NumPy 2.
# The oldest release runs every test file (as the pinned one does); the others run CORE_FILES
# (see there) and their EXTRA unless --full is given.
VERSIONS = {
    "4.2.23": ("3.11", []),
    "4.3.0": ("3.11", ["numpy<2"]),
    "4.4.0": ("3.11", ["numpy<2"]),
    "4.5.15": ("3.11", []),
    "5.1.2": ("3.13", []),
    "5.2.3": ("3.13", []),
}
# What the Blender tests need besides bpy, pinned as in requirements-dev.txt: pytest, and openjd-cli
# (with PyYAML) for the farm template.
TEST_TOOLS = [
    line.strip() for line in (ROOT / "requirements-dev.txt").read_text().splitlines() if line.startswith(("pytest==", "openjd-cli=="))
]


def python_for(minor: str) -> str:
    """A working CPython `minor`: pyenv's newest (its shims may not be active), else the PATH's."""
    pyenv = Path(os.environ.get("PYENV_ROOT", Path.home() / ".pyenv"))
    candidates = [str(p) for p in sorted(pyenv.glob(f"versions/{minor}.*/bin/python{minor}"), reverse=True)]
    if shutil.which(f"python{minor}"):
        candidates.append(shutil.which(f"python{minor}"))
    for exe in candidates:
        if subprocess.run([exe, "--version"], capture_output=True).returncode == 0:
            return exe
    raise SystemExit(f"CPython {minor} is needed for these Blender releases (e.g. pyenv install {minor})")


def run(cmd, **kw) -> None:
    print("+", " ".join(map(str, cmd)), flush=True)
    subprocess.run(cmd, check=True, **kw)


def prepare(version: str, minor: str, extras: list[str]) -> Path:
    venv = ROOT / ".venvs" / f"bpy-{version}"
    py = venv / "bin" / "python"
    stamp = venv / "bpy-installed"
    wanted = " ".join([version, *TEST_TOOLS, *extras])
    if not stamp.exists() or stamp.read_text() != wanted:
        if not stamp.exists():
            shutil.rmtree(venv, ignore_errors=True)
            run([python_for(minor), "-m", "venv", str(venv)])
        run([str(py), "-m", "pip", "install", "--quiet", f"bpy=={version}", *TEST_TOOLS, *extras])
        stamp.write_text(wanted)
    zips = sorted((ROOT / "dist").glob("dq_skin-*-linux_x64.zip"))
    if len(zips) != 1:
        raise SystemExit(f"expected one Linux extension zip in dist/, found {zips}: run `make addon` first")
    # A dqskin of its own in the venv (as earlier runs installed) would only be shadowed; take it out.
    run([str(py), "-m", "pip", "uninstall", "--quiet", "--yes", "dqskin"])
    run([str(py), str(ROOT / "addon" / "install.py"), str(zips[0]), str(venv / "user")], cwd=venv)
    return venv


FULL = ("4.2.23",)
# The newest release also runs, beyond the core files, what depends on Blender's extension
# system as it is there: installing from the extension repository, the launcher finding the
# extension, and the docs' examples that do both.
EXTRA = {"5.2.3": ("test_extension_repository.py", "test_docs_examples.py")}

# What differs between releases and what these files exercise: the memory readers' struct layouts
# (test_pose_memory, test_production), the evaluation routes, node groups and drivers (test_feed,
# test_modifier, test_painting), DQ Skin's own methods wherever artists work (simulations, brushes,
# Edit Mode, exports, Apply: test_own_methods_everywhere; Rigify: test_rigify_centers), what a
# node without the extension renders (test_preflight), the kernels against the Armature modifier
# (test_exactness, test_optimized_centers, test_animation), bakes, renders, the UI's data and the
# package. Left out here, run on the oldest and the pinned releases: the Armature modifier's
# hand-overs (test_consumers), everyday scenarios and faults, the command lines, farms, the
# docs' examples, extension repositories and weights, which use those same mechanisms. About 4
# minutes a release here instead of 10 (CI's time limit; docs/building.md).
CORE_FILES = (
    "test_animation.py",
    "test_bake.py",
    "test_exactness.py",
    "test_feed.py",
    "test_modifier.py",
    "test_optimized_centers.py",
    "test_own_methods_everywhere.py",
    "test_packaging.py",
    "test_painting.py",
    "test_pose_memory.py",
    "test_preflight.py",
    "test_production.py",
    "test_render.py",
    "test_rigify_centers.py",
    "test_where_artists_look.py",
)


def main(argv: list[str]) -> int:
    full = "--full" in argv
    argv = [a for a in argv if a != "--full"]
    chosen = argv or list(VERSIONS)
    unknown = [v for v in chosen if v not in VERSIONS]
    if unknown:
        raise SystemExit(f"unknown Blender release(s) {unknown}; known: {list(VERSIONS)}")
    results = {}
    for version in chosen:
        t = time.perf_counter()
        venv = prepare(version, *VERSIONS[version])
        failed = run_files(venv, None if full or version in FULL else CORE_FILES + EXTRA.get(version, ()))
        results[version] = (failed, time.perf_counter() - t)
    print("\nBlender release  result   time")
    for version, (failed, seconds) in results.items():
        print(f"{version:<16} {'passed' if not failed else 'FAILED':<8} {seconds:5.0f} s  {' '.join(failed)}")
    return 0 if not any(failed for failed, _ in results.values()) else 1


# A test file that takes longer than this has hung (the longest takes about 3 minutes).
FILE_TIMEOUT = 900


def run_files(venv: Path, only: tuple[str, ...] | None) -> list[str]:
    """Each test file of tests/blender (or those named in `only`) in a pytest process of its own
    (as `make test` runs them in one): a crash inside one Blender release's bpy module then costs
    that file, not the files after it, and says which file it was. Returns the files that failed."""
    env = dict(os.environ, DQSKIN_BLENDER_USER=str(venv / "user"))
    failed = []
    paths = sorted((ROOT / "tests" / "blender").glob("test_*.py"))
    missing = set(only or ()) - {p.name for p in paths}
    if missing:
        raise SystemExit(f"CORE_FILES names files that do not exist: {sorted(missing)}")
    for path in paths:
        if only is not None and path.name not in only:
            continue
        t = time.perf_counter()
        cmd = [str(venv / "bin" / "python"), "-m", "pytest", "-q", "-p", "no:cacheprovider", str(path.relative_to(ROOT))]
        try:
            code = subprocess.run(cmd, cwd=ROOT, env=env, timeout=FILE_TIMEOUT).returncode
        except subprocess.TimeoutExpired:  # (subprocess.run kills the process)
            code = f"timed out after {FILE_TIMEOUT} s"
        print(f"  {path.name}: {'passed' if code == 0 else f'FAILED ({code})'} in {time.perf_counter() - t:.0f} s", flush=True)
        if code != 0:
            failed.append(path.name)
    return failed


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

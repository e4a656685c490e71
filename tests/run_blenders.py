"""`make test-blenders`: the Blender tests on other Blender releases than the pinned one.

Each release gets its own virtual environment, `.venvs/bpy-VERSION/`, with its own CPython (3.11
up to Blender 5.0, 3.13 from 5.1) and its `bpy` wheel from PyPI, and the Linux extension zip
from `dist/` installed into its own Blender user folder (`.venvs/bpy-VERSION/user`), which puts
the zip's `dqskin` wheel into that folder's extension site-packages; then `tests/blender` runs
there, on that module, with DQSKIN_BLENDER_USER pointing at the folder. Usage: python tests/run_blenders.py [--full] [VERSION ...] (default: all of VERSIONS; --full runs
every file on every release; --pinned runs every file on the pinned release in this Python, as
`make test` does; DQSKIN_TEST_JOBS=N runs N files at once, two by default).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import NamedTuple

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


class Target(NamedTuple):
    """Where one release's tests run: its Python, and its Blender user folder with the
    extension installed (None: conftest.py's default, .blender_user/)."""

    python: Path
    user: Path | None


# The name the pinned release's results go under.
PINNED = "pinned"


def prepare(version: str, minor: str, extras: list[str]) -> Target:
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
    return Target(py, venv / "user")


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
    pinned = argv == ["--pinned"]
    chosen = [PINNED] if pinned else argv or list(VERSIONS)
    unknown = [v for v in chosen if v not in VERSIONS and not pinned]
    if unknown:
        raise SystemExit(f"unknown Blender release(s) {unknown}; known: {list(VERSIONS)}")
    t = time.perf_counter()
    if pinned:
        # `make test`'s Blender part: the pinned release of requirements-dev.txt, in this Python's
        # environment, on the extension `make setup` installed into .blender_user/ (conftest.py's
        # default), every file.
        targets, full = {PINNED: Target(Path(sys.executable), None)}, True
    else:
        targets = {version: prepare(version, *VERSIONS[version]) for version in chosen}
    jobs = [
        (version, path)
        for version in chosen
        for path in test_files(None if full or version in FULL else CORE_FILES + EXTRA.get(version, ()))
    ]
    results = run_jobs(targets, jobs)
    print("\nBlender release  result   time in its files")
    for version in chosen:
        mine = [(name, r) for (v, name), r in results.items() if v == version]
        failed = [name for name, (ok, _) in mine if not ok]
        seconds = sum(s for _, (_, s) in mine)
        print(f"{version:<16} {'passed' if not failed else 'FAILED':<8} {seconds:5.0f} s  {' '.join(failed)}")
    print(f"{len(jobs)} files in {time.perf_counter() - t:.0f} s, {workers()} at a time")
    return 0 if all(ok for ok, _ in results.values()) else 1


# A test file that takes longer than this has hung (the longest takes about 3 minutes).
FILE_TIMEOUT = 900
# Files measured to take longest (about 1-3 minutes each, where the others take seconds): they
# start first, so that the last minutes of a run are not one of them alone.
LONG_FILES = ("test_own_methods_everywhere.py", "test_cli.py", "test_consumers.py", "test_docs_examples.py", "test_everyday.py")


def workers() -> int:
    """How many test files run at once: DQSKIN_TEST_JOBS, else two (each is one Blender process,
    mostly one thread busy; CI's machines have two cores or more)."""
    wanted = os.environ.get("DQSKIN_TEST_JOBS", "2")
    if not wanted.isdigit() or int(wanted) < 1:
        raise SystemExit(f"DQSKIN_TEST_JOBS must be a whole number of at least 1, not {wanted!r}")
    return int(wanted)


def test_files(only: tuple[str, ...] | None) -> list[Path]:
    """The test files of tests/blender, or those named in `only`."""
    paths = sorted((ROOT / "tests" / "blender").glob("test_*.py"))
    missing = set(only or ()) - {p.name for p in paths}
    if missing:
        raise SystemExit(f"CORE_FILES names files that do not exist: {sorted(missing)}")
    return [p for p in paths if only is None or p.name in only]


def run_jobs(targets: dict[str, Target], jobs: list[tuple[str, Path]]) -> dict[tuple[str, str], tuple[bool, float]]:
    """Each (release, test file) in a pytest process of its own (as `make test` runs them in one),
    `workers()` at a time: a crash inside one Blender release's bpy module then costs that file,
    not the files after it, and says which file it was. A file's output goes to a log in
    target/blender-tests/RELEASE/ and is printed when it fails. Returns (passed, seconds) per release and file."""
    order = sorted(jobs, key=lambda job: job[1].name not in LONG_FILES)  # stable: long ones first

    def run_one(job: tuple[str, Path]) -> tuple[bool, float]:
        version, path = job
        target = targets[version]
        log = ROOT / "target" / "blender-tests" / version / f"{path.stem}.log"
        log.parent.mkdir(parents=True, exist_ok=True)
        env = dict(os.environ)
        if target.user is not None:
            env["DQSKIN_BLENDER_USER"] = str(target.user)
        # A temporary directory of the file's own, removed after it: each bpy process makes a
        # session directory there (Blender's `blender_XXXXXX`) that it does not remove when pytest
        # ends it, and the tests' Blender subprocesses theirs (thousands a run otherwise left in /tmp).
        tmp = tempfile.mkdtemp(prefix="dqs-")  # (short: the tests check messages that name paths)
        env["TMPDIR"] = tmp
        cmd = [str(target.python), "-m", "pytest", "-q", "-p", "no:cacheprovider", str(path.relative_to(ROOT))]
        t = time.perf_counter()
        with log.open("w") as out:
            try:
                code = subprocess.run(cmd, cwd=ROOT, env=env, stdout=out, stderr=subprocess.STDOUT, timeout=FILE_TIMEOUT).returncode
            except subprocess.TimeoutExpired:  # (subprocess.run kills the process)
                code = f"timed out after {FILE_TIMEOUT} s"
            finally:
                shutil.rmtree(tmp, ignore_errors=True)
        seconds = time.perf_counter() - t
        lines = log.read_text(errors="replace").splitlines()
        summary = next((line.strip() for line in reversed(lines) if line.strip()), "")  # pytest's "N passed in …"
        print(f"  {version} {path.name}: {'passed' if code == 0 else f'FAILED ({code})'} in {seconds:.0f} s ({summary})", flush=True)
        if code != 0:
            print("\n".join(f"    | {line}" for line in lines[-120:]), flush=True)
        return code == 0, seconds

    with ThreadPoolExecutor(max_workers=workers()) as pool:
        return {(v, p.name): r for (v, p), r in zip(order, pool.map(run_one, order), strict=True)}


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

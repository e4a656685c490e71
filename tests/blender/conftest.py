"""Headless Blender tests on the `bpy` wheel, using the DQ Skin extension as users install it.

`make setup` builds the extension zip and installs it into `.blender_user/` (ignored by git);
here BLENDER_USER_RESOURCES points there before bpy is imported, and the extension is enabled the
way any installed extension is: `addon_utils.enable("bl_ext.user_default.dq_skin")`. Every test
starts from an empty factory scene.

The compiled core these tests run is the one from the zip: the `dqskin` wheel that Blender
installed into the user folder's extension site-packages. Any other `dqskin` on the path (the
editable one `maturin develop` puts in .venv for tests/python) is taken off `sys.path` before
`bpy` is imported, and the extension's site-packages goes first on the PYTHONPATH of every
process the tests start (`python -m dqskin.blender`, scripts opening saved files), so none of
them can pick up another copy. test_packaging.py checks which file was imported.
"""

from __future__ import annotations

import gc
import os
import signal
import sys
import threading
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
# The Blender user folder with the extension installed (`make setup` fills .blender_user/; the
# tests of other Blender versions use their own, see the Makefile's test-blenders).
USER = Path(os.environ.get("DQSKIN_BLENDER_USER", ROOT / ".blender_user"))
ASSETS = ROOT.parent / "shared" / "assets"
# Where Blender puts the wheels of installed extensions (addon_utils: `.local/lib/pythonX.Y/site-packages`).
EXTENSION_SITE_PACKAGES = USER / "extensions" / ".local" / "lib" / f"python{sys.version_info[0]}.{sys.version_info[1]}" / "site-packages"

if "dqskin" in sys.modules:
    raise pytest.UsageError(
        f"dqskin was imported from {sys.modules['dqskin'].__file__} before the Blender tests: run tests/blender in its "
        "own pytest process (make test does), so that they use the module of the installed extension"
    )
sys.path[:] = [p for p in sys.path if not (Path(p or ".") / "dqskin" / "__init__.py").is_file()]
os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, [str(EXTENSION_SITE_PACKAGES), os.environ.get("PYTHONPATH")]))
os.environ["BLENDER_USER_RESOURCES"] = str(USER)

import bpy  # noqa: E402  (after BLENDER_USER_RESOURCES)

# Tests send SIGINT to their subprocesses, as Ctrl-C does: a shell that starts this run in the
# background without job control has SIGINT ignored (POSIX), which children would inherit.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

EXTENSION = "bl_ext.user_default.dq_skin"


@pytest.fixture(scope="session")
def dq_skin():
    """The enabled extension module."""
    import addon_utils

    if not (USER / "extensions" / "user_default" / "dq_skin").is_dir():
        pytest.fail(f"the DQ Skin extension is not installed in {USER}: run `make setup`")
    module = addon_utils.enable(EXTENSION, default_set=True)
    assert module is not None, f"{EXTENSION} could not be enabled"
    return module


@pytest.fixture(autouse=True)
def empty_scene(dq_skin):
    """A fresh, empty factory scene for every test (the extension stays enabled).

    The collection afterwards finalizes the previous test's garbage here rather than inside
    some import of this test: on CPython 3.11 an import that a finalizer starts in the middle of
    another import can fail with `KeyError` in importlib (python/cpython#91351, fixed in 3.12);
    Cycles' `CyclesRender.__del__` imports, and did so once inside the glTF importer (bpy 4.5)."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    gc.collect()
    yield


@pytest.fixture(autouse=True)
def no_python_thread(dq_skin):
    """No test leaves a Python thread running: one running Python beside Blender's operators
    crashes the bpy module within seconds (docs/architecture.md), so DQ Skin runs none (its
    long work runs on the core's own threads, `dqskin.Job`)."""
    before = set(threading.enumerate())
    yield
    started = [t.name for t in set(threading.enumerate()) - before if t.is_alive()]
    assert not started, f"Python threads left running: {started}"


def node_route_for_every_size(dq_skin, monkeypatch) -> None:
    """Characters of every size take the result-object route where nothing needs a deform-only
    modifier (by default only those above `decisions.CACHE_ROUTE_VERTICES` do), so that the small
    test characters exercise it."""
    monkeypatch.setattr(dq_skin.model.decisions, "CACHE_ROUTE_VERTICES", 0)


@pytest.fixture(autouse=True)
def _node_route_for_rigs(request, dq_skin, monkeypatch):
    """Tests parametrized with `rig` "B-Bones, node route" (`scenes.RIGS`) run with
    `node_route_for_every_size`."""
    callspec = getattr(request.node, "callspec", None)
    if callspec is not None and callspec.params.get("rig") == "B-Bones, node route":
        node_route_for_every_size(dq_skin, monkeypatch)
    yield


@pytest.fixture
def assets() -> Path:
    if not ASSETS.is_dir():
        pytest.fail(f"the shared test characters are missing: {ASSETS}")
    return ASSETS


# The Blender tests' process ends once pytest has reported and returned its status, before the
# bpy module's C++ static destructors run, which fail in released Blenders with or without DQ
# Skin (gdb on the processes): Blender 4.2 frees Python-defined classes (the glTF exporter's)
# after Python has finalized, a segfault on exit once a glTF export ran (~SpaceType ->
# bpy_class_free -> PyGILState_Ensure); Blender 4.5 can hang on exit for good, its delayed-close
# thread still waiting on the condition variable that ~GlobalState destroys (what ran the last
# CI past its time limit). The launcher of the batch commands skips the same teardown after a
# signal.
_STATUS = pytest.StashKey[int]()


def pytest_sessionfinish(session, exitstatus):
    session.config.stash[_STATUS] = int(exitstatus)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(config.stash.get(_STATUS, 1))

"""Headless Blender tests on the `bpy` wheel, using the DQ Skin extension as users install it.

`make setup` builds the extension zip and installs it into `.blender_user/` (ignored by git);
here BLENDER_USER_RESOURCES points there before bpy is imported, and the extension is enabled the
way any installed extension is: `addon_utils.enable("bl_ext.user_default.dq_skin")`. Every test
starts from an empty factory scene.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
# The Blender user folder with the extension installed (`make setup` fills .blender_user/; the
# tests of other Blender versions use their own, see the Makefile's test-blenders).
USER = Path(os.environ.get("DQSKIN_BLENDER_USER", ROOT / ".blender_user"))
ASSETS = ROOT.parent / "shared" / "assets"
os.environ["BLENDER_USER_RESOURCES"] = str(USER)

import bpy  # noqa: E402  (after BLENDER_USER_RESOURCES)

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
    """A fresh, empty factory scene for every test (the extension stays enabled)."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    yield


@pytest.fixture
def assets() -> Path:
    if not ASSETS.is_dir():
        pytest.fail(f"the shared test characters are missing: {ASSETS}")
    return ASSETS

"""The Blender tests run the compiled core from the installed extension zip: the `dqskin` wheel
Blender put into the user folder's extension site-packages, not the editable module of .venv
(conftest.py takes every other copy off the path), in this process and in those it starts."""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import dqskin
from conftest import EXTENSION_SITE_PACKAGES, ROOT

DIST = ROOT / "dist"


def test_the_core_is_the_one_blender_installed_from_the_zip(dq_skin):
    assert Path(dqskin.__file__).is_relative_to(EXTENSION_SITE_PACKAGES), dqskin.__file__
    assert Path(dqskin._dqskin.__file__).is_relative_to(EXTENSION_SITE_PACKAGES), dqskin._dqskin.__file__
    # The add-on's `from . import dqskin` is that package itself, not a second copy.
    assert dq_skin.dqskin is dqskin and sys.modules[f"{dq_skin.__name__}.dqskin"] is dqskin
    from bl_ext.user_default.dq_skin.dqskin import pc2

    assert pc2 is dqskin.pc2
    # Byte for byte the module inside the wheel of the zip that was installed (as in dist/).
    installed = tomllib.loads((Path(dq_skin.__file__).parent / "blender_manifest.toml").read_text())
    (wheel,) = installed["build"]["generated"]["wheels"]
    with zipfile.ZipFile(DIST / Path(wheel).name) as w:
        (module,) = [n for n in w.namelist() if n.startswith("dqskin/_dqskin.") and n.endswith((".so", ".pyd"))]
        assert Path(dqskin._dqskin.__file__).read_bytes() == w.read(module)


def test_no_other_dqskin_is_on_the_path():
    others = [p for p in sys.path if (Path(p or ".") / "dqskin" / "__init__.py").is_file() and Path(p) != EXTENSION_SITE_PACKAGES]
    assert not others, others


def test_processes_started_by_the_tests_import_the_same_core():
    r = subprocess.run(
        [sys.executable, "-c", "import dqskin; print(dqskin._dqskin.__file__)"],
        capture_output=True,
        text=True,
        env=dict(os.environ),
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    assert Path(r.stdout.strip()) == Path(dqskin._dqskin.__file__)

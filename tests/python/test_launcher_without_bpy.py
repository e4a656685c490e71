"""`python -m dqskin.blender` after `pip install dqskin` alone (no `bpy` module): it says what it
needs and how else to run the commands, and exits without a traceback, writing nothing."""

from __future__ import annotations

import subprocess
import sys

import pytest

# `python -m dqskin.blender` where `bpy` cannot be imported (`pip install dqskin` alone): the
# launcher runs with `bpy` made unimportable, as in an environment without it.
WITHOUT_BPY = "import runpy, sys; sys.modules['bpy'] = None; sys.argv[0] = 'dqskin.blender'; runpy.run_module('dqskin.blender', run_name='__main__', alter_sys=True)"


@pytest.mark.parametrize(("args", "code"), [(["--help"], 0), ([], 1), (["bake", "shot.blend", "--object", "Body", "--out", "body.pc2"], 1)])
def test_the_launcher_without_bpy_says_what_it_needs_and_exits_cleanly(args, code, tmp_path):
    r = subprocess.run([sys.executable, "-c", WITHOUT_BPY, *args], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert r.returncode == code, r.stderr
    assert "Traceback" not in r.stderr, r.stderr
    assert "cannot import" in r.stderr and "pip install bpy" in r.stderr and "blender -b --command dq_skin" in r.stderr, r.stderr
    assert not list(tmp_path.iterdir()), "nothing is written"

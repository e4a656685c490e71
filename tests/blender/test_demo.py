"""`make demo`'s Blender part (`addon/demo.py`), run as the README's first command runs it: CesiumMan
with DQ Skin in place of its Armature modifier, each method against Blender's own."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from conftest import USER

ROOT = Path(__file__).resolve().parents[2]


def test_the_demo_runs_and_matches_the_armature_modifier():
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(USER))
    r = subprocess.run([sys.executable, str(ROOT / "addon" / "demo.py")], capture_output=True, text=True, timeout=600, env=env)
    assert r.returncode == 0, r.stdout + r.stderr
    # "method  max deviation  of diagonal  Armature  DQ Skin", one row per method: a method switch
    # that did nothing would leave Dual Quaternion as far from Preserve Volume as Linear is.
    rows = {m: float(of_diagonal) for m, _dev, of_diagonal in re.findall(r"^(Linear|Dual Quaternion)\s+(\S+)\s+(\S+)", r.stdout, re.M)}
    assert set(rows) == {"Linear", "Dual Quaternion"}, r.stdout
    assert all(v < 1e-5 for v in rows.values()), r.stdout

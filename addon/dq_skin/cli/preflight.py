# SPDX-License-Identifier: GPL-3.0-or-later
"""``preflight FILE``: the objects of a file that would render differently on a node without the
DQ Skin extension (a render farm): every DQ Skin modifier that renders one of DQ Skin's own
methods, unbaked, or whose bake would not play there. Exit code 0 when none would, 3 when some
would (each named, with the reason), as any other command 1 on failure and 2 on wrong usage."""

from __future__ import annotations

import bpy

from ..blender import elsewhere
from ..engine.context import dq_skin_modifiers

DIFFERS = 3  # the exit code when an object would render differently


class Differs(Exception):
    """Objects that would render differently; the message names them."""


def findings() -> list[str]:
    """One line per DQ Skin modifier that renders differently without the extension, over every
    object of every scene that renders (linked ones too)."""
    rendered = {o for scene in bpy.data.scenes for o in scene.objects if not o.hide_render}
    lines = []
    for obj in sorted(rendered, key=lambda o: o.name_full):
        if obj.type != "MESH":
            continue
        for mod in dq_skin_modifiers(obj):
            why = elsewhere.reason(obj, mod, elsewhere.group_weights_of(obj))
            if why:
                lines.append(f"{obj.name_full}: {mod.name} {why}")
    return lines


def run(path: str) -> str:
    """The report for the file loaded from `path` (raises `Differs` with it when anything
    would render differently)."""
    lines = findings()
    if lines:
        raise Differs(f"{len(lines)} object(s) in {path} would render differently without the DQ Skin extension:\n" + "\n".join(lines))
    return f"{path}: every object renders the same without the DQ Skin extension"

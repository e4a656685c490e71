# SPDX-License-Identifier: GPL-3.0-or-later
"""Blender's own command line: `blender -b --command dq_skin compare|bake|apply|merge ...` runs the
batch commands (`batch`), with the same options, exit codes and atomic writes as
`python -m dqskin.blender`."""

from __future__ import annotations

import bpy

from ..session import SESSION
from . import batch

COMMAND = "dq_skin"


def execute(argv) -> int:
    """What Blender runs for `--command dq_skin ARGS...`: its exit code."""
    return batch.main(list(argv), prog=f"blender --command {COMMAND}")


def register() -> None:
    SESSION.commands.append(bpy.utils.register_cli_command(COMMAND, execute))


def unregister() -> None:
    while SESSION.commands:
        bpy.utils.unregister_cli_command(SESSION.commands.pop())

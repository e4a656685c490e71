# SPDX-License-Identifier: GPL-3.0-or-later
"""Blender's own command line: `blender -b --command dq_skin compare|bake|apply|merge ...` runs the
batch commands (`batch`), with the same options, exit codes and atomic writes as
`python -m dqskin.blender`. Blender's `-t N` (`--threads N`) before `--command` sizes DQ Skin's
thread pool too."""

from __future__ import annotations

import sys

import bpy

from ..session import SESSION
from . import batch

COMMAND = "dq_skin"


def blender_threads(argv: list[str]) -> int | None:
    """Blender's `-t N` / `--threads N` from its command line (`sys.argv` in Blender: all of it),
    among the options before `--command`; None if not given or 0 (Blender: one per core)."""
    try:
        end = next(i for i, arg in enumerate(argv) if arg in ("-c", "--command"))
    except StopIteration:
        return None
    threads = None
    for i, arg in enumerate(argv[1:end], 1):
        if arg in ("-t", "--threads") and i + 1 < end:
            try:
                threads = int(argv[i + 1])
            except ValueError:
                pass  # Blender itself refuses it
    return threads if threads and threads > 0 else None


def execute(argv) -> int:
    """What Blender runs for `--command dq_skin ARGS...`: its exit code."""
    return batch.main(list(argv), prog=f"blender --command {COMMAND}", threads=blender_threads(sys.argv))


def register() -> None:
    SESSION.commands.append(bpy.utils.register_cli_command(COMMAND, execute))


def unregister() -> None:
    while SESSION.commands:
        bpy.utils.unregister_cli_command(SESSION.commands.pop())

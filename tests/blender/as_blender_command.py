"""Runs `blender -b --command dq_skin ARGS...` as Blender does, with the bpy module (there is no
Blender binary here): Blender enables the installed extensions, then calls the function the
extension registered with `bpy.utils.register_cli_command` and exits with its return value.
Usage: python as_blender_command.py [-t N] ARGS...: `-t N` is Blender's own option (render
threads), given before `--command` as in `blender -b -t N --command dq_skin ARGS...`; `sys.argv`
is Blender's whole command line, as in Blender."""

import os
import sys

import bpy  # noqa: F401  (first: it makes Blender's own modules importable)

import addon_utils  # noqa: E402

EXTENSION = "bl_ext.user_default.dq_skin"

if addon_utils.enable(EXTENSION, default_set=True) is None:
    sys.exit(f"{EXTENSION} is not installed")
cli = sys.modules[f"{EXTENSION}.cli.command"]
session = sys.modules[EXTENSION].SESSION
# Blender accepted the registration (register_cli_command raises otherwise) under this name.
assert cli.COMMAND == "dq_skin" and len(session.commands) == 1, session.commands
args = sys.argv[1:]
blender_options = args[:2] if args[:1] == ["-t"] else []
args = args[len(blender_options) :]
sys.argv = ["blender", "-b", *blender_options, "--command", cli.COMMAND, *args]
code = cli.execute(args)
# Blender's own exit frees the file's data while Python still runs; the bpy module frees it from
# a C exit hook after Python has finalized, which on 4.2 crashes on any Python driver's compiled
# expression (DQ Skin's feed has one): end as the launcher does, once everything is written.
sys.stdout.flush()
sys.stderr.flush()
os._exit(code)

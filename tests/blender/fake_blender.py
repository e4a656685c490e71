"""Stands in for the `blender` program where the docs' examples run it (there is no Blender binary
here, only the `bpy` module): `blender [-b] [-t N] [--online-mode] [--factory-startup] (--command
NAME ARGS... | --python FILE)`. It starts as Blender does, as far as the examples need: the user's
preferences and add-ons from BLENDER_USER_RESOURCES (unless --factory-startup), online access
with --online-mode, then the command (Blender's own `extension` command, or one that an
installed extension registered, `dq_skin`, called as Blender calls it, exiting with its code) or
the script (exiting with 1 if it raised, as `--python-exit-code 1` makes Blender do).

Tests put a `blender` script that runs this file first on the PATH (see `docs_examples.py`).
"""

import os
import sys

import bpy

import addon_utils  # noqa: E402  (importable once bpy is)

USAGE = "usage: blender [-b] [-t N] [--online-mode] [--factory-startup] (--command NAME [ARGS...] | --python FILE)"


def command_function(name: str):
    """The function `bpy.utils.register_cli_command(name, fn)` registered: Blender's own
    `extension`, or an enabled extension's (found by its `cli.command` module)."""
    if name == "extension":
        import importlib

        return importlib.import_module("bl_pkg.bl_extension_cli").cli_extension_handler
    for module_name, module in list(sys.modules.items()):
        if module_name.startswith("bl_ext.") and module_name.endswith(".cli.command") and getattr(module, "COMMAND", None) == name:
            return module.execute
    return None


def run_script(path: str) -> int:
    """A script, as `blender -b --python FILE` runs it (with `bpy` already imported)."""
    import runpy
    import traceback

    try:
        runpy.run_path(path, run_name="__main__")
    except SystemExit as e:
        return e.code if isinstance(e.code, int) else 0 if e.code is None else 1
    except Exception:
        traceback.print_exc()
        return 1
    return 0


def main(argv: list[str]) -> int:
    factory, online = False, False
    while argv and argv[0] not in ("-c", "--command", "-P", "--python"):
        option = argv.pop(0)
        if option in ("-b", "--background"):
            continue
        if option in ("-t", "--threads") and argv:
            argv.pop(0)  # render threads: Blender's, left in sys.argv for the commands to read
            continue
        if option == "--online-mode":
            online = True
        elif option == "--factory-startup":
            factory = True
        else:
            print(f"fake blender: unsupported option {option!r}\n{USAGE}", file=sys.stderr)
            return 2
    if len(argv) < 2:
        print(USAGE, file=sys.stderr)
        return 2
    name, args = argv[1], argv[2:]
    if not factory and os.path.isfile(os.path.join(bpy.utils.resource_path("USER"), "config", "userpref.blend")):
        if bpy.app.version >= (4, 3):
            bpy.ops.wm.read_userpref()
            addon_utils.reset_all()
        else:
            # Blender 4.2's bpy module crashes in wm.read_userpref: the extensions installed in
            # User Default are enabled instead (what installing them there did); repositories
            # added by the user are not known (the tests that need them skip on 4.2).
            for mod in addon_utils.modules(refresh=True):
                if mod.__name__.startswith("bl_ext.user_default."):
                    addon_utils.enable(mod.__name__, default_set=True)
    if online:
        bpy.context.preferences.system.use_online_access = True
    if argv[0] in ("-P", "--python"):
        return run_script(name)
    run = command_function(name)
    if run is None:
        print(f"Unrecognized command: {name!r} (is the extension that registers it installed and enabled?)", file=sys.stderr)
        return 1
    return run(args)


if __name__ == "__main__":
    code = main(sys.argv[1:])
    # End as Blender's own exit and the launcher do, once everything is written: the bpy module's
    # teardown can crash or hang on some releases (see conftest.py).
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)

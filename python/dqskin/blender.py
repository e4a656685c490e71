"""``python -m dqskin.blender COMMAND ...``: the DQ Skin extension's batch commands (bake, apply,
merge, compare) with the ``bpy`` module, the same as ``blender -b --command dq_skin COMMAND ...``.

This is only a launcher; the commands are the extension's, which must be installed in an
extension repository (user, studio or system; local or remote) of the Blender user folder named
by ``BLENDER_USER_RESOURCES`` (or ``--user-resources DIR``, applied here because it must be set
before ``bpy`` is imported). It imports ``bpy`` when run, never when
``dqskin`` is imported, so the package itself needs no Blender. ``--help`` lists the commands.
"""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

PROG = "python -m dqskin.blender"
# The extension's id; Blender names its module `bl_ext.REPOSITORY.dq_skin` after the repository
# it is installed in (`bl_ext.user_default.dq_skin` from a zip installed as users do). Its entry
# point: `batch.main(argv, prog, launched)`.
EXTENSION_ID = "dq_skin"


def installed_extension(bpy) -> str | None:
    """The module name of DQ Skin as installed in any extension repository of the user's
    preferences (user, studio or system repositories, local or remote), as Blender reads them at
    startup: the one enabled in the preferences first, else the first repository holding it."""
    found = _extension_in_preferences(bpy)
    if found is not None:
        return found
    # The bpy module starts from factory preferences (which know user_default and the system
    # repositories): the user's own repositories are in their userpref.blend. Blender 4.2's bpy
    # module crashes reading it (a segmentation fault in wm.read_userpref), so there DQ Skin is
    # found in the repositories it starts with only.
    userpref = Path(bpy.utils.resource_path("USER")) / "config" / "userpref.blend"
    if userpref.is_file() and bpy.app.version >= (4, 3):
        bpy.ops.wm.read_userpref()
        return _extension_in_preferences(bpy)
    return None


def _extension_in_preferences(bpy) -> str | None:
    """DQ Skin's module in the preferences as they are: enabled first, else installed."""
    import addon_utils

    enabled = [a.module for a in bpy.context.preferences.addons if a.module.startswith("bl_ext.") and a.module.endswith(f".{EXTENSION_ID}")]
    installed = [
        f"bl_ext.{repo.module}.{EXTENSION_ID}"
        for repo in bpy.context.preferences.extensions.repos
        if repo.enabled and (Path(repo.directory) / EXTENSION_ID / "blender_manifest.toml").is_file()
    ]
    known = {m.__name__ for m in addon_utils.modules(refresh=True)}
    return next((name for name in [*enabled, *installed] if name in known), None)


def _user_resources(argv: list[str]) -> str | None:
    """`--user-resources DIR` (or `=DIR`) before the command, as the extension's parser reads it."""
    for i, arg in enumerate(argv):
        if not arg.startswith("-") and not (i and argv[i - 1] == "--threads"):
            return None  # the command: its own options follow
        if arg == "--user-resources" and i + 1 < len(argv):
            return argv[i + 1]
        if arg.startswith("--user-resources="):
            return arg.partition("=")[2]
    return None


# What the launcher says where `bpy` cannot be imported (`pip install dqskin` alone).
NEEDS_BPY = """{prog}: runs the DQ Skin Blender extension's batch commands (bake, apply, merge,
compare) with Blender's `bpy` module, which this Python cannot import ({python}, {version}).
It needs:
  - the `bpy` module of your Blender release in this Python: `pip install bpy==5.0.1` on
    CPython 3.11 (each Blender release has its own; see pypi.org/project/bpy);
  - the DQ Skin extension installed in a Blender user folder, named by BLENDER_USER_RESOURCES or
    --user-resources DIR.
Or run the same commands with Blender itself: blender -b --command dq_skin COMMAND ...
Without Blender, `import dqskin` gives the skinning functions for numpy arrays."""


def _bpy_importable() -> bool:
    """Whether `bpy` can be imported here, without importing it (which starts Blender)."""
    import importlib.util

    return importlib.util.find_spec("bpy") is not None


def _stop(signum, _frame):
    # Before the extension takes over (importing bpy): nothing has been started or written.
    print(f"{PROG}: interrupted ({signal.Signals(signum).name}); nothing written", file=sys.stderr)
    raise SystemExit(128 + signum)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _stop)
    folder = _user_resources(argv)
    if folder:
        os.environ["BLENDER_USER_RESOURCES"] = str(Path(folder).resolve())
    if not _bpy_importable():
        print(NEEDS_BPY.format(prog=PROG, python=sys.executable, version=sys.version.split()[0]), file=sys.stderr)
        return 0 if argv and argv[0] in ("-h", "--help") else 1
    import bpy  # (after BLENDER_USER_RESOURCES)

    import addon_utils

    name = installed_extension(bpy)
    extension = addon_utils.enable(name, default_set=True) if name else None
    if extension is None:
        where = os.environ.get("BLENDER_USER_RESOURCES", "the default Blender user folder")
        print(f"{PROG}: the DQ Skin extension is not installed in any extension repository of {where}", file=sys.stderr)
        return 1
    code = extension.batch.main(argv, prog=PROG, launched=True)
    # The command has written and closed everything: end here, without the bpy module's C++
    # teardown at exit, which takes about half a second with bpy loaded (a command stopped by a
    # signal must stop within a second) and can fail in released Blenders (4.2 segfaults on exit
    # once a glTF export ran; 4.5 can hang on exit for good: see tests/blender/conftest.py), which
    # would make a farm task that did its work fail or never end.
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


if __name__ == "__main__":
    raise SystemExit(main())

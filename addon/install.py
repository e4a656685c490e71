"""Installs a built DQ Skin extension zip into a Blender user folder, the way Blender installs any
extension, and enables it there.

Usage: python addon/install.py ZIP USER_FOLDER. Scripts then use it with BLENDER_USER_RESOURCES
set to USER_FOLDER and `addon_utils.enable("bl_ext.user_default.dq_skin", default_set=True)`.
"""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path


def main() -> int:
    if len(sys.argv) != 3:
        raise SystemExit(__doc__)
    zip_path = Path(sys.argv[1]).resolve()
    user = Path(sys.argv[2]).resolve()
    if not zip_path.is_file():
        raise SystemExit(f"no extension zip at {zip_path} (run make addon)")
    # A clean user folder, so that an older install cannot linger.
    shutil.rmtree(user, ignore_errors=True)
    user.mkdir(parents=True)
    os.environ["BLENDER_USER_RESOURCES"] = str(user)
    import bpy  # noqa: E402  (BLENDER_USER_RESOURCES must be set first)

    result = bpy.ops.extensions.package_install_files(filepath=str(zip_path), repo="user_default", enable_on_install=True)
    if result != {"FINISHED"}:
        raise SystemExit(f"installing {zip_path} failed: {result}")
    bpy.ops.wm.save_userpref()
    import addon_utils

    mod = addon_utils.enable("bl_ext.user_default.dq_skin", default_set=True)
    if mod is None:
        raise SystemExit("the installed extension could not be enabled")
    print(f"installed and enabled {mod.__name__} from {zip_path} in {user}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

# SPDX-License-Identifier: GPL-3.0-or-later
"""DQ Skin: dual quaternion skinning for Blender, exact against the Armature modifier.

Blender glue only: `rig` reads Blender data into arrays for the bundled `dqskin` module (the Rust
core), which does all the math.
"""

from . import rig  # noqa: F401  (imported so that a broken bundle fails at enable time)


def register():
    pass


def unregister():
    pass

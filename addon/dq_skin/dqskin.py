# SPDX-License-Identifier: GPL-3.0-or-later
"""The compiled core: the `dqskin` wheel this extension bundles (listed in its manifest; Blender
installs it into the extensions' site-packages). The add-on's modules write `from . import
dqskin` and `from .dqskin import pc2`; this module makes both the very package the wheel
installed (not a copy), so there is one `dqskin` in the process."""

import sys

import dqskin
import dqskin.memory  # noqa: F401  (the memory readers: `dqskin.memory`)
import dqskin.pc2  # noqa: F401  (an attribute of the package, for `from .dqskin import pc2`)

sys.modules[__name__] = dqskin

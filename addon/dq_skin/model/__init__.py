# SPDX-License-Identifier: GPL-3.0-or-later
"""Plain data and pure decisions: what the add-on knows about each DQ Skin modifier, the keys
that say when something must be computed again, and the choices made from them. Nothing here
imports Blender, so `tests/python` tests it as it is."""

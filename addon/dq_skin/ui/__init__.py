# SPDX-License-Identifier: GPL-3.0-or-later
"""The DQ Skin panel and menus."""

# SPDX-License-Identifier: GPL-3.0-or-later
"""The animation tools and the comparison scene."""

# SPDX-License-Identifier: GPL-3.0-or-later
"""The operators artists run on DQ Skin modifiers, and the weighting operators."""

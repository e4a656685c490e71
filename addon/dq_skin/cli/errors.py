# SPDX-License-Identifier: GPL-3.0-or-later
"""The batch commands' one failure: a one-line reason to stop with exit code 1."""

from __future__ import annotations


class Failure(Exception):
    """A one-line reason to stop with a non-zero exit code."""

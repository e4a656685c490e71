# SPDX-License-Identifier: GPL-3.0-or-later
"""One object for each distinct content of what characters of one rig read alike: the bone
names, rest matrices, envelope rows and segment counts of a binding, the vertex-group names of
a mesh. A crowd of 200 characters on copies of one rig keeps one of each instead of 200 (a
crowd keeps every byte a character once per character)."""

from __future__ import annotations

import numpy as np


class Interned:
    """`interned(value)`: the first value of that content seen (`value` itself if new). Arrays
    kept are made read-only, since every character holding one shares it; lists are never
    changed by their holders. Owned by the session; forgotten with it, and wholesale past
    `LIMIT` distinct contents (sharing is only a saving: forgetting never changes a result)."""

    LIMIT = 1024

    def __init__(self):
        self._kept: dict = {}

    def __call__(self, value):
        key = _content(value)
        got = self._kept.get(key)
        if got is not None:
            return got
        if len(self._kept) >= self.LIMIT:
            self._kept.clear()
        if isinstance(value, np.ndarray):
            value.flags.writeable = False
        self._kept[key] = value
        return value

    def __len__(self) -> int:
        return len(self._kept)

    def forget(self) -> None:
        self._kept.clear()


def _content(value) -> tuple:
    if isinstance(value, np.ndarray):
        return ("array", value.dtype.str, value.shape, value.tobytes())
    if isinstance(value, (list, tuple)):
        return (type(value).__name__, tuple(value))
    raise TypeError(f"Interned keeps arrays, lists and tuples, not {type(value).__name__}")

# SPDX-License-Identifier: GPL-3.0-or-later
"""One object for each distinct content of what characters of one rig read alike: the bone
names, rest matrices, envelope rows and segment counts of a binding, the vertex-group names of
a mesh. A crowd of 200 characters on copies of one rig keeps one of each instead of 200 (a
crowd keeps every byte a character once per character)."""

from __future__ import annotations

import weakref

import numpy as np


class Interned:
    """`interned(value)`: the first value of that content seen (`value` itself if new). Arrays
    kept are made read-only, since every character holding one shares it, and go when no
    character holds them any more (a rig edited again and again leaves nothing behind); lists
    and tuples of names are never changed by their holders and are kept up to `LIMIT` contents,
    then all forgotten (sharing is only a saving: forgetting never changes a result). Owned by
    the session and forgotten with it."""

    LIMIT = 256

    def __init__(self):
        self._arrays = weakref.WeakValueDictionary()
        self._names: dict = {}

    def __call__(self, value):
        key = _content(value)
        kept = self._arrays if isinstance(value, np.ndarray) else self._names
        got = kept.get(key)
        if got is not None:
            return got
        if kept is self._names and len(kept) >= self.LIMIT:
            kept.clear()
        if isinstance(value, np.ndarray):
            value.flags.writeable = False
        kept[key] = value
        return value

    def __len__(self) -> int:
        return len(self._arrays) + len(self._names)

    def forget(self) -> None:
        self._arrays.clear()
        self._names.clear()


def _content(value) -> tuple:
    if isinstance(value, np.ndarray):
        return (value.dtype.str, value.shape, value.tobytes())
    if isinstance(value, (list, tuple)):
        return (type(value).__name__, tuple(value))
    raise TypeError(f"Interned keeps arrays, lists and tuples, not {type(value).__name__}")

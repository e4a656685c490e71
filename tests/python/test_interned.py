"""The session's table of shared contents (`model.interned`): what characters of one rig read
alike is kept once, never altered, and forgetting it only costs memory."""

from __future__ import annotations

import gc

import addon_modules
import numpy as np
import pytest

Interned = addon_modules.load("model", "interned").Interned


def test_equal_contents_give_the_first_object_and_different_ones_their_own():
    interned = Interned()
    rest = np.arange(32, dtype=np.float32).reshape(2, 4, 4)
    assert interned(rest) is rest
    assert interned(rest.copy()) is rest
    other = rest.copy()
    other[1, 3, 3] = 2.0
    assert interned(other) is other
    # The same bytes of another shape or type are another content.
    reshaped, as_int = interned(rest.reshape(4, 8).copy()), interned(rest.view(np.int32).copy())
    assert reshaped is not rest and as_int is not rest and as_int is not reshaped
    names = ["Hips", "Spine"]
    assert interned(names) is names and interned(["Hips", "Spine"]) is names
    assert interned(("Hips", "Spine")) is not names  # a tuple is not a list
    assert len(interned) == 6


def test_what_is_shared_cannot_be_changed_through_one_holder():
    interned = Interned()
    rows = interned(np.ones((3, 11), np.float32))
    with pytest.raises(ValueError):
        rows[0, 0] = 2.0


def test_arrays_go_when_no_holder_keeps_them_and_names_past_the_limit():
    interned = Interned()
    held = [interned(np.full(4, k, np.float32)) for k in range(8)]
    for k in range(8, 100):
        interned(np.full(4, k, np.float32))  # (a content nobody holds: an edited rig's old one)
    gc.collect()
    assert len(interned) == len(held)
    assert all(interned(np.full(4, k, np.float32)) is held[k] for k in range(8))
    names = [interned([f"Bone{k}", "Spine"]) for k in range(Interned.LIMIT)]
    assert interned(["Bone0", "Spine"]) is names[0]
    again = interned(["Bone", "Head"])  # one more: the names start again
    assert interned(["Bone0", "Spine"]) is not names[0] and interned(["Bone", "Head"]) is again
    assert len(interned) <= len(held) + Interned.LIMIT
    interned.forget()
    assert len(interned) == 0


def test_other_values_are_refused_by_name():
    with pytest.raises(TypeError, match="dict"):
        Interned()({"a": 1})

"""The session's table of shared contents (`model.interned`): what characters of one rig read
alike is kept once, never altered, and forgetting it only costs memory."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


def _interned_module():
    # (The model imports nothing of Blender's: loaded on its own, outside the add-on package.)
    spec = importlib.util.spec_from_file_location("dq_skin_model_interned", ROOT / "addon" / "dq_skin" / "model" / "interned.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


Interned = _interned_module().Interned


def test_equal_contents_give_the_first_object_and_different_ones_their_own():
    interned = Interned()
    rest = np.arange(32, dtype=np.float32).reshape(2, 4, 4)
    assert interned(rest) is rest
    assert interned(rest.copy()) is rest
    other = rest.copy()
    other[1, 3, 3] = 2.0
    assert interned(other) is other
    # The same bytes of another shape or type are another content.
    assert interned(rest.reshape(4, 8).copy()) is not rest
    assert interned(rest.view(np.int32).copy()) is not rest
    names = ["Hips", "Spine"]
    assert interned(["Hips", "Spine"]) is not names and interned(list(names)) == names
    assert interned(("Hips", "Spine")) is not interned(["Hips", "Spine"])  # a tuple is not a list
    assert len(interned) == 6


def test_what_is_shared_cannot_be_changed_through_one_holder():
    interned = Interned()
    rows = interned(np.ones((3, 11), np.float32))
    with pytest.raises(ValueError):
        rows[0, 0] = 2.0


def test_past_its_limit_it_starts_again_and_still_gives_equal_contents():
    interned = Interned()
    first = interned(np.zeros(4, np.float32))
    for k in range(1, Interned.LIMIT + 1):
        interned(np.full(4, k, np.float32))
    assert len(interned) <= Interned.LIMIT
    again = interned(np.zeros(4, np.float32))
    np.testing.assert_array_equal(again, first)
    interned.forget()
    assert len(interned) == 0


def test_other_values_are_refused_by_name():
    with pytest.raises(TypeError, match="dict"):
        Interned()({"a": 1})

"""The typed keys of the add-on's model (`model.keys`): equal inputs give equal keys and a changed
input another key, and what a character keeps for the whole session stays small."""

from __future__ import annotations

import addon_modules
import numpy as np

PoseKey = addon_modules.load("model", "keys").PoseKey


def _pose(bones: int, seed: int = 7) -> np.ndarray:
    return np.random.default_rng(seed).standard_normal((bones, 4, 4)).astype(np.float32)


def test_a_pose_key_from_matrices_follows_every_bit_of_them():
    pose = _pose(19)
    key = PoseKey.of_matrices(pose)
    assert key == PoseKey.of_matrices(pose.copy()) and hash(key) == hash(PoseKey.of_matrices(pose.copy()))
    for bone, row, column in [(0, 0, 0), (18, 3, 3), (9, 1, 2)]:
        moved = pose.copy()
        moved[bone, row, column] = np.nextafter(moved[bone, row, column], np.float32(np.inf))
        assert PoseKey.of_matrices(moved) != key, (bone, row, column)
    assert PoseKey.of_matrices(pose[:18].copy()) != key  # a bone fewer
    assert not key.from_memory


def test_a_pose_key_keeps_a_digest_not_the_matrices():
    # A character keeps its last frame's key all session: one 64-bit digest, whatever its bone
    # count (a Rigify character's matrices are about 10 KB).
    for bones in (1, 19, 170):
        key = PoseKey.of_matrices(_pose(bones))
        assert isinstance(key.matrices_digest, int) and -(2**63) <= key.matrices_digest < 2**63
        assert key == PoseKey(matrices_digest=key.matrices_digest)  # (it holds nothing else)


def test_a_pose_key_from_memory_is_its_signatures():
    key = PoseKey(pose_signature=5, binding_signature=9)
    assert key.from_memory and key == PoseKey(pose_signature=5, binding_signature=9)
    assert key != PoseKey(pose_signature=6, binding_signature=9)
    assert key != PoseKey.of_matrices(_pose(2))

"""Meshes the centers-of-rotation tests share: a tube over a chain of bones, and dense weights."""

from __future__ import annotations

import dqskin
import numpy as np

F = np.float32


def tube(rings=24, segments=16, bones=6, seed=0, length=3.0):
    """A tube along Y over a chain of bones, 4 smooth influences per vertex that drift around
    the tube (so weight vectors are mostly unique)."""
    rng = np.random.default_rng(seed)
    y = np.repeat(np.linspace(0, length, rings), segments)
    phi = np.tile(np.linspace(0, 2 * np.pi, segments, endpoint=False), rings)
    positions = np.stack([0.3 * np.cos(phi), y, -0.3 * np.sin(phi)], axis=1).astype(F)
    s = y / length * bones + 0.15 * np.sin(2 * phi) + 0.01 * rng.standard_normal(len(y))
    raw = np.exp(-(((s[:, None] - (np.arange(bones) + 0.5)) / 0.8) ** 2))
    top = np.argsort(-raw, axis=1)[:, :4]
    w = np.take_along_axis(raw, top, axis=1)
    w /= w.sum(axis=1, keepdims=True)
    influences = dqskin.Influences.from_dense(top, w.astype(F), bones)
    ring = lambda r, k: r * segments + k % segments  # noqa: E731
    tris = []
    for r in range(rings - 1):
        for k in range(segments):
            tris += [[ring(r, k), ring(r, k + 1), ring(r + 1, k + 1)], [ring(r, k), ring(r + 1, k + 1), ring(r + 1, k)]]
    rest = np.tile(np.eye(4, dtype=F), (bones, 1, 1))
    rest[:, 1, 3] = np.arange(bones) * length / bones
    return positions, np.array(tris, np.int64), influences, rest


def dense_of(influences) -> np.ndarray:
    """`(V, B)` weights of `influences`."""
    out = np.zeros((influences.vertex_count, influences.bone_count), np.float64)
    rows = np.repeat(np.arange(influences.vertex_count), np.diff(influences.offsets.astype(np.int64)))
    np.add.at(out, (rows, influences.bones.astype(np.int64)), influences.weights)
    return out

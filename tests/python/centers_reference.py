"""Float64 references of Optimized Centers of Rotation (Le & Hodgins, SIGGRAPH 2016), straight
from the formulas: the precompute (`brute_force_centers`) and the per-frame skinning
(`reference_skin`). Shared by the module's tests and the Blender tests (B-Bones, envelopes)."""

from __future__ import annotations

import numpy as np
import reference
from dqmath import quat_to_mat3

SIGMA = 0.1


def normalized_weights(offsets, bones, weights, bone_count):
    """Dense ``(V, B)`` weights, repeated bones added, normalized to sum 1; all zero where the
    total is ≤ 0.0001 (skinning leaves those vertices in place)."""
    v = len(offsets) - 1
    w = np.zeros((v, bone_count))
    for i in range(v):
        for k in range(offsets[i], offsets[i + 1]):
            w[i, bones[k]] += float(weights[k])
    total = w.sum(axis=1)
    ok = total > reference.CONTRIB_THRESHOLD
    w[ok] /= total[ok, None]
    w[~ok] = 0.0
    return w


def brute_force_centers(positions, triangles, influences, sigma=SIGMA):
    """The paper's precompute straight from the formula: every vertex against every triangle,
    ``s(a, b) = Σ_{j≠k} aⱼaₖbⱼbₖ·exp(−(aⱼbₖ − aₖbⱼ)²/σ²)``. Returns (centers or NaN, has)."""
    p = np.asarray(positions, np.float64)
    tri = np.asarray(triangles, np.int64)
    a_all = normalized_weights(influences.offsets, influences.bones, influences.weights, influences.bone_count)
    area = 0.5 * np.linalg.norm(np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]]), axis=1)
    centroid = p[tri].mean(axis=1)
    b = a_all[tri].mean(axis=1)  # (T, B)
    centers = np.full_like(p, np.nan)
    has = np.zeros(len(p), bool)
    for v, a in enumerate(a_all):
        s = np.zeros(len(tri))
        for j in np.nonzero(a)[0]:
            for k in np.nonzero(a)[0]:
                if j != k:
                    u = a[j] * b[:, k] - a[k] * b[:, j]
                    s += a[j] * a[k] * b[:, j] * b[:, k] * np.exp(-(u * u) / sigma**2)
        den = float(np.sum(s * area))
        if den > 0:
            centers[v] = (s * area) @ centroid / den
            has[v] = True
    return centers, has


def reference_skin(positions, centers, influences, deform, rest, *, premat=None, postmat=None, mask=None):
    """The per-frame formula in float64: ``v' = Σ wⱼ·Mⱼ·c + R·Σ wⱼ·Sⱼ·(v − c)`` (armature space,
    weights over their total), ``R`` the rotation of the sign-aligned sum of the bones'
    rotations (Blender's, via ``reference.mat4_to_dquat``), ``Sⱼ = Rⱼᵀ·M₃ⱼ`` for bones on
    Blender's scale path, else the identity."""
    pre = np.eye(4) if premat is None else np.asarray(premat, np.float64)
    post = np.eye(4) if postmat is None else np.asarray(postmat, np.float64)
    deform = np.asarray(deform, np.float64)
    bones = [reference.mat4_to_dquat(r, m) for r, m in zip(np.asarray(rest, np.float64), deform)]
    stretch = [quat_to_mat3(d.quat).T @ m[:3, :3] if d.scale_weight else np.eye(3) for d, m in zip(bones, deform)]
    out = np.empty((len(positions), 3))
    off, idx, wts = influences.offsets, influences.bones, influences.weights
    for v, p in enumerate(np.asarray(positions, np.float64)):
        a = 1.0 if mask is None else float(mask[v])
        if a == 0.0:
            out[v] = p
            continue
        co = pre[:3, :3] @ p + pre[:3, 3]
        c = pre[:3, :3] @ np.asarray(centers[v], np.float64) + pre[:3, 3]
        anchor, offset, q, contrib = np.zeros(3), np.zeros(3), np.zeros(4), 0.0
        for k in range(off[v], off[v + 1]):
            w, b = float(wts[k]), int(idx[k])
            anchor += w * (deform[b, :3, :3] @ c + deform[b, :3, 3])
            offset += w * (stretch[b] @ (co - c))
            q += (-w if np.dot(bones[b].quat, q) < 0 else w) * bones[b].quat
            contrib += w
        if contrib > reference.CONTRIB_THRESHOLD and np.dot(q, q) > 0:
            moved = anchor / contrib + quat_to_mat3(q / np.linalg.norm(q)) @ (offset / contrib)
            co = co + (moved - co) * a
        out[v] = post[:3, :3] @ co + post[:3, 3]
    return out


def diagonal(p):
    p = np.asarray(p, np.float64)
    return float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))

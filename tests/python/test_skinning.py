"""dqskin.skin() against the float64 reference of Blender's Armature modifier (reference.py) on
random meshes and rigs, plus the candy-wrapper rig, Influences.from_dense, ``out=``, threads and
the GIL."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from functools import cache

import dqskin
import numpy as np
import pytest
import reference
from dqmath import qmul, quat_from_axis_angle, quat_to_mat3, random_axis, random_unit_quat

# Per-vertex tolerance, relative to the magnitude of the expected position: |got − want| <=
# REL_TOL·(1 + |want|). dqskin computes in float32 (unit round-off 6e-8) while the reference
# is float64 on the same float32 inputs. A vertex goes through premat, up to 8 bone transforms
# (matrices with entries up to ~2 and translations up to ~4), the DQS sum and its division by
# |q|², and postmat: a few dozen dependent float32 operations on values up to ~10x the output,
# i.e. up to a few hundred ulps of the magnitude, ~2e-5 relative. The "1 +" keeps the bound
# meaningful for vertices that land near the origin after large intermediate values. (The Rust
# kernel tests use the same bound against the same reference.)
REL_TOL = 2e-5
# Hand-made rigs with coordinates up to ~14 and exact (or nearly) matrices: a few float32
# roundings, ulp(14) = 9.5e-7.
SIMPLE_RIG_TOL = 4e-6
# The float64 reference checked against itself: only float64 round-off.
FLOAT64_TOL = 1e-12
# Candy wrapper (radius 0.5, float32): the rest ring area matches the inscribed polygon to
# float32 round-off (relative 1e-5 is generous); ring vertices stay in their plane and on their
# circle to a few ulps; LBS at exactly 180° leaves an area of order (0.5·1e-7)², i.e. a ratio
# ~1e-13, bounded by 1e-6; DQS and cos²(θ/2) area ratios hold to float32 round-off, 1e-4.
AREA_REL_TOL = 1e-5
RING_TOL = 1e-5
COLLAPSED_AREA_RATIO = 1e-6
AREA_RATIO_TOL = 1e-4

SEEDS = [0, 1, 2, 3, 4]
VERTICES = 203  # not a multiple of the kernels' lane count (16), so the tail batch is tested


# ---------------------------------------------------------------------------------------------
# Random rigs and meshes


def rigid4(q, t):
    m = np.eye(4)
    m[:3, :3] = quat_to_mat3(q)
    m[:3, 3] = t
    return m


def make_rig(rng, bones):
    """Rest matrices are rigid; deform matrices (posed @ inv(rest), Blender's matrix_channel)
    are rigid, non-uniformly scaled, sheared, mirrored, or rotated 170-179° away from the first
    bone (so that DQS sign flips happen). Bone 0 is rigid; every kind appears when bones >= 6."""
    kinds = ["rigid", "scaled", "sheared", "mirrored", "antipodal", "antipodal"]
    kinds += list(rng.choice(["rigid", "rigid", "scaled", "sheared", "mirrored", "antipodal"], size=max(0, bones - 6)))
    kinds = kinds[:bones]
    first_rot = random_unit_quat(rng)
    rest, deform = [], []
    for b, kind in enumerate(kinds):
        rest_m = rigid4(random_unit_quat(rng), rng.uniform(-2, 2, 3))
        if b == 0:
            rot = first_rot
        elif kind == "antipodal":
            angle = np.radians(rng.uniform(170.0, 179.0))
            rot = qmul(quat_from_axis_angle(random_axis(rng), angle), first_rot)
        else:
            rot = random_unit_quat(rng)
        posed = rigid4(rot, rng.uniform(-2, 2, 3))
        extra = rng.uniform(-0.6, 0.6, 3)
        if kind == "scaled":
            # non-uniform: each axis grown to 1-2.2x or shrunk to 0.5-0.9x
            factors = np.where(rng.random(3) < 0.3, rng.uniform(0.5, 0.9, 3), 1.0 + 2.0 * np.abs(extra))
            posed = posed @ np.diag(np.append(factors, 1.0))
        elif kind == "sheared":
            shear = np.eye(4)
            shear[0, 1] = extra[0]
            shear[1, 2] = extra[1]
            posed = posed @ shear
        elif kind == "mirrored":
            posed = posed @ np.diag([-1.0, 1.0, 1.0 + abs(extra[2]), 1.0])
        deform.append(posed @ np.linalg.inv(rest_m))
        rest.append(rest_m)
    return np.array(deform, dtype=np.float32), np.array(rest, dtype=np.float32), kinds


def make_influences(rng, vertices, bones):
    """CSR influences: 1-8 per vertex (some vertices none), zero weights, unnormalized weights
    (sums far from 1) and repeated bones."""
    counts = rng.integers(1, 9, size=vertices)
    counts[rng.random(vertices) < 0.08] = 0
    counts[:3] = [0, 8, 1]
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    n = int(offsets[-1])
    b = rng.integers(0, bones, size=n)
    kind = rng.random(n)
    w = np.where(kind < 0.12, 0.0, np.where(kind < 0.25, rng.uniform(1.0, 3.0, n), rng.uniform(0.0, 1.0, n)))
    # A few vertices whose weights are all zero.
    for v in (5, 6):
        w[offsets[v] : offsets[v + 1]] = 0.0
    return offsets, b.astype(np.int64), w.astype(np.float32)


@cache
def case(seed):
    rng = np.random.default_rng(seed)
    bones = int(rng.integers(6, 10))
    deform, rest, kinds = make_rig(rng, bones)
    positions = rng.uniform(-3, 3, size=(VERTICES, 3)).astype(np.float32)
    offsets, b, w = make_influences(rng, VERTICES, bones)
    s = rng.uniform(0.5, 2.0)
    premat = (rigid4(random_unit_quat(rng), rng.uniform(-2, 2, 3)) @ np.diag([s, s, s, 1.0])).astype(np.float32)
    other_postmat = rigid4(random_unit_quat(rng), rng.uniform(-1, 1, 3)).astype(np.float32)
    mask = rng.choice([0.0, 1.0, 0.5], size=VERTICES).astype(np.float32)
    partial = rng.random(VERTICES) < 0.3
    mask[partial] = rng.uniform(0, 1, partial.sum())
    blend_amount = rng.uniform(0, 1, VERTICES).astype(np.float32)
    blend_amount[:10] = [0, 1, 0, 1, 0.5, 0, 1, 0.25, 0.75, 1]
    return dict(
        deform=deform,
        rest=rest,
        kinds=kinds,
        positions=positions,
        offsets=offsets,
        bones=b,
        weights=w,
        premat=premat,
        postmat_inverse=np.linalg.inv(premat.astype(np.float64)).astype(np.float32),
        other_postmat=other_postmat,
        mask=mask,
        blend_amount=blend_amount,
    )


OPTIONS = ["plain", "spaces", "spaces_mask", "mask_other_postmat"]


def options_for(c, name):
    if name == "plain":
        return {}
    if name == "spaces":
        return dict(premat=c["premat"], postmat=c["postmat_inverse"])
    if name == "spaces_mask":
        return dict(premat=c["premat"], postmat=c["postmat_inverse"], mask=c["mask"])
    if name == "mask_other_postmat":
        return dict(postmat=c["other_postmat"], mask=c["mask"])
    raise AssertionError(name)


def influences_of(c):
    return dqskin.Influences(c["offsets"], c["bones"], c["weights"], len(c["deform"]))


@cache
def reference_result(seed, options, dqs):
    c = case(seed)
    stats = reference.Stats()
    out = reference.skin(
        c["positions"],
        c["offsets"],
        c["bones"],
        c["weights"],
        c["deform"],
        c["rest"],
        dqs=dqs,
        stats=stats,
        **options_for(c, options),
    )
    return out, stats


def assert_close(got, want, tol=REL_TOL, what=""):
    got = np.asarray(got, dtype=np.float64)
    err = np.linalg.norm(got - want, axis=1)
    bound = tol * (1.0 + np.linalg.norm(want, axis=1))
    bad = np.flatnonzero(~(err <= bound))
    assert bad.size == 0, (
        f"{what}: {bad.size} vertices off, first {bad[:5]}: got {got[bad[:3]]}, want {want[bad[:3]]}, "
        f"worst err/bound {np.max(err / bound):.3g}"
    )


# ---------------------------------------------------------------------------------------------
# Against the reference


def test_random_cases_exercise_the_interesting_paths():
    """The data really contain what the tests claim: sign flips, every kind of scaled bone,
    vertices with no (or only zero) weights, unnormalized weights, 1 to 8 influences."""
    for seed in SEEDS:
        c = case(seed)
        _, stats = reference_result(seed, "plain", True)
        assert stats.sign_flips > 0, seed
        kinds = c["kinds"]
        scaled_kinds = {kinds[b] for b in stats.scaled_bones}
        assert {"scaled", "sheared", "mirrored"} <= scaled_kinds, (seed, scaled_kinds)
        assert "rigid" not in scaled_kinds and "antipodal" not in scaled_kinds
        counts = np.diff(c["offsets"])
        assert counts.min() == 0 and counts.max() == 8
        sums = np.add.reduceat(c["weights"].astype(np.float64), c["offsets"][:-1])[counts > 0]
        assert np.any(sums > 1.5) and np.any((sums < 0.9) & (sums > 1e-3))
        assert stats.moved < VERTICES


@pytest.mark.parametrize("options", OPTIONS)
@pytest.mark.parametrize("seed", SEEDS)
def test_linear_matches_reference(seed, options):
    c = case(seed)
    got = dqskin.skin(c["positions"], influences_of(c), c["deform"], c["rest"], method="linear", **options_for(c, options))
    want, _ = reference_result(seed, options, False)
    assert got.dtype == np.float32 and got.shape == (VERTICES, 3)
    assert_close(got, want, what="linear")
    if "mask" in options:
        masked = c["mask"] == 0
        np.testing.assert_array_equal(got[masked], c["positions"][masked])


@pytest.mark.parametrize("options", OPTIONS)
@pytest.mark.parametrize("seed", SEEDS)
def test_linear_needs_no_rest_matrices(seed, options):
    c = case(seed)
    got = dqskin.skin(c["positions"], influences_of(c), c["deform"], None, method="linear", **options_for(c, options))
    want, _ = reference_result(seed, options, False)
    assert_close(got, want, what="linear without rest")


@pytest.mark.parametrize("options", OPTIONS)
@pytest.mark.parametrize("seed", SEEDS)
def test_dual_quaternion_matches_reference(seed, options):
    c = case(seed)
    got = dqskin.skin(c["positions"], influences_of(c), c["deform"], c["rest"], method="dual_quaternion", **options_for(c, options))
    want, _ = reference_result(seed, options, True)
    assert_close(got, want, what="dual_quaternion")
    if "mask" in options:
        # Blender returns a vertex with mask weight 0 untouched: bit for bit, no round trip.
        masked = c["mask"] == 0
        assert masked.any()
        np.testing.assert_array_equal(got[masked], c["positions"][masked])


@pytest.mark.parametrize("options", OPTIONS)
@pytest.mark.parametrize("seed", SEEDS)
def test_blend_matches_reference(seed, options):
    c = case(seed)
    factor = 0.8
    got = dqskin.skin(
        c["positions"],
        influences_of(c),
        c["deform"],
        c["rest"],
        method="blend",
        blend=c["blend_amount"],
        blend_factor=factor,
        **options_for(c, options),
    )
    lbs, _ = reference_result(seed, options, False)
    dq, _ = reference_result(seed, options, True)
    alpha = (np.float32(factor) * c["blend_amount"]).astype(np.float64)[:, None]
    assert_close(got, (1 - alpha) * lbs + alpha * dq, what="blend")
    if "mask" in options:
        masked = c["mask"] == 0
        np.testing.assert_array_equal(got[masked], c["positions"][masked])
    # Without a per-vertex array, blend_factor alone is alpha.
    got = dqskin.skin(c["positions"], influences_of(c), c["deform"], c["rest"], method="blend", blend_factor=0.3, **options_for(c, options))
    assert_close(got, 0.7 * lbs + 0.3 * dq, what="blend_factor only")


def test_reference_blend_helper_is_the_mix():
    c = case(0)
    alpha = c["blend_amount"].astype(np.float64)
    mixed = reference.blend(c["positions"], c["offsets"], c["bones"], c["weights"], c["deform"], c["rest"], alpha)
    lbs, _ = reference_result(0, "plain", False)
    dq, _ = reference_result(0, "plain", True)
    np.testing.assert_allclose(mixed, (1 - alpha[:, None]) * lbs + alpha[:, None] * dq, rtol=FLOAT64_TOL, atol=FLOAT64_TOL)


# Blend at alpha = 0 or 1 is the same computation as the pure method, up to round-off in the
# mixing step (one float32 multiply-add of values of the output's magnitude): 1e-6 relative.
MIX_TOL = 1e-6
# Mixing in between, compared with a mix of dqskin's own LBS and DQS results: a few float32
# roundings of the output magnitude.
MIX_BETWEEN_TOL = 2e-6


@pytest.mark.parametrize("seed", SEEDS[:3])
def test_blend_endpoints_and_linear_mix(seed):
    c = case(seed)
    opts = options_for(c, "spaces_mask")
    args = (c["positions"], influences_of(c), c["deform"], c["rest"])
    lin = dqskin.skin(*args, method="linear", **opts).astype(np.float64)
    dq = dqskin.skin(*args, method="dual_quaternion", **opts).astype(np.float64)
    assert np.max(np.linalg.norm(lin - dq, axis=1)) > 0.1, "LBS and DQS should differ on this rig"
    zeros = np.zeros(VERTICES, np.float32)
    ones = np.ones(VERTICES, np.float32)
    assert_close(dqskin.skin(*args, method="blend", blend_factor=0.0, **opts), lin, MIX_TOL, "factor 0")
    assert_close(dqskin.skin(*args, method="blend", blend=zeros, **opts), lin, MIX_TOL, "amount 0")
    assert_close(dqskin.skin(*args, method="blend", blend_factor=1.0, **opts), dq, MIX_TOL, "factor 1")
    assert_close(dqskin.skin(*args, method="blend", blend=ones, **opts), dq, MIX_TOL, "amount 1")
    for factor in (0.25, 0.5, 0.9):
        got = dqskin.skin(*args, method="blend", blend_factor=factor, **opts)
        assert_close(got, (1 - factor) * lin + factor * dq, MIX_BETWEEN_TOL, f"factor {factor}")
    amount = c["blend_amount"]
    got = dqskin.skin(*args, method="blend", blend=amount, blend_factor=0.5, **opts)
    alpha = 0.5 * amount.astype(np.float64)[:, None]
    assert_close(got, (1 - alpha) * lin + alpha * dq, MIX_BETWEEN_TOL, "per-vertex amount")


def test_method_aliases():
    c = case(1)
    args = (c["positions"], influences_of(c), c["deform"], c["rest"])
    lin = dqskin.skin(*args, method="linear")
    dq = dqskin.skin(*args, method="dual_quaternion")
    bl = dqskin.skin(*args, method="blend", blend_factor=0.5)
    np.testing.assert_array_equal(dqskin.skin(*args, method="LINEAR"), lin)
    np.testing.assert_array_equal(dqskin.skin(*args, method="lbs"), lin)
    np.testing.assert_array_equal(dqskin.skin(*args, method="DUAL_QUATERNION"), dq)
    np.testing.assert_array_equal(dqskin.skin(*args, method="dqs"), dq)
    np.testing.assert_array_equal(dqskin.skin(*args), dq)  # the default is dual_quaternion
    np.testing.assert_array_equal(dqskin.skin(*args, method="BLEND", blend_factor=0.5), bl)
    np.testing.assert_array_equal(dqskin.skin(*args, method=dqskin.Method.LINEAR), lin)
    np.testing.assert_array_equal(dqskin.skin(*args, method=dqskin.Method.DUAL_QUATERNION), dq)
    np.testing.assert_array_equal(dqskin.skin(*args, method=dqskin.Method.BLEND, blend_factor=0.5), bl)
    np.testing.assert_array_equal(dqskin.skin(*args, method="Dual Quaternion"), dq)
    assert not np.allclose(lin, dq)


def test_one_method_enum_for_names_aliases_and_labels():
    M = dqskin.Method
    members = [M.LINEAR, M.DUAL_QUATERNION, M.BLEND, M.CENTERS_OF_ROTATION]
    assert [m.label for m in members] == ["Linear", "Dual Quaternion", "Blend", "Optimized Centers"]
    spellings = {
        M.LINEAR: ["linear", "LINEAR", "lbs", "Linear"],
        M.DUAL_QUATERNION: ["dual_quaternion", "DUAL_QUATERNION", "dqs", "Dual Quaternion"],
        M.BLEND: ["blend", "BLEND", "Blend"],
        M.CENTERS_OF_ROTATION: ["centers_of_rotation", "CENTERS_OF_ROTATION", "cor", "Optimized Centers"],
    }
    for member, names in spellings.items():
        assert M(member) == member
        for name in names:
            assert M(name) == member, name
    assert len(set(members)) == 4 and M.LINEAR != M.BLEND and M.LINEAR != 0
    c = case(1)
    with pytest.raises(ValueError, match=r"method must be a dqskin.Method.*got 'slerp'"):
        dqskin.skin(c["positions"], influences_of(c), c["deform"], c["rest"], method="slerp")
    with pytest.raises(TypeError, match=r"value must be a dqskin.Method or a string, got int"):
        M(1)


# ---------------------------------------------------------------------------------------------
# Specific behaviours


def single_bone_rig():
    rest = np.eye(4, dtype=np.float32)[None]
    deform = np.eye(4, dtype=np.float32)[None].copy()
    deform[0, :3, 3] = [1.0, 0.0, 0.0]
    return deform, rest


@pytest.mark.parametrize("method", ["linear", "dual_quaternion", "blend"])
def test_vertices_without_enough_weight_stay_put(method):
    """Blender moves a vertex only if its total weight is > 0.0001; others only go through the
    premat/postmat round trip (and a mask of 0 skips even that)."""
    deform, rest = single_bone_rig()
    positions = np.tile(np.float32([1.0, 2.0, 3.0]), (5, 1))
    # no influences; 0.00005 + 0.00005 (= the threshold, not above it); a zero weight;
    # 0.00011 (just above: moves fully, since weights are normalized); 1.0
    infl = dqskin.Influences(np.array([0, 0, 2, 3, 4, 5]), np.zeros(5, np.int64), np.float32([5e-5, 5e-5, 0.0, 1.1e-4, 1.0]), 1)
    kw = dict(blend_factor=0.5) if method == "blend" else {}
    out = dqskin.skin(positions, infl, deform, rest, method=method, **kw)
    np.testing.assert_array_equal(out[:3], positions[:3])
    np.testing.assert_allclose(out[3:], [[2.0, 2.0, 3.0]] * 2, atol=SIMPLE_RIG_TOL)
    pre = np.eye(4, dtype=np.float32)
    pre[2, 3] = 10.0
    post = np.eye(4, dtype=np.float32)
    post[2, 3] = 1.0
    out = dqskin.skin(positions, infl, deform, rest, method=method, premat=pre, postmat=post, **kw)
    np.testing.assert_allclose(out[:3], [[1.0, 2.0, 14.0]] * 3, atol=SIMPLE_RIG_TOL)
    np.testing.assert_allclose(out[3:], [[2.0, 2.0, 14.0]] * 2, atol=SIMPLE_RIG_TOL)
    mask = np.float32([0, 1, 1, 0, 0.5])
    out = dqskin.skin(positions, infl, deform, rest, method=method, premat=pre, postmat=post, mask=mask, **kw)
    # mask 0: bit-identical, no round trip
    np.testing.assert_array_equal(out[[0, 3]], positions[[0, 3]])
    np.testing.assert_allclose(out[4], [1.5, 2.0, 14.0], atol=SIMPLE_RIG_TOL)


@pytest.mark.parametrize("method", ["linear", "dual_quaternion"])
def test_weights_are_divided_by_their_sum(method):
    c = case(2)
    args = (c["positions"], c["deform"], c["rest"])
    infl = influences_of(c)
    scaled = dqskin.Influences(c["offsets"], c["bones"], c["weights"] * np.float32(3.0), len(c["deform"]))
    a = dqskin.skin(args[0], infl, *args[1:], method=method)
    b = dqskin.skin(args[0], scaled, *args[1:], method=method)
    assert_close(b, a.astype(np.float64), REL_TOL, "weights x3")


# Order test: coordinates ~1, rotations only; float32 round-off is ~1e-7.
ORDER_TOL = 1e-5


def test_influence_order_decides_dqs_signs():
    """Three bones whose rotations are pairwise more than 90° apart in quaternion space: the sign
    each gets depends on the running sum, so two orders of the same pairs give different
    results, each matching Blender's (the reference) in its order."""
    rest = np.tile(np.eye(4, dtype=np.float32), (3, 1, 1))
    deform = np.tile(np.eye(4), (3, 1, 1))
    for b, angle in enumerate([0.0, 2.4, -2.4]):
        deform[b, :3, :3] = quat_to_mat3(quat_from_axis_angle([0, 0, 1], angle))
    deform = deform.astype(np.float32)
    positions = np.float32([[1.0, 0.5, 0.0], [1.0, 0.5, 0.0]])
    offsets = np.array([0, 3, 6])
    bones = np.array([0, 1, 2, 0, 2, 1])
    weights = np.float32([0.5, 0.3, 0.2, 0.5, 0.2, 0.3])
    infl = dqskin.Influences(offsets, bones, weights, 3)
    got = dqskin.skin(positions, infl, deform, rest, method="dual_quaternion")
    want = reference.skin(positions, offsets, bones, weights, deform, rest, dqs=True)
    assert np.linalg.norm(want[0] - want[1]) > 0.1, want
    assert_close(got, want, ORDER_TOL, "order")
    # LBS does not depend on the order.
    lin = dqskin.skin(positions, infl, deform, rest, method="linear")
    np.testing.assert_allclose(lin[0], lin[1], atol=SIMPLE_RIG_TOL)


@pytest.mark.parametrize("method", ["linear", "dual_quaternion", "blend"])
def test_empty_mesh_and_rig(method):
    eye = np.tile(np.eye(4, dtype=np.float32), (2, 1, 1))
    empty = dqskin.Influences(np.array([0]), np.zeros(0, np.int64), np.zeros(0, np.float32), 2)
    out = dqskin.skin(np.zeros((0, 3), np.float32), empty, eye, eye, method=method)
    assert out.shape == (0, 3) and out.dtype == np.float32
    # No bones: nothing moves, but premat/postmat still apply.
    no_bones = dqskin.Influences(np.array([0, 0, 0]), np.zeros(0, np.int64), np.zeros(0, np.float32), 0)
    positions = np.float32([[1, 2, 3], [-1, 0, 4]])
    none = np.zeros((0, 4, 4), np.float32)
    np.testing.assert_array_equal(dqskin.skin(positions, no_bones, none, none, method=method), positions)
    shift = np.eye(4, dtype=np.float32)
    shift[:3, 3] = [0, 0, 1]
    np.testing.assert_array_equal(
        dqskin.skin(positions, no_bones, none, none, method=method, postmat=shift), positions + np.float32([0, 0, 1])
    )


# ---------------------------------------------------------------------------------------------
# Candy wrapper


def shoelace_xz(points):
    x, z = points[:, 0].astype(np.float64), points[:, 2].astype(np.float64)
    return 0.5 * abs(np.dot(x, np.roll(z, -1)) - np.dot(z, np.roll(x, -1)))


def test_candy_wrapper():
    cyl = dqskin.TwistCylinder()
    middle = cyl.ring(cyl.rings // 2)
    rest_area = dqskin.polygon_area(cyl.positions[middle])
    # The ring is a regular inscribed polygon of `segments` sides, radius 0.5.
    n = cyl.segments
    expected = 0.5 * n * 0.5**2 * np.sin(2 * np.pi / n)
    assert rest_area == pytest.approx(expected, rel=AREA_REL_TOL)
    assert shoelace_xz(cyl.positions[middle]) == pytest.approx(expected, rel=AREA_REL_TOL)

    def middle_ring(method, angle):
        out = dqskin.skin(cyl.positions, cyl.influences, cyl.twist(angle), cyl.rest, method=method)
        ring = out[middle]
        # The twist is about the cylinder's axis: the middle ring stays in its plane y = 2.
        np.testing.assert_allclose(ring[:, 1], 2.0, atol=RING_TOL)
        return ring

    lin = middle_ring("linear", np.pi)
    dq = middle_ring("dual_quaternion", np.pi)
    # LBS at 180°: each middle vertex is the average of p and its half-turn image, the axis point.
    assert dqskin.polygon_area(lin) / rest_area < COLLAPSED_AREA_RATIO
    assert shoelace_xz(lin) / rest_area < COLLAPSED_AREA_RATIO
    assert np.max(np.linalg.norm(lin[:, [0, 2]], axis=1)) < RING_TOL
    # DQS rotates the ring by 90° instead: same area, same radius.
    assert dqskin.polygon_area(dq) / rest_area == pytest.approx(1.0, abs=AREA_RATIO_TOL)
    assert shoelace_xz(dq) / rest_area == pytest.approx(1.0, abs=AREA_RATIO_TOL)
    np.testing.assert_allclose(np.linalg.norm(dq[:, [0, 2]], axis=1), 0.5, atol=RING_TOL)
    # In between, the middle ring (weights 0.5/0.5) keeps cos²(θ/2) of its area with LBS.
    for degrees in (60.0, 120.0, 150.0):
        theta = np.radians(degrees)
        lin = middle_ring("linear", theta)
        dq = middle_ring("dual_quaternion", theta)
        assert shoelace_xz(lin) / rest_area == pytest.approx(np.cos(theta / 2) ** 2, abs=AREA_RATIO_TOL)
        assert shoelace_xz(dq) / rest_area == pytest.approx(1.0, abs=AREA_RATIO_TOL)
        out = dqskin.skin(cyl.positions, cyl.influences, cyl.twist(theta), cyl.rest, method="blend", blend_factor=0.5)
        half = shoelace_xz(out[middle]) / rest_area
        assert np.cos(theta / 2) ** 2 < half < 1.0


# ---------------------------------------------------------------------------------------------
# Influences, out=, threads


def test_influences_from_dense_equals_csr_built_by_hand():
    rng = np.random.default_rng(11)
    v, k, bones = 57, 4, 7
    dense_b = rng.integers(0, bones, size=(v, k))
    dense_w = rng.uniform(0, 1, size=(v, k)).astype(np.float32)
    dense_w[rng.random((v, k)) < 0.3] = 0.0
    dense_w[3] = 0.0  # a vertex with no influence left
    offsets, csr_b, csr_w = [0], [], []
    for row in range(v):
        for col in range(k):
            if dense_w[row, col] != 0.0:
                csr_b.append(dense_b[row, col])
                csr_w.append(dense_w[row, col])
        offsets.append(len(csr_b))
    by_hand = dqskin.Influences(np.array(offsets), np.array(csr_b), np.array(csr_w, np.float32), bones)
    dense = dqskin.Influences.from_dense(dense_b.astype(np.uint16), dense_w, bones)
    assert dense.offsets.dtype == np.uint32 and dense.bones.dtype == np.uint32 and dense.weights.dtype == np.float32
    np.testing.assert_array_equal(dense.offsets, offsets)
    np.testing.assert_array_equal(dense.bones, csr_b)
    np.testing.assert_array_equal(dense.weights, np.array(csr_w, np.float32))
    np.testing.assert_array_equal(by_hand.offsets, dense.offsets)
    assert (dense.vertex_count, dense.bone_count, len(dense)) == (v, bones, len(csr_b))
    assert dense.max_per_vertex == max(np.diff(offsets))
    assert "Influences(" in repr(dense)
    deform, rest, _ = make_rig(rng, bones)
    positions = rng.uniform(-1, 1, (v, 3)).astype(np.float32)
    for method in ("linear", "dual_quaternion"):
        np.testing.assert_array_equal(
            dqskin.skin(positions, dense, deform, rest, method=method),
            dqskin.skin(positions, by_hand, deform, rest, method=method),
        )


def test_influences_round_trip_their_arrays():
    c = case(0)
    infl = influences_of(c)
    np.testing.assert_array_equal(infl.offsets, c["offsets"])
    np.testing.assert_array_equal(infl.bones, c["bones"])
    np.testing.assert_array_equal(infl.weights, c["weights"])
    assert infl.vertex_count == VERTICES and infl.bone_count == len(c["deform"])
    assert infl.max_per_vertex == 8 and len(infl) == c["offsets"][-1]


@pytest.mark.parametrize("bone_count, slot_bytes", [(300, 96), (257, 96), (256, 80), (7, 80)])
@pytest.mark.parametrize("most", [3, 15, 16, 255, 256])
def test_influences_keep_each_vertex_count_and_bone_in_as_few_bits_as_the_largest_needs(most, bone_count, slot_bytes):
    """Counts are half a byte a vertex up to 15 influences, a byte up to 255, two above; bone
    indices a byte up to 256 bones, two above (a slot of 16 lanes is 16 weights and 16 indices);
    every vertex's pairs still read back whole and in order at each width, also from lanes
    taken by decreasing count."""
    rng = np.random.default_rng(most)
    counts = rng.integers(0, most + 1, 101)
    counts[7] = most
    offsets = np.concatenate([[0], np.cumsum(counts)])
    bones = rng.integers(0, bone_count, offsets[-1])
    bones[offsets[7]] = bone_count - 1  # the largest index each width holds
    weights = rng.random(offsets[-1]).astype(np.float32)
    infl = dqskin.Influences(offsets, bones, weights, bone_count)
    np.testing.assert_array_equal(infl.offsets, offsets)
    np.testing.assert_array_equal(infl.bones, bones)
    np.testing.assert_array_equal(infl.weights, weights)
    # The kernels' slots: 16-vertex batches padded to their longest vertex, in vertex order or,
    # where that saves more than a byte a vertex, by decreasing count (one window of 256 here).
    in_order = sum(counts[b : b + 16].max() for b in range(0, 101, 16))
    by_count = np.sort(counts)[::-1]
    in_window = sum(by_count[b : b + 16].max() for b in range(0, 101, 16))
    ordered = (in_order - in_window) * slot_bytes > 101
    slots = in_window if ordered else in_order
    lanes = slot_bytes * slots + 4 * (7 + 1) + (101 if ordered else 0)  # slots, batch starts, lane positions
    per_vertex = {3: 0.5, 15: 0.5, 16: 1, 255: 1, 256: 2}[most]
    assert infl.nbytes == lanes + int(np.ceil(101 * per_vertex))


@pytest.mark.parametrize("method", ["linear", "dual_quaternion", "blend"])
def test_out_is_filled_in_place_and_returned(method):
    c = case(1)
    args = (c["positions"], influences_of(c), c["deform"], c["rest"])
    kw = dict(method=method, mask=c["mask"])
    if method == "blend":
        kw["blend"] = c["blend_amount"]
    expected = dqskin.skin(*args, **kw)
    out = np.full((VERTICES, 3), np.nan, dtype=np.float32)
    positions_before = c["positions"].copy()
    result = dqskin.skin(*args, out=out, **kw)
    assert result is out
    np.testing.assert_array_equal(out, expected)
    np.testing.assert_array_equal(c["positions"], positions_before)  # input untouched
    # Reusing the buffer overwrites it completely (including masked-out vertices).
    out[:] = 1e30
    assert dqskin.skin(*args, out=out, **kw) is out
    np.testing.assert_array_equal(out, expected)


@pytest.mark.slow
def test_results_do_not_depend_on_the_thread_count():
    cyl = dqskin.TwistCylinder(rings=200, segments=64, blend_zone=0.3)
    deform = cyl.twist(2.0)
    original = dqskin.get_num_threads()
    try:
        results = {}
        for threads in (1, 2):
            dqskin.set_num_threads(threads)
            assert dqskin.get_num_threads() == threads
            results[threads] = [
                dqskin.skin(cyl.positions, cyl.influences, deform, cyl.rest, method=m, blend_factor=0.4)
                if m == "blend"
                else dqskin.skin(cyl.positions, cyl.influences, deform, cyl.rest, method=m)
                for m in ("linear", "dual_quaternion", "blend")
            ]
        for a, b in zip(results[1], results[2]):
            np.testing.assert_array_equal(a, b)
    finally:
        dqskin.set_num_threads(original)
    assert dqskin.get_num_threads() == original


# ---------------------------------------------------------------------------------------------
# The GIL

GIL_VERTICES = 2_000_000
GIL_CALLS = 4
# Calls shorter than this are too short to measure reliably; the test is skipped then.
MIN_CALL_SECONDS = 0.005
# How the test decides: the first half of each call (as timed by the worker) is cut into BINS
# equal slices, and coverage is the fraction of slices in which the main thread completed at
# least one loop iteration. Only the first half is used because a call's end is blurred: when
# skin() returns, the worker must win the GIL back from the spinning main thread (a few ms)
# before it can take its end timestamp, so the main thread legitimately runs at the end of every
# window even if skin() held the GIL. With the GIL released (and dqskin on one worker thread, so
# that the main thread has a core of its own on a two-core machine) coverage is ~1; if skin()
# held the GIL the main thread could not run at all in the first half: coverage 0 (checked by
# substituting a GIL-holding call). On a machine loaded with three extra busy processes coverage
# was still 0.5-0.7, so requiring 20 % is generous both ways.
BINS = 10
MIN_COVERAGE = 0.2


@pytest.mark.slow
def test_gil_is_released_during_skin():
    rng = np.random.default_rng(5)
    bones = 16
    deform, rest, _ = make_rig(rng, bones)
    positions = rng.uniform(-1, 1, (GIL_VERTICES, 3)).astype(np.float32)
    per_vertex = 4
    offsets = np.arange(GIL_VERTICES + 1, dtype=np.int64) * per_vertex
    infl = dqskin.Influences(
        offsets,
        rng.integers(0, bones, GIL_VERTICES * per_vertex, dtype=np.int32),
        rng.uniform(0.1, 1.0, GIL_VERTICES * per_vertex).astype(np.float32),
        bones,
    )
    out = np.empty_like(positions)

    state = {"call": None}
    windows = []  # (start, end) of each call, measured in the worker right around skin()
    stamps = {}  # call index -> times of the main thread's loop iterations while it ran

    def worker():
        for i in range(GIL_CALLS):
            state["call"] = i
            t0 = time.perf_counter()
            dqskin.skin(positions, infl, deform, rest, method="dual_quaternion", out=out)
            t1 = time.perf_counter()
            state["call"] = None
            windows.append((t0, t1))

    original_threads = dqskin.get_num_threads()
    old_interval = sys.getswitchinterval()
    try:
        dqskin.set_num_threads(1)
        dqskin.skin(positions, infl, deform, rest, method="dual_quaternion", out=out)  # warm up
        sys.setswitchinterval(0.001)
        thread = threading.Thread(target=worker)
        thread.start()
        while thread.is_alive():
            i = state["call"]
            if i is not None:
                stamps.setdefault(i, []).append(time.perf_counter())
        thread.join()
    finally:
        sys.setswitchinterval(old_interval)
        dqskin.set_num_threads(original_threads)

    assert len(windows) == GIL_CALLS
    durations = np.array([t1 - t0 for t0, t1 in windows])
    if np.min(durations) < MIN_CALL_SECONDS:
        pytest.skip(f"skin() took only {np.min(durations) * 1e3:.1f} ms: too short to measure")
    coverage, iterations = [], []
    for i, (t0, t1) in enumerate(windows):
        half = 0.5 * (t1 - t0)
        ts = np.array(stamps.get(i, []))
        inside = ts[(ts >= t0) & (ts < t0 + half)]
        iterations.append(inside.size)
        bins = np.unique(np.minimum(((inside - t0) / half * BINS).astype(int), BINS - 1))
        coverage.append(bins.size / BINS)
    assert np.mean(coverage) > MIN_COVERAGE, (
        f"the main thread ran during only {np.mean(coverage):.0%} of the first halves of the "
        f"skin() calls (per call {coverage}, durations {durations}, iterations {iterations})"
    )


# ---------------------------------------------------------------------------------------------
# Kernel copies

# Skins random meshes with every method, rigid and scaled rigs, each kind of spaces, on the copy
# DQSKIN_SIMD names, and prints a digest of each result's bytes.
COPY_DIGESTS = r"""
import hashlib, json
import dqskin, numpy as np

def rotations(rng, n):
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], 1)

def affine(rng, n, scale):
    m = np.tile(np.eye(4), (n, 1, 1))
    m[:, :3, :3] = rotations(rng, n) * scale
    m[:, :3, 3] = rng.normal(size=(n, 3))
    return m.astype(np.float32)

digests = {}
for seed in range(3):
    rng = np.random.default_rng(seed)
    vertices, bones = 4099, 24
    positions = rng.normal(size=(vertices, 3)).astype(np.float32)
    slots = rng.integers(0, bones, size=(vertices, 6))
    weights = rng.random((vertices, 6)).astype(np.float32)
    weights[rng.random((vertices, 6)) < 0.3] = 0.0
    influences = dqskin.Influences.from_dense(slots, weights, bones)
    rest = affine(rng, bones, 1.0)
    obj = affine(rng, 1, 1.0)[0]
    scaled_obj = affine(rng, 1, 1.7)[0]
    spaces = {
        "none": {},
        "rigid": dict(premat=np.linalg.inv(obj), postmat=obj),
        "scaled": dict(premat=np.linalg.inv(scaled_obj), postmat=scaled_obj),
        "other": dict(premat=np.linalg.inv(obj), postmat=scaled_obj, mask=rng.random(vertices).astype(np.float32)),
    }
    extra = {
        "linear": {},
        "dual_quaternion": {},
        "blend": dict(blend=rng.random(vertices).astype(np.float32), blend_factor=0.7),
        "centers_of_rotation": dict(centers=rng.normal(size=(vertices, 3)).astype(np.float32)),
    }
    for rig in ("rigid", "scaled"):
        deform = affine(rng, bones, 1.0 if rig == "rigid" else rng.uniform(0.6, 1.4, size=(bones, 1, 3)))
        for method, more in extra.items():
            for name, space in spaces.items():
                out = dqskin.skin(positions, influences, deform, rest, method=method, **more, **space)
                digests[f"{seed} {rig} {method} {name}"] = hashlib.sha256(out.tobytes()).hexdigest()
print(json.dumps(digests))
"""


def fused_copies():
    """The kernel copies with fused multiply-adds this CPU runs (x86-64 Linux: from its flags),
    each with its batches asking for their inputs ahead and without (`-noprefetch`)."""
    try:
        with open("/proc/cpuinfo") as cpuinfo:
            flags = next(line for line in cpuinfo if line.startswith("flags")).split()
    except (OSError, StopIteration):
        return []
    if "avx2" not in flags or "fma" not in flags:
        return []
    sets = ["avx2", "avx512"] if "avx512f" in flags else ["avx2"]
    return [copy for s in sets for copy in (s, f"{s}-noprefetch")]


@pytest.mark.slow
def test_every_copy_with_fused_multiply_adds_gives_the_same_bytes():
    # Which copy runs is chosen by timing in each process: a result must not depend on it (a
    # farm's chunks, baked in separate processes or on other CPUs, are merged byte for byte).
    copies = fused_copies()
    if len(copies) < 2:
        pytest.skip(f"one copy with fused multiply-adds here ({copies})")
    digests = {}
    for simd in copies:
        env = {**os.environ, "DQSKIN_SIMD": simd}
        run = subprocess.run([sys.executable, "-c", COPY_DIGESTS], env=env, capture_output=True, text=True, timeout=300)
        assert run.returncode == 0, run.stderr
        digests[simd] = json.loads(run.stdout)
    first, *others = copies
    for simd in others:
        differ = [k for k, d in digests[first].items() if digests[simd][k] != d]
        assert not differ, f"{simd} and {first} differ on {len(differ)} of {len(digests[first])}: {differ[:8]}"


KERNEL_COPIES = """
import json, numpy as np, dqskin
rng = np.random.default_rng(5)
n, bones = 700, 6
positions = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
bone_ids = rng.integers(0, bones, (n, 4))
weights = rng.uniform(0.1, 1, (n, 4)).astype(np.float32)
influences = dqskin.Influences.from_dense(bone_ids, weights, bone_count=bones)
rest = np.tile(np.eye(4, dtype=np.float32), (bones, 1, 1))
deform = rest.copy()
deform[:, :3, 3] = rng.uniform(-1, 1, (bones, 3))
before = dqskin.kernel_copies()
first = dqskin.skin(positions, influences, deform, rest, method="dual_quaternion")
same = all(np.array_equal(dqskin.skin(positions, influences, deform, rest, method="dual_quaternion"), first) for _ in range(40))
print(json.dumps({"before": before, "after": dqskin.kernel_copies(), "same": same}))
"""


def test_kernel_copies_says_which_copy_each_variant_chose():
    # A process's first calls of a variant measure the copies in turn (the same bits on each);
    # once measured, `kernel_copies` names the one that stays. DQSKIN_SIMD names it throughout.
    copies = fused_copies()
    for env_copy in [None, *copies[:1]]:
        env = {k: v for k, v in os.environ.items() if k != "DQSKIN_SIMD"}
        if env_copy:
            env["DQSKIN_SIMD"] = env_copy
        run = subprocess.run([sys.executable, "-c", KERNEL_COPIES], env=env, capture_output=True, text=True, timeout=120)
        assert run.returncode == 0, run.stderr
        got = json.loads(run.stdout)
        assert got["same"], "a call during the measurement gave other bytes"
        before = {(v, s): c for v, s, c in got["before"]}
        after = {(v, s): c for v, s, c in got["after"]}
        variants = {"linear", "dual_quaternion", "dual_quaternion_scaled", "blend", "blend_scaled", "centers", "centers_scaled"}
        assert set(before) == set(after) == {(v, s) for v in variants for s in ("cached", "streamed")}
        if env_copy:
            assert set(after.values()) == {env_copy}, after
        elif len(copies) > 1:
            assert before[("dual_quaternion", "cached")] is None, "nothing measured before the first call"
            assert after[("dual_quaternion", "cached")] in copies, after
            assert after[("dual_quaternion", "streamed")] is None, "larger meshes are measured apart"
        else:
            assert after[("dual_quaternion", "cached")] is not None

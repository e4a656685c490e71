"""Per-frame effective influences (envelopes, B-Bones) and the small helpers around them."""

from __future__ import annotations

import dqskin
import numpy as np
import pytest

F32 = np.float32


def distfactor(co, head, tail, rad1, rad2, rdist):
    """Blender's distfactor_to_bone, straight from armature_deform.cc, in float64."""
    bdelta = tail - head
    l = np.linalg.norm(bdelta)
    bdelta = bdelta / l if l else bdelta
    pdelta = co - head
    a = bdelta @ pdelta
    if a < 0:
        dist_sq, rad = np.sum((head - co) ** 2), rad1
    elif a > l:
        dist_sq, rad = np.sum((tail - co) ** 2), rad2
    else:
        dist_sq = pdelta @ pdelta - a * a
        rad = (a / l) * rad2 + (1 - a / l) * rad1 if l else rad1
    if dist_sq < rad * rad:
        return 1.0
    if rdist == 0 or dist_sq >= (rad + rdist) ** 2:
        return 0.0
    d = np.sqrt(dist_sq) - rad
    return 1.0 - d * d / (rdist * rdist)


def envelope_rows(rng, bones):
    rows = np.zeros((bones, 11), F32)
    for b in range(bones):
        head = np.array([0.0, 0.0, b * 1.0])
        rows[b, 0:3] = head
        rows[b, 3:6] = head + [0.0, 0.0, 1.0]
        rows[b, 6:10] = rng.uniform(0.05, 0.4), rng.uniform(0.05, 0.4), rng.uniform(0.0, 1.0), rng.uniform(0.3, 1.0)
    return rows


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_envelope_weights_follow_blender(seed):
    rng = np.random.default_rng(seed)
    bones, count = 4, 300
    rows = envelope_rows(rng, bones)
    rows[1, 10] = 1.0  # bone 1 multiplies its group weights by its envelope
    positions = rng.uniform([-1, -1, -0.5], [1, 1, 4.5], (count, 3)).astype(F32)
    # Half the vertices have groups (bones 1 and 2), half none.
    lists = [[(1, 0.7), (2, 0.3)] if v % 2 else [] for v in range(count)]
    offsets = np.cumsum([0] + [len(l) for l in lists])
    infl = dqskin.Influences(offsets, np.array([b for l in lists for b, _ in l]), np.array([w for l in lists for _, w in l], F32), bones)
    premat = np.eye(4, dtype=F32)
    premat[:3, 3] = [0.1, -0.2, 0.3]
    eff = infl.effective(positions, premat, envelopes=rows, use_vertex_groups=True, use_envelopes=True)
    co = positions.astype(np.float64) + [0.1, -0.2, 0.3]
    rows64 = rows.astype(np.float64)
    for v in range(count):
        start, end = eff.offsets[v], eff.offsets[v + 1]
        got = list(zip(eff.bones[start:end].tolist(), eff.weights[start:end].tolist()))
        if lists[v]:
            f = distfactor(co[v], rows64[1, 0:3], rows64[1, 3:6], *rows64[1, 6:9])
            want = [(1, 0.7 * f), (2, 0.3)]
        else:
            want = []
            for b in range(bones):
                f = distfactor(co[v], rows64[b, 0:3], rows64[b, 3:6], *rows64[b, 6:9])
                if f > 0 and f * rows64[b, 9] > 0:
                    want.append((b, f * rows64[b, 9]))
        assert [b for b, _ in got] == [b for b, _ in want], v
        np.testing.assert_allclose([w for _, w in got], [w for _, w in want], rtol=1e-5, atol=1e-6)


def test_b_bone_influences_split_between_segment_joints():
    infl = dqskin.Influences(np.array([0, 1]), np.array([1]), F32([0.8]), 2)
    rest = np.stack([np.eye(4, dtype=F32)] * 2)
    eff = infl.effective(F32([[0.0, 1.5, 0.0]]), bbone_segments=np.array([1, 4]), rest=rest, lengths=F32([1.0, 2.0]))
    # Bone 1 has 4 segments over length 2: y = 1.5 is 3/4 along, exactly at joint 3 of its
    # joints (bones 2..6), so all weight is on that joint and none on the next.
    assert eff.bone_count == 2 + 5
    assert eff.bones.tolist() == [2 + 3, 2 + 4]
    np.testing.assert_allclose(eff.weights, [0.8, 0.0], atol=1e-7)
    mapped = infl.effective(
        F32([[0.0, 1.5, 0.0]]),
        bbone_segments=np.array([1, 4]),
        rest=rest,
        lengths=F32([1.0, 2.0]),
        bbone_mapping={1: (np.array([1], np.int32), F32([0.25]))},
    )
    assert mapped.bones.tolist() == [3, 4]
    np.testing.assert_allclose(mapped.weights, [0.6, 0.2], rtol=1e-6)


def test_bbone_segment_matrices_follow_blenders_formula():
    rng = np.random.default_rng(3)

    def rigid():
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        q *= np.sign(np.linalg.det(q))
        m = np.eye(4)
        m[:3, :3], m[:3, 3] = q, rng.normal(size=3)
        return m

    channel, rest = rigid(), rigid()
    pose = np.stack([rigid() for _ in range(4)])
    rest_joints = np.stack([rigid() for _ in range(4)])
    deform, basis = dqskin.bbone_segment_matrices(channel.astype(F32), rest.astype(F32), pose.astype(F32), rest_joints.astype(F32))
    for a in range(4):
        want = channel @ rest @ pose[a] @ np.linalg.inv(rest_joints[a]) @ np.linalg.inv(rest)
        np.testing.assert_allclose(deform[a], want, atol=2e-5)
        b = rest @ rest_joints[a]
        b[:3, :3] /= np.linalg.norm(b[:3, :3], axis=0)
        np.testing.assert_allclose(basis[a], b, atol=2e-5)


def test_transform_points_is_the_affine_transform():
    rng = np.random.default_rng(4)
    m = np.eye(4, dtype=F32)
    m[:3, :3] = rng.normal(size=(3, 3))
    m[:3, 3] = rng.normal(size=3)
    p = rng.normal(size=(50, 3)).astype(F32)
    np.testing.assert_allclose(dqskin.transform_points(m, p), p @ m[:3, :3].T + m[:3, 3], rtol=1e-5, atol=1e-5)


def test_bad_effective_inputs_are_named():
    infl = dqskin.Influences(np.array([0, 1]), np.array([1]), F32([0.8]), 2)
    pos = F32([[0.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match="envelopes must have shape"):
        infl.effective(pos, envelopes=np.zeros((3, 11), F32))
    with pytest.raises(ValueError, match="envelopes contains a NaN"):
        infl.effective(pos, envelopes=np.full((2, 11), np.nan, F32))
    with pytest.raises(ValueError, match="positions must have shape"):
        infl.effective(np.zeros((2, 3), F32))
    with pytest.raises(ValueError, match="rest is required"):
        infl.effective(pos, bbone_segments=np.array([1, 4]))
    with pytest.raises(ValueError, match="bbone_segments must have 2 entries"):
        infl.effective(pos, bbone_segments=np.array([4]), rest=np.stack([np.eye(4, dtype=F32)] * 2), lengths=F32([1, 1]))
    with pytest.raises(ValueError, match="B-Bone 1"):
        infl.effective(pos, bbone_segments=np.array([1, 4]), rest=np.stack([np.eye(4, dtype=F32)] * 2), lengths=F32([1, 0]))
    with pytest.raises(ValueError, match="bbone_mapping index must have shape"):
        infl.effective(
            pos,
            bbone_segments=np.array([1, 4]),
            rest=np.stack([np.eye(4, dtype=F32)] * 2),
            lengths=F32([1, 1]),
            bbone_mapping={1: (np.zeros(3, np.int32), F32([0, 0, 0]))},
        )
    with pytest.raises(ValueError, match="matrix is not affine"):
        dqskin.transform_points(np.ones((4, 4), F32), pos)
    with pytest.raises(ValueError, match="pose_joints has 2 matrices but rest_joints has 3"):
        dqskin.bbone_segment_matrices(np.eye(4), np.eye(4), np.stack([np.eye(4)] * 2), np.stack([np.eye(4)] * 3))


def test_bad_pose_inputs_are_named():
    infl = dqskin.Influences(np.array([0, 1]), np.array([1]), F32([0.8]), 2)
    pos = F32([[0.0, 0.0, 0.0]])
    for wrong in (object(), np.eye(4, dtype=F32), "pose", 3):
        with pytest.raises(TypeError, match="pose must be a dqskin.PoseData"):
            infl.effective(pos, pose=wrong)
    with pytest.raises(TypeError, match="PoseData"):
        dqskin.PoseData()
    with pytest.raises(TypeError, match="blend_file must be the bytes of a .blend file"):
        dqskin.memory.PoseMemory("file.blend")
    with pytest.raises(ValueError, match="blend_file: not an uncompressed .blend file"):
        dqskin.memory.PoseMemory(b"\x1f\x8b" + b"\0" * 30)
    with pytest.raises(ValueError, match="blend_file"):
        dqskin.memory.PoseMemory(b"BLENDER-v402" + b"\0" * 64)

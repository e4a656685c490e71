"""B-Bones and envelopes through the pose reader (Blender's memory: channel matrices, bone data,
the runtime B-Bone cache): what it reads against Blender's Python API, and DQ Skin against the
Armature modifier on every B-Bone setting, with the memory path (no per-joint or per-vertex
Python) and with the Python path it falls back to.

Bar: max vertex distance ≤ 1e-5 × the mesh's bounding-box diagonal; the segment mapping equal to
`PoseBone.bbone_segment_index` to the bit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from characters import rigify_character
from dqtest import REL_TOL, add_dq_skin, evaluated_positions, reference_copy
from dqtest import deviation as relative_deviation
from scenes import armature_chain, armature_modifier, chain_weights, link, tube

import bpy

from mathutils import Quaternion, Vector

LENGTH = 4.0


def bbone_rig(segments: int = 6, mapping: str = "STRAIGHT", rings: int = 48):
    """A tube along Z on a connected chain of 4 bones whose middle two are B-Bones with a curved
    rest shape, plus two non-deforming bones to serve as custom handles; posed to bend and twist."""
    arm = armature_chain("Rig", 4, LENGTH)
    bpy.ops.object.mode_set(mode="EDIT")
    for name, head in (("HandleStart", (0.6, 0.0, 0.9)), ("HandleEnd", (-0.5, 0.3, 3.1))):
        b = arm.data.edit_bones.new(name)
        b.head = head
        b.tail = (head[0], head[1] + 0.5, head[2])
    bpy.ops.object.mode_set(mode="OBJECT")
    for name in ("HandleStart", "HandleEnd"):
        arm.data.bones[name].use_deform = False
        arm.pose.bones[name].rotation_mode = "QUATERNION"
    obj = tube("Tube", rings, 16, LENGTH, 0.4)
    chain_weights(obj, arm, LENGTH, blend=0.8)
    mod = armature_modifier(obj, arm)
    for b in middle(arm.data.bones):
        b.bbone_segments = segments
        b.bbone_mapping_mode = mapping
        b.bbone_curveinx = 0.35
        b.bbone_curveoutz = -0.25
    pbs = arm.pose.bones
    pbs["Bone1"].rotation_quaternion = Quaternion((1, 0, 0), 0.6)
    pbs["Bone2"].rotation_quaternion = Quaternion((0, 1, 0.2), 1.1)
    pbs["Bone3"].rotation_quaternion = Quaternion((0, 0, 1), 0.8)
    return obj, arm, mod


def middle(collection):
    return [collection["Bone1"], collection["Bone2"]]


def _segments(arm, n):
    for b in middle(arm.data.bones):
        b.bbone_segments = n


def _ease_rest(arm):
    for b in middle(arm.data.bones):
        b.bbone_easein, b.bbone_easeout = 1.8, 0.3


def _ease_pose(arm):
    for pb in middle(arm.pose.bones):
        pb.bbone_easein, pb.bbone_easeout = 1.4, -0.6


def _handles(kind):
    def apply(arm):
        bones, pbs = arm.data.bones, arm.pose.bones
        for b in middle(bones):
            b.bbone_handle_type_start = b.bbone_handle_type_end = kind
            b.bbone_custom_handle_start = bones["HandleStart"]
            b.bbone_custom_handle_end = bones["HandleEnd"]
        pbs["HandleStart"].location = (0.2, -0.1, 0.3)
        pbs["HandleStart"].rotation_quaternion = Quaternion((0, 0, 1), 0.7)
        pbs["HandleEnd"].rotation_quaternion = Quaternion((1, 0, 0), -0.5)

    return apply


def _roll(arm):
    arm.data.bones["Bone1"].bbone_rollin = 0.3
    for pb in middle(arm.pose.bones):
        pb.bbone_rollin, pb.bbone_rollout = 0.9, -0.7


def _inherit_end_roll(arm):
    arm.pose.bones["Bone1"].bbone_rollout = 1.1
    arm.data.bones["Bone2"].use_endroll_as_inroll = True


def _scale(arm):
    pbs = arm.pose.bones
    pbs["Bone1"].bbone_scalein = (1.4, 1.0, 0.7)
    pbs["Bone1"].bbone_scaleout = (0.6, 1.3, 1.2)
    pbs["Bone2"].bbone_scalein = (1.2, 0.8, 1.5)


def _ease_scale(arm):
    _handles("ABSOLUTE")(arm)
    _scale(arm)
    bones = arm.data.bones
    for b in middle(bones):
        b.use_scale_easing = True
        b.bbone_handle_use_ease_start = b.bbone_handle_use_ease_end = True
        b.bbone_handle_use_scale_start = (True, False, True)
        b.bbone_handle_use_scale_end = (False, True, True)
    arm.pose.bones["HandleStart"].scale = (1.5, 0.8, 1.2)
    arm.pose.bones["HandleEnd"].scale = (0.7, 1.6, 0.9)


def _curve(arm):
    for b in middle(arm.data.bones):
        b.bbone_curveinz, b.bbone_curveoutx = 0.2, -0.3
    for pb in middle(arm.pose.bones):
        pb.bbone_curveinx, pb.bbone_curveinz = 0.8, -0.4
        pb.bbone_curveoutx, pb.bbone_curveoutz = -0.6, 0.5


def _scaled_bones(arm):
    pbs = arm.pose.bones
    pbs["Bone1"].scale = (1.3, 0.8, 1.1)
    pbs["Bone2"].scale = (0.7, 1.4, 0.9)


CASES = {
    "segments 2": lambda arm: _segments(arm, 2),
    "segments 8": lambda arm: _segments(arm, 8),
    "segments 32": lambda arm: _segments(arm, 32),
    "ease in and out, rest": _ease_rest,
    "ease in and out, pose": _ease_pose,
    "handles auto": _handles("AUTO"),
    "handles absolute": _handles("ABSOLUTE"),
    "handles relative": _handles("RELATIVE"),
    "handles tangent": _handles("TANGENT"),
    "roll in and out": _roll,
    "inherit end roll": _inherit_end_roll,
    "scale in and out": _scale,
    "ease and scale from handles": _ease_scale,
    "curve in and out": _curve,
    "scaled bones": _scaled_bones,
}


def _reads(dq_skin):
    """A fresh per-call pose cache over the session's reader."""
    readers = dq_skin.SESSION.readers
    return dq_skin.blender.pose.PoseReads(readers.pose, readers.pose_error)


@pytest.fixture
def memory_only(dq_skin, monkeypatch):
    """The Python path fails if it runs: whatever passes used the pose from memory."""

    def refuse(*_a, **_k):
        raise AssertionError("the Python path ran: the pose should come from memory")

    for name in ("with_bbone_joints", "curved_bbone_mapping", "bone_lengths"):
        monkeypatch.setattr(dq_skin.blender.rig, name, refuse)
    return dq_skin


@pytest.fixture
def python_only(dq_skin, monkeypatch):
    """The pose reader refuses every read: the Python path deforms."""

    class Refusing:
        def read(self, armature):
            raise ValueError("armature: refused by the test")

    readers = dq_skin.SESSION.readers
    readers.pose  # built first, then its pose reader replaced
    monkeypatch.setattr(readers, "_pose", Refusing())
    return dq_skin


def compare(dq_skin, obj, arm, method: str, frame: int = 3):
    reference = reference_copy(obj, method == "DUAL_QUATERNION")
    mod = add_dq_skin(obj, method)
    bpy.context.scene.frame_set(frame)
    st = dq_skin.SESSION.state_of(obj, mod)
    assert st.status.live, st.status.message
    ours, theirs = evaluated_positions(obj), evaluated_positions(reference)
    dev = relative_deviation(ours, theirs)
    assert dev <= REL_TOL, dev
    return mod, reference, theirs


@pytest.mark.parametrize("method", ["LINEAR", "DUAL_QUATERNION"])
@pytest.mark.parametrize("mapping", ["STRAIGHT", "CURVED"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_every_b_bone_setting_matches_the_armature_modifier(memory_only, case, mapping, method):
    obj, arm, _ = bbone_rig(mapping=mapping)
    CASES[case](arm)
    _, reference, theirs = compare(memory_only, obj, arm, method)
    # The case's B-Bones really shape the deformation: as plain bones the mesh differs.
    _segments(arm, 1)
    assert np.abs(evaluated_positions(reference) - theirs).max() > 1e-3


@pytest.mark.parametrize("method", ["LINEAR", "DUAL_QUATERNION"])
def test_the_python_path_matches_too(python_only, method):
    obj, arm, _ = bbone_rig(mapping="CURVED")
    _curve(arm)
    _handles("RELATIVE")(arm)
    compare(python_only, obj, arm, method)


@pytest.mark.parametrize("mapping", ["STRAIGHT", "CURVED"])
@pytest.mark.parametrize("method", ["LINEAR", "DUAL_QUATERNION"])
def test_envelopes_on_b_bones(memory_only, method, mapping):
    obj, arm, arm_mod = bbone_rig(mapping=mapping)
    for b in arm.data.bones:
        b.envelope_distance, b.head_radius, b.tail_radius = 0.6, 0.3, 0.3
    # Every third vertex has no group (envelopes fill in); Bone1 multiplies its group.
    for g in obj.vertex_groups:
        g.remove(list(range(0, len(obj.data.vertices), 3)))
    arm.data.bones["Bone1"].use_envelope_multiply = True
    arm_mod.use_bone_envelopes = True
    compare(memory_only, obj, arm, method)


@pytest.mark.parametrize("method", ["LINEAR", "DUAL_QUATERNION"])
def test_segments_and_mapping_changed_by_script(memory_only, method):
    obj, arm, _ = bbone_rig(segments=4)
    mod, reference, _ = compare(memory_only, obj, arm, method)
    for segments, mapping, frame in ((12, "CURVED", 5), (1, "CURVED", 7), (3, "STRAIGHT", 9)):
        for b in middle(arm.data.bones):
            b.bbone_segments = segments
            b.bbone_mapping_mode = mapping
        bpy.context.scene.frame_set(frame)
        assert memory_only.SESSION.state_of(obj, mod).status.live
        dev = relative_deviation(evaluated_positions(obj), evaluated_positions(reference))
        assert dev <= REL_TOL, (segments, mapping, dev)


@pytest.mark.parametrize("method", ["LINEAR", "DUAL_QUATERNION"])
def test_animating_only_the_b_bone_shape(memory_only, method):
    """Keys on B-Bone properties alone leave every `matrix_channel` as it was: the result must
    still follow them."""
    obj, arm, _ = bbone_rig(mapping="CURVED")
    pb = arm.pose.bones["Bone1"]
    for frame, value in ((1, 0.0), (10, 1.5)):
        pb.bbone_curveinx = value
        pb.bbone_easeout = value
        pb.keyframe_insert("bbone_curveinx", frame=frame)
        pb.keyframe_insert("bbone_easeout", frame=frame)
    mod, reference, first = compare(memory_only, obj, arm, method, frame=1)
    bpy.context.scene.frame_set(10)
    theirs = evaluated_positions(reference)
    assert np.abs(theirs - first).max() > 1e-2, "the keys move the mesh"
    assert relative_deviation(evaluated_positions(obj), theirs) <= REL_TOL


def _row_major(m) -> np.ndarray:
    return np.array(m, np.float32)


def test_the_reader_gives_what_the_python_api_gives(dq_skin):
    obj, arm, _ = bbone_rig(segments=8, mapping="CURVED")
    _curve(arm)
    _handles("RELATIVE")(arm)
    _ease_scale(arm)
    arm.data.bones["Bone2"].bbone_mapping_mode = "STRAIGHT"
    arm.data.bones["Bone0"].bbone_segments = 3  # Straight, not curved at rest
    arm.data.bones["Bone3"].use_envelope_multiply = True
    arm.data.bones["Bone3"].envelope_weight = 0.4
    bpy.context.scene.frame_set(4)
    arm_eval = arm.evaluated_get(bpy.context.evaluated_depsgraph_get())
    reads = _reads(dq_skin)
    data = reads.read(arm_eval)
    assert data is not None, reads.error
    pbs = list(arm_eval.pose.bones)
    deforming = [pb for pb in pbs if pb.bone.use_deform]
    assert data.names == [pb.name for pb in deforming]
    np.testing.assert_array_equal(data.bone_indices, [i for i, pb in enumerate(pbs) if pb.bone.use_deform])
    b = len(deforming)
    assert data.bone_count == b
    deform, rest = data.deform, data.rest
    np.testing.assert_array_equal(deform[:b], [_row_major(pb.matrix_channel) for pb in deforming])
    np.testing.assert_array_equal(rest[:b], [_row_major(pb.bone.matrix_local) for pb in deforming])
    np.testing.assert_array_equal(data.segments, [pb.bone.bbone_segments for pb in deforming])
    mesh = dq_skin.SESSION.meshes.get(obj, dq_skin.SESSION.readers.mesh)
    binding = dq_skin.blender.rig.bind(mesh, arm_eval)
    np.testing.assert_array_equal(data.envelopes, dq_skin.blender.rig.envelopes(arm_eval, binding))
    # The joints: Blender's cache against what its Python API gives for them.
    first = b
    for pb in deforming:
        n = pb.bone.bbone_segments
        if n < 2:
            continue
        joints = np.array([_row_major(pb.bbone_segment_matrix(a)) for a in range(n + 1)])
        rest_joints = np.array([_row_major(pb.bbone_segment_matrix(a, rest=True)) for a in range(n + 1)])
        want_deform, want_rest = dq_skin.dqskin.bbone_segment_matrices(
            _row_major(pb.matrix_channel), _row_major(pb.bone.matrix_local), joints, rest_joints
        )
        np.testing.assert_allclose(deform[first : first + n + 1], want_deform, atol=2e-5)
        np.testing.assert_allclose(rest[first : first + n + 1], want_rest, atol=2e-6)
        first += n + 1
    assert first == data.expanded_bone_count == len(deform) == len(rest)
    # The segment mapping, Straight and Curved, to the bit: one vertex per sample point, weight 1
    # on one B-Bone, so its two effective weights are exactly 1 − blend and blend.
    rng = np.random.default_rng(5)
    points = np.column_stack([rng.uniform(-0.8, 0.8, 400), rng.uniform(-0.8, 0.8, 400), rng.uniform(-0.3, LENGTH + 0.3, 400)]).astype(
        np.float32
    )
    offsets = np.arange(len(points) + 1)
    first = b
    checked = 0
    for k, pb in enumerate(deforming):
        n = int(data.segments[k])
        if n < 2:
            continue
        influences = dq_skin.dqskin.Influences(offsets, np.full(len(points), k), np.ones(len(points), np.float32), b)
        effective = influences.effective(points, pose=data)
        pairs_bones = effective.bones.reshape(-1, 2)
        pairs_weights = effective.weights.reshape(-1, 2)
        for v, co in enumerate(points):
            index, blend = pb.bbone_segment_index(Vector(co.tolist()))
            assert pairs_bones[v, 0] - first == index, (pb.name, v)
            assert pairs_weights[v, 1] == np.float32(blend), (pb.name, v, pairs_weights[v, 1], blend)
            checked += 1
        first += n + 1
    assert checked == 400 * 3


def test_the_reader_refuses_what_is_not_an_armature(dq_skin):
    obj, arm, _ = bbone_rig()
    readers = dq_skin.SESSION.readers
    reader = readers.pose
    assert reader is not None, readers.pose_error
    with pytest.raises(ValueError, match="armature must be an armature object"):
        reader.read(obj)
    with pytest.raises(TypeError, match="armature must be a bpy.types.Object"):
        reader.read(arm.data)
    with pytest.raises(TypeError, match="armature must be a bpy.types.Object"):
        reader.read(arm.as_pointer())
    empty = link(bpy.data.objects.new("Empty", None))
    with pytest.raises(ValueError, match="armature"):
        reader.read(empty)
    assert reader.read(arm).bone_count == 4


def test_the_channel_matrices_alone_are_the_python_apis(dq_skin, monkeypatch):
    """`PoseMemory.channel_matrices`, what characters without B-Bones or envelopes read every
    frame: every pose bone's `matrix_channel` (deforming or not), in `pose.bones` order, to the
    bit; what is not an armature is refused; a reader whose first read disagrees with Blender's
    data is refused for the session and the Python path deforms, still equal to Blender."""
    obj, arm, _ = bbone_rig()
    arm.data.bones["Bone1"].use_deform = False
    arm.pose.bones["Bone2"].rotation_quaternion = Quaternion((0, 1, 0), 0.6)
    arm.pose.bones["Bone3"].scale = (1.2, 0.9, 1.1)
    bpy.context.scene.frame_set(3)
    arm_eval = arm.evaluated_get(bpy.context.evaluated_depsgraph_get())
    readers = dq_skin.SESSION.readers
    reader = readers.pose
    assert reader is not None, readers.pose_error
    got = reader.channel_matrices(arm_eval)
    assert got.shape == (len(arm.pose.bones), 4, 4) == (6, 4, 4) and got.dtype == np.float32
    np.testing.assert_array_equal(got, [_row_major(pb.matrix_channel) for pb in arm_eval.pose.bones])
    raw = readers._pose
    with pytest.raises(ValueError, match="armature must be an armature object"):
        raw.channel_matrices(obj)
    with pytest.raises(TypeError, match="armature must be a bpy.types.Object"):
        raw.channel_matrices(arm.data)
    with pytest.raises(ValueError, match="armature"):
        raw.channel_matrices(link(bpy.data.objects.new("Empty", None)))
    # A reader that disagrees on its first read: refused, and the Python path deforms.
    check = dq_skin.blender.memory_check
    monkeypatch.setattr(readers, "channels_checked", False)
    monkeypatch.setattr(check, "channels_differ", lambda *_: "the bones' channel matrices (made up by the test)")
    monkeypatch.setattr(readers, "_pose", readers._pose)  # (put back after the test)
    arm.data.bones["Bone1"].use_deform = True
    for b in arm.data.bones:
        b.bbone_segments = 1
    ref = reference_copy(obj, True)
    add_dq_skin(obj, "DUAL_QUATERNION")
    bpy.context.scene.frame_set(5)
    assert readers.pose is None and "channel matrices (made up" in readers.pose_error, readers.pose_error
    st = dq_skin.SESSION.status_of(obj, [m for m in obj.modifiers if m.type == "NODES"][0])
    assert st.live, st.message
    assert relative_deviation(evaluated_positions(obj), evaluated_positions(ref)) <= REL_TOL


def test_the_reader_follows_bones_added_and_removed(dq_skin):
    """The reader keeps each armature's channel count (Blender's API counts by visiting every
    pose bone); a read after bones were added or removed walks them against the new count, for
    the whole pose and the channel matrices alike, and another armature is never read with the
    first one's count."""
    _obj, arm, _ = bbone_rig()
    reader = dq_skin.SESSION.readers._pose
    assert reader is not None, dq_skin.SESSION.readers.pose_error

    def evaluated():
        return arm.evaluated_get(bpy.context.evaluated_depsgraph_get())

    def read_both():
        a = evaluated()
        return reader.read(a), reader.channel_matrices(a)

    def edit_bones(change):
        bpy.context.view_layer.objects.active = arm
        bpy.ops.object.mode_set(mode="EDIT")
        change(arm.data.edit_bones)
        bpy.ops.object.mode_set(mode="OBJECT")
        bpy.context.view_layer.update()

    def added(bones):
        b = bones.new("Added")
        b.head, b.tail = (0.0, 0.0, 5.0), (0.0, 0.0, 6.0)

    for change, count in ((None, 6), (added, 7), (lambda bones: bones.remove(bones["Added"]), 6)):
        if change is not None:
            edit_bones(change)
        for _ in range(2):  # (the second read with the count kept by the first)
            data, matrices = read_both()
            assert len(matrices) == len(arm.pose.bones) == count
            assert data.bone_count == sum(b.use_deform for b in arm.data.bones)
            np.testing.assert_array_equal(matrices, [_row_major(pb.matrix_channel) for pb in evaluated().pose.bones])
    other = bpy.data.objects.new("Other rig", bpy.data.armatures.new("Other rig"))
    link(other)
    bpy.context.view_layer.update()
    assert len(reader.channel_matrices(other.evaluated_get(bpy.context.evaluated_depsgraph_get()))) == 0


def test_binding_and_pose_signatures(dq_skin):
    obj, arm, _ = bbone_rig()
    dg = bpy.context.evaluated_depsgraph_get()

    def read():
        return _reads(dq_skin).read(arm.evaluated_get(bpy.context.evaluated_depsgraph_get()))

    bpy.context.scene.frame_set(1)
    base = read()
    assert base is not None and dg is not None
    same = read()
    assert (same.binding_signature, same.pose_signature) == (base.binding_signature, base.pose_signature)
    arm.pose.bones["Bone1"].bbone_curveinx = 0.9  # the pose's B-Bone shape only
    bpy.context.view_layer.update()
    shaped = read()
    assert shaped.binding_signature == base.binding_signature and shaped.pose_signature != base.pose_signature
    arm.data.bones["Bone2"].bbone_easein = 1.7  # the rest shape
    bpy.context.view_layer.update()
    rest = read()
    assert rest.binding_signature != base.binding_signature
    arm.data.bones["HandleEnd"].use_deform = True
    bpy.context.view_layer.update()
    assert read().binding_signature != rest.binding_signature
    assert read().bone_count == 5


def test_many_segments_and_many_bones_per_frame_read_once(memory_only):
    """Every DQ Skin frame reads the pose once and computes influences only when the vertices or
    the bones' rest data change."""
    obj, arm, _ = bbone_rig(segments=16, mapping="CURVED")
    mod, reference, _ = compare(memory_only, obj, arm, "DUAL_QUATERNION")
    st = memory_only.SESSION.state_of(obj, mod)
    kept = st.binding.binding.effective[1]
    for frame in (4, 5, 6):
        arm.pose.bones["Bone2"].rotation_quaternion = Quaternion((0, 1, 0), 0.2 * frame)
        arm.pose.bones["Bone2"].keyframe_insert("rotation_quaternion", frame=frame)
    for frame in (4, 5, 6):
        bpy.context.scene.frame_set(frame)
        assert relative_deviation(evaluated_positions(obj), evaluated_positions(reference)) <= REL_TOL
    assert st.binding.binding.effective[1] is kept, "the pose alone does not change the influences"
    arm.data.bones["Bone1"].bbone_easein = 0.4
    bpy.context.scene.frame_set(7)
    assert st.binding.binding.effective[1] is not kept
    assert relative_deviation(evaluated_positions(obj), evaluated_positions(reference)) <= REL_TOL
    assert math.isfinite(st.status.seconds)


def test_a_frame_reads_each_armature_once(memory_only, monkeypatch):
    """The feed's driver reads the pose in Blender's evaluation (see `routes.feed`), once for two
    characters on one rig, and the frame handler then reads nothing
    (`playback.fed_frame_stands`). Where the driver did not skin (here: as if an operator were
    running), the handler's full evaluation needs the pose for the binding's signature and for
    the frame: one read per armature and frame there too (each read of a Rigify rig costs about
    0.1-0.2 ms)."""
    obj, arm, _ = bbone_rig(segments=8, mapping="CURVED")
    other = link(obj.copy())
    other.data = obj.data.copy()
    reference = reference_copy(obj, True)
    mods = [add_dq_skin(o, "DUAL_QUATERNION") for o in (obj, other)]
    for frame in (2, 3, 4, 5):
        arm.pose.bones["Bone2"].rotation_quaternion = Quaternion((0, 1, 0), 0.2 * frame)
        arm.pose.bones["Bone2"].keyframe_insert("rotation_quaternion", frame=frame)
    bpy.context.scene.frame_set(2)
    session = memory_only.SESSION
    assert session.readers.pose is not None, session.readers.pose_error
    reader = session.readers._pose  # the raw reader: the checked wrapper reads through `_pose`
    reads = []
    assert all(session.state_of(o, m).output.route is not None for o, m in zip((obj, other), mods))

    class Counting:
        def read(self, armature):
            in_driver = any(f.filename.endswith("fed.py") for f in __import__("traceback").extract_stack())
            reads.append(("driver" if in_driver else "handler", armature.name))
            return reader.read(armature)

    monkeypatch.setattr(session.readers, "_pose", Counting())
    for frame in (3, 4, 5):
        reads.clear()
        bpy.context.scene.frame_set(frame)
        assert reads == [("driver", arm.name)], reads
        for o, mod in zip((obj, other), mods):
            assert memory_only.SESSION.state_of(o, mod).status.live
            assert relative_deviation(evaluated_positions(o), evaluated_positions(reference)) <= REL_TOL
    monkeypatch.setattr(session.routes.feeds, "_busy", lambda: True)
    for frame in (2, 4):
        reads.clear()
        bpy.context.scene.frame_set(frame)
        assert reads == [("handler", arm.name)], reads
        for o in (obj, other):
            assert relative_deviation(evaluated_positions(o), evaluated_positions(reference)) <= REL_TOL


def test_the_poses_kept_for_the_frame_handler_stay_one_per_armature(memory_only):
    """The feed keeps the poses it read for the frame handler after it (`Feeds.keep`); posing
    without changing frames runs the driver again and again in the same frame change: only the
    newest read of the armature is kept (not one per run), and it is the pose shown."""
    obj, arm, _ = bbone_rig(segments=4)
    reference = reference_copy(obj, True)
    add_dq_skin(obj, "DUAL_QUATERNION")
    scene = bpy.context.scene
    for f in (2, 3):
        scene.frame_set(f)
    feeds = memory_only.SESSION.routes.feeds
    pb = arm.pose.bones["Bone2"]
    for k in range(1, 6):
        pb.rotation_quaternion = Quaternion((0, 1, 0), 0.15 * k)
        bpy.context.view_layer.update()
        _stamp, reads = feeds._kept
        assert reads is not None and len(reads._read) == 1, k
        assert relative_deviation(evaluated_positions(obj), evaluated_positions(reference)) <= REL_TOL, k
    ((data, error),) = reads._read.values()
    assert data is not None, error
    np.testing.assert_array_equal(
        data.deform[: data.bone_count],
        [_row_major(b.matrix_channel) for b in arm.evaluated_get(bpy.context.evaluated_depsgraph_get()).pose.bones if b.bone.use_deform],
    )


def test_a_generated_rigify_character_matches_the_armature_modifier(memory_only):
    """Rigify's human rig (160 deforming bones, 52 B-Bones with custom handles, ease and scale)
    on a body with automatic weights, playing an animation that bends, twists and scales."""
    body, rig = rigify_character()
    bbones = [b for b in rig.data.bones if b.use_deform and b.bbone_segments > 1]
    assert len(bbones) >= 40
    other = body.copy()
    bpy.context.scene.collection.objects.link(other)
    pairs = []
    for obj, method in ((body, "LINEAR"), (other, "DUAL_QUATERNION")):
        reference = reference_copy(obj, method == "DUAL_QUATERNION")
        pairs.append((obj, add_dq_skin(obj, method), reference))
    rest = evaluated_positions(pairs[0][2])
    for frame in (1, 12, 20, 33):
        bpy.context.scene.frame_set(frame)
        for obj, mod, reference in pairs:
            assert memory_only.SESSION.state_of(obj, mod).status.live
            theirs = evaluated_positions(reference)
            dev = relative_deviation(evaluated_positions(obj), theirs)
            assert dev <= REL_TOL, (obj.name, frame, dev)
    assert np.abs(theirs - rest).max() > 0.05, "the animation moves the body"


def test_the_readers_are_checked_against_blenders_data_on_their_first_read(dq_skin, monkeypatch):
    """A reader's first read in a session is compared with what Blender's Python API gives; one
    that disagrees (a Blender whose structs changed under it) is refused for the session with
    the reason, and DQ Skin deforms through the Python paths, still equal to the Armature
    modifier."""
    check = dq_skin.blender.memory_check
    obj, arm, _ = bbone_rig(segments=6)
    other, other_arm, _ = bbone_rig(segments=3)
    other_arm.pose.bones["Bone1"].rotation_quaternion = Quaternion((1, 0, 0), 0.7)
    other.vertex_groups["Bone3"].add([0], 0.3, "REPLACE")  # another weight on a sampled vertex
    bpy.context.scene.frame_set(4)
    dg = bpy.context.evaluated_depsgraph_get()
    reads = _reads(dq_skin)
    data = reads.read(arm.evaluated_get(dg))
    assert data is not None, reads.error
    # What the check compares: the right armature agrees, another armature's pose does not.
    assert check.pose_differs(data, arm.evaluated_get(dg)) == ""
    assert check.pose_differs(data, other_arm.evaluated_get(dg)) != ""
    mesh = dq_skin.SESSION.meshes.get(obj, None)
    assert check.groups_differ(mesh.groups, obj.data) == ""
    assert check.groups_differ(mesh.groups, other.data) != ""
    # A session whose readers disagree: both refused on their first read, with the reason.
    readers = dq_skin.SESSION.readers
    monkeypatch.setattr(readers, "pose_checked", False)
    monkeypatch.setattr(readers, "mesh_checked", False)
    monkeypatch.setattr(check, "pose_differs", lambda *_: "the bones' pose matrices (made up by the test)")
    monkeypatch.setattr(check, "groups_differ", lambda *_: "the weights of vertex 0 (made up by the test)")
    monkeypatch.setattr(readers, "_pose", readers._pose)  # (put back after the test)
    monkeypatch.setattr(readers, "_mesh", readers._mesh)
    dq_skin.SESSION.meshes.forget()
    ref = reference_copy(obj, True)
    add_dq_skin(obj, "DUAL_QUATERNION")
    bpy.context.scene.frame_set(6)
    assert readers.pose is None and "disagrees with Blender's data" in readers.pose_error, readers.pose_error
    assert readers.mesh is None and "disagrees with Blender's data" in readers.mesh_error, readers.mesh_error
    st = dq_skin.SESSION.status_of(obj, [m for m in obj.modifiers if m.type == "NODES"][0])
    assert st.live, st.message
    assert relative_deviation(evaluated_positions(obj), evaluated_positions(ref)) <= REL_TOL


def _heap_bytes() -> int | None:
    """Bytes in use on the C heap (glibc's `mallinfo2`), or None where it is not available."""
    import ctypes
    import ctypes.util
    import sys

    if not sys.platform.startswith("linux"):
        return None

    class MallInfo2(ctypes.Structure):
        _fields_ = [
            (n, ctypes.c_size_t)
            for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks", "keepcost")
        ]

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.mallinfo2.restype = MallInfo2
    except (OSError, AttributeError):
        return None
    info = libc.mallinfo2()
    return info.uordblks + info.hblkhd


def test_positions_read_from_memory_are_blenders_and_leave_copies_sharing(dq_skin):
    """The positions reader gives exactly what the Python API gives, finds the `position` layer
    among other vector attributes, and reading a copy of a mesh does not make Blender give the
    copy its own array (reading through the Python API does: 12 bytes per vertex)."""
    check = dq_skin.blender.memory_check
    meshdata = dq_skin.blender.meshdata
    obj = tube("Positions", 40, 24, 4.0, 0.5)
    mesh = obj.data
    mesh.attributes.new("positions", "FLOAT_VECTOR", "POINT").data.foreach_set("vector", np.full(len(mesh.vertices) * 3, 7.0, np.float32))
    mesh.attributes.new("rest", "FLOAT_VECTOR", "POINT")
    reader = dq_skin.SESSION.readers.mesh
    assert reader is not None, dq_skin.SESSION.readers.mesh_error
    got = reader.positions(mesh)
    want = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.attributes["position"].data.foreach_get("vector", want)
    if bpy.app.version >= (5, 1, 0):
        # Blender 5.1 keeps mesh attributes outside the vertex CustomData the reader reads: it
        # says so (None) and the Python API reads instead.
        assert got is None
        assert np.array_equal(meshdata.read_positions(mesh, reader).ravel(), want)
        pytest.skip("Blender 5.1+ keeps positions in its attribute storage: read through the Python API")
    assert got is not None, dq_skin.SESSION.readers.positions_error
    assert got.dtype == np.float32 and got.shape == (len(mesh.vertices), 3)
    assert np.array_equal(got.ravel(), want)
    assert np.array_equal(meshdata.read_positions(mesh, reader), got)
    # What the first-read check compares: another mesh's positions disagree.
    other = tube("Other", 40, 24, 4.0, 0.5)
    other.data.vertices[0].co.x += 0.5
    assert check.positions_differ(got, mesh) == ""
    assert check.positions_differ(got, other.data) != ""
    with pytest.raises(TypeError, match="bpy.types.Mesh"):
        reader.positions(obj)
    # Copies share their positions until one is read through the Python API.
    heap = _heap_bytes()
    if heap is None:
        pytest.skip("no heap statistics on this platform")
    copies = [mesh.copy() for _ in range(30)]
    before = _heap_bytes()
    kept = [reader.positions(c) for c in copies]
    by_memory = (_heap_bytes() - before) / len(copies)
    before = _heap_bytes()
    for c in copies:
        c.attributes["position"].data.foreach_get("vector", want)
    by_python = (_heap_bytes() - before) / len(copies)
    size = 12 * len(mesh.vertices)
    assert all(np.array_equal(k, got) for k in kept)
    assert by_python >= 0.9 * size, (by_python, size)  # (what the reader avoids)
    assert by_memory <= size + 1024, (by_memory, size)  # only our own array


def test_bound_weights_are_released_and_read_again_when_needed(dq_skin):
    """Once bound, a mesh's weights are not kept twice (the binding has them): they are read
    again from memory when a binding must be made again, and weights a script changed without
    Blender telling DQ Skin are the ones used then, the mesh being read again on its next use."""
    obj = tube("Released", 40, 24, LENGTH, 0.5)
    arm = armature_chain("ReleasedRig", 4, LENGTH)
    chain_weights(obj, arm, LENGTH)
    obj.parent = arm
    armature_modifier(obj, arm)
    arm.pose.bones["Bone1"].rotation_mode = "QUATERNION"
    arm.pose.bones["Bone1"].rotation_quaternion = Quaternion((1, 0, 0), 0.6)
    ref = reference_copy(obj, False)
    add_dq_skin(obj, "LINEAR")
    bpy.context.scene.frame_set(2)
    session = dq_skin.SESSION
    reader = session.readers.mesh
    assert reader is not None, session.readers.mesh_error
    data = session.meshes.get(obj, reader)
    assert data.has_groups and data.held_groups is None  # released once bound
    first = data.groups  # read again from memory: the same weights
    assert data.held_groups is not None and not data.changed_under
    assert dq_skin.blender.meshdata.digest_of(first) == data.groups_digest
    data.release_groups()
    # A weight changed behind DQ Skin's back: read again, it is the one used, and the mesh is
    # read again (a new version) on its next use.
    obj.vertex_groups["Bone2"].add([5], 0.123, "REPLACE")
    ref.vertex_groups["Bone2"].add([5], 0.123, "REPLACE")
    got = data.groups
    assert data.changed_under
    a, b = int(got.offsets[5]), int(got.offsets[6])
    assert np.float32(0.123) in got.weights[a:b]
    assert session.meshes.peek(obj) is None
    again = session.meshes.get(obj, reader)
    assert again is not data and again.version > data.version and not again.changed_under
    bpy.context.scene.frame_set(3)
    assert relative_deviation(evaluated_positions(obj), evaluated_positions(ref)) <= REL_TOL

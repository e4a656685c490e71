"""The animation tools on objects and on pose bones, checking the keys they write numerically."""

from __future__ import annotations

import math

import numpy as np
import pytest
from dqtest import import_character

import bpy

from mathutils import Euler, Matrix, Quaternion

ANGLE_TOL = 1e-4  # rad per frame: f32 keys, LINEAR interpolation between them
F32 = np.float32


@pytest.fixture
def dq(dq_skin):
    from bl_ext.user_default.dq_skin import dqskin
    from bl_ext.user_default.dq_skin.tools import keys

    return dqskin, keys


def keyed_object(name, frames, rotations, locations=None, euler=False):
    obj = bpy.data.objects.new(name, None)
    bpy.context.scene.collection.objects.link(obj)
    obj.rotation_mode = "XYZ" if euler else "QUATERNION"
    for i, f in enumerate(frames):
        if euler:
            obj.rotation_euler = rotations[i]
            obj.keyframe_insert("rotation_euler", frame=f)
        else:
            obj.rotation_quaternion = rotations[i]
            obj.keyframe_insert("rotation_quaternion", frame=f)
        if locations is not None:
            obj.location = locations[i]
            obj.keyframe_insert("location", frame=f)
    return obj


def run_on_objects(op, objects, active=None, **props):
    active = active or objects[0]
    for o in bpy.context.scene.objects:
        o.select_set(o in objects)
    bpy.context.view_layer.objects.active = active
    with bpy.context.temp_override(selected_objects=objects, active_object=active, object=active):
        return op(**props)


def rotation_at(dq, obj, frame, bone=None):
    k = dq[1]
    target = k.Target(obj, bone)
    return k.rotations_at(target, [frame])[0]


def angle_between(a, b):
    """Rotation angle between two quaternions, in float64 and without acos (which turns float32
    rounding near 1 into ~4e-4 rad)."""
    a = np.asarray(a, np.float64) / np.linalg.norm(a)
    b = np.asarray(b, np.float64) / np.linalg.norm(b)
    if np.dot(a, b) < 0:
        b = -b
    return 4 * math.atan2(np.linalg.norm(a - b), np.linalg.norm(a + b))


KEY_FRAMES = [1, 11, 17]
KEY_ROTATIONS = [Quaternion((1, 0, 0, 0)), Quaternion((1, 0, 0), 2.0), Quaternion((0.3, 1, 0), 2.6)]


def test_slerp_bake_on_an_object(dq):
    dqskin, keys = dq
    obj = keyed_object("Spinner", KEY_FRAMES, KEY_ROTATIONS)
    assert run_on_objects(bpy.ops.anim.dq_rotation_bake, [obj], method="SLERP", step=0.5) == {"FINISHED"}
    # A sub-frame sample is Slerp of the neighbouring keys.
    q1, q11 = np.array(KEY_ROTATIONS[0], F32), np.array(KEY_ROTATIONS[1], F32)
    want = dqskin.slerp(q1, q11, (5.5 - 1) / 10)
    assert angle_between(rotation_at(dq, obj, 5.5), want) < 1e-5
    # Constant angular speed between two keys, frame by frame.
    rots = [rotation_at(dq, obj, f) for f in range(11, 18)]
    speeds = [angle_between(a, b) for a, b in zip(rots, rots[1:])]
    assert max(speeds) - min(speeds) < ANGLE_TOL, speeds
    # Unit quaternions, keys kept.
    for f, q in zip(KEY_FRAMES, KEY_ROTATIONS):
        got = rotation_at(dq, obj, f)
        assert abs(np.linalg.norm(got) - 1) < 1e-6
        assert angle_between(got, np.array(q)) < 1e-5


def test_squad_bake_on_pose_bones_of_the_fox(dq, assets):
    dqskin, keys = dq
    bpy.ops.import_scene.gltf(filepath=str(assets / "Fox.glb"))
    arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
    name = "b_Neck_04"
    target = keys.Target(arm, name)
    # Thin the bone's rotation keys to every 8th frame, so there is something to bake.
    for i in range(4):
        fc = keys.channel(target, "rotation_quaternion", i)
        for k in [k for k in fc.keyframe_points if round(k.co[0]) % 8][::-1]:
            fc.keyframe_points.remove(k, fast=True)
        fc.update()
    frames = keys.key_frames(target)
    key_rots = keys.rotations_at(target, frames)
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="POSE")
    pb = arm.pose.bones[name]
    with bpy.context.temp_override(selected_pose_bones=[pb], active_pose_bone=pb):
        assert bpy.ops.anim.dq_rotation_bake(method="SQUAD", step=1.0) == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    for f, q in zip(frames, key_rots):
        assert angle_between(keys.rotations_at(target, [f])[0], q) < 1e-5
    mid = float(frames[1] + 3)
    want = dqskin.sample_rotations(frames, key_rots, np.array([mid], F32), method="squad")[0]
    assert angle_between(keys.rotations_at(target, [mid])[0], want) < 1e-5


def test_euler_rotation_is_converted_to_quaternion_keys(dq):
    dqskin, keys = dq
    eulers = [Euler((0, 0, 0)), Euler((1.0, 0.2, 0)), Euler((0.5, 1.5, -0.7))]
    obj = keyed_object("Eul", KEY_FRAMES, eulers, euler=True)
    assert run_on_objects(bpy.ops.anim.dq_rotation_bake, [obj], method="SLERP", step=1.0) == {"FINISHED"}
    assert obj.rotation_mode == "QUATERNION"
    assert keys.rotation_kind(keys.Target(obj)) == "QUATERNION"
    assert keys.channel(keys.Target(obj), "rotation_euler", 0) is None
    for f, e in zip(KEY_FRAMES, eulers):
        assert angle_between(rotation_at(dq, obj, f), np.array(e.to_quaternion())) < 1e-5


def test_quaternion_cleanup_removes_every_sign_flip(dq):
    dqskin, keys = dq
    rots = [Quaternion((0, 1, 0), 0.4 * i) for i in range(10)]
    for i in (3, 4, 8):
        rots[i] = -rots[i]
    obj = keyed_object("Flippy", list(range(1, 11)), rots)
    assert run_on_objects(bpy.ops.anim.dq_quaternion_cleanup, [obj]) == {"FINISHED"}
    fixed = keys.rotations_at(keys.Target(obj), np.arange(1, 11, dtype=F32))
    assert np.all(np.sum(fixed[1:] * fixed[:-1], axis=1) >= 0)
    for got, q in zip(fixed, rots):
        assert angle_between(got, np.array(q)) < 1e-5  # same rotations


def test_screw_inbetweens_move_at_constant_speed_along_the_screw(dq):
    dqskin, keys = dq
    obj = keyed_object(
        "Screw",
        [1, 21],
        [Quaternion((1, 0, 0, 0)), Quaternion((0, 0, 1), 2.0)],
        locations=[(0, 0, 0), (2.0, 1.0, 3.0)],
    )
    assert run_on_objects(bpy.ops.anim.dq_screw_inbetweens, [obj], step=1.0) == {"FINISHED"}
    t = keys.Target(obj)
    frames = np.arange(1, 22, dtype=F32)
    rot, loc = keys.rotations_at(t, frames), keys.locations_at(t, frames)
    dqs = [dqskin.DualQuat.from_rotation_translation(r, p) for r, p in zip(rot, loc)]
    steps = [(a.conjugate() * b).shortest().screw() for a, b in zip(dqs, dqs[1:])]
    angles = [s.angle for s in steps]
    pitches = [s.pitch for s in steps]
    assert max(angles) - min(angles) < ANGLE_TOL and max(pitches) - min(pitches) < 1e-4
    # It is the ScLERP screw, not a straight line: the midpoint is off the chord.
    want = dqskin.sclerp(dqs[0].to_array(), dqs[-1].to_array(), 0.5)
    mid = dqs[10]
    np.testing.assert_allclose(mid.translation, dqskin.DualQuat(want[:4], want[4:]).translation, atol=1e-4)
    assert np.linalg.norm(np.array(mid.translation) - np.array([1.0, 0.5, 1.5])) > 0.1


@pytest.mark.parametrize("method", ["DLB", "DIB", "SCLERP"])
def test_blend_transforms_of_objects(dq, method):
    dqskin, keys = dq
    sources = []
    for i, (axis, angle, loc) in enumerate([((0, 0, 1), 0.5, (1, 0, 0)), ((1, 0, 0), 1.2, (0, 2, 0)), ((0, 1, 1), -0.7, (0, 0, 3))]):
        o = bpy.data.objects.new(f"Src{i}", None)
        bpy.context.scene.collection.objects.link(o)
        o.matrix_world = Matrix.LocRotScale(loc, Quaternion(axis, angle), (1, 1, 1))
        sources.append(o)
    if method == "SCLERP":
        sources = sources[:2]
    target = bpy.data.objects.new("Target", None)
    bpy.context.scene.collection.objects.link(target)
    target.rotation_mode = "QUATERNION"
    target.scale = (2, 2, 2)
    weights = [0.2, 0.5, 0.3][: len(sources)]
    result = run_on_objects(
        bpy.ops.anim.dq_blend_transforms,
        sources + [target],
        active=target,
        method=method,
        weights=weights + [1.0] * (16 - len(weights)),
        keyframe=True,
    )
    assert result == {"FINISHED"}
    dqs = np.stack([dqskin.DualQuat.from_matrix(np.array(o.matrix_world, F32)).to_array() for o in sources])
    w = np.array(weights, F32)
    want = {
        "DLB": lambda: dqskin.dlb(dqs, w),
        "DIB": lambda: dqskin.dib(dqs, w)[0],
        "SCLERP": lambda: dqskin.sclerp(dqs[0], dqs[1], w[1] / w.sum()),
    }[method]()
    got = dqskin.DualQuat.from_matrix(np.array(target.matrix_world.normalized(), F32), check=False)
    assert np.abs(np.abs(np.dot(got.to_array()[:4], want[:4])) - 1) < 1e-5
    np.testing.assert_allclose(got.translation, dqskin.DualQuat(want[:4], want[4:]).translation, atol=1e-5)
    np.testing.assert_allclose(target.matrix_world.to_scale(), (2, 2, 2), atol=1e-5)  # scale kept
    assert keys.rotation_kind(keys.Target(target)) == "QUATERNION"  # keyframed


def test_blend_transforms_of_pose_bones(dq, assets):
    dqskin, keys = dq
    obj, arm_mod = import_character(assets / "CesiumMan.glb")
    arm = arm_mod.object
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="POSE")
    names = [pb.name for pb in arm.pose.bones][:4]
    pbs = [arm.pose.bones[n] for n in names]
    sources, active = pbs[:3], pbs[3]
    with bpy.context.temp_override(selected_pose_bones=pbs, active_pose_bone=active):
        assert bpy.ops.anim.dq_blend_transforms(method="DIB") == {"FINISHED"}
    bpy.context.view_layer.update()
    sources = sorted(sources, key=lambda pb: pb.name)
    dqs = np.stack([dqskin.DualQuat.from_matrix(np.array(arm.matrix_world @ pb.matrix, F32), check=False).to_array() for pb in sources])
    want = dqskin.dib(dqs, np.ones(3, F32))[0]
    got = dqskin.DualQuat.from_matrix(np.array(arm.matrix_world @ active.matrix, F32), check=False)
    assert np.abs(np.abs(np.dot(got.to_array()[:4], want[:4])) - 1) < 1e-4
    np.testing.assert_allclose(got.translation, dqskin.DualQuat(want[:4], want[4:]).translation, atol=1e-4)
    bpy.ops.object.mode_set(mode="OBJECT")


def test_tools_report_clear_errors(dq):
    empty = bpy.data.objects.new("Unkeyed", None)
    bpy.context.scene.collection.objects.link(empty)
    for op in (bpy.ops.anim.dq_rotation_bake, bpy.ops.anim.dq_quaternion_cleanup, bpy.ops.anim.dq_screw_inbetweens):
        with pytest.raises(RuntimeError, match="has keyed|two or more"):
            run_on_objects(op, [empty])
    with pytest.raises(RuntimeError, match="Select the transforms"):
        run_on_objects(bpy.ops.anim.dq_blend_transforms, [empty])


def test_spring_smoothing_keeps_keys_and_lowers_curvature(dq):
    dqskin, keys = dq
    frames = [1, 11, 17, 31]
    rots = KEY_ROTATIONS + [Quaternion((0, 0, 1), -1.0)]
    obj = keyed_object("Springy", frames, rots)
    assert run_on_objects(bpy.ops.anim.dq_spring_smoothing, [obj], iterations=600) == {"FINISHED"}
    t = keys.Target(obj)
    for f, q in zip(frames, rots):
        assert angle_between(rotation_at(dq, obj, f), np.array(q)) < 1e-5
    grid = np.arange(1, 32, dtype=F32)
    spring_curve = keys.rotations_at(t, grid)
    squad = dqskin.sample_rotations(np.array(frames, F32), np.array([tuple(q) for q in rots], F32), grid, method="squad")
    assert dqskin.curvature_energy(spring_curve) < dqskin.curvature_energy(squad)


def test_rotation_speed_plot_before_and_after_a_bake(dq, tmp_path):
    dqskin, keys = dq
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, 17
    obj = keyed_object("Plotted", KEY_FRAMES, KEY_ROTATIONS)
    # Blender's own (component-wise) interpolation first, then Slerp.
    run_on_objects(bpy.ops.anim.dq_rotation_bake, [obj], method="SLERP", step=1.0)
    path = tmp_path / "speed.png"
    assert run_on_objects(bpy.ops.anim.dq_rotation_speed_plot, [obj], width=200, height=100, filepath=str(path)) == {"FINISHED"}
    image = bpy.data.images["Rotation Speed Plotted"]
    assert tuple(image.size) == (200, 100)
    assert path.is_file() and path.stat().st_size > 0
    frames = np.arange(1, 18, dtype=F32)
    direct = np.degrees(dqskin.angular_speeds(keys.rotations_at(keys.Target(obj), frames)))
    np.testing.assert_allclose(image["dq_skin_speeds_deg"], direct, atol=1e-4)
    before = np.array(image["dq_skin_speeds_before_deg"])
    assert len(before) == 16 and np.ptp(before[:10]) > np.ptp(direct[:10]) + 1e-3  # Blender's was uneven
    pixels = np.array(image.pixels[:]).reshape(100, 200, 4)
    assert (pixels[..., :3] > 0.99).all(axis=-1).sum() > 100  # the white curve is drawn


def test_tools_are_in_the_animation_menus(dq_skin):
    lines = []
    menu = type(
        "M", (), {"layout": type("L", (), {"operator": lambda self, idname, **_: lines.append(idname), "separator": lambda self: None})()}
    )()
    dq_skin.panel.VIEW3D_MT_dq_skin_animation.draw(menu, bpy.context)
    assert lines == [
        "anim.dq_blend_transforms",
        "anim.dq_screw_inbetweens",
        "anim.dq_rotation_bake",
        "anim.dq_quaternion_cleanup",
        "anim.dq_spring_smoothing",
        "anim.dq_rotation_speed_plot",
    ]
    for idname in lines:
        assert hasattr(bpy.ops.anim, idname.split(".")[1])


@pytest.mark.parametrize("tool", ["cleanup", "inbetweens", "spring", "plot"])
def test_tools_on_pose_bones_of_the_fox(dq, assets, tool, tmp_path):
    dqskin, keys = dq
    bpy.ops.import_scene.gltf(filepath=str(assets / "Fox.glb"))
    arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
    name = "b_Hip_01"  # keyed location and rotation
    target = keys.Target(arm, name)
    for prop, size in (("rotation_quaternion", 4), ("location", 3)):
        for i in range(size):
            fc = keys.channel(target, prop, i)
            assert fc is not None, (prop, i)
            for k in [k for k in fc.keyframe_points if round(k.co[0]) % 10][::-1]:
                fc.keyframe_points.remove(k, fast=True)
            fc.update()
    frames = keys.key_frames(target)
    before_rot = keys.rotations_at(target, frames)
    before_loc = keys.locations_at(target, frames)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = int(frames[0]), int(frames[-1])
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="POSE")
    pb = arm.pose.bones[name]
    ops = {
        "cleanup": lambda: bpy.ops.anim.dq_quaternion_cleanup(),
        "inbetweens": lambda: bpy.ops.anim.dq_screw_inbetweens(step=2.0),
        "spring": lambda: bpy.ops.anim.dq_spring_smoothing(iterations=200),
        "plot": lambda: bpy.ops.anim.dq_rotation_speed_plot(width=120, height=80, filepath=str(tmp_path / "fox.png")),
    }
    with bpy.context.temp_override(selected_pose_bones=[pb], active_pose_bone=pb):
        assert ops[tool]() == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    # The keys' rotations (and locations) are where they were.
    after_rot = keys.rotations_at(target, frames)
    for a, b in zip(after_rot, before_rot):
        assert angle_between(a, b) < 1e-5
    np.testing.assert_allclose(keys.locations_at(target, frames), before_loc, atol=1e-5)
    if tool == "plot":
        image = bpy.data.images[f"Rotation Speed {arm.name}:{name}"]
        assert len(image["dq_skin_speeds_deg"]) == int(frames[-1] - frames[0])
        assert (tmp_path / "fox.png").is_file()


def test_screw_inbetweens_on_a_frame_range_leave_the_rest_alone(dq):
    dqskin, keys = dq
    obj = keyed_object(
        "Ranged",
        [1, 11, 21],
        [Quaternion((1, 0, 0, 0)), Quaternion((0, 0, 1), 1.0), Quaternion((0, 0, 1), 2.0)],
        locations=[(0, 0, 0), (1.0, 0.0, 0.0), (1.0, 2.0, 0.0)],
    )
    t = keys.Target(obj)
    outside = keys.locations_at(t, np.arange(11, 22, dtype=F32))
    props = dict(step=1.0, use_frame_range=True, frame_start=3.0, frame_end=9.0)
    assert run_on_objects(bpy.ops.anim.dq_screw_inbetweens, [obj], **props) == {"FINISHED"}
    frames = keys.key_frames(t, ("location",))
    assert frames.min() == 1 and frames.max() == 21 and set(np.arange(3, 10)).issubset(set(frames.tolist()))
    np.testing.assert_allclose(keys.locations_at(t, np.arange(11, 22, dtype=F32)), outside, atol=1e-6)
    with pytest.raises(RuntimeError, match="End must be after its Start"):
        run_on_objects(bpy.ops.anim.dq_screw_inbetweens, [obj], step=1.0, use_frame_range=True, frame_start=5.0, frame_end=5.0)

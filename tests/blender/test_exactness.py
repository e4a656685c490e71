"""The DQ Skin math path (the extension's `rig` glue and its bundled `dqskin`) against Blender's
own Armature modifier: Linear vs Preserve Volume off, Dual Quaternion vs Preserve Volume on.

Bar: max vertex distance ≤ 1e-5 × the mesh's bounding-box diagonal.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from dqtest import REL_TOL, action_frames, evaluated_positions, import_character
from scenes import rig_tube

import bpy

from mathutils import Matrix, Quaternion

METHODS = {"linear": False, "dual_quaternion": True}  # ours -> use_deform_preserve_volume


def kernel_deviation(rig, mesh_obj, mod, method: str, binding=None) -> tuple[float, np.ndarray]:
    """Max distance between ours and Blender's, relative to the bounding-box diagonal."""
    mod.use_deform_preserve_volume = METHODS[method]
    reference = evaluated_positions(mesh_obj)
    if binding is None:
        binding = rig.bind(mesh_obj, mod.object, mod.vertex_group, mod.invert_vertex_group)
    positions = rig.mesh_positions(mesh_obj.data)
    ours = rig.skin(binding, mesh_obj, mod.object, positions, method)
    diag = float(np.linalg.norm(reference.max(0) - reference.min(0)))
    return float(np.abs(ours - reference).max()) / diag, reference


@pytest.fixture
def rig(dq_skin):
    """The add-on's rig reader, binding an object's mesh as the session reads it."""
    module, session = dq_skin.blender.rig, dq_skin.SESSION

    class Rig:
        mesh_positions = staticmethod(module.mesh_positions)
        skin = staticmethod(module.skin)

        @staticmethod
        def bind(obj, armature, *args):
            return module.bind(session.meshes.get(obj, session.readers.mesh), armature, *args)

    return Rig


def check_both(rig, mesh_obj, mod):
    results = {}
    for method in METHODS:
        dev, reference = kernel_deviation(rig, mesh_obj, mod, method)
        assert dev <= REL_TOL, f"{method}: max deviation {dev:.2e} of the diagonal"
        results[method] = reference
    return results


@pytest.mark.parametrize("degrees", [0, 45, 90, 135, 180])
def test_twisted_cylinder(rig, degrees):
    mesh_obj, arm, mod = rig_tube()
    arm.pose.bones["Bone1"].rotation_quaternion = Quaternion((0, 1, 0), math.radians(degrees))
    refs = check_both(rig, mesh_obj, mod)
    if degrees == 180:
        # The candy wrapper is real in Blender too, so the two references must differ a lot.
        gap = np.abs(refs["linear"] - refs["dual_quaternion"]).max()
        assert gap > 0.1, gap


def test_bent_elbow(rig):
    mesh_obj, arm, mod = rig_tube(bones=2)
    arm.pose.bones["Bone1"].rotation_quaternion = Quaternion((1, 0, 0), math.radians(110))
    check_both(rig, mesh_obj, mod)


def test_long_chain(rig):
    mesh_obj, arm, mod = rig_tube(rings=60, bones=12, length=12.0)
    for i, pb in enumerate(arm.pose.bones):
        pb.rotation_quaternion = Quaternion((math.sin(i), 0.3, math.cos(i)), 0.4 + 0.1 * i)
    check_both(rig, mesh_obj, mod)


def test_non_uniform_scale_and_shear(rig):
    # A non-uniformly scaled parent with a rotated child gives the child a sheared matrix;
    # both take Blender's DQS scale path.
    mesh_obj, arm, mod = rig_tube(bones=3)
    pbs = arm.pose.bones
    pbs["Bone0"].scale = (1.6, 0.7, 1.2)
    pbs["Bone1"].rotation_quaternion = Quaternion((1, 0.4, 0), math.radians(50))
    pbs["Bone2"].scale = (0.5, 1.8, 1.0)
    pbs["Bone2"].rotation_quaternion = Quaternion((0, 1, 0), math.radians(120))
    check_both(rig, mesh_obj, mod)


def test_object_and_armature_transforms_and_a_parent(rig):
    mesh_obj, arm, mod = rig_tube(bones=3)
    parent = bpy.data.objects.new("Parent", None)
    bpy.context.scene.collection.objects.link(parent)
    parent.matrix_world = Matrix.LocRotScale((1, -2, 0.5), Quaternion((0, 0, 1), 0.7), (1.5, 1.5, 1.5))
    arm.parent = parent
    mesh_obj.parent = parent
    arm.location = (0.3, 0.1, -0.2)
    arm.rotation_euler = (0.2, -0.4, 1.1)
    mesh_obj.location = (-0.5, 0.25, 0.0)
    mesh_obj.rotation_euler = (0.0, 0.3, 0.0)
    mesh_obj.scale = (1.0, 1.3, 0.8)
    arm.pose.bones["Bone1"].rotation_quaternion = Quaternion((0, 1, 0), 2.0)
    arm.pose.bones["Bone2"].rotation_quaternion = Quaternion((1, 0, 0), 1.0)
    check_both(rig, mesh_obj, mod)


@pytest.mark.parametrize("invert", [False, True])
def test_mask_vertex_group(rig, invert):
    mesh_obj, arm, mod = rig_tube()
    mask = mesh_obj.vertex_groups.new(name="Mask")
    for v in mesh_obj.data.vertices:
        if v.index % 3:
            mask.add([v.index], (v.index % 7) / 6.0, "REPLACE")
    mod.vertex_group = "Mask"
    mod.invert_vertex_group = invert
    arm.pose.bones["Bone1"].rotation_quaternion = Quaternion((1, 0, 0), 1.2)
    check_both(rig, mesh_obj, mod)


def test_unnormalized_weights_and_vertices_without_weights(rig):
    skip = set(range(0, 24 * 16, 5))
    mesh_obj, arm, mod = rig_tube(scale=0.35, skip=skip)
    arm.pose.bones["Bone1"].rotation_quaternion = Quaternion((1, 1, 0), 1.4)
    refs = check_both(rig, mesh_obj, mod)
    rest = rig.mesh_positions(mesh_obj.data)
    # Vertices without weights stay where they are, in Blender and in ours.
    np.testing.assert_allclose(refs["linear"][sorted(skip)], rest[sorted(skip)], atol=1e-6)


def test_groups_without_bones_and_bones_without_deform_are_ignored(rig):
    mesh_obj, arm, mod = rig_tube(bones=3)
    extra = mesh_obj.vertex_groups.new(name="NotABone")
    extra.add(list(range(0, 50)), 0.8, "ADD")
    arm.data.bones["Bone2"].use_deform = False
    arm.pose.bones["Bone1"].rotation_quaternion = Quaternion((1, 0, 0), 0.9)
    arm.pose.bones["Bone2"].rotation_quaternion = Quaternion((0, 1, 0), 0.9)
    check_both(rig, mesh_obj, mod)


@pytest.mark.parametrize("asset", ["RiggedSimple.glb", "RiggedFigure.glb", "CesiumMan.glb", "Fox.glb"])
def test_every_frame_of_every_animation(rig, assets, asset):
    mesh_obj, mod = import_character(assets / asset)
    arm = mod.object
    actions = [a for a in bpy.data.actions]
    assert actions, f"{asset} has no animation"
    binding = rig.bind(mesh_obj, arm, mod.vertex_group, mod.invert_vertex_group)
    scene = bpy.context.scene
    worst = {m: 0.0 for m in METHODS}
    frames = 0
    rest = rig.mesh_positions(mesh_obj.data)
    for action in actions:
        arm.animation_data.action = action
        moved = 0.0
        for frame in action_frames(action):
            scene.frame_set(frame)
            for method in METHODS:
                dev, reference = kernel_deviation(rig, mesh_obj, mod, method, binding)
                worst[method] = max(worst[method], dev)
            moved = max(moved, float(np.abs(reference - rest).max()))
            frames += 1
        # The action really plays (otherwise the comparison would prove little).
        assert moved > 1e-3, f"{asset}: action {action.name} does not move the mesh"
    assert frames >= len(actions) * 2
    for method, dev in worst.items():
        assert dev <= REL_TOL, f"{asset} {method}: worst deviation {dev:.2e} of the diagonal over {frames} frames"

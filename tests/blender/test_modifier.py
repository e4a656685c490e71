"""The DQ Skin modifier in Blender: added by its operator, live on frame changes and posing,
equal to the Armature modifier, and removable without a trace."""

from __future__ import annotations

import math

import numpy as np
import pytest
from dqtest import REL_TOL, add_dq_skin, deviation, draw_panel, evaluated_positions, import_character, is_carrier, reference_copy
from scenes import rig_tube

import bpy

from mathutils import Quaternion


def snapshot(obj):
    """Everything of the object and its mesh that DQ Skin must leave as it found it."""
    mesh = obj.data
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    return {
        "modifiers": [(m.name, m.type, m.show_viewport, m.show_render) for m in obj.modifiers],
        "object_props": sorted(obj.keys()),
        "mesh_props": sorted(mesh.keys()),
        "attributes": sorted(a.name for a in mesh.attributes),
        "groups": [g.name for g in obj.vertex_groups],
        "weights": [[(g.group, round(g.weight, 7)) for g in v.groups] for v in mesh.vertices],
        "co": co.tobytes(),
        "shape_keys": [(k.name, k.value) for k in mesh.shape_keys.key_blocks] if mesh.shape_keys else None,
        "animation": None
        if obj.animation_data is None
        else (obj.animation_data.action, [d.data_path for d in obj.animation_data.drivers], len(obj.animation_data.nla_tracks)),
    }


@pytest.mark.parametrize("asset", ["RiggedSimple.glb", "RiggedFigure.glb", "CesiumMan.glb", "Fox.glb"])
@pytest.mark.parametrize("method, preserve_volume", [("DUAL_QUATERNION", True), ("LINEAR", False)])
def test_follows_every_frame_of_every_animation_exactly(dq_skin, assets, asset, method, preserve_volume):
    obj, arm_mod = import_character(assets / asset)
    arm = arm_mod.object
    reference = reference_copy(obj, preserve_volume)
    mod = add_dq_skin(obj, method)
    assert not arm_mod.show_viewport and not arm_mod.show_render
    scene = bpy.context.scene
    rest = evaluated_positions(reference)
    worst, moved, frames = 0.0, 0.0, 0
    for action in bpy.data.actions:
        arm.animation_data.action = action
        start, end = (int(round(f)) for f in action.frame_range)
        for frame in [*range(start, end + 1), start + 1]:  # ends with a jump back
            scene.frame_set(frame)
            ours, theirs = evaluated_positions(obj), evaluated_positions(reference)
            worst = max(worst, deviation(ours, theirs))
            moved = max(moved, float(np.abs(theirs - rest).max()))
            frames += 1
    assert worst <= REL_TOL, f"{asset}: worst {worst:.2e} over {frames} frames"
    assert moved > 1e-3  # the character really moves
    assert dq_skin.SESSION.status_of(obj, mod).message == ""


def test_follows_posing_without_a_frame_change(dq_skin):
    obj, arm, arm_mod = rig_tube()
    reference = reference_copy(obj, True)
    add_dq_skin(obj, "DUAL_QUATERNION")
    bpy.context.scene.frame_set(1)
    arm.pose.bones["Bone1"].rotation_quaternion = Quaternion((0, 1, 0), math.radians(150))
    bpy.context.view_layer.update()
    dev = deviation(evaluated_positions(obj), evaluated_positions(reference))
    assert dev <= REL_TOL, dev


def test_shape_keys_are_applied_before_skinning(dq_skin):
    obj, arm, arm_mod = rig_tube()
    basis = obj.shape_key_add(name="Basis")
    key = obj.shape_key_add(name="Bulge")
    for i, p in enumerate(key.data):
        p.co = basis.data[i].co * 1.3
    key.value = 0.6
    reference = reference_copy(obj, True)
    add_dq_skin(obj, "DUAL_QUATERNION")
    arm.pose.bones["Bone1"].rotation_quaternion = Quaternion((1, 0, 0), 1.3)
    bpy.context.scene.frame_set(2)
    dev = deviation(evaluated_positions(obj), evaluated_positions(reference))
    assert dev <= REL_TOL, dev


def test_remove_operator_restores_the_object_exactly(dq_skin):
    obj, arm, arm_mod = rig_tube()
    obj.vertex_groups.new(name="Mask").add([1, 2, 3], 0.5, "REPLACE")
    arm_mod.vertex_group = "Mask"
    before = snapshot(obj)
    add_dq_skin(obj)
    bpy.context.scene.frame_set(3)
    assert snapshot(obj) != before
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.object.dq_skin_remove() == {"FINISHED"}
    assert snapshot(obj) == before
    assert not [o for o in bpy.data.objects if o.get("dq_skin_result")]


def test_plain_modifier_removal_restores_the_object_too(dq_skin):
    obj, arm, arm_mod = rig_tube()
    before = snapshot(obj)
    mod = add_dq_skin(obj)
    bpy.context.scene.frame_set(3)
    obj.modifiers.remove(mod)
    bpy.context.view_layer.update()
    assert snapshot(obj) == before


def test_add_reports_a_clear_error_without_an_armature_modifier(dq_skin):
    obj, arm, arm_mod = rig_tube()
    obj.modifiers.remove(arm_mod)
    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(object=obj, active_object=obj):
        with pytest.raises(RuntimeError, match="has no Armature modifier"):
            bpy.ops.object.dq_skin_add()
    assert not [m for m in obj.modifiers if m.type == "NODES"]


def test_settings_come_from_the_armature_modifier(dq_skin):
    obj, arm, arm_mod = rig_tube()
    obj.vertex_groups.new(name="Mask")
    arm_mod.vertex_group = "Mask"
    arm_mod.invert_vertex_group = True
    arm_mod.use_deform_preserve_volume = False
    mod = add_dq_skin(obj)
    s = dq_skin.blender.settings.read(mod)
    assert (s.armature, s.method.name, s.mask_group, s.invert_mask) == (arm, "LINEAR", "Mask", True)
    assert [m for m in obj.modifiers if not is_carrier(m)].index(mod) == 0  # where the Armature modifier was


def test_armature_in_edit_mode_is_reported_and_passes_the_mesh_through(dq_skin):
    obj, arm, arm_mod = rig_tube()
    arm.pose.bones["Bone1"].rotation_quaternion = Quaternion((1, 0, 0), 1.0)
    mod = add_dq_skin(obj)
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.context.scene.frame_set(5)
    st = dq_skin.SESSION.status_of(obj, mod)
    assert "Edit Mode" in st.message
    rest = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.vertices.foreach_get("co", rest)
    np.testing.assert_allclose(evaluated_positions(obj), rest.reshape(-1, 3), atol=1e-6)
    bpy.ops.object.mode_set(mode="OBJECT")


def test_blend_between_linear_and_dual_quaternion(dq_skin):
    obj, arm, arm_mod = rig_tube()
    amount = obj.vertex_groups.new(name="Amount")
    for v in obj.data.vertices:
        amount.add([v.index], (v.index % 5) / 4.0, "REPLACE")
    arm.pose.bones["Bone1"].rotation_quaternion = Quaternion((0, 1, 0), 2.5)
    lbs_ref = reference_copy(obj, False)
    dqs_ref = reference_copy(obj, True)
    mod = add_dq_skin(obj, "BLEND")
    from bl_ext.user_default.dq_skin.ops.modifiers import set_attribute, set_input

    set_attribute(mod, "Blend Amount", "Amount")
    set_input(mod, "Blend Factor", 0.8)
    bpy.context.scene.frame_set(6)
    lbs, dqs = evaluated_positions(lbs_ref), evaluated_positions(dqs_ref)
    alpha = 0.8 * (np.arange(len(lbs)) % 5 / 4.0)[:, None]
    want = (1 - alpha) * lbs + alpha * dqs
    dev = deviation(evaluated_positions(obj), want)
    assert dev <= REL_TOL, dev
    assert np.abs(lbs - dqs).max() > 0.05  # the two methods really differ here


def test_several_objects_keep_their_own_settings_through_save_and_load(dq_skin, tmp_path):
    a, arm_a, _ = rig_tube()
    b, arm_b, _ = rig_tube()
    b.location = (3.0, 0.0, 0.0)
    for arm in (arm_a, arm_b):
        arm.pose.bones["Bone1"].rotation_quaternion = Quaternion((0, 1, 0), 2.6)
    add_dq_skin(a, "LINEAR")
    add_dq_skin(b, "DUAL_QUATERNION")
    names = (a.name, b.name)
    path = tmp_path / "two.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))
    a, b = (bpy.data.objects[n] for n in names)
    methods = [dq_skin.blender.settings.read(next(m for m in o.modifiers if m.type == "NODES")).method.name for o in (a, b)]
    assert methods == ["LINEAR", "DUAL_QUATERNION"]
    bpy.context.scene.frame_set(7)
    for obj, pv in ((a, False), (b, True)):
        reference = reference_copy(obj, pv)
        dev = deviation(evaluated_positions(obj), evaluated_positions(reference))
        assert dev <= REL_TOL, (obj.name, dev)


def envelope_rig(groups: bool, multiply: bool, skip=()):
    obj, arm, arm_mod = rig_tube(bones=3, skip=skip)
    if not groups:
        obj.vertex_groups.clear()
    for i, b in enumerate(arm.data.bones):
        b.head_radius, b.tail_radius = 0.15 + 0.05 * i, 0.25
        b.envelope_distance = 0.6 + 0.2 * i
        b.envelope_weight = 1.0 - 0.2 * i
        b.use_envelope_multiply = multiply
    arm.pose.bones["Bone1"].rotation_quaternion = Quaternion((1, 0, 0), 1.1)
    arm.pose.bones["Bone2"].rotation_quaternion = Quaternion((0, 1, 0), 2.3)
    return obj, arm, arm_mod


@pytest.mark.parametrize("method, preserve_volume", [("DUAL_QUATERNION", True), ("LINEAR", False)])
@pytest.mark.parametrize(
    "case",
    ["envelopes only", "envelope times vertex group", "envelopes where groups are missing"],
)
def test_envelopes_match_the_armature_modifier(dq_skin, case, method, preserve_volume):
    if case == "envelopes only":
        obj, arm, arm_mod = envelope_rig(groups=False, multiply=False)
        arm_mod.use_vertex_groups = False
        arm_mod.use_bone_envelopes = True
    elif case == "envelope times vertex group":
        obj, arm, arm_mod = envelope_rig(groups=True, multiply=True)
        arm_mod.use_bone_envelopes = False
    else:
        obj, arm, arm_mod = envelope_rig(groups=True, multiply=False, skip=set(range(0, 200, 3)))
        arm_mod.use_bone_envelopes = True
    reference = reference_copy(obj, preserve_volume)
    mod = add_dq_skin(obj, method)
    bpy.context.scene.frame_set(8)
    assert dq_skin.SESSION.status_of(obj, mod).message == ""
    ours, theirs = evaluated_positions(obj), evaluated_positions(reference)
    dev = deviation(ours, theirs)
    assert dev <= REL_TOL, dev
    rest = rig_positions(obj)
    assert np.abs(theirs - rest).max() > 0.05  # the envelopes really move the mesh


def rig_positions(obj):
    co = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


@pytest.mark.parametrize("mapping", ["STRAIGHT", "CURVED"])
@pytest.mark.parametrize("method, preserve_volume", [("DUAL_QUATERNION", True), ("LINEAR", False)])
def test_b_bones_match_the_armature_modifier(dq_skin, method, preserve_volume, mapping):
    obj, arm, arm_mod = rig_tube(rings=40, bones=3)
    bones = arm.data.bones
    bones["Bone1"].bbone_segments = 6
    bones["Bone2"].bbone_segments = 3
    bones["Bone1"].bbone_mapping_mode = mapping
    bones["Bone2"].bbone_mapping_mode = mapping
    # A curved rest shape, which is what the Curved mapping follows.
    bones["Bone1"].bbone_curveinx = 1.0
    bones["Bone1"].bbone_curveoutx = 1.0
    bones["Bone1"].bbone_easein = 1.5
    pbs = arm.pose.bones
    pbs["Bone1"].bbone_curveinx = 1.2
    pbs["Bone1"].bbone_curveoutx = -0.9
    pbs["Bone1"].bbone_curveinz = 0.6
    pbs["Bone1"].bbone_rollout = 0.8
    pbs["Bone1"].rotation_quaternion = Quaternion((1, 0, 0), 0.7)
    pbs["Bone2"].rotation_quaternion = Quaternion((0, 1, 0), 1.9)
    pbs["Bone2"].bbone_scalein = (1.3, 1.0, 0.8)
    reference = reference_copy(obj, preserve_volume)
    mod = add_dq_skin(obj, method)
    bpy.context.scene.frame_set(9)
    assert dq_skin.SESSION.status_of(obj, mod).message == ""
    ours, theirs = evaluated_positions(obj), evaluated_positions(reference)
    dev = deviation(ours, theirs)
    assert dev <= REL_TOL, dev
    if mapping == "CURVED":
        # The curved mapping really differs from the straight one here.
        for b in ("Bone1", "Bone2"):
            bones[b].bbone_mapping_mode = "STRAIGHT"
        assert deviation(evaluated_positions(reference), theirs) > 10 * REL_TOL
    # The B-Bones really bend the mesh differently from plain bones.
    for b in ("Bone1", "Bone2"):
        bones[b].bbone_segments = 1
    plain = evaluated_positions(reference)
    assert np.abs(plain - theirs).max() > 0.01


def test_panel_shows_method_status_and_errors(dq_skin):
    obj, arm, arm_mod = rig_tube()
    weights = ["[object.dq_skin_automatic_weights]", "[object.dq_skin_transfer_weights]"]  # the first row
    assert draw_panel(dq_skin, obj) == [*weights, "[object.dq_skin_add]"]
    add_dq_skin(obj, "BLEND")
    bpy.context.scene.frame_set(2)
    lines = draw_panel(dq_skin, obj)
    assert lines[:2] == weights
    lines = lines[2:]
    assert lines[0] == "DQ Skin: Blend"
    assert "bones" in lines[1] and "influences" in lines[1] and "ms" in lines[1]
    assert lines[-2:] == ["[object.dq_skin_remove]", "[object.dq_skin_bake]"]  # the bake is the object's
    arm_mod_obj = arm
    bpy.context.view_layer.objects.active = arm_mod_obj
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.context.scene.frame_set(3)
    assert any("Edit Mode" in line for line in draw_panel(dq_skin, obj))
    bpy.ops.object.mode_set(mode="OBJECT")


def test_vertex_count_changed_by_an_earlier_modifier_is_reported(dq_skin):
    obj, arm, arm_mod = rig_tube()
    mod = add_dq_skin(obj)
    subsurf = obj.modifiers.new("Subdivision", "SUBSURF")
    with bpy.context.temp_override(object=obj, active_object=obj):
        bpy.ops.object.modifier_move_to_index(modifier=subsurf.name, index=0)
    bpy.context.scene.frame_set(4)
    assert "changed the vertex count" in dq_skin.SESSION.status_of(obj, mod).message
    assert len(evaluated_positions(obj)) > len(obj.data.vertices)  # passed through, not broken


def test_missing_armature_is_reported_and_passes_the_mesh_through(dq_skin):
    obj, arm, arm_mod = rig_tube()
    arm.pose.bones["Bone1"].rotation_quaternion = Quaternion((1, 0, 0), 1.0)
    mod = add_dq_skin(obj)
    from bl_ext.user_default.dq_skin.ops.modifiers import set_input

    set_input(mod, "Armature", None)
    bpy.context.scene.frame_set(5)
    assert dq_skin.SESSION.status_of(obj, mod).message == "No armature object set"
    np.testing.assert_allclose(evaluated_positions(obj), rig_positions(obj), atol=1e-6)


def test_adding_dq_skin_twice_is_refused_with_a_reason(dq_skin):
    """A mesh parented to its armature, with DQ Skin: adding DQ Skin again (the Add Modifier menu)
    would deform it a second time. Refused, saying so; the stack and the result stay."""
    obj, arm, arm_mod = rig_tube()
    obj.parent = arm
    add_dq_skin(obj, "DUAL_QUATERNION")
    bpy.context.scene.frame_set(2)
    before = [(m.name, m.type) for m in obj.modifiers]
    shown = evaluated_positions(obj)
    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(object=obj, active_object=obj):
        with pytest.raises(RuntimeError, match="already has DQ Skin"):
            bpy.ops.object.dq_skin_add()
    assert [(m.name, m.type) for m in obj.modifiers] == before
    bpy.context.view_layer.update()
    assert deviation(evaluated_positions(obj), shown) == 0.0
    # A second armature's modifier is a second DQ Skin's own (two armatures, two deformations).
    second = obj.modifiers.new("Armature.001", "ARMATURE")
    second.object = arm
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.object.dq_skin_add() == {"FINISHED"}
    assert len([m for m in obj.modifiers if m.type == "NODES"]) == 2

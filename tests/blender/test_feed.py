"""Characters with B-Bones or envelopes are skinned inside Blender's first evaluation (`feed`):
the frame handler then writes nothing and Blender does not evaluate the scene a second time.
Checked here: that it happens (the handler's writes and the driver's runs are counted), that
every frame still equals the Armature modifier's on its own object, including frames where
more than the pose changed (the handler's full evaluation must catch what the driver cannot
know), renders of another frame than the viewport's, save and reload, removal, and a deleted
cache file.

Bar: max vertex distance ≤ 1e-5 × the mesh's bounding-box diagonal (`dqtest.REL_TOL`).
"""

from __future__ import annotations

import os

import pytest
from conftest import feed_every_size
from dqtest import add_dq_skin, animate, assert_same, dq_skin_mods, get_input, reference_copy, select_only, status
from test_pose_memory import bbone_rig
from test_render import SAME_IMAGE, changed, render_frame, setup_scene

import bpy


@pytest.fixture(autouse=True)
def _feed_these_small_characters(dq_skin, monkeypatch):
    feed_every_size(dq_skin, monkeypatch)


def fed_character(dq_skin, method: str):
    """The B-Bone tube, animated, with DQ Skin, and the Armature modifier on its own object."""
    obj, arm, _ = bbone_rig()
    animate(arm)
    reference = reference_copy(obj, method != "LINEAR")
    reference.data = obj.data.copy()
    add_dq_skin(obj, method)
    for f in (2, 3):
        bpy.context.scene.frame_set(f)
    return obj, arm, reference


def result_of(dq_skin, obj):
    mod = dq_skin_mods(obj)[0]
    return dq_skin.SESSION.state_of(obj, mod).output.result


class Writes:
    """Counts what DQ Skin's handlers write into results."""

    def __init__(self, dq_skin, monkeypatch):
        self.count = 0
        original = dq_skin.routes.results.write_positions

        def counted(result, positions):
            self.count += 1
            original(result, positions)

        monkeypatch.setattr(dq_skin.routes.results, "write_positions", counted)


@pytest.mark.parametrize("method", ["LINEAR", "DUAL_QUATERNION"])
def test_b_bone_frames_are_skinned_in_the_first_evaluation(dq_skin, monkeypatch, method):
    obj, arm, reference = fed_character(dq_skin, method)
    result = result_of(dq_skin, obj)
    assert dq_skin.SESSION.route.feeds.fed(result) is not None, status(dq_skin, obj).message
    writes = Writes(dq_skin, monkeypatch)
    runs = dq_skin.SESSION.route.feeds.runs(result)
    for k, f in enumerate((5, 9, 14, 18), start=1):
        bpy.context.scene.frame_set(f)
        assert_same(obj, reference, f"frame {f}")
        assert dq_skin.SESSION.route.feeds.runs(result) == runs + k, "the driver skins once per frame"
    assert writes.count == 0, "the frame handler wrote a result the driver had made"


def test_what_the_pose_alone_does_not_say_is_caught(dq_skin):
    """The driver only knows the pose: a changed method, a moved object, an edited bone and a
    changed setting, each made by a script right before the frame change, must still show."""
    obj, arm, reference = fed_character(dq_skin, "LINEAR")
    scene = bpy.context.scene
    mod = dq_skin_mods(obj)[0]
    ref_mod = next(m for m in reference.modifiers if m.type == "ARMATURE")
    dq_skin.blender.nodes.put_method(mod, "Dual Quaternion")
    ref_mod.use_deform_preserve_volume = True
    scene.frame_set(6)
    assert_same(obj, reference, "after the method changed")
    for o in (obj, reference):
        o.location.x += 0.7
    scene.frame_set(8)
    assert_same(obj, reference, "after the object moved")
    for o in (obj, reference):
        o.rotation_euler.z += 0.4
    arm.location.y += 0.3
    scene.frame_set(10)
    assert_same(obj, reference, "after both moved")
    arm.data.bones["Bone1"].bbone_segments = 3
    scene.frame_set(12)
    assert_same(obj, reference, "after a B-Bone lost segments")
    dq_skin.blender.nodes.put(mod, "Use Envelopes", True)
    ref_mod.use_bone_envelopes = True
    arm.data.bones["Bone2"].envelope_distance = 0.4
    scene.frame_set(15)
    assert_same(obj, reference, "with envelopes on")
    scene.frame_set(17)
    assert_same(obj, reference, "the next frame")
    assert dq_skin.SESSION.route.feeds.fed(result_of(dq_skin, obj)) is not None


def test_what_the_object_alone_says_is_caught(dq_skin):
    """The frame handler takes the driver's frame without the full evaluation when the driver
    skinned it (`modifier.fed_frame_stands`): each edit of the object a script makes right
    before a frame change (weights, a renamed group, a modifier before DQ Skin, the companion
    switched on, DQ Skin switched off in the viewport) must still show."""
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    scene = bpy.context.scene
    mod = dq_skin_mods(obj)[0]
    for o in (obj, reference):
        o.vertex_groups["Bone2"].add(list(range(0, 200, 3)), 0.9, "REPLACE")
    scene.frame_set(6)
    assert_same(obj, reference, "after weights changed")
    for o in (obj, reference):
        o.vertex_groups["Bone1"].name = "Renamed"
    scene.frame_set(8)
    assert_same(obj, reference, "after a bone's group was renamed")
    for o in (obj, reference):
        o.vertex_groups["Renamed"].name = "Bone1"
    scene.frame_set(9)
    assert_same(obj, reference, "after it was named back")
    assert dq_skin.SESSION.route.feeds.fed(result_of(dq_skin, obj)) is not None
    for o in (obj, reference):
        d = o.modifiers.new("Displace", "DISPLACE")
        d.strength = 0.2
        d.show_viewport = False
        bpy.ops.object.select_all(action="DESELECT")
        with bpy.context.temp_override(object=o, active_object=o):
            bpy.ops.object.modifier_move_to_index(modifier="Displace", index=0)
    scene.frame_set(10)
    assert_same(obj, reference, "with a switched-off modifier before")
    for o in (obj, reference):
        o.modifiers["Displace"].show_viewport = True
    scene.frame_set(11)
    assert_same(obj, reference, "after the modifier before DQ Skin was switched on")
    for o in (obj, reference):
        o.modifiers.remove(o.modifiers["Displace"])
    scene.frame_set(12)
    assert_same(obj, reference, "after it was removed")
    c = obj.modifiers[dq_skin.blender.nodes.get_companion(mod)["name"]]
    c.show_viewport = True  # the user asks for Blender's deformation
    scene.frame_set(13)
    assert not mod.show_viewport and status(dq_skin, obj).mode.value != "live"
    assert_same(obj, reference, "with the companion switched on")
    mod.show_viewport = True
    scene.frame_set(14)
    assert status(dq_skin, obj).live and not c.show_viewport
    assert_same(obj, reference, "with DQ Skin back on")
    mod.show_viewport = False
    scene.frame_set(15)
    assert c.show_viewport and not status(dq_skin, obj).live
    assert_same(obj, reference, "with DQ Skin off in the viewport")


def test_an_edit_without_a_frame_change_shows(dq_skin):
    """Posing in the interface: a bone rotated, then the view layer updated."""
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    arm.pose.bones["Bone2"].rotation_quaternion = (0.8, 0.2, 0.5, 0.1)
    bpy.context.view_layer.update()
    assert_same(obj, reference, "after posing")


def test_a_render_of_another_frame_shows_that_frame(dq_skin, tmp_path):
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    scene = setup_scene()
    scene.camera.location = (0.0, -9.0, 2.0)
    assert dq_skin.SESSION.route.feeds.fed(result_of(dq_skin, obj)) is not None

    def show(which):
        obj.hide_render = which is not obj
        reference.hide_render = which is not reference

    show(obj)
    ours = render_frame(scene, 14, tmp_path / "ours")
    show(reference)
    theirs = render_frame(scene, 14, tmp_path / "theirs")
    other = render_frame(scene, 6, tmp_path / "other")
    assert changed(theirs, other) > 10 * SAME_IMAGE, "frames 6 and 14 should look different"
    assert changed(ours, theirs) < SAME_IMAGE, changed(ours, theirs)


def test_files_hold_nothing_of_it_and_removing_dq_skin_removes_it(dq_skin, tmp_path):
    obj, arm, reference = fed_character(dq_skin, "LINEAR")
    path = dq_skin.SESSION.route.feeds.fed(result_of(dq_skin, obj)).path
    assert os.path.exists(path)
    blend = tmp_path / "fed.blend"
    names = obj.name, reference.name
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    assert not [
        o.name for o in bpy.data.objects if any(m.type == "MESH_CACHE" for m in o.modifiers) and not dq_skin.routes.results.is_result(o)
    ]
    obj, reference = (bpy.data.objects[n] for n in names)
    for f in (4, 7, 11):
        bpy.context.scene.frame_set(f)
        assert_same(obj, reference, f"reopened, frame {f}")
    result = result_of(dq_skin, obj)
    feed = dq_skin.SESSION.route.feeds.fed(result)
    assert feed is not None
    path = feed.path
    select_only(obj)
    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.object.dq_skin_remove() == {"FINISHED"}
    assert not os.path.exists(path), "the cache file outlived its modifier"
    assert not dq_skin_mods(obj)
    bpy.context.scene.frame_set(13)
    assert_same(obj, reference, "after DQ Skin was removed")


def test_a_deleted_cache_file_is_made_again(dq_skin):
    obj, arm, reference = fed_character(dq_skin, "LINEAR")
    feed = dq_skin.SESSION.route.feeds.fed(result_of(dq_skin, obj))
    os.unlink(feed.path)
    for f in (6, 10):
        bpy.context.scene.frame_set(f)
        assert_same(obj, reference, f"frame {f} after the file was deleted")
    assert os.path.exists(feed.path)


def test_vertex_group_characters_are_not_fed(dq_skin):
    """Vertex groups alone keep the handler's batched path (one kernel call for a crowd)."""
    from dqtest import animated_tube

    obj, arm, _ = animated_tube()
    add_dq_skin(obj, "LINEAR")
    bpy.context.scene.frame_set(3)
    assert dq_skin.SESSION.route.feeds.fed(result_of(dq_skin, obj)) is None
    assert get_input(dq_skin_mods(obj)[0], "Result") is not None

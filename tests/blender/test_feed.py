"""Every character is skinned inside Blender's first evaluation (the feed, `routes.feed`), on
both routes (a Mesh Cache carrier on the character; a result object): the frame handler then
publishes nothing and Blender does not evaluate the scene a second time. Checked here: that it
happens (the handler's publishing and the driver's runs are counted), that every frame still
equals the Armature modifier's on its own object, including frames where more than the pose
changed (the handler's full evaluation must catch what the driver cannot know), renders of
another frame than the viewport's, save and reload, removal, and a deleted cache file.

Bar: max vertex distance ≤ 1e-5 × the mesh's bounding-box diagonal (`dqtest.REL_TOL`).
"""

from __future__ import annotations

import os

import numpy as np
import pytest
from conftest import node_route_for_every_size
from dqtest import (
    add_dq_skin,
    animate,
    assert_same,
    deviation,
    dq_skin_mods,
    evaluated_positions,
    fed_runs,
    is_carrier,
    names_of_calls,
    reference_copy,
    route_of,
    select_only,
    status,
    swap_armature,
)
from test_pose_memory import bbone_rig
from test_render import SAME_IMAGE, changed, render_frame, setup_scene

import bpy

ROUTES = ["cache", "node"]


@pytest.fixture(params=ROUTES)
def route(request, dq_skin, monkeypatch) -> str:
    """The route the characters of a test take (the small test characters take the Mesh Cache
    carrier unless told otherwise)."""
    if request.param == "node":
        node_route_for_every_size(dq_skin, monkeypatch)
    return request.param


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


class Publishes:
    """Counts what DQ Skin's handlers publish outside Blender's evaluation."""

    def __init__(self, dq_skin, monkeypatch):
        self.count = 0
        routes = dq_skin.SESSION.routes
        original = routes.publish

        def counted(*args, **kwargs):
            self.count += 1
            original(*args, **kwargs)

        monkeypatch.setattr(routes, "publish", counted)


@pytest.mark.parametrize("method", ["LINEAR", "DUAL_QUATERNION"])
def test_b_bone_frames_are_skinned_in_the_first_evaluation(dq_skin, monkeypatch, method, route):
    obj, arm, reference = fed_character(dq_skin, method)
    assert route_of(dq_skin, obj) == route, status(dq_skin, obj).message
    published = Publishes(dq_skin, monkeypatch)
    runs = fed_runs(dq_skin, obj)
    for k, f in enumerate((5, 9, 14, 18), start=1):
        bpy.context.scene.frame_set(f)
        assert_same(obj, reference, f"frame {f}")
        assert fed_runs(dq_skin, obj) == runs + k, "the driver skins once per frame"
    assert published.count == 0, "the frame handler published a frame the driver had made"


def _normals(mesh) -> np.ndarray:
    out = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertex_normals.foreach_get("vector", out)
    return out.reshape(-1, 3)


def _ray_hits(obj_eval, box: np.ndarray) -> list:
    """Rays cast at the evaluated object from outside its bounds (`box`: the reference's, in
    object space) along both side axes, at five places along its longest axis."""
    from mathutils import Vector

    lo, hi = box.min(0), box.max(0)
    size = hi - lo
    long_axis = int(np.argmax(size))
    hits = []
    for t in (0.1, 0.3, 0.5, 0.7, 0.9):
        for side in [a for a in range(3) if a != long_axis]:
            origin = (lo + hi) / 2
            origin[long_axis] = lo[long_axis] + t * size[long_axis]
            origin[side] = hi[side] + size[side]
            direction = np.zeros(3)
            direction[side] = -1.0
            hit, location, _normal, _face = obj_eval.ray_cast(Vector(origin), Vector(direction))
            hits.append((hit, tuple(location)))
    return hits


def test_fed_frames_come_with_fresh_normals_bounds_and_ray_casts(dq_skin, route):
    """What Blender keeps about an evaluated mesh (its normals, its bounds, the BVH tree that ray
    casts, Shrinkwrap and snapping use) is made for each fed frame, not kept from the one before:
    the feed writes positions inside Blender's evaluation, and the carrier after it must make
    Blender treat them as new. Each frame's caches are filled (read) before the next frame."""
    obj, _arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    assert route_of(dq_skin, obj) == route, status(dq_skin, obj).message
    runs = fed_runs(dq_skin, obj)
    for k, f in enumerate((5, 9, 14, 18), start=1):
        bpy.context.scene.frame_set(f)
        assert fed_runs(dq_skin, obj) == runs + k, "the driver skins once per frame"
        dg = bpy.context.evaluated_depsgraph_get()
        got, ref = obj.evaluated_get(dg), reference.evaluated_get(dg)
        assert_same(obj, reference, f"frame {f}")
        box = np.array([list(c) for c in ref.bound_box])
        diag = float(np.linalg.norm(box.max(0) - box.min(0)))
        assert np.abs(np.array([list(c) for c in got.bound_box]) - box).max() <= 1e-5 * diag, f"frame {f}: bounds"
        assert np.abs(_normals(got.data) - _normals(ref.data)).max() <= 1e-4, f"frame {f}: vertex normals"
        hits, expected = _ray_hits(got, box), _ray_hits(ref, box)
        assert [h for h, _ in hits] == [h for h, _ in expected] and any(h for h, _ in expected), f"frame {f}: ray casts"
        assert max(float(np.abs(np.subtract(a, b)).max()) for (_, a), (_, b) in zip(hits, expected)) <= 1e-5 * diag, f"frame {f}: ray casts"


@pytest.mark.parametrize("method", ["LINEAR", "DUAL_QUATERNION", "BLEND", "CENTERS_OF_ROTATION"])
def test_vertex_group_characters_are_fed_too(dq_skin, monkeypatch, method, route):
    """Vertex groups alone, every method: fed, and equal to what DQ Skin computes outside the
    evaluation (Linear and Dual Quaternion: to Blender's Armature modifier too)."""
    from dqtest import animated_tube

    obj, arm, _ = animated_tube()
    reference = reference_copy(obj, method != "LINEAR")
    add_dq_skin(obj, method)
    bpy.context.scene.frame_set(3)
    assert route_of(dq_skin, obj) == route
    published = Publishes(dq_skin, monkeypatch)
    runs = fed_runs(dq_skin, obj)
    mod = dq_skin_mods(obj)[0]
    for k, f in enumerate((5, 9, 14), start=1):
        bpy.context.scene.frame_set(f)
        assert fed_runs(dq_skin, obj) == runs + k
        if method in ("LINEAR", "DUAL_QUATERNION"):
            assert_same(obj, reference, f"frame {f}")
        fed = evaluated_positions(obj)
        # The full evaluation of the same frame (forced) publishes the same positions.
        tracker = dq_skin.SESSION.tracker
        tracker.evaluate(tracker.record_of(obj), bpy.context.evaluated_depsgraph_get(), force=True)
        assert deviation(evaluated_positions(obj), fed) <= 1e-6, (f, method)
        assert dq_skin.SESSION.status_of(obj, mod).live
    assert published.count == 3  # (the forced ones)


def test_what_the_pose_alone_does_not_say_is_caught(dq_skin, route):
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
    assert route_of(dq_skin, obj) == route


def test_a_keyed_setting_plays(dq_skin, route):
    """DQ Skin's settings can be keyed like any modifier's: in playback each frame shows what
    its keys give there (the driver skins with the settings of the last full evaluation; the
    frame handler compares the stored values on every frame). Blend with its Blend Factor keyed
    0, then 1: Linear, then Dual Quaternion, then Linear again when played back."""
    obj, arm, dual = fed_character(dq_skin, "BLEND")
    linear = reference_copy(obj, False)
    linear.data = obj.data.copy()
    nodes = dq_skin.blender.nodes
    mod = dq_skin_mods(obj)[0]
    ident = nodes.socket_ids(mod.node_group)["Blend Factor"]
    if dq_skin.blender.compat.RNA_INPUTS:
        path = getattr(mod.properties.inputs, ident).path_from_id("value")
    else:
        path = f'{mod.path_from_id()}["{ident}"]'
    for frame in range(5, 11):  # (a key on every frame played: no interpolation between)
        nodes.put(mod, "Blend Factor", 0.0 if frame < 8 else 1.0)
        assert obj.keyframe_insert(data_path=path, frame=frame)
    scene = bpy.context.scene
    runs = fed_runs(dq_skin, obj)
    for f in (5, 6, 7, 8, 9, 10, 6):
        scene.frame_set(f)
        assert_same(obj, dual if f >= 8 else linear, f"frame {f}")
    assert fed_runs(dq_skin, obj) >= runs + 5  # (fed where the factor did not change)
    assert route_of(dq_skin, obj) == route


def test_what_the_object_alone_says_is_caught(dq_skin, route):
    """The frame handler takes the driver's frame without the full evaluation when the driver
    skinned it (`playback.fed_frame_stands`): each edit of the object a script makes right
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
    assert route_of(dq_skin, obj) == route
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


def test_an_edit_without_a_frame_change_shows(dq_skin, route):
    """Posing in the interface: a bone rotated, then the view layer updated."""
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    arm.pose.bones["Bone2"].rotation_quaternion = (0.8, 0.2, 0.5, 0.1)
    bpy.context.view_layer.update()
    assert_same(obj, reference, "after posing")


def assert_renders_as(obj, reference, scene, tmp_path) -> None:
    """An animation render of frame 14 (started from another frame) shows `obj` as it shows
    `reference` (each rendered alone)."""

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


def test_a_render_of_another_frame_shows_that_frame(dq_skin, tmp_path, route):
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    scene = setup_scene()
    scene.camera.location = (0.0, -9.0, 2.0)
    assert route_of(dq_skin, obj) == route
    assert_renders_as(obj, reference, scene, tmp_path)


def is_evaluated(obj) -> bool:
    return obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).is_evaluated


def hide(obj, how: str, hidden: bool) -> None:
    """Hides `obj` from the viewport's evaluation the way `how` says: the object disabled in
    viewports, its collection disabled there, or its collection excluded from the view layer."""
    if how == "object":
        obj.hide_viewport = hidden
        return
    collection = obj.users_collection[0]
    if how == "collection":
        collection.hide_viewport = hidden
    else:
        layer = bpy.context.view_layer.layer_collection.children[collection.name]
        layer.exclude = hidden


@pytest.mark.parametrize("how", ["object", "collection", "excluded"])
def test_a_hidden_character_costs_nothing_and_shows_when_shown(dq_skin, monkeypatch, route, how):
    """Blender does not evaluate an object disabled in viewports (or in a disabled or excluded
    collection); a DQ Skin character so hidden must not be evaluated or skinned either (the
    feed's driver variables would pull it into the graph), while one hidden with the eye icon,
    which Blender still evaluates, stays fed. Shown again, it shows the frame it is on."""
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    scene = bpy.context.scene
    collection = bpy.data.collections.new("Crowd")
    scene.collection.children.link(collection)
    hidden = obj.copy()
    collection.objects.link(hidden)
    eye = obj.copy()
    scene.collection.objects.link(eye)
    for f in (3, 4):  # (a copy joins the feed at its first full evaluation)
        scene.frame_set(f)
    assert fed_runs(dq_skin, hidden) > 0 and fed_runs(dq_skin, eye) > 0
    hide(hidden, how, True)
    eye.hide_set(True)
    bpy.context.view_layer.update()
    scene.frame_set(5)
    published = Publishes(dq_skin, monkeypatch)
    runs = fed_runs(dq_skin, hidden), fed_runs(dq_skin, eye)
    for f in (6, 7, 8):
        scene.frame_set(f)
        assert not is_evaluated(hidden), f"frame {f}: the hidden character is evaluated"
        assert_same(obj, reference, f"frame {f}")
    assert fed_runs(dq_skin, hidden) == runs[0], "the hidden character was skinned"
    assert fed_runs(dq_skin, eye) == runs[1] + 3, "the character hidden with the eye icon was not fed"
    assert published.count == 0
    # Shown again by a script, right before a frame change (no update in between).
    hide(hidden, how, False)
    scene.frame_set(9)
    assert_same(hidden, reference, "shown, at the frame change")
    # (Its own batch of the feed skins it from the frame change it shows at; the scene's batch,
    # which it joins then, may skin the same frame once more.)
    assert fed_runs(dq_skin, hidden) > runs[0], "the shown character is not fed at the frame it shows at"
    for f in (10, 11):
        before = fed_runs(dq_skin, hidden)
        scene.frame_set(f)
        assert_same(hidden, reference, f"frame {f}")
        assert fed_runs(dq_skin, hidden) == before + 1, f"frame {f}: the shown character is not fed once"
    # Hidden by a script right before a frame change, shown in the interface.
    hide(hidden, how, True)
    scene.frame_set(12)
    scene.frame_set(13)
    assert not is_evaluated(hidden)
    hide(hidden, how, False)
    bpy.context.view_layer.update()
    assert_same(hidden, reference, "shown in the interface")
    assert route_of(dq_skin, hidden) == route


def test_a_hidden_character_saved_and_reopened_shows_when_shown(dq_skin, tmp_path, route):
    """Saved while disabled in viewports, reopened: not evaluated until shown, then skinned at
    the frame it is on, and fed from then on."""
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    obj.hide_viewport = True
    bpy.context.view_layer.update()
    blend = tmp_path / "hidden.blend"
    names = obj.name, reference.name
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    obj, reference = (bpy.data.objects[n] for n in names)
    scene = bpy.context.scene
    for f in (4, 5):
        scene.frame_set(f)
        assert not is_evaluated(obj)
    obj.hide_viewport = False
    bpy.context.view_layer.update()
    assert_same(obj, reference, "shown")
    scene.frame_set(6)
    runs = fed_runs(dq_skin, obj)
    for f in (7, 8):
        scene.frame_set(f)
        assert_same(obj, reference, f"frame {f}")
    assert fed_runs(dq_skin, obj) == runs + 2
    assert route_of(dq_skin, obj) == route


def test_a_character_hidden_in_viewports_renders(dq_skin, tmp_path, route):
    """Disabled in viewports but not in renders (a usual way to keep a heavy character out of
    the viewport): the render shows it skinned at the rendered frame."""
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    scene = setup_scene()
    scene.camera.location = (0.0, -9.0, 2.0)
    obj.hide_viewport = True
    bpy.context.view_layer.update()
    scene.frame_set(3)
    assert not is_evaluated(obj)
    assert_renders_as(obj, reference, scene, tmp_path)


def test_a_character_hidden_in_viewports_is_fed_inside_a_render(dq_skin, tmp_path, route):
    """Disabled in viewports and rendered: the render's graph skins it inside its first
    evaluation (what a simulation stepping there, or anything else reading it there, sees),
    through a batch of the feed that only its own carriers pull into a graph, so the viewport's
    graph still never evaluates it."""
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    scene = setup_scene()
    obj.hide_viewport = True
    bpy.context.view_layer.update()
    for f in (3, 4):
        scene.frame_set(f)
        assert not is_evaluated(obj)
    runs = fed_runs(dq_skin, obj)
    scene.frame_start, scene.frame_end = 5, 7
    scene.render.filepath = str(tmp_path / "hidden_####")
    bpy.ops.render.render(animation=True)
    assert fed_runs(dq_skin, obj) >= runs + 3, "a render's graph does not feed the hidden character"
    for f in (8, 9):
        scene.frame_set(f)
        assert not is_evaluated(obj), "the viewport's graph evaluates the hidden character"
    obj.hide_viewport = False
    bpy.context.view_layer.update()
    runs = fed_runs(dq_skin, obj)
    for f in (10, 11):
        scene.frame_set(f)
        assert_same(obj, reference, f"shown again, frame {f}")
    assert fed_runs(dq_skin, obj) == runs + 2, "shown again, it is not fed"


def test_a_character_in_an_excluded_collection_shows_through_its_instance(dq_skin, route):
    """A character's collection excluded from the view layer and shown by a collection instance
    (how linked characters are often placed): Blender evaluates it through the instance, so the
    feed must follow it although its own collection is excluded."""
    obj, arm, reference = fed_character(dq_skin, "LINEAR")
    scene = bpy.context.scene
    collection = bpy.data.collections.new("Character")
    scene.collection.children.link(collection)
    collection.objects.link(obj)
    scene.collection.objects.unlink(obj)
    bpy.context.view_layer.layer_collection.children["Character"].exclude = True
    instance = bpy.data.objects.new("Instance", None)
    instance.instance_type = "COLLECTION"
    instance.instance_collection = collection
    scene.collection.objects.link(instance)
    bpy.context.view_layer.update()
    for f in (5, 6):
        scene.frame_set(f)
        assert is_evaluated(obj)
        assert_same(obj, reference, f"frame {f}")
    runs = fed_runs(dq_skin, obj)
    for k, f in enumerate((7, 8), start=1):
        scene.frame_set(f)
        assert_same(obj, reference, f"frame {f}")
        assert fed_runs(dq_skin, obj) == runs + k, "the instanced character is not fed"


def test_files_hold_nothing_of_it_and_removing_dq_skin_removes_it(dq_skin, tmp_path, route):
    obj, arm, reference = fed_character(dq_skin, "LINEAR")
    blend = tmp_path / "fed.blend"
    names = obj.name, reference.name
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    assert any(is_carrier(m) for m in obj.modifiers) == (route == "cache"), "the carrier is back after the save"
    assert_same(obj, reference, "right after the save")
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    assert not [o.name for o in bpy.data.objects if any(is_carrier(m) for m in o.modifiers)], "a carrier was saved"
    assert not [o.name for o in bpy.data.objects if o.animation_data and o.animation_data.drivers], "a driver was saved"
    obj, reference = (bpy.data.objects[n] for n in names)
    for f in (4, 7, 11):
        bpy.context.scene.frame_set(f)
        assert_same(obj, reference, f"reopened, frame {f}")
    assert route_of(dq_skin, obj) == route
    st = dq_skin.SESSION.state_of(obj, dq_skin_mods(obj)[0])
    path = st.output.pointcache.path if route == "cache" else None
    select_only(obj)
    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.object.dq_skin_remove() == {"FINISHED"}
    assert path is None or not os.path.exists(path), "the cache file outlived its modifier"
    assert not dq_skin_mods(obj) and not any(is_carrier(m) for m in obj.modifiers)
    assert obj.animation_data is None or not obj.animation_data.drivers
    bpy.context.scene.frame_set(13)
    assert_same(obj, reference, "after DQ Skin was removed")


@pytest.mark.parametrize("earlier", ["version", "outputs"])
def test_a_node_group_saved_by_an_earlier_version_is_brought_up_to_date(dq_skin, tmp_path, route, earlier):
    """A file whose DQ Skin node group an earlier version saved (its version's tag, or today's
    version with outputs of before (`nodes.OUTPUTS`), and outputs that are not today's: here none
    at all) plays as today's once opened: the group's outputs are rebuilt in place, and its
    modifiers keep their settings."""
    nodes = dq_skin.blender.nodes
    obj, _arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    group = dq_skin_mods(obj)[0].node_group
    if earlier == "version":
        group[nodes.GROUP_TAG] = 4
    else:
        del group[nodes.OUTPUTS_TAG]
    for link in [k for k in group.links if k.to_node.bl_idname == "NodeGroupOutput"]:
        group.links.remove(link)
    names = obj.name, reference.name, group.name
    blend = tmp_path / "earlier.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    obj, reference, group = bpy.data.objects[names[0]], bpy.data.objects[names[1]], bpy.data.node_groups[names[2]]
    assert nodes.version_of(group) == nodes.VERSION and group[nodes.OUTPUTS_TAG] == nodes.OUTPUTS
    assert [k for k in group.links if k.to_node.bl_idname == "NodeGroupOutput"], "the outputs were not rebuilt"
    for f in (4, 9):
        bpy.context.scene.frame_set(f)
        assert_same(obj, reference, f"reopened, frame {f}")
    assert route_of(dq_skin, obj) == route


def file_positions(dq_skin, path) -> np.ndarray:
    return np.fromfile(path, np.float32, offset=dq_skin.routes.pointcache.HEADER_SIZE).reshape(-1, 3)


def test_the_cache_file_is_the_output(dq_skin):
    """On the Mesh Cache route the kernel writes the carrier's file itself (mapped into memory):
    no copy of the positions stays in the process, and the file holds what the object shows."""
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    st = dq_skin.SESSION.state_of(obj, dq_skin_mods(obj)[0])
    assert route_of(dq_skin, obj) == "cache"
    runs = fed_runs(dq_skin, obj)
    for f in (6, 7):
        bpy.context.scene.frame_set(f)
        assert_same(obj, reference, f"frame {f}")
        assert np.array_equal(file_positions(dq_skin, st.output.pointcache.path), evaluated_positions(obj))
    assert fed_runs(dq_skin, obj) == runs + 2
    assert dq_skin.routes.pointcache.is_mapped(st.output.buffer) and st.output.pointcache.is_buffer(st.output.buffer)


def test_a_deleted_cache_file_is_made_again(dq_skin):
    obj, arm, reference = fed_character(dq_skin, "LINEAR")
    st = dq_skin.SESSION.state_of(obj, dq_skin_mods(obj)[0])
    path = st.output.pointcache.path
    os.unlink(path)
    for f in (6, 10):
        bpy.context.scene.frame_set(f)
        assert_same(obj, reference, f"frame {f} after the file was deleted")
    assert os.path.exists(path)
    # The kernel writes the new file from then on (not the deleted one's memory).
    assert st.output.pointcache.is_buffer(st.output.buffer)
    bpy.context.scene.frame_set(11)
    assert np.array_equal(file_positions(dq_skin, path), evaluated_positions(obj))


@pytest.mark.parametrize("method", ["DUAL_QUATERNION", "CENTERS_OF_ROTATION"])
def test_the_result_route_keeps_no_buffer_between_fed_frames(dq_skin, monkeypatch, method):
    """On the result-object route the feed writes each frame into the result Blender evaluates:
    DQ Skin keeps no output array of its own between full evaluations (12 bytes a vertex), and
    what needs the last frame shown still gets it: Edit Mode shows it, Apply as Shape Key
    stores the frame's positions, the frames after equal the Armature modifier's."""
    from dqtest import animated_tube

    node_route_for_every_size(dq_skin, monkeypatch)
    obj, _arm, _ = animated_tube()
    reference = reference_copy(obj, True)
    add_dq_skin(obj, method)
    dq_skin_mods(obj)[0].show_in_editmode = True  # (Edit Mode shows the pose)
    select_only(obj)
    bpy.context.scene.frame_set(3)
    assert route_of(dq_skin, obj) == "node", status(dq_skin, obj).message
    st = dq_skin.SESSION.state_of(obj, dq_skin_mods(obj)[0])
    runs = fed_runs(dq_skin, obj)
    for k, f in enumerate((5, 9), start=1):
        bpy.context.scene.frame_set(f)
        assert fed_runs(dq_skin, obj) == runs + k
        assert st.output.buffer is None and st.output.job.out is None, "a buffer kept between fed frames"
        if method == "DUAL_QUATERNION":
            assert_same(obj, reference, f"frame {f}")
    shown = evaluated_positions(obj)
    assert st.output.buffer is None
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.context.view_layer.update()
    assert deviation(evaluated_positions(obj), shown) <= 1e-6, "Edit Mode shows the last frame"
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.context.scene.frame_set(12)
    if method == "DUAL_QUATERNION":
        assert_same(obj, reference, "frame 12, after Edit Mode")
    shown = evaluated_positions(obj)
    mod = dq_skin_mods(obj)[0]
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.object.dq_skin_apply_as_shape_key(modifier=mod.name, keep_modifier=True) == {"FINISHED"}
    stored = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.shape_keys.key_blocks[-1].data.foreach_get("co", stored)
    assert deviation(stored.reshape(-1, 3), shown) <= 1e-6


def checks_through_python(dq_skin, monkeypatch) -> list:
    """The objects whose fed frame is checked through Blender's Python API from now on (not
    from their state in memory, `playback.FedCheck`), one name per check."""
    return names_of_calls(monkeypatch, dq_skin.engine.playback, "_fed_frame_stands")


def checks_while_playing(dq_skin, monkeypatch, obj, reference) -> list:
    """Frames 4 and 5, then 6 to 8 each equal to `reference`: the objects whose fed frames were
    checked through Blender's Python API in the last three (see `checks_through_python`)."""
    for f in (4, 5):
        bpy.context.scene.frame_set(f)
    checked = checks_through_python(dq_skin, monkeypatch)
    for f in (6, 7, 8):
        bpy.context.scene.frame_set(f)
        assert_same(obj, reference, f"frame {f}")
    return checked


def _reference_modifier(reference):
    return next(m for m in reference.modifiers if m.type == "ARMATURE")


# What a script may change between two frames of playback, each on the character and on its
# reference so that the two stay equal: (DQ Skin's modifier, the reference's Armature modifier).
SCRIPT_CHANGES = {
    "a vertex group renamed": lambda dq, obj, ref, mod, arm: [o.vertex_groups["Bone1"].__setattr__("name", "Renamed") for o in (obj, ref)],
    "the method": lambda dq, obj, ref, mod, arm: (
        dq.blender.nodes.put_method(mod, "Linear"),
        setattr(_reference_modifier(ref), "use_deform_preserve_volume", False),
    ),
    "bone envelopes on": lambda dq, obj, ref, mod, arm: (
        dq.blender.nodes.put(mod, "Use Envelopes", True),
        setattr(_reference_modifier(ref), "use_bone_envelopes", True),
    ),
    "a mask vertex group": lambda dq, obj, ref, mod, arm: (
        dq.blender.nodes.put_attribute(mod, "Mask", "Bone2"),
        setattr(_reference_modifier(ref), "vertex_group", "Bone2"),
    ),
    "another armature": swap_armature,
    "the companion shown": lambda dq, obj, ref, mod, arm: setattr(
        obj.modifiers[dq.blender.nodes.get_companion(mod)["name"]], "show_viewport", True
    ),
    "DQ Skin hidden": lambda dq, obj, ref, mod, arm: setattr(mod, "show_viewport", False),
}


@pytest.mark.parametrize("change", sorted(SCRIPT_CHANGES))
def test_fed_frames_are_checked_from_memory_and_every_change_is_seen(dq_skin, monkeypatch, route, change):
    """While nothing but the pose changes, the frame handler checks a fed frame from the
    object's state in Blender's memory (one read), not through the Python API (dozens of calls a
    character and frame); what a script changes before the next frame is seen there and
    followed at once (the frame equals the Armature modifier set up the same way)."""
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    scene = bpy.context.scene
    checked = checks_while_playing(dq_skin, monkeypatch, obj, reference)
    assert checked == [], "frames where only the pose changed were checked through the Python API"
    assert dq_skin.SESSION.readers.object_state_checked
    SCRIPT_CHANGES[change](dq_skin, obj, reference, dq_skin_mods(obj)[0], arm)
    scene.frame_set(9)
    assert_same(obj, reference, f"after {change}")
    scene.frame_set(10)
    assert_same(obj, reference, f"the frame after {change}")


# What a script may change of an armature's bones between two frames (both DQ Skin and the
# reference deform with the armature).
BONE_CHANGES = {
    "nothing": lambda bones: None,
    "a B-Bone's rest shape": lambda bones: setattr(bones["Bone2"], "bbone_easein", 1.7),
    "a bone's deform flag": lambda bones: setattr(bones["Bone1"], "use_deform", False),
}


@pytest.mark.parametrize("change", sorted(BONE_CHANGES))
def test_an_armature_updated_on_every_frame_is_checked_from_memory(dq_skin, monkeypatch, route, change):
    """A Rigify rig's armature data is updated on every frame (its drivers), its bones
    unchanged: the frame handler still checks a fed frame from the object's state in memory
    (the bones compared by their binding signature, from the pose the feed read), not through
    the Python API; a bone a script edits before the next frame is seen there (the frame equals
    the Armature modifier's)."""
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    scene = bpy.context.scene
    # Keyed on the armature's data, as Rigify's drivers are: Blender updates it on every frame.
    for frame, value in ((1, 0.0), (20, 1.0)):
        arm.data["dq_skin_test_wiggle"] = value
        arm.data.keyframe_insert('["dq_skin_test_wiggle"]', frame=frame)
    updates = []
    counting = lambda _scene, depsgraph: updates.extend(u.id.original == arm.data for u in depsgraph.updates)  # noqa: E731
    bpy.app.handlers.frame_change_post.append(counting)
    try:
        checked = checks_while_playing(dq_skin, monkeypatch, obj, reference)
    finally:
        bpy.app.handlers.frame_change_post.remove(counting)
    assert sum(updates) >= 3, "the armature's data was not updated on every frame: the test tests nothing"
    assert checked == [], "frames where the armature's data was updated, its bones unchanged, were checked through the Python API"
    BONE_CHANGES[change](arm.data.bones)
    scene.frame_set(9)
    assert_same(obj, reference, f"after {change}")
    scene.frame_set(10)
    assert_same(obj, reference, f"the frame after {change}")
    assert status(dq_skin, obj).live


def full_evaluations(dq_skin, monkeypatch) -> list:
    """The objects DQ Skin evaluates fully (through Blender's Python API) from now on."""
    return names_of_calls(monkeypatch, dq_skin.engine.pipeline, "evaluate_object")


def play_watching(watched, obj, reference, frames) -> list:
    """`frames`, each equal to `reference` (if given): the names of the objects of `watched`
    Blender evaluated at those frame changes."""
    seen = []

    def handler(_scene, depsgraph):
        seen.extend(u.id.original.name for u in depsgraph.updates if u.id.original in watched)

    bpy.app.handlers.frame_change_post.append(handler)
    try:
        for f in frames:
            bpy.context.scene.frame_set(f)
            if reference is not None:
                assert_same(obj, reference, f"frame {f}")
    finally:
        bpy.app.handlers.frame_change_post.remove(handler)
    return seen


def stand_still(arm) -> None:
    """The rig keeps frame 8's pose and loses its animation; frame 9 shown."""
    bpy.context.scene.frame_set(8)
    arm.animation_data.action = None
    bpy.context.scene.frame_set(9)


def test_a_held_pose_is_neither_skinned_nor_evaluated_again(dq_skin, monkeypatch, route):
    """Past its last key a rig holds its pose: Blender evaluates the bones again on every frame,
    and the feed finds the frame it skinned last still standing: no kernel run on the carrier's
    route (its file holds the frame), no full evaluation after it, the mesh equal to the
    Armature modifier's."""
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    scene = bpy.context.scene
    scene.frame_set(21)  # (the last key is on frame 20)
    runs = fed_runs(dq_skin, obj)
    evaluated = full_evaluations(dq_skin, monkeypatch)
    published = Publishes(dq_skin, monkeypatch)
    for f in (22, 23, 25, 24):
        scene.frame_set(f)
        assert_same(obj, reference, f"frame {f}")
    assert evaluated == [], "held frames were evaluated through the Python API"
    assert published.count == 0
    if route == "cache":
        assert fed_runs(dq_skin, obj) == runs, "a held frame was skinned again"
    else:  # the result object is evaluated again from its own mesh: skinned again
        assert fed_runs(dq_skin, obj) == runs + 4
    scene.frame_set(12)  # moving again
    assert_same(obj, reference, "frame 12, after the held frames")
    assert fed_runs(dq_skin, obj) > runs


def _posed(dq, obj, ref, mod, arm):
    arm.pose.bones["Bone2"].rotation_quaternion = (0.8, 0.2, 0.5, 0.1)


def _vertex_moved(dq, obj, ref, mod, arm):
    for o in (obj, ref):
        o.data.vertices[5].co.x += 0.25


def _object_moved(dq, obj, ref, mod, arm):
    for o in (obj, ref):
        o.location.y += 0.5


# What a script may change on a character standing still before the next frame change.
STILL_CHANGES = {**SCRIPT_CHANGES, "a bone posed": _posed, "a vertex moved": _vertex_moved, "the object moved": _object_moved}


@pytest.mark.parametrize("change", sorted(STILL_CHANGES))
def test_a_character_standing_still_costs_nothing_and_every_change_is_seen(dq_skin, monkeypatch, route, change):
    """A rig with no animation: Blender evaluates neither it nor a mesh it deforms with the
    Armature modifier at a frame change, and neither DQ Skin's feed nor its full evaluation
    runs (the feed's driver runs only when what it follows changes); whatever a script changes
    before the next frame change is seen then (the mesh equals the Armature modifier's)."""
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    scene = bpy.context.scene
    stand_still(arm)
    assert_same(obj, reference, "frame 9, standing still")
    runs = fed_runs(dq_skin, obj)
    evaluated = full_evaluations(dq_skin, monkeypatch)
    published = Publishes(dq_skin, monkeypatch)
    seen = play_watching({obj, arm, reference}, obj, reference, (10, 11, 12))
    assert seen == [], "Blender evaluated the character standing still"
    assert evaluated == [] and published.count == 0, "DQ Skin evaluated the character standing still"
    assert fed_runs(dq_skin, obj) == runs
    STILL_CHANGES[change](dq_skin, obj, reference, dq_skin_mods(obj)[0], arm)
    scene.frame_set(13)
    assert_same(obj, reference, f"after {change}")
    scene.frame_set(14)
    assert_same(obj, reference, f"the frame after {change}")
    if change == "a bone posed":
        assert fed_runs(dq_skin, obj) == runs + 1, "the new pose was not skinned by the feed"


@pytest.mark.parametrize("method", ["LINEAR", "DUAL_QUATERNION", "BLEND", "CENTERS_OF_ROTATION"])
def test_every_method_standing_still_costs_nothing_and_follows_a_new_pose(dq_skin, monkeypatch, method, route):
    """Vertex groups alone, every method, the rig standing still: no evaluation at all over three
    frame changes, the mesh as the full evaluation computes it (forced); a bone posed by a
    script is skinned by the feed at the next frame change, again as the full evaluation does."""
    from dqtest import animated_tube

    obj, arm, _ = animated_tube()
    add_dq_skin(obj, method)
    for f in (3, 5):
        bpy.context.scene.frame_set(f)
    stand_still(arm)
    tracker = dq_skin.SESSION.tracker

    def as_fully_evaluated(what: str) -> np.ndarray:
        fed = evaluated_positions(obj)
        tracker.evaluate(tracker.record_of(obj), bpy.context.evaluated_depsgraph_get(), force=True)
        assert deviation(evaluated_positions(obj), fed) <= 1e-6, (what, method)
        return fed

    before = as_fully_evaluated("frame 9")
    runs = fed_runs(dq_skin, obj)
    evaluated = full_evaluations(dq_skin, monkeypatch)
    seen = play_watching({obj, arm}, obj, None, (10, 11, 12))
    assert seen == [] and evaluated == [] and fed_runs(dq_skin, obj) == runs
    assert deviation(evaluated_positions(obj), before) == 0.0
    arm.pose.bones[1].rotation_quaternion = (0.8, 0.2, 0.5, 0.1)
    bpy.context.scene.frame_set(13)
    assert fed_runs(dq_skin, obj) == runs + 1, "the new pose was not skinned by the feed"
    posed = as_fully_evaluated("posed")
    assert deviation(posed, before) > 1e-3, "posing the bone changed nothing: the test tests nothing"
    assert dq_skin.SESSION.status_of(obj, dq_skin_mods(obj)[0]).live


def test_a_character_standing_still_under_a_modifier_that_moves_with_time(dq_skin, monkeypatch, route):
    """A Wave after DQ Skin: Blender evaluates the mesh on every frame, the rig standing still;
    the carrier gives the frame DQ Skin skinned last (the feed does not run), and nothing is
    evaluated through the Python API."""
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    for o in (obj, reference):
        wave = o.modifiers.new("Wave", "WAVE")
        wave.height, wave.time_offset = 0.2, -3.0
    stand_still(arm)
    runs = fed_runs(dq_skin, obj)
    evaluated = full_evaluations(dq_skin, monkeypatch)
    seen = play_watching({obj}, obj, reference, (10, 11, 12))
    assert len(seen) == 3, "the Wave did not make Blender evaluate the mesh: the test tests nothing"
    assert evaluated == [] and fed_runs(dq_skin, obj) == runs


@pytest.mark.parametrize("rig", ["standing still", "moving"])
def test_shape_keys_a_script_adds_play(dq_skin, route, rig):
    """A script adds shape keys to the mesh and keys a value: the mesh follows the shape key on
    every frame, equal to the Armature modifier's (the feed's driver follows the shape keys
    too, so a rig standing still does not hold them)."""
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    scene = bpy.context.scene
    scene.frame_set(8)
    if rig == "standing still":
        arm.animation_data.action = None
    for o in (obj, reference):
        o.shape_key_add(name="Basis")
        bulge = o.shape_key_add(name="Bulge")
        for p in bulge.data:
            p.co.x *= 1.4
        for frame, value in ((10, 0.0), (14, 1.0)):
            bulge.value = value
            bulge.keyframe_insert("value", frame=frame)
    scene.frame_set(9)
    runs = fed_runs(dq_skin, obj)
    for f in (10, 11, 12, 13):
        scene.frame_set(f)
        assert_same(obj, reference, f"frame {f}")
    assert fed_runs(dq_skin, obj) >= runs + 3, "the shape keys' frames were not fed"


def _autoexec_probe():
    """An Empty whose property a driver sets to the frame through an attribute access, which
    Blender refuses while Python scripts may not run automatically: it tells that mode."""
    probe = bpy.data.objects.new("Auto-run probe", None)
    bpy.context.scene.collection.objects.link(probe)
    probe["frame"] = -1.0
    driver = probe.driver_add('["frame"]').driver
    driver.type = "SCRIPTED"
    driver.expression = "frame.real"
    return probe.name


@pytest.mark.parametrize("rig", ["moving", "standing still"])
def test_a_file_reopened_without_python_auto_execution_is_fed(dq_skin, tmp_path, route, rig):
    """Files from elsewhere open with Python's auto-execution off, Blender's default: drivers may
    call nothing Blender does not know. The feed's driver, made by the add-on after the file is
    open, still runs: frames are skinned inside Blender's first evaluation, equal to the Armature
    modifier, and a rig standing still is evaluated neither by Blender nor by DQ Skin."""
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    names = obj.name, reference.name, arm.name, _autoexec_probe()
    blend = tmp_path / "from elsewhere.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    prefs = bpy.context.preferences.filepaths
    trusted = prefs.use_scripts_auto_execute
    prefs.use_scripts_auto_execute = False
    try:
        bpy.ops.wm.open_mainfile(filepath=str(blend), use_scripts=False)
        obj, reference, arm, probe = (bpy.data.objects[n] for n in names)
        scene = bpy.context.scene
        if rig == "standing still":
            arm.animation_data.action = None
        for f in (4, 5):
            scene.frame_set(f)
        probe_eval = probe.evaluated_get(bpy.context.evaluated_depsgraph_get())
        assert probe_eval["frame"] != 5.0, "Python's auto-execution is on: the test tests nothing"
        runs = fed_runs(dq_skin, obj)
        seen = play_watching({obj, reference}, obj, reference, (6, 7, 8))
        assert route_of(dq_skin, obj) == route
        if rig == "moving":
            assert fed_runs(dq_skin, obj) == runs + 3, "frames were not skinned by the feed"
        else:
            assert seen == [] and fed_runs(dq_skin, obj) == runs
    finally:
        prefs.use_scripts_auto_execute = trusted


def test_the_object_state_reader_is_checked_on_its_first_read(dq_skin, monkeypatch):
    """The object-state reader's first read in a session is compared with what Blender's
    Python API gives (`memory_check.object_state_differs`): it agrees on a character, catches
    another object's state, and a reader that disagrees is refused for the session with the
    reason; the Python path then checks every frame, still equal to the Armature modifier."""
    check = dq_skin.blender.memory_check
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    other, _, _ = bbone_rig()
    readers = dq_skin.SESSION.readers
    raw = readers._object_state
    assert raw is not None, readers.object_state_error
    assert check.object_state_differs(raw.describe(obj), obj) == ""
    assert check.object_state_differs(raw.describe(obj), other) != ""
    described = raw.describe(obj)
    described["modifiers"][-1]["mode"] ^= check.SHOWN_IN_VIEWPORT
    assert "shown in the viewport" in check.object_state_differs(described, obj)
    monkeypatch.setattr(readers, "object_state_checked", False)
    monkeypatch.setattr(readers, "_object_state", raw)  # (put back after the test)
    monkeypatch.setattr(check, "object_state_differs", lambda *_: "the object's mode (made up by the test)")
    checked = checks_through_python(dq_skin, monkeypatch)
    for f in (4, 5, 6):
        bpy.context.scene.frame_set(f)
        assert_same(obj, reference, f"frame {f}")
    assert readers.object_state is None and "disagrees with Blender's data" in readers.object_state_error
    assert len(checked) == 3, checked


def _in_mode(obj, mode: str) -> None:
    select_only(obj)
    bpy.ops.object.mode_set(mode=mode)


def _companion(dq, obj, mod):
    return obj.modifiers[dq.blender.nodes.get_companion(mod)["name"]]


# What else a script or the interface may change, that the object's state must show.
STATE_CHANGES = {
    **SCRIPT_CHANGES,
    "the object in Edit Mode": lambda dq, obj, ref, mod, arm: _in_mode(obj, "EDIT"),
    "the armature in Edit Mode": lambda dq, obj, ref, mod, arm: _in_mode(arm, "EDIT"),
    "the companion renamed": lambda dq, obj, ref, mod, arm: setattr(_companion(dq, obj, mod), "name", "Renamed"),
    "the companion's render switch": lambda dq, obj, ref, mod, arm: setattr(_companion(dq, obj, mod), "show_render", True),
    "the companion moved": lambda dq, obj, ref, mod, arm: obj.modifiers.move(len(obj.modifiers) - 1, 0),
    "a vertex group added": lambda dq, obj, ref, mod, arm: obj.vertex_groups.new(name="Extra"),
    "a modifier added": lambda dq, obj, ref, mod, arm: obj.modifiers.new("Smooth", "SMOOTH"),
    "the armature's input cleared": lambda dq, obj, ref, mod, arm: dq.blender.nodes.put(mod, "Armature", None),
}


@pytest.mark.parametrize("change", sorted(STATE_CHANGES))
def test_the_object_state_read_from_memory_shows_every_change(dq_skin, change):
    """The state the fast check compares (`ObjectStateMemory`, read from Blender's memory)
    stays the same while only the frame changes, and differs after each change a script or the
    interface can make to what the frame handler's check reads, whether or not Blender reports
    it as an update."""
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    reader = dq_skin.SESSION.readers.object_state
    assert reader is not None, dq_skin.SESSION.readers.object_state_error
    before = reader.digest(obj)
    bpy.context.scene.frame_set(7)
    assert reader.digest(obj) == before, "the frame alone changed the state"
    STATE_CHANGES[change](dq_skin, obj, reference, dq_skin_mods(obj)[0], arm)
    assert reader.digest(obj) != before


def test_the_object_state_reader_refuses_what_is_not_an_object(dq_skin):
    """Addresses come from Blender itself: anything but a `bpy.types.Object` is refused with a
    clear error before any memory is read; a digest of another length is never unchanged."""
    obj, _arm, _ref = fed_character(dq_skin, "DUAL_QUATERNION")
    raw = dq_skin.SESSION.readers._object_state
    for wrong in (obj.data, "Tube", 12345, None):
        for call in (raw.digest, raw.describe, lambda o: raw.unchanged(o, b"")):
            with pytest.raises(TypeError, match="obj must be a bpy.types.Object"):
                call(wrong)
    assert len(raw.digest(obj)) == 16
    assert not raw.unchanged(obj, b"") and not raw.unchanged(obj, raw.digest(obj)[:8])
    assert raw.unchanged(obj, raw.digest(obj))
    with pytest.raises(TypeError, match="blend_file must be the bytes of a .blend file"):
        dq_skin.dqskin.memory.ObjectStateMemory("file.blend")
    with pytest.raises(ValueError, match="blend_file"):
        dq_skin.dqskin.memory.ObjectStateMemory(b"BLENDER-v402" + b"\0" * 64)


@pytest.mark.skipif(bpy.app.version >= (5, 2, 0), reason="5.2 has no ID properties on modifiers for a script to write")
def test_a_setting_written_without_an_update_is_seen_from_memory(dq_skin, route):
    """A script may write a DQ Skin input as an ID property (`mod[identifier] = value`, up to
    Blender 5.1) without tagging anything: Blender reports no update, and only the object's
    state in memory shows the change. The next frame must show it (here: the method made
    Linear, equal to the Armature modifier without Preserve Volume)."""
    obj, arm, reference = fed_character(dq_skin, "DUAL_QUATERNION")
    scene = bpy.context.scene
    for f in (4, 5, 6):
        scene.frame_set(f)
    nodes = dq_skin.blender.nodes
    mod = dq_skin_mods(obj)[0]
    ident = nodes.socket_ids(mod.node_group)["Method"]
    linear = next(k for k, v in nodes.menu_values(mod.node_group).items() if v == "Linear")
    mod[ident] = linear  # (no update_tag: nothing reaches the dependency graph)
    _reference_modifier(reference).use_deform_preserve_volume = False
    scene.frame_set(7)
    assert_same(obj, reference, "the frame after the method was written")
    assert nodes.get_method(mod) == "Linear"

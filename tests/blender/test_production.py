"""DQ Skin in the scenes artists and pipelines actually have, each compared with the same scene
under Blender's own Armature modifier (its *twin*, see `dqtest.twin`), frame by frame, Linear and
Dual Quaternion, most of them on a vertex-group rig and on a B-Bone rig (`scenes.RIGS`: the
frame handler skins the one, the feed the other): duplicates, crowds, append, library overrides, linked instances, files opened
without the add-on, Apply, several DQ Skins, any modifier after DQ Skin, viewport off and render
on, and the panel's status in each case.

Bar: ≤ 1e-5 × the bounding-box diagonal (`dqtest.REL_TOL`).
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from dqtest import (
    METHODS,
    REL_TOL,
    add_dq_skin,
    animate,
    animated_tube,
    assert_fed,
    assert_same,
    check_frames,
    deviation,
    dq_skin_mods,
    draw_panel,
    evaluated_positions,
    fed_runs,
    get_input,
    import_character,
    is_carrier,
    moved,
    output_of,
    plain_twin,
    select_only,
    stack,
    status,
    twin,
)
from scenes import RIGS, armature_chain, chain_weights, rig_tube, tube

import bpy

from mathutils import Quaternion

ROOT = Path(__file__).resolve().parents[2]


# -- duplicates and crowds ------------------------------------------------------------------------


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("how", ["mesh and armature (Shift+D)", "mesh and armature (Alt+D)", "mesh only (Shift+D)"])
def test_duplicates_follow_their_own_armature(dq_skin, method, rig, how):
    obj, arm, _ = animated_tube(rig=rig)
    add_dq_skin(obj, method)
    if rig != "vertex groups":
        assert_fed(dq_skin, obj)
    bpy.context.scene.frame_set(5)
    linked = "Alt+D" in how
    if "armature" in how:
        select_only(obj, arm)
    else:
        select_only(obj)
    assert bpy.ops.object.duplicate_move(OBJECT_OT_duplicate={"linked": linked}) == {"FINISHED"}
    dup = bpy.context.view_layer.objects.active
    assert dup is not obj and dq_skin_mods(dup)
    dup.location.x += 3.0
    if "armature" in how:
        dup_arm = dup.parent
        assert dup_arm is not arm and get_input(dq_skin_mods(dup)[0], "Armature") == dup_arm
        # The duplicate armature gets its own animation, so one pose showing on the other fails.
        dup_arm.animation_data_clear()
        animate(dup_arm, seed=0.7)
    pairs = [(obj, twin(obj)), (dup, twin(dup))]
    check_frames(pairs)
    assert moved(dup) > 0.1
    outputs = {output_of(o, m) for o in (obj, dup) for m in dq_skin_mods(o)}
    assert len(outputs) == 2, "each copy has its own output"


def test_copy_modifiers_to_selected(dq_skin):
    obj, arm, _ = animated_tube()
    add_dq_skin(obj, "DUAL_QUATERNION")
    other = tube("Other", 24, 16, 4.0, 0.4)
    other.location.x = 2.0
    chain_weights(other, arm, 4.0)
    other.parent = arm
    select_only(obj, other)
    with bpy.context.temp_override(object=obj, active_object=obj, selected_objects=[obj, other]):
        for m in list(obj.modifiers):
            assert bpy.ops.object.modifier_copy_to_selected(modifier=m.name) == {"FINISHED"}
    assert stack(other) == ["NODES", "ARMATURE"]
    check_frames([(obj, twin(obj)), (other, twin(other))])
    assert output_of(other, dq_skin_mods(other)[0]) != output_of(obj, dq_skin_mods(obj)[0])


def _crowd_member(dq_skin, obj, arm, i: int, own_mesh: bool = False):
    """A copy of `obj` (sharing its mesh, or with a copy of its own) on its own copy of `arm`,
    animated differently and set beside it; DQ Skin and its companion follow the new armature."""
    a = arm.copy()
    a.data = arm.data
    a.animation_data_clear()
    bpy.context.scene.collection.objects.link(a)
    animate(a, seed=0.2 * i)
    a.location.x = 2.5 * i
    o = obj.copy()
    if own_mesh:
        o.data = obj.data.copy()
    bpy.context.scene.collection.objects.link(o)
    o.parent = a
    mod = dq_skin_mods(o)[0]
    dq_skin.blender.nodes.put(mod, "Armature", a)
    o.modifiers[dq_skin.blender.nodes.get_companion(mod)["name"]].object = a
    return o


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
def test_crowd_of_linked_duplicates_with_their_own_armatures(dq_skin, method, rig):
    """One mesh, many objects, each deformed by its own armature (a crowd)."""
    obj, arm, _ = animated_tube(rig=rig)
    add_dq_skin(obj, method)
    if rig != "vertex groups":
        assert_fed(dq_skin, obj)
    pairs = [(obj, twin(obj))]
    for i in range(1, 5):
        o = _crowd_member(dq_skin, obj, arm, i)
        assert o.data is obj.data
        pairs.append((o, twin(o)))
    check_frames(pairs)
    assert len({output_of(o, dq_skin_mods(o)[0]) for o, _ in pairs}) == len(pairs)


@pytest.mark.parametrize("method", METHODS)
def test_a_crowd_of_copies_shares_one_influences_until_one_is_painted(dq_skin, method):
    """Copies of a character (each with its own copy of the mesh, as Shift+D makes them) on
    their own armatures: their bindings share one `Influences` (the same weights on bones
    mapped the same way); painting one copy gives it its own, the others keep theirs, and every
    frame equals the Armature modifier's."""
    obj, arm, _ = animated_tube()
    add_dq_skin(obj, method)
    pairs = [(obj, twin(obj))]
    for i in range(1, 4):
        o = _crowd_member(dq_skin, obj, arm, i, own_mesh=True)
        assert o.data is not obj.data
        pairs.append((o, twin(o)))

    def influences():
        return [dq_skin.SESSION.state_of(o, dq_skin_mods(o)[0]).binding.binding.influences for o, _ in pairs]

    check_frames(pairs)
    first = influences()
    assert all(i is first[0] for i in first), "copies with the same weights bind to one Influences"
    painted = pairs[2][0]
    painted.vertex_groups[0].add(list(range(0, len(painted.data.vertices), 3)), 0.25, "REPLACE")
    painted.data.update()
    check_frames(pairs)
    after = influences()
    assert after[2] is not first[0] and all(after[k] is first[0] for k in (0, 1, 3))
    assert not np.array_equal(after[2].weights, first[0].weights)


@pytest.mark.parametrize("method", METHODS)
def test_a_crowd_of_copies_keeps_one_of_what_its_rig_gives_alike(dq_skin, method):
    """Copies of a character on copies of one rig keep one list of bone names, one set of rest
    matrices, envelope rows and segment counts, one tuple of vertex-group names (a crowd keeps
    every byte a character once per character), read-only since all share them; a copy whose
    rig's rest pose is edited gets rest matrices of its own, and every frame of every copy
    equals the Armature modifier's."""
    obj, arm, _ = animated_tube()
    add_dq_skin(obj, method)
    pairs = [(obj, twin(obj))]
    for i in range(1, 4):
        o = _crowd_member(dq_skin, obj, arm, i, own_mesh=True)
        pairs.append((o, twin(o)))

    def kept():
        rows = []
        for o, _ in pairs:
            cache = dq_skin.SESSION.state_of(o, dq_skin_mods(o)[0]).binding
            names = dq_skin.SESSION.meshes.peek_any(o).group_names
            rows.append((cache.binding.bone_names, cache.binding.rest, cache.envelopes, cache.segments, names))
        return rows

    check_frames(pairs)
    first = kept()
    for k, what in enumerate(("bone names", "rest matrices", "envelope rows", "segment counts", "group names")):
        assert all(row[k] is first[0][k] for row in first), f"copies keep one {what}"
    for array in first[0][1:4]:
        assert not array.flags.writeable
    # One copy's rig gets a rest pose of its own.
    edited = pairs[2][0].parent
    edited.data = edited.data.copy()
    select_only(edited)
    bpy.ops.object.mode_set(mode="EDIT")
    bone = edited.data.edit_bones[1]
    bone.tail = bone.tail + bone.z_axis * 0.3
    bpy.ops.object.mode_set(mode="OBJECT")
    check_frames(pairs)
    after = kept()
    assert after[2][1] is not first[0][1] and not np.array_equal(after[2][1], first[0][1])
    assert all(after[k][1] is first[0][1] for k in (0, 1, 3))
    assert dq_skin.SESSION.interned  # (what the session keeps: forgotten with it)


# -- files: append, link, override, without the add-on ------------------------------------------


def character_file(path: Path, method: str = "DUAL_QUATERNION", frame: int = 7, rig: str = "vertex groups") -> None:
    """A library file with one character in the collection "Character", DQ Skin on, saved at
    `frame`."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    obj, arm, _ = animated_tube(rig=rig)
    coll = bpy.data.collections.new("Character")
    bpy.context.scene.collection.children.link(coll)
    for o in (obj, arm):
        bpy.context.scene.collection.objects.unlink(o)
        coll.objects.link(o)
    obj.name, arm.name = "Body", "Skeleton"
    add_dq_skin(obj, method)
    bpy.context.scene.frame_set(frame)
    bpy.ops.wm.save_as_mainfile(filepath=str(path))


@pytest.mark.parametrize("rig", RIGS)
def test_appended_character(dq_skin, rig, tmp_path):
    lib = tmp_path / "char.blend"
    character_file(lib, rig=rig)
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    with bpy.data.libraries.load(str(lib), link=False) as (src, dst):
        dst.collections = ["Character"]
    bpy.context.scene.collection.children.link(dst.collections[0])
    body = bpy.data.objects["Body"]
    check_frames([(body, twin(body))])
    assert status(dq_skin, body).live


def override(lib: Path, name: str = "Character"):
    """Links the character collection and makes a library override of it (the standard way a
    character gets into a shot); returns the overridden mesh and armature."""
    with bpy.data.libraries.load(str(lib), link=True) as (src, dst):
        dst.collections = ["Character"]
    coll = dst.collections[0]
    inst = bpy.data.objects.new(name, None)
    inst.instance_type = "COLLECTION"
    inst.instance_collection = coll
    bpy.context.scene.collection.objects.link(inst)
    ov = coll.override_hierarchy_create(bpy.context.scene, bpy.context.view_layer, reference=inst, do_fully_editable=True)
    objs = list(ov.all_objects)
    body = next(o for o in objs if o.type == "MESH")
    skel = next(o for o in objs if o.type == "ARMATURE")
    return body, skel


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
def test_library_overrides_one_and_two_with_different_actions_saved_and_reopened(dq_skin, tmp_path, method, rig):
    lib = tmp_path / "char.blend"
    character_file(lib, method, rig=rig)
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    a_body, a_skel = override(lib, "A")
    b_body, b_skel = override(lib, "B")
    assert a_body.override_library is not None and a_body is not b_body
    # Give B its own action: the same keys, half the angles.
    action = b_skel.animation_data.action.copy()
    for fc in _fcurves(action):
        for kp in fc.keyframe_points:
            for point in (kp.co, kp.handle_left, kp.handle_right):
                point.y = point.y if "rotation_quaternion" in fc.data_path and fc.array_index == 0 else point.y * 0.5
    b_skel.animation_data.action = action
    b_body.location.x = 3.0
    pairs = [(a_body, plain_twin(a_body, "A twin")), (b_body, plain_twin(b_body, "B twin"))]
    check_frames(pairs)
    assert status(dq_skin, a_body).live and status(dq_skin, b_body).live
    if bpy.app.version < (5, 1, 0):  # (5.1+: the memory reader does not find positions)
        # The kernel reads the linked mesh's own positions (no copy of ours).
        for body in (a_body, b_body):
            source = dq_skin.SESSION.meshes.peek_any(body).source
            assert isinstance(source, dq_skin.dqskin.memory.MeshPositions), dq_skin.SESSION.readers.positions_error
    path = tmp_path / "shot.blend"
    names = [o.name for o, _ in pairs] + [r.name for _, r in pairs]
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))
    objs = [bpy.data.objects[n] for n in names]
    check_frames([(objs[0], objs[2]), (objs[1], objs[3])])
    assert status(dq_skin, objs[0]).live and status(dq_skin, objs[1]).live
    assert moved(objs[1]) > 0.1


def _layer_of(collection, layer=None):
    """The view layer's collection entry of `collection` (at any depth)."""
    layer = layer or bpy.context.view_layer.layer_collection
    for child in layer.children:
        if child.collection == collection:
            return child
        found = _layer_of(collection, child)
        if found is not None:
            return found
    return None


@pytest.mark.parametrize("how", ["collection", "excluded"])
def test_an_overridden_character_in_a_hidden_collection_costs_nothing_and_shows_when_shown(dq_skin, tmp_path, how):
    """A linked and overridden character whose collection is disabled in viewports or excluded
    from the view layer (a shot's characters switched off while another is worked on): not
    evaluated and not skinned while hidden; shown again by a script right before a frame change,
    it shows that frame and is fed; the same after saving and reopening the shot while hidden."""
    lib = tmp_path / "char.blend"
    character_file(lib, rig="B-Bones")
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    body, _skel = override(lib)
    assert body.override_library is not None
    ref = plain_twin(body)  # (in the scene's own collection: it stays shown)
    scene = bpy.context.scene

    def set_hidden(obj, hidden: bool) -> None:
        collection = obj.users_collection[0]
        if how == "collection":
            collection.hide_viewport = hidden
        else:
            _layer_of(collection).exclude = hidden

    def evaluated(obj) -> bool:
        return obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).is_evaluated

    check_frames([(body, ref)], (3, 4))
    assert fed_runs(dq_skin, body) > 0
    set_hidden(body, True)
    bpy.context.view_layer.update()
    scene.frame_set(5)
    runs = fed_runs(dq_skin, body)
    for f in (6, 7):
        scene.frame_set(f)
        assert not evaluated(body), f"frame {f}: the hidden character is evaluated"
    assert fed_runs(dq_skin, body) == runs, "the hidden character was skinned"
    set_hidden(body, False)
    scene.frame_set(8)
    assert_same(body, ref, "shown by a script at the frame change")
    scene.frame_set(9)
    assert_same(body, ref, "frame 9")
    # (Its own batch of the feed skins it from the frame change it shows at.)
    assert fed_runs(dq_skin, body) == runs + 2, "the shown character is not fed"
    # Saved while hidden, reopened: still not evaluated, and shown in the interface it shows
    # the frame it is on.
    set_hidden(body, True)
    bpy.context.view_layer.update()
    path = tmp_path / "shot.blend"
    names = body.name, ref.name
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))
    body, ref = (next(o for o in bpy.data.objects if o.name == n and o.library is None) for n in names)
    assert body.override_library is not None
    scene = bpy.context.scene
    scene.frame_set(10)
    assert not evaluated(body)
    set_hidden(body, False)
    bpy.context.view_layer.update()
    assert_same(body, ref, "shown after reopening")
    check_frames([(body, ref)], (11, 12))
    assert status(dq_skin, body).live
    assert_fed(dq_skin, body)


def _fcurves(action):
    """F-curves of an action (channel bags of slotted actions in Blender 4.4+)."""
    if hasattr(action, "layers") and action.layers:
        for layer in action.layers:
            for strip in layer.strips:
                for bag in strip.channelbags:
                    yield from bag.fcurves
    else:
        yield from action.fcurves


def test_plain_linked_instance_plays_the_library_animation(dq_skin, tmp_path):
    """Linked without override nothing can be changed: Blender's Armature modifier (the
    companion, saved active) deforms it, and the panel says so."""
    lib = tmp_path / "char.blend"
    character_file(lib)
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    with bpy.data.libraries.load(str(lib), link=True) as (src, dst):
        dst.collections = ["Character"]
    inst = bpy.data.objects.new("Instance", None)
    inst.instance_type = "COLLECTION"
    inst.instance_collection = dst.collections[0]
    bpy.context.scene.collection.objects.link(inst)
    body = (
        bpy.data.objects["Body", str(lib)]
        if ("Body", str(lib)) in bpy.data.objects
        else next(o for o in bpy.data.objects if o.name == "Body")
    )
    assert body.library is not None
    # Reference: the same mesh and armature through a local object with a plain Armature modifier.
    ref = bpy.data.objects.new("Reference", body.data)
    bpy.context.scene.collection.objects.link(ref)
    ref.parent = body.parent
    m = ref.modifiers.new("Armature", "ARMATURE")
    m.object = body.parent
    m.use_deform_preserve_volume = True
    worst = check_frames([(body, ref)])
    assert worst <= REL_TOL
    assert moved(body) > 0.1
    st = status(dq_skin, body)
    assert st.mode.value == "linked" and "Library Override" in st.message


WITHOUT_ADDON = """
import sys, json, bpy, numpy as np
bpy.ops.wm.open_mainfile(filepath=sys.argv[1])
assert not any(m.startswith("bl_ext.user_default.dq_skin") for m in sys.modules), "the add-on must not be loaded here"
scene = bpy.context.scene
out = {}
for frame in (3, 12, 19):
    scene.frame_set(frame)
    dg = bpy.context.evaluated_depsgraph_get()
    def pos(name):
        me = bpy.data.objects[name].evaluated_get(dg).to_mesh()
        a = np.empty(len(me.vertices) * 3, np.float32); me.vertices.foreach_get("co", a)
        return a.reshape(-1, 3)
    a, b = pos("Body"), pos("Twin")
    out[frame] = float(np.abs(a - b).max() / np.linalg.norm(b.max(0) - b.min(0)))
mod = bpy.data.objects["Body"].modifiers["DQ Skin"]
warnings = [w.message for w in getattr(mod, "node_warnings", [])]
print("RESULT", json.dumps({"dev": out, "warnings": warnings}))
"""


def farm_env(tmp_path: Path) -> dict:
    """The environment of a machine without DQ Skin: an empty Blender user folder."""
    import os

    env = dict(os.environ)
    empty = tmp_path / "farm_user"
    empty.mkdir(exist_ok=True)
    env["BLENDER_USER_RESOURCES"] = str(empty)
    return env


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
def test_file_opened_without_the_add_on_shows_blenders_deformation_every_frame(dq_skin, tmp_path, method, rig):
    """A render node without DQ Skin: every frame is Blender's own deformation (not the pose
    of the frame the file was saved on), and the modifier says DQ Skin is not running."""
    import json

    path = tmp_path / "shot.blend"
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    obj, arm, _ = animated_tube(rig=rig)
    obj.name = "Body"
    add_dq_skin(obj, method)
    if rig != "vertex groups":
        assert_fed(dq_skin, obj)
    tw = twin(obj, "Twin")
    bpy.context.scene.frame_set(7)
    check_frames([(obj, tw)], frames=(7,))
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    # The open session is untouched by saving.
    assert status(dq_skin, obj).live or bpy.context.scene.frame_set(8) is None
    bpy.context.scene.frame_set(8)
    assert status(dq_skin, obj).live
    script = tmp_path / "without.py"
    script.write_text(WITHOUT_ADDON)
    r = subprocess.run([sys.executable, str(script), str(path)], capture_output=True, text=True, timeout=300, env=farm_env(tmp_path))
    assert r.returncode == 0, r.stderr
    line = next(l for l in r.stdout.splitlines() if l.startswith("RESULT "))
    got = json.loads(line[7:])
    assert all(d <= REL_TOL for d in got["dev"].values()), got
    if bpy.app.version >= (4, 3, 0):
        assert any("not deforming" in w for w in got["warnings"]), got["warnings"]


def test_saved_file_has_no_results_and_active_companions(dq_skin, tmp_path):
    obj, arm, _ = animated_tube()
    add_dq_skin(obj)
    bpy.context.scene.frame_set(6)
    path = tmp_path / "a.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    with bpy.data.libraries.load(str(path), link=True) as (src, dst):
        names = list(src.objects) + list(src.meshes)
        dst.objects = [obj.name]
    # Neither result objects nor their meshes (a copy of the character) are written.
    assert not any(n.startswith(".DQ Skin result") for n in names), names
    saved = dst.objects[0]
    assert saved.library is not None
    c = saved.modifiers["Armature"]
    assert c.show_viewport and c.show_render and c.use_vertex_groups  # Blender's deformation
    assert get_input(dq_skin_mods(saved)[0], "Result") is None
    # Still live here after saving.
    bpy.context.scene.frame_set(9)
    assert status(dq_skin, obj).live and not obj.modifiers["Armature"].show_viewport


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
def test_undo_and_redo_stay_exact_and_leave_no_orphans(dq_skin, method, rig):
    obj, arm, _ = animated_tube(rig=rig)
    add_dq_skin(obj, method)
    if rig != "vertex groups":
        assert_fed(dq_skin, obj)
    ref = twin(obj, "twin", share_mesh=False)
    names = (obj.name, ref.name, arm.name)
    bpy.context.scene.frame_set(4)
    bpy.ops.ed.undo_push(message="frame 4")
    arm.location.x += 0.5
    arm.pose.bones[1].rotation_quaternion = Quaternion((0.0, 1.0, 0.0), 1.1)
    bpy.context.view_layer.update()
    bpy.ops.ed.undo_push(message="moved")
    for step in ("undo", "redo", "undo"):
        assert getattr(bpy.ops.ed, step)() == {"FINISHED"}
        obj, ref, arm = (bpy.data.objects[n] for n in names)  # undo re-reads data-blocks
        check_frames([(obj, ref)], frames=(4, 11, 17))
        outputs = [o.name for o in bpy.data.objects if o.get("dq_skin_result")] + [m.name for m in obj.modifiers if is_carrier(m)]
        assert len(outputs) == 1, outputs
        assert not [d.name for d in (*bpy.data.meshes, *bpy.data.objects) if d.users == 0]
        assert status(dq_skin, obj).live


# -- Apply, remove, several DQ Skins ------------------------------------------------------------


# How Apply is called: as the modifier panel and Ctrl+A do (Blender's window manager registers
# the operator, as `undo=True` makes the bpy module do) or by a script (not registered).
APPLIED_FROM = ["user interface", "script"]


def tube_and_reference(method: str, later: str, rig: str = "vertex groups"):
    """An animated tube with a `later` modifier after its Armature modifier, and a copy with a
    mesh of its own whose Armature modifier deforms as `method` does (the reference)."""
    obj, _arm, _ = animated_tube(rig=rig)
    obj.modifiers.new(later.replace("_", " ").title(), later)
    ref = obj.copy()
    ref.data = obj.data.copy()
    bpy.context.scene.collection.objects.link(ref)
    ref.modifiers["Armature"].use_deform_preserve_volume = method == "DUAL_QUATERNION"
    return obj, ref


def apply_modifier(obj, name: str, applied_from: str) -> None:
    with bpy.context.temp_override(object=obj, active_object=obj):
        if applied_from == "user interface":
            assert bpy.ops.object.modifier_apply("EXEC_DEFAULT", True, modifier=name) == {"FINISHED"}
            assert bpy.context.window_manager.operators[-1].bl_idname == "OBJECT_OT_modifier_apply"
        else:
            assert bpy.ops.object.modifier_apply(modifier=name) == {"FINISHED"}


@pytest.mark.parametrize("applied_from", APPLIED_FROM)
@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
def test_apply_gives_the_builtin_applied_mesh_and_leaves_nothing_behind(dq_skin, method, rig, applied_from):
    obj, ref = tube_and_reference(method, "SUBSURF", rig=rig)
    mod = add_dq_skin(obj, method)
    if rig != "vertex groups":
        assert_fed(dq_skin, obj)
    bpy.context.scene.frame_set(13)
    apply_modifier(obj, mod.name, applied_from)
    apply_modifier(ref, "Armature", "script")
    bpy.context.view_layer.update()
    a, b = (np.array([v.co for v in o.data.vertices], np.float32) for o in (obj, ref))
    assert deviation(a, b) <= REL_TOL
    assert [m.type for m in obj.modifiers] == [m.type for m in ref.modifiers] == ["SUBSURF"]
    assert not [x for x in obj.data.attributes if x.name.startswith("dq_skin")]
    assert not [o for o in bpy.data.objects if o.get("dq_skin_result")]
    assert not [k for k in obj.keys() if k.startswith("dq_skin")]


@pytest.mark.parametrize("applied_from", APPLIED_FROM)
@pytest.mark.parametrize("method", METHODS)
def test_apply_where_blender_deforms_keeps_what_was_shown(dq_skin, method, applied_from):
    """A DQ Skin handed over to its companion (Corrective Smooth after it magnifies the last
    bits) passes the mesh through, so Blender's Apply of it changes no position: the companion
    is applied in its place, and the mesh is Blender's applied Armature modifier's, the stack the
    same. (Once the companion was removed instead, or put back as before `dq_skin_add` where a
    script applied it: the character showed its rest pose, or its deformation changed.)"""
    obj, ref = tube_and_reference(method, "CORRECTIVE_SMOOTH")
    mod = add_dq_skin(obj, method)
    bpy.context.scene.frame_set(13)
    assert status(dq_skin, obj).mode.name == "HANDED_OVER"
    assert deviation(evaluated_positions(obj), evaluated_positions(ref)) <= REL_TOL
    apply_modifier(obj, mod.name, applied_from)
    apply_modifier(ref, "Armature", "script")
    bpy.context.view_layer.update()
    a, b = (np.array([v.co for v in o.data.vertices], np.float32) for o in (obj, ref))
    assert deviation(a, b) <= REL_TOL, "the mesh takes the deformation that was shown"
    assert stack(obj) == stack(ref) == ["CORRECTIVE_SMOOTH"]
    assert deviation(evaluated_positions(obj), evaluated_positions(ref)) <= REL_TOL
    assert moved(obj) == 0.0, "nothing deforms the applied mesh any more"
    assert not [x for x in obj.data.attributes if x.name.startswith(("dq_skin", ".dq_skin"))]
    assert not [k for k in obj.keys() if k.startswith("dq_skin")]


def two_armature_rig():
    """A tube deformed by two armatures: the lower half by one, the upper by the other, each
    Armature modifier with a mask group."""
    obj, arm, mod = rig_tube(bones=2)
    arm2 = armature_chain("Rig2", 2, 4.0)
    arm2.location.x = 0.0
    for a, seed in ((arm, 0.0), (arm2, 0.9)):
        animate(a, seed)
    upper = obj.vertex_groups.new(name="Upper")
    for v in obj.data.vertices:
        upper.add([v.index], min(1.0, max(0.0, (v.co.z - 1.5) / 1.0)), "REPLACE")
    mod.vertex_group = "Upper"
    mod.invert_vertex_group = True
    mod2 = obj.modifiers.new("Armature.001", "ARMATURE")
    mod2.object = arm2
    mod2.vertex_group = "Upper"
    return obj, arm, arm2


@pytest.mark.parametrize("method", METHODS)
def test_two_dq_skins_equal_two_armature_modifiers(dq_skin, method):
    obj, arm, arm2 = two_armature_rig()
    first = add_dq_skin(obj, method)
    second = add_dq_skin(obj, method)
    assert stack(obj) == ["NODES", "ARMATURE", "NODES", "ARMATURE"]
    assert get_input(second, "Armature") == arm2
    tw = twin(obj)
    check_frames([(obj, tw)])
    assert status(dq_skin, obj, first).live and status(dq_skin, obj, second).live
    assert status(dq_skin, obj, second).source.value == "chain"


def test_removing_one_of_two_restores_only_its_own_armature_modifier(dq_skin):
    obj, arm, arm2 = two_armature_rig()
    before = [(m.name, m.show_viewport, m.show_render, m.use_vertex_groups) for m in obj.modifiers]
    add_dq_skin(obj)
    second = add_dq_skin(obj)
    bpy.context.scene.frame_set(9)
    obj.modifiers.remove(second)  # the X button
    bpy.context.view_layer.update()
    mods = [(m.name, m.type) for m in obj.modifiers if not is_carrier(m)]
    assert mods == [("DQ Skin", "NODES"), ("Armature", "ARMATURE"), ("Armature.001", "ARMATURE")]
    a2 = obj.modifiers["Armature.001"]
    assert (a2.name, a2.show_viewport, a2.show_render, a2.use_vertex_groups) == before[1]
    assert not obj.modifiers["Armature"].show_viewport  # still the first DQ Skin's companion, parked
    ref = obj.copy()
    bpy.context.scene.collection.objects.link(ref)
    ref.modifiers.remove(ref.modifiers["DQ Skin"])
    for k in ("show_viewport", "show_render", "use_vertex_groups"):
        setattr(ref.modifiers["Armature"], k, True)
    ref.modifiers["Armature"].use_deform_preserve_volume = False
    check_frames([(obj, ref)])


# -- any modifier after DQ Skin ------------------------------------------------------------------


def later_modifier(obj, kind: str):
    if kind == "SUBSURF":
        m = obj.modifiers.new(kind, "SUBSURF")
        m.levels = 2
    elif kind == "SOLIDIFY":
        m = obj.modifiers.new(kind, "SOLIDIFY")
        m.thickness = 0.05
    elif kind == "MIRROR":
        m = obj.modifiers.new(kind, "MIRROR")
        m.use_axis = (False, True, False)
        m.use_mirror_merge = False
    elif kind == "DECIMATE":
        m = obj.modifiers.new(kind, "DECIMATE")
        m.decimate_type = "UNSUBDIV"
        m.iterations = 1
    elif kind == "WELD":
        m = obj.modifiers.new(kind, "WELD")
        m.merge_threshold = 1e-4
    elif kind == "EDGE_SPLIT":
        m = obj.modifiers.new(kind, "EDGE_SPLIT")
        m.use_edge_angle = False
        for e in list(obj.data.edges)[::7]:
            e.use_edge_sharp = True
    elif kind == "TRIANGULATE":
        m = obj.modifiers.new(kind, "TRIANGULATE")
        m.quad_method = "FIXED"
    elif kind == "NODES":
        group = bpy.data.node_groups.new("Subdivide and offset", "GeometryNodeTree")
        group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
        group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
        gi, go = group.nodes.new("NodeGroupInput"), group.nodes.new("NodeGroupOutput")
        sub = group.nodes.new("GeometryNodeSubdivideMesh")
        off = group.nodes.new("GeometryNodeSetPosition")
        off.inputs["Offset"].default_value = (0.0, 0.0, 0.1)
        group.links.new(gi.outputs[0], sub.inputs[0])
        group.links.new(sub.outputs[0], off.inputs["Geometry"])
        group.links.new(off.outputs[0], go.inputs[0])
        m = obj.modifiers.new(kind, "NODES")
        m.node_group = group
    elif kind == "CORRECTIVE_SMOOTH":
        m = obj.modifiers.new(kind, "CORRECTIVE_SMOOTH")
        m.iterations = 10
    elif kind == "SMOOTH":
        m = obj.modifiers.new(kind, "SMOOTH")
        m.iterations = 5
    elif kind == "DISPLACE":
        m = obj.modifiers.new(kind, "DISPLACE")
        m.strength = 0.2
        m.direction = "NORMAL"
    return m


LATER = [
    "SUBSURF",
    "SOLIDIFY",
    "MIRROR",
    "DECIMATE",
    "WELD",
    "EDGE_SPLIT",
    "TRIANGULATE",
    "NODES",
    "CORRECTIVE_SMOOTH",
    "SMOOTH",
    "DISPLACE",
]


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("kind", LATER)
def test_any_modifier_after_dq_skin(dq_skin, kind, method, rig):
    obj, arm, _ = animated_tube(rings=16, segments=12, rig=rig)
    later_modifier(obj, kind)
    add_dq_skin(obj, method)
    if rig != "vertex groups" and kind != "CORRECTIVE_SMOOTH":
        assert_fed(dq_skin, obj)
    names = stack(obj)
    assert names[0] == "NODES" and names[1] == "ARMATURE"
    tw = twin(obj)
    check_frames([(obj, tw)])
    st = status(dq_skin, obj)
    if kind == "CORRECTIVE_SMOOTH":
        # Corrective Smooth magnifies its input's last float bits: Linear and Dual Quaternion
        # hand over to the Armature modifier there (bit for bit Blender's), and say so.
        assert st.mode.value == "handed over" and "Corrective Smooth" in st.message, st.message
    else:
        assert st.live and st.message == "", st.message


def test_later_modifiers_run_once_per_frame(dq_skin, monkeypatch):
    """Blender evaluates each frame once: DQ Skin's positions are there in its first evaluation
    (the feed), so the modifiers after DQ Skin run once, on the real mesh, and the frame handler
    publishes nothing for Blender to evaluate again. Also with shape keys driven by a bone (the
    object changes in the first evaluation anyway)."""
    obj, arm, _ = animated_tube()
    later_modifier(obj, "SUBSURF")
    add_dq_skin(obj)
    other, arm2, _ = animated_tube(seed=0.5)
    other.location.x = 3
    basis = other.shape_key_add(name="Basis")
    key = other.shape_key_add(name="Corrective")
    for i, p in enumerate(key.data):
        p.co = basis.data[i].co * 1.2
    fc = key.driver_add("value")
    var = fc.driver.variables.new()
    var.type = "TRANSFORMS"
    var.targets[0].id = arm2
    var.targets[0].bone_target = "Bone1"
    var.targets[0].transform_type = "ROT_X"
    var.targets[0].rotation_mode = "SWING_TWIST_X"
    fc.driver.expression = "abs(var)"
    later_modifier(other, "SUBSURF")
    add_dq_skin(other)
    seen = []

    def after_dq_skin(scene, depsgraph):
        # Runs after DQ Skin's own handler: what the first evaluation produced for each object.
        for o in (obj, other):
            seen.append((o.name, len(o.evaluated_get(depsgraph).data.vertices)))

    routes = dq_skin.SESSION.routes
    published = []
    original = routes.publish
    bpy.app.handlers.frame_change_post.append(after_dq_skin)
    try:
        tw, tw2 = twin(obj, share_mesh=False), twin(other, share_mesh=False)
        for f in (2, 3):
            bpy.context.scene.frame_set(f)
        monkeypatch.setattr(routes, "publish", lambda *a, **k: published.append(1) or original(*a, **k))
        seen.clear()
        for f in (5, 8, 11, 15):
            bpy.context.scene.frame_set(f)
            assert_same(obj, tw)
            assert_same(other, tw2)
    finally:
        bpy.app.handlers.frame_change_post.remove(after_dq_skin)
    subdivided = len(tw.evaluated_get(bpy.context.evaluated_depsgraph_get()).data.vertices)
    assert subdivided > len(obj.data.vertices)
    assert all(n == subdivided for _, n in seen), seen
    assert not published, "the frame handler published a frame: Blender would evaluate it again"


# -- shape keys, render, viewport ------------------------------------------------------------------


@pytest.mark.parametrize("method", METHODS)
def test_driven_corrective_shape_keys(dq_skin, method):
    obj, arm, _ = animated_tube()
    basis = obj.shape_key_add(name="Basis")
    bulge = obj.shape_key_add(name="Bulge")
    for i, p in enumerate(bulge.data):
        co = basis.data[i].co
        p.co = (co.x * 1.3, co.y * 1.3, co.z)
    group = obj.vertex_groups.new(name="BulgeArea")
    group.add([v.index for v in obj.data.vertices if 1.5 < v.co.z < 2.5], 0.7, "REPLACE")
    bulge.vertex_group = "BulgeArea"
    side = obj.shape_key_add(name="Side")
    for i, p in enumerate(side.data):
        p.co = basis.data[i].co + basis.data[i].co.normalized() * 0.0
        p.co.x += 0.2
    side.relative_key = bulge
    side.value = 0.4
    fc = bulge.driver_add("value")
    var = fc.driver.variables.new()
    var.type = "TRANSFORMS"
    var.targets[0].id = arm
    var.targets[0].bone_target = "Bone1"
    var.targets[0].transform_type = "ROT_W"
    fc.driver.expression = "1 - var"
    add_dq_skin(obj, method)
    check_frames([(obj, twin(obj))])
    assert status(dq_skin, obj).source.value == "mesh"


def render_image(path: Path, frame: int, hide) -> np.ndarray:
    """An animation render (Cycles, CPU, small) of the single frame `frame`, started from
    another frame, with `hide` hidden; the tube rigs fill the picture."""
    scene = bpy.context.scene
    if scene.camera is None:
        cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
        cam.data.type = "ORTHO"
        cam.data.ortho_scale = 9.0
        cam.location = (0.0, -12.0, 1.5)
        cam.rotation_euler = (math.pi / 2, 0.0, 0.0)
        scene.collection.objects.link(cam)
        scene.camera = cam
        sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
        sun.data.energy = 4.0
        sun.rotation_euler = (0.6, 0.2, 0.4)
        scene.collection.objects.link(sun)
        scene.render.engine = "CYCLES"
        scene.cycles.device = "CPU"
        scene.cycles.samples = 2
        scene.cycles.seed = 7
        scene.render.resolution_x = scene.render.resolution_y = 80
        scene.render.resolution_percentage = 100
        scene.render.image_settings.file_format = "PNG"
    hidden = [(o, o.hide_render) for o in hide]
    for o in hide:
        o.hide_render = True
    try:
        scene.frame_set(1)
        scene.frame_start = scene.frame_end = frame
        scene.render.filepath = str(path) + "_####"
        bpy.ops.render.render(animation=True)
    finally:
        for o, h in hidden:
            o.hide_render = h
    image = bpy.data.images.load(f"{path}_{frame:04d}.png")
    try:
        return np.array(image.pixels[:], np.float32).reshape(-1, 4)
    finally:
        bpy.data.images.remove(image)


def test_viewport_off_render_on(dq_skin, tmp_path):
    """Off in the viewport, on in renders: the panel says so and the render is DQ Skin's."""
    obj, arm, _ = animated_tube()
    mod = add_dq_skin(obj, "DUAL_QUATERNION")
    mod.show_viewport = False
    bpy.context.scene.frame_set(3)
    st = status(dq_skin, obj)
    assert st.mode.value == "off" and "Off in the viewport" in st.message and "Waiting" not in st.message
    tw = twin(obj)
    tw.location.x = 0.0
    # Render ours alone, then the twin alone, at the same frame: the same picture.
    ours = render_image(tmp_path / "ours", frame=12, hide=[tw])
    theirs = render_image(tmp_path / "theirs", frame=12, hide=[obj])
    other = render_image(tmp_path / "other", frame=3, hide=[obj])
    assert same_picture(ours, theirs) and not same_picture(theirs, other)


def test_panel_status_says_what_is_wrong_and_where(dq_skin):
    obj, arm, _ = animated_tube()
    mod = add_dq_skin(obj)
    bpy.context.scene.frame_set(3)
    lines = draw_panel(dq_skin, obj)
    assert any("bones" in l and "influences" in l for l in lines), lines
    # Deforming modifier before DQ Skin and a topology change after it: DQ Skin cannot see what
    # reaches it; the panel names the modifier and Blender's Armature modifier takes over.
    smooth = obj.modifiers.new("Smooth Before", "SMOOTH")
    with bpy.context.temp_override(object=obj, active_object=obj):
        bpy.ops.object.modifier_move_to_index(modifier=smooth.name, index=0)
    sub = later_modifier(obj, "SUBSURF")
    bpy.context.scene.frame_set(4)
    bpy.context.scene.frame_set(5)
    lines = draw_panel(dq_skin, obj)
    st = status(dq_skin, obj, mod)
    assert st.mode.value == "fallback" and sub.name in st.message, st.message
    assert any("Armature" in l and "instead" in l for l in lines), lines
    tw = twin(obj)
    # The twin has Blender's own Armature modifier; ours falls back to exactly that.
    assert_same(obj, tw)
    # Without the later subdivision it reads the coordinates and skins again.
    sub_name = sub.name
    obj.modifiers.remove(sub)
    tw.modifiers.remove(tw.modifiers[sub_name])
    bpy.context.scene.frame_set(6)
    bpy.context.scene.frame_set(7)
    assert status(dq_skin, obj, mod).live and status(dq_skin, obj, mod).source.value == "capture"
    assert_same(obj, tw)


# -- what already worked and must keep working ----------------------------------------------------


def test_two_scenes_renames_nla_and_method_changes(dq_skin):
    obj, arm, _ = animated_tube()
    mod = add_dq_skin(obj, "LINEAR")
    tw = twin(obj)
    check_frames([(obj, tw)], frames=(3, 8))
    # Renames of the object, the modifier and the armature.
    obj.name, mod.name, arm.name = "Renamed", "Skin It", "Skeleton"
    check_frames([(obj, tw)], frames=(9, 4))
    # Method change.
    dq_skin.blender.nodes.put_method(mod, "Dual Quaternion")
    tw.modifiers["Armature"].use_deform_preserve_volume = True
    check_frames([(obj, tw)], frames=(10, 12))
    # NLA: the action in a strip, played from the NLA.
    action = arm.animation_data.action
    track = arm.animation_data.nla_tracks.new()
    track.strips.new("Strip", 1, action)
    arm.animation_data.action = None
    check_frames([(obj, tw)], frames=(5, 15))
    # A second scene linking the same objects, at another frame.
    scene2 = bpy.data.scenes.new("Other")
    scene2.collection.objects.link(obj)
    scene2.collection.objects.link(arm)
    scene2.collection.objects.link(tw)
    window_scene = bpy.context.window.scene if bpy.context.window else None
    scene2.frame_set(17)
    dg2 = scene2.view_layers[0].depsgraph
    dev = deviation(evaluated_positions(obj, dg2), evaluated_positions(tw, dg2))
    assert dev <= REL_TOL, dev
    del window_scene


@pytest.mark.parametrize("fmt", ["ALEMBIC", "USD"])
def test_export_writes_the_skinned_animation(dq_skin, tmp_path, fmt):
    """Exporters step through frames themselves: the file holds DQ Skin's animation, equal to
    what Blender's Armature modifier gives (recorded from the twin before exporting)."""
    obj, arm, _ = animated_tube()
    obj.name = "Body"
    add_dq_skin(obj, "DUAL_QUATERNION")
    tw = twin(obj, "Twin")
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, 12
    frames = (2, 6, 11)
    expected = {}
    for f in frames:
        scene.frame_set(f)
        expected[f] = _world(tw)
    tw.hide_render = tw.hide_viewport = True
    bpy.data.objects.remove(tw)
    path = tmp_path / ("out.abc" if fmt == "ALEMBIC" else "out.usdc")
    if fmt == "ALEMBIC":
        assert bpy.ops.wm.alembic_export(filepath=str(path), start=1, end=12) == {"FINISHED"}
    else:
        assert bpy.ops.wm.usd_export(filepath=str(path), export_animation=True) == {"FINISHED"}
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    if fmt == "ALEMBIC":
        bpy.ops.wm.alembic_import(filepath=str(path))
    else:
        bpy.ops.wm.usd_import(filepath=str(path))
    # The skinned mesh comes back as a mesh played by a cache modifier.
    body = next(o for o in bpy.data.objects if o.type == "MESH" and any(m.type == "MESH_SEQUENCE_CACHE" for m in o.modifiers))
    scene = bpy.context.scene
    for f in frames:
        scene.frame_set(f)
        dev = deviation(_world(body), expected[f])
        assert dev <= REL_TOL, (f, dev)
    assert np.abs(expected[2] - expected[11]).max() > 0.1  # animated, not frozen


def _world(obj) -> np.ndarray:
    p = evaluated_positions(obj)
    m = np.array(obj.matrix_world, np.float32)
    return (p @ m[:3, :3].T + m[:3, 3]).astype(np.float32)


@pytest.mark.parametrize("in_viewports", [True, False], ids=["shown", "disabled in viewports"])
def test_motion_blur_render_matches_the_armature_modifier(dq_skin, tmp_path, in_viewports):
    """Motion blur evaluates the render's graph at sub-frames; a character disabled in viewports
    (kept out of the viewport's graph, as heavy characters on a farm often are) is skinned
    there too."""
    obj, arm, _ = animated_tube()
    add_dq_skin(obj, "DUAL_QUATERNION")
    tw = twin(obj)
    obj.hide_viewport = tw.hide_viewport = not in_viewports
    bpy.context.view_layer.update()
    scene = bpy.context.scene
    scene.render.use_motion_blur = True
    ours = render_image(tmp_path / "ours", frame=9, hide=[tw])
    theirs = render_image(tmp_path / "theirs", frame=9, hide=[obj])
    scene.render.use_motion_blur = False
    sharp = render_image(tmp_path / "sharp", frame=9, hide=[obj])
    assert same_picture(ours, theirs), "motion-blurred DQ Skin differs from the Armature modifier"
    assert not same_picture(theirs, sharp), "motion blur should show"


def same_picture(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal up to rounding: at most 0.1 % of pixels differ by more than 2.5/255."""
    return float((np.abs(a - b).max(axis=-1) > 2.5 / 255).mean()) < 1e-3


# -- weights: read fast, follow painting ---------------------------------------------------------


@pytest.mark.parametrize("asset", ["RiggedSimple.glb", "RiggedFigure.glb", "CesiumMan.glb", "Fox.glb"])
def test_weights_read_from_memory_equal_the_python_api(dq_skin, assets, asset):
    """The vertex-group reader (Blender's memory, through its SDNA) gives exactly what
    `MeshVertex.groups` gives, in stored order."""
    obj, _ = import_character(assets / asset)
    readers = dq_skin.SESSION.readers
    assert readers.mesh is not None, readers.mesh_error
    fast = dq_skin.blender.meshdata.read_groups(obj.data, readers.mesh)
    slow = dq_skin.blender.meshdata.read_groups(obj.data, None)
    assert fast is not None and slow is not None
    np.testing.assert_array_equal(fast.offsets, slow.offsets)
    np.testing.assert_array_equal(fast.groups, slow.groups)
    np.testing.assert_array_equal(fast.weights, slow.weights)
    assert len(fast.groups) > len(obj.data.vertices)  # several groups per vertex somewhere


def test_weight_changes_show_on_the_next_evaluation(dq_skin):
    """Painting weights (here `VertexGroup.add`/`remove`, what a brush stroke does to the data)
    shows up skinned at once, as with the Armature modifier."""
    obj, arm, _ = animated_tube()
    add_dq_skin(obj, "DUAL_QUATERNION")
    tw = twin(obj)
    bpy.context.scene.frame_set(12)
    assert_same(obj, tw)
    before = evaluated_positions(obj)
    rng = np.random.default_rng(2)
    for step in range(4):
        idx = rng.choice(len(obj.data.vertices), 40, replace=False).tolist()
        group = obj.vertex_groups[step % 2]
        group.add(idx, 0.9 - 0.2 * step, "REPLACE")
        if step == 3:
            obj.vertex_groups[0].remove(idx[:10])
        bpy.context.view_layer.update()
        assert_same(obj, tw, f"after weight change {step}")
    assert np.abs(evaluated_positions(obj) - before).max() > 1e-3  # the weights really changed the result
    # A new group for a bone that had none, and a mask group added on the DQ Skin modifier.
    bone = arm.data.bones[0].name
    obj.vertex_groups[bone].add([0, 1, 2], 1.0, "ADD")
    bpy.context.view_layer.update()
    assert_same(obj, tw)


def test_add_to_all_selected_objects_at_once(dq_skin, monkeypatch):
    objs = []
    for i in range(4):
        obj, arm, _ = animated_tube(seed=0.1 * i)
        arm.location.x = 2.0 * i
        objs.append(obj)
    plain = tube("Plain", 4, 6, 1.0, 0.2)  # no Armature modifier: skipped, said so
    select_only(objs[0], *objs[1:], plain)
    scans = []
    scan = dq_skin.SESSION.scan
    build = scan.build

    def counted(version):
        scans.append(version)
        return build(version)

    monkeypatch.setattr(scan, "build", counted)
    with bpy.context.temp_override(active_object=objs[0], selected_objects=[*objs, plain]):
        assert bpy.ops.object.dq_skin_add(all_selected=True, method="DUAL_QUATERNION") == {"FINISHED"}
    # What simulates on what is scanned once for the operator (not once per object: with 200
    # characters that was 1.2 s), and again at most for the update Blender runs after it.
    assert len(scans) <= 2, scans
    assert all(len(dq_skin_mods(o)) == 1 for o in objs) and not dq_skin_mods(plain)
    assert all(status(dq_skin, o).live for o in objs)  # skinned right away
    check_frames([(o, twin(o)) for o in objs], frames=(4, 15))


def test_switching_the_companion_on_shows_blenders_deformation_once_and_back(dq_skin):
    obj, arm, _ = animated_tube()
    mod = add_dq_skin(obj, "LINEAR")
    tw = twin(obj)
    bpy.context.scene.frame_set(8)
    c = obj.modifiers["Armature"]
    assert not c.show_viewport and not c.use_vertex_groups  # parked while DQ Skin deforms
    # The user switches the Armature modifier on to compare: DQ Skin steps aside in the
    # viewport, Blender's deformation shows (once, with DQ Skin's settings), renders unchanged.
    c.show_viewport = True
    bpy.context.view_layer.update()
    bpy.context.scene.frame_set(9)
    assert c.show_viewport and c.use_vertex_groups and not mod.show_viewport and mod.show_render
    assert status(dq_skin, obj, mod).mode.value == "off"
    assert_same(obj, tw)
    # Switching DQ Skin back on parks the Armature modifier again.
    mod.show_viewport = True
    bpy.context.view_layer.update()
    bpy.context.scene.frame_set(10)
    assert not c.show_viewport and not c.use_vertex_groups
    assert status(dq_skin, obj, mod).live
    assert_same(obj, tw)


def test_disabling_the_add_on_leaves_blenders_deformation(dq_skin):
    import addon_utils

    obj, arm, _ = animated_tube()
    add_dq_skin(obj, "DUAL_QUATERNION")
    tw = twin(obj)
    bpy.context.scene.frame_set(6)
    addon_utils.disable("bl_ext.user_default.dq_skin", default_set=False)
    try:
        assert obj.modifiers["Armature"].show_viewport
        assert get_input(dq_skin_mods(obj)[0], "Result") is None
        check_frames([(obj, tw)], frames=(7, 14))
    finally:
        addon_utils.enable("bl_ext.user_default.dq_skin", default_set=False)
    bpy.context.scene.frame_set(3)
    assert status(dq_skin, obj).live and not obj.modifiers["Armature"].show_viewport
    assert_same(obj, tw)

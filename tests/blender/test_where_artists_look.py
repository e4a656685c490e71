"""Where artists look for DQ Skin: the Add Modifier menu, the A/B switch against Blender's own
deformation, painting the blend, and a description on everything they can click."""

from __future__ import annotations

import numpy as np
import pytest
from dqtest import (
    METHODS,
    _Recorder,
    add_dq_skin,
    animated_tube,
    assert_same,
    draw_panel,
    evaluated_positions,
    is_carrier,
    stack,
    status,
    twin,
)
from scenes import rig_tube, tube

import bpy


def drawn(menu_idname: str, obj) -> list[str]:
    """What a menu's draw functions (Blender's and those appended by add-ons) put in it."""
    lines = []
    menu = getattr(bpy.types, menu_idname)
    fake = type("M", (), {"layout": _Recorder(lines)})()
    context = type("C", (), {"object": obj, "active_object": obj})()
    for fn in getattr(menu.draw, "_draw_funcs", [menu.draw]):
        try:
            fn(fake, context)
        except (AttributeError, TypeError):
            pass  # Blender's own entries use layout calls the recorder does not have
    return lines


def test_the_add_modifier_deform_menu_has_dq_skin(dq_skin):
    obj, arm, _ = rig_tube()
    assert "[object.dq_skin_add]" in drawn("OBJECT_MT_modifier_add_deform", obj)
    empty = bpy.data.objects.new("Empty", None)
    assert "[object.dq_skin_add]" not in drawn("OBJECT_MT_modifier_add_deform", empty)


def test_the_menu_operator_gives_the_stack_dq_skin_add_gives(dq_skin):
    a, arm_a, _ = rig_tube()
    b, arm_b, _ = rig_tube()
    add_dq_skin(a)
    bpy.context.view_layer.objects.active = b
    with bpy.context.temp_override(object=b, active_object=b):
        assert bpy.ops.object.dq_skin_add("EXEC_DEFAULT") == {"FINISHED"}  # what the menu entry runs
    assert (
        [(m.type, m.name) for m in a.modifiers if not is_carrier(m)]
        == [(m.type, m.name) for m in b.modifiers if not is_carrier(m)]
        == [("NODES", "DQ Skin"), ("ARMATURE", "Armature")]
    )


@pytest.mark.parametrize("parent_type", ["OBJECT", "ARMATURE"])
def test_a_mesh_parented_to_an_armature_without_armature_modifier(dq_skin, parent_type):
    obj, arm, arm_mod = animated_tube()
    obj.modifiers.remove(arm_mod)
    obj.parent_type = parent_type  # ARMATURE: Blender's legacy parenting, which deforms by itself
    reference = obj.copy()
    reference.data = obj.data.copy()
    bpy.context.scene.collection.objects.link(reference)
    if parent_type == "OBJECT":
        reference.modifiers.new("Armature", "ARMATURE").object = arm
    add_dq_skin(obj, "LINEAR")
    assert stack(obj) == ["NODES", "ARMATURE"]
    assert obj.parent_type == "OBJECT"
    for f in (4, 12):
        bpy.context.scene.frame_set(f)
        assert_same(obj, reference, f"frame {f}")
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.object.dq_skin_remove() == {"FINISHED"}
    assert [m.type for m in obj.modifiers] == [] and obj.parent_type == parent_type  # as it was


def test_no_armature_to_use_is_reported(dq_skin):
    obj = tube("Lonely", 4, 6, 1.0, 0.2)
    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(object=obj, active_object=obj):
        with pytest.raises(RuntimeError, match="not parented to an armature"):
            bpy.ops.object.dq_skin_add()
    assert not obj.modifiers


@pytest.mark.parametrize("method", [*METHODS, "BLEND"])
def test_the_ab_switch_shows_exactly_blenders_deformation_and_back(dq_skin, method):
    obj, arm, _ = animated_tube()
    mod = add_dq_skin(obj, method)
    if method == "BLEND":
        dq_skin.blender.nodes.put(mod, "Blend Factor", 0.5)
    reference = twin(obj, share_mesh=False)  # Blender's Armature modifier with DQ Skin's settings
    bpy.context.scene.frame_set(12)
    ours = evaluated_positions(obj)
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.object.dq_skin_show_blender() == {"FINISHED"}
    assert not mod.show_viewport and mod.show_render  # renders keep DQ Skin
    assert_same(obj, reference, "Blender's deformation")
    st = status(dq_skin, obj)
    assert st.compared.startswith("Largest difference") and "vertex" in st.compared
    assert any(line.startswith("Largest difference") for line in draw_panel(dq_skin, obj))
    bpy.context.scene.frame_set(13)
    assert_same(obj, reference, "Blender's deformation, next frame")
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.object.dq_skin_show_blender() == {"FINISHED"}
    assert mod.show_viewport and status(dq_skin, obj).live
    bpy.context.scene.frame_set(12)
    np.testing.assert_array_equal(evaluated_positions(obj), ours)
    if method == "BLEND":
        # Blend differs from Preserve Volume: the switch shows it.
        assert float(st.compared.split()[2]) > 1e-4


def test_painting_the_blend_creates_selects_and_enters_weight_paint(dq_skin):
    obj, arm, _ = animated_tube()
    mod = add_dq_skin(obj, "BLEND")
    dq_skin.blender.nodes.put(mod, "Blend Factor", 0.3)
    bpy.context.scene.frame_set(9)
    before = evaluated_positions(obj)
    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.object.dq_skin_paint_blend() == {"FINISHED"}
    try:
        assert obj.mode == "WEIGHT_PAINT"
        group = obj.vertex_groups.active
        assert group.name == "DQ Skin Blend" and dq_skin.blender.nodes.get_attribute(mod, "Blend Amount") == group.name
        weights = dq_skin.SESSION.meshes.get(obj, dq_skin.SESSION.readers.mesh).group_weights(group.name)
        assert np.allclose(weights, 0.3)  # filled with the factor, which is now 1
        assert dq_skin.blender.nodes.get(mod, "Blend Factor") == 1.0
        assert any("vertex group 'DQ Skin Blend'" in line and "0.30 to 0.30" in line for line in draw_panel(dq_skin, obj))
    finally:
        bpy.ops.object.mode_set(mode="OBJECT")
    bpy.context.scene.frame_set(9)
    np.testing.assert_allclose(evaluated_positions(obj), before, atol=1e-6)  # the look did not change
    # A second time it selects the same group.
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.object.dq_skin_paint_blend() == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    assert [g.name for g in obj.vertex_groups].count("DQ Skin Blend") == 1


def test_painting_the_blend_needs_the_blend_method(dq_skin):
    obj, arm, _ = animated_tube()
    add_dq_skin(obj, "LINEAR")
    with bpy.context.temp_override(object=obj, active_object=obj):
        with pytest.raises(RuntimeError, match="choose the Blend method"):
            bpy.ops.object.dq_skin_paint_blend()


def test_everything_an_artist_can_click_says_what_it_does(dq_skin):
    for cls in dq_skin.CLASSES:
        doc = (getattr(cls, "bl_description", "") or cls.__doc__ or "").strip()
        assert len(doc) > 20, f"{cls.__name__} has no description"
        rna = getattr(cls, "bl_rna", None)
        for prop in rna.properties if rna is not None else []:
            if prop.identifier not in ("rna_type",) and prop.identifier in getattr(cls, "__annotations__", {}):
                # Hidden ones too: the preferences, the file browser and scripts show them.
                assert prop.name.strip() and prop.name != prop.identifier, f"{cls.__name__}.{prop.identifier} has no name"
                assert len(prop.description) > 10, f"{cls.__name__}.{prop.identifier} has no description"
    group = dq_skin.blender.node_group.ensure_group()
    for item in group.interface.items_tree:
        if getattr(item, "item_type", "") == "SOCKET" and item.in_out == "INPUT" and item.name != "Geometry":
            assert len(item.description) > 15, f"the DQ Skin input {item.name!r} has no description"
    # Blender's own names where the meaning is the same.
    descriptions = " ".join(i.description for i in group.interface.items_tree if getattr(i, "item_type", "") == "SOCKET")
    for blender_name in ("Preserve Volume", "Vertex Groups", "Bone Envelopes"):
        assert blender_name in descriptions


class _MenuRecorder(_Recorder):
    """A layout that also records submenus (`{VIEW3D_MT_...}`)."""

    def menu(self, idname, **_):
        self.lines.append(f"{{{idname}}}")

    def operator_context(self, *_):
        pass


def operators_in_menus(dq_skin, obj) -> set[str]:
    """Every operator DQ Skin puts in Blender's menus (its draw functions and its own submenus)."""
    lines = []
    fake = type("M", (), {"layout": _MenuRecorder(lines)})()
    context = type("C", (), {"object": obj, "active_object": obj, "mode": "OBJECT"})()
    own_menus = {cls.bl_idname: cls for cls in dq_skin.CLASSES if issubclass(cls, bpy.types.Menu)}
    for name, fn in dq_skin.panel.MENUS:
        menu = getattr(bpy.types, name)
        assert fn in menu.draw._draw_funcs, f"nothing of DQ Skin's in {name}"
        fn(fake, context)
    drawn_menus = set()
    while True:
        todo = {line[1:-1] for line in lines if line.startswith("{")} - drawn_menus
        if not todo:
            break
        for idname in todo:
            drawn_menus.add(idname)
            if idname in own_menus:
                own_menus[idname].draw(fake, context)
    assert set(own_menus) <= drawn_menus, f"DQ Skin menus in no menu: {set(own_menus) - drawn_menus}"
    return {line[1:-1] for line in lines if line.startswith("[")}


def test_every_operator_is_in_a_menu_so_the_search_finds_it(dq_skin):
    """F3 finds what is in a menu: every registered DQ Skin operator is in one (Object > DQ
    Skin, Object > Parent, Add Modifier > Deform, Object and Pose > Animation > DQ Skin)."""
    obj, arm, _ = rig_tube()
    found = operators_in_menus(dq_skin, obj)
    operators = {cls.bl_idname for cls in registered_operators(dq_skin)}
    assert len(operators) >= 16
    assert not operators - found, f"in no menu: {sorted(operators - found)}"


def registered_operators(dq_skin) -> list:
    """Every operator class of the add-on's modules that Blender has registered."""
    found, todo = [], list(bpy.types.Operator.__subclasses__())
    while todo:
        cls = todo.pop()
        todo.extend(cls.__subclasses__())
        if cls.__module__.startswith(dq_skin.__name__) and getattr(cls, "is_registered", False) and getattr(cls, "bl_idname", ""):
            found.append(cls)
    return found


def poll(op, obj, selected=None) -> bool:
    selected = [obj] if selected is None else selected
    with bpy.context.temp_override(object=obj, active_object=obj, selected_objects=selected, selected_editable_objects=selected):
        return op.poll()


def test_tools_are_greyed_out_where_they_cannot_run(dq_skin):
    """The menu entries' polls: the DQ Skin tools need DQ Skin on the active mesh, Cancel
    Optimized Centers a computation, the animation tools keyed rotation (or two transforms to
    blend). Greyed out, a script's call says why."""
    from mathutils import Quaternion

    ops = bpy.ops.object
    obj, arm, _ = rig_tube()
    needs_dq_skin = (
        ops.dq_skin_show_blender,
        ops.dq_skin_paint_blend,
        ops.dq_skin_apply_as_shape_key,
        ops.dq_skin_bake,
        ops.dq_skin_remove,
    )
    assert poll(ops.dq_skin_add, obj)
    assert not any(poll(op, obj) for op in needs_dq_skin)
    with bpy.context.temp_override(object=obj, active_object=obj):
        with pytest.raises(RuntimeError, match="Tube has no DQ Skin modifier"):
            ops.dq_skin_remove()
    add_dq_skin(obj)
    assert all(poll(op, obj) for op in needs_dq_skin)
    assert not poll(ops.dq_skin_cancel_centers, obj)  # nothing computing

    anim = bpy.ops.anim
    rotation_tools = (anim.dq_quaternion_cleanup, anim.dq_rotation_bake, anim.dq_spring_smoothing, anim.dq_rotation_speed_plot)
    still = bpy.data.objects.new("Still", None)
    bpy.context.scene.collection.objects.link(still)
    assert not any(poll(op, still) for op in (*rotation_tools, anim.dq_screw_inbetweens, anim.dq_blend_transforms))
    with bpy.context.temp_override(object=still, active_object=still, selected_objects=[still]):
        with pytest.raises(RuntimeError, match="Nothing selected has keyed rotation"):
            anim.dq_rotation_bake()
    keyed = bpy.data.objects.new("Keyed", None)
    bpy.context.scene.collection.objects.link(keyed)
    keyed.rotation_mode = "QUATERNION"
    for frame, angle in ((1, 0.0), (10, 1.0)):
        keyed.rotation_quaternion = Quaternion((0.0, 0.0, 1.0), angle)
        keyed.keyframe_insert("rotation_quaternion", frame=frame)
    assert all(poll(op, keyed) for op in (*rotation_tools, anim.dq_screw_inbetweens))
    assert not poll(anim.dq_blend_transforms, keyed)  # one transform: nothing to blend
    assert poll(anim.dq_blend_transforms, keyed, [keyed, still])


def test_preferences_set_the_threads_and_the_centers_cache(dq_skin, tmp_path, monkeypatch):
    """Edit > Preferences > Add-ons > DQ Skin: the core's threads (0: all) and the disk space of
    the Optimized Centers cache, both acting as soon as they change."""
    import os

    from conftest import EXTENSION

    core = dq_skin.dqskin
    prefs = bpy.context.preferences.addons[EXTENSION].preferences
    assert (prefs.threads, prefs.centers_cache_mb) == (0, 1024)
    assert dq_skin.SESSION.centers.disk_bytes == 1 << 30
    before = core.get_num_threads()
    monkeypatch.setattr(dq_skin.engine.centers, "_folder", lambda: tmp_path)  # not the real cache
    for i in range(3):  # 600 kB each, the newest last
        path = tmp_path / f"{i}.npy"
        np.save(path, np.zeros((50_000, 3), np.float32))
        os.utime(path, (1000 + i, 1000 + i))
    try:
        for n in (1, 3):
            prefs.threads = n
            assert core.get_num_threads() == n
        prefs.threads = 0
        assert core.get_num_threads() == dq_skin.ui.preferences.all_threads()
        prefs.centers_cache_mb = 2
        assert dq_skin.SESSION.centers.disk_bytes == 2 << 20
        assert sorted(p.name for p in tmp_path.iterdir()) == ["0.npy", "1.npy", "2.npy"]  # 1.8 MB: kept
        prefs.centers_cache_mb = 1
        assert dq_skin.SESSION.centers.disk_bytes == 1 << 20
        assert sorted(p.name for p in tmp_path.iterdir()) == ["2.npy"]  # trimmed to 1 MB, oldest first
    finally:
        prefs.threads, prefs.centers_cache_mb = 0, 1024
        core.set_num_threads(before)
    assert dq_skin.SESSION.centers.disk_bytes == 1 << 30


def test_the_manifest_and_internal_errors_say_where_to_report(dq_skin):
    """The extension's page (Get Extensions shows it) and what it may touch on disk; the panel's
    internal error names where to report it, with a button to open the page."""
    import tomllib
    from pathlib import Path

    manifest = tomllib.loads((Path(dq_skin.__file__).parent / "blender_manifest.toml").read_text())
    assert manifest["website"] == "https://github.com/dqskin/dqskin"
    files = manifest["permissions"]["files"]
    assert "point caches" in files and "Optimized Centers" in files
    issues = dq_skin.model.runtime.ISSUES_URL
    assert issues == manifest["website"] + "/issues"
    obj, arm, _ = rig_tube()
    add_dq_skin(obj)
    errors = dq_skin.SESSION.errors
    errors.last = "ValueError: for the test"
    try:
        lines = draw_panel(dq_skin, obj)
    finally:
        errors.last = ""
    assert f"Internal error (please report it at {issues}): ValueError: for the test" in lines
    assert "[wm.url_open]" in lines

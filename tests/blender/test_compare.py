"""Comparison scenes: built-in rigs and a character side by side, the report and a render."""

from __future__ import annotations

import numpy as np
import pytest
from dqtest import import_character

import bpy


def test_builtin_rigs_comparison_report_and_render(dq_skin, tmp_path):
    compare = dq_skin.compare
    with bpy.context.temp_override(active_object=None, selected_objects=[]):
        assert bpy.ops.object.dq_skin_comparison_scene() == {"FINISHED"}
    collection = bpy.data.collections["DQ Skin Comparison"]
    labels = [o for o in collection.objects if o.type == "FONT"]
    assert len(labels) == 3 * len(compare.VARIANTS)
    rows = []
    for rig in ("Candy Wrapper Twist", "Elbow Bend", "Shoulder Raise"):
        meshes = sorted(
            (o for o in collection.objects if o.type == "MESH" and o.name.startswith(rig)), key=lambda o: o.matrix_world.translation.x
        )
        rows.append(dict(zip((v[0] for v in compare.VARIANTS), meshes)))
    result = compare.report(bpy.context, bpy.context.scene, rows, list(range(*compare.FRAMES, 8)) + [compare.FRAMES[1]])
    twist = result[0]["methods"]
    # Exact where Blender is exact, different where the methods differ: the candy wrapper.
    assert twist["DQ Skin Linear"]["max_deviation_from_armature_linear"] < 1e-5
    assert twist["DQ Skin Dual Quaternion"]["max_deviation_from_armature_preserve_volume"] < 1e-5
    assert twist["Armature Linear"]["volume_relative_to_rest"] < 0.9  # the candy wrapper loses volume
    assert twist["DQ Skin Dual Quaternion"]["volume_relative_to_rest"] > 0.97
    lbs, dqs, blend = (twist[n]["volume_relative_to_rest"] for n in ("DQ Skin Linear", "DQ Skin Dual Quaternion", "DQ Skin Blend"))
    assert lbs < blend < dqs
    path = tmp_path / "comparison.png"
    compare.render(bpy.context.scene, path, width=320, height=180, samples=2)
    image = bpy.data.images.load(str(path))
    assert tuple(image.size) == (320, 180)
    assert np.array(image.pixels[:]).reshape(180, 320, 4)[..., :3].max() > 0.2  # something lit

    # The deviation view: at the last frame, each variant coloured by its distance from Armature
    # Linear on one scale, whose top is the largest distance in the report's terms.
    bpy.context.scene.frame_set(compare.FRAMES[1])
    # (The add-on's runtime objects, in no scene and never saved, are not the user's scene.)
    before = {o.name: o.hide_render for o in bpy.data.objects if not o.is_runtime_data}
    meshes, materials = len(bpy.data.meshes), len(bpy.data.curves)
    path = tmp_path / "deviation.png"
    scale = compare.render_deviation(bpy.context, bpy.context.scene, rows, path, width=320, samples=1)
    last = compare.report(bpy.context, bpy.context.scene, rows, [compare.FRAMES[1]])
    top = max(m["max_deviation_from_armature_linear"] for r in last for m in r["methods"].values())
    assert scale == pytest.approx(top, rel=1e-6) and scale > 0.1  # Preserve Volume differs at the joints
    image = bpy.data.images.load(str(path))
    width, height = image.size
    assert width == 320 and 0.5 * width < height < 2 * width  # the height follows the layout
    pixels = np.array(image.pixels[:]).reshape(height, width, 4)[..., :3]
    r, g, b = pixels[..., 0], pixels[..., 1], pixels[..., 2]
    # Both ends of the scale are on the picture (purple: no deviation; yellow: the most), not
    # only one colour: the legend has both, the meshes the purple and the colours between.
    purple = (b - g > 0.15) & (r - g > 0.1)
    yellow = (r > 0.6) & (g > 0.6) & (b < 0.5 * g)
    assert purple.sum() > 500 and yellow.sum() > 5, (purple.sum(), yellow.sum())
    # The scene is left as it was: no still copies or legend, nothing left hidden.
    assert {o.name: o.hide_render for o in bpy.data.objects if not o.is_runtime_data} == before
    assert (len(bpy.data.meshes), len(bpy.data.curves)) == (meshes, materials)


def test_labels_sit_above_their_own_row(dq_skin):
    with bpy.context.temp_override(active_object=None, selected_objects=[]):
        assert bpy.ops.object.dq_skin_comparison_scene() == {"FINISHED"}
    collection = bpy.data.collections["DQ Skin Comparison"]
    labels = sorted((o for o in collection.objects if o.type == "FONT"), key=lambda o: -o.location.z)
    heights = sorted({round(o.location.z, 4) for o in labels}, reverse=True)
    assert len(heights) == 3  # one label height per row
    sizes = {round(o.data.size, 6) for o in labels}
    assert len(sizes) == 1  # one size for every row
    meshes = [o for o in collection.objects if o.type == "MESH"]
    columns = sorted({round(m.matrix_world.translation.x, 4) for m in meshes})
    step = columns[1] - columns[0]
    for label in labels:
        # Its own mesh: in its column, under it, within one row.
        below = [
            m
            for m in meshes
            if abs(m.matrix_world.translation.x - label.location.x) < step / 2
            and 0 < label.location.z - m.matrix_world.translation.z < heights[0] - heights[1]
        ]
        assert len(below) == 1, label.name
        column = round((below[0].matrix_world.translation.x - columns[0]) / step)
        assert label.name.startswith(dq_skin.compare.VARIANTS[column][0] + " label"), label.name


def test_comparison_of_a_character(dq_skin, assets):
    obj, arm_mod = import_character(assets / "RiggedSimple.glb")
    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(active_object=obj, object=obj, selected_objects=[obj]):
        assert bpy.ops.object.dq_skin_comparison_scene() == {"FINISHED"}
    collection = bpy.data.collections["DQ Skin Comparison"]
    meshes = sorted((o for o in collection.objects if o.type == "MESH"), key=lambda o: o.matrix_world.translation.x)
    assert len(meshes) == len(dq_skin.compare.VARIANTS) == 6 and not obj.visible_get()
    row = dict(zip((v[0] for v in dq_skin.compare.VARIANTS), meshes))
    result = dq_skin.compare.report(bpy.context, bpy.context.scene, [row], [1, 10, 20])
    m = result[0]["methods"]
    assert m["DQ Skin Linear"]["max_deviation_from_armature_linear"] < 1e-5
    assert m["DQ Skin Dual Quaternion"]["max_deviation_from_armature_preserve_volume"] < 1e-5


def test_operator_writes_the_report(dq_skin, tmp_path):
    import json

    bpy.context.scene.frame_start, bpy.context.scene.frame_end = 1, 6
    with bpy.context.temp_override(active_object=None, selected_objects=[]):
        assert bpy.ops.object.dq_skin_comparison_scene(report_dir=str(tmp_path)) == {"FINISHED"}
    rows = json.loads((tmp_path / "report.json").read_text())["rows"]
    assert len(rows) == 3 and len(rows[0]["methods"]) == 6
    assert "| Candy Wrapper Twist | DQ Skin Blend |" in (tmp_path / "report.md").read_text()

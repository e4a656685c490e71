"""Painting weights with the method shown: Paint Blend shows the blend while it is painted, and
in Weight Paint with Optimized Centers the centers follow each stroke (updated from the last
ones: only what the stroke reaches is computed again, equal to a full computation bit for bit).

A stroke is what a weight brush leaves: new weights on the vertices under it, the mesh tagged,
one update (Blender then evaluates; DQ Skin skins again in that evaluation).
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from dqtest import REL_TOL, add_dq_skin, deviation, evaluated_positions, import_character, reference_copy, route_of, status
from scenes import RIGS, make_rig

import bpy


def stroke(obj, group, vertices, weight: float) -> float:
    """Paints `weight` on `vertices` of `group` as a brush stroke does; returns the seconds until
    Blender shows the result (the update that follows the stroke)."""
    group.add([int(v) for v in vertices], weight, "REPLACE")
    obj.data.update()
    t = time.perf_counter()
    bpy.context.view_layer.update()
    return time.perf_counter() - t


def under_brush(obj, radius: float, at: int = 0) -> np.ndarray:
    co = np.array([v.co for v in obj.data.vertices], np.float64)
    return np.flatnonzero(np.linalg.norm(co - co[at], axis=1) < radius)


def group_weights(obj, name: str) -> np.ndarray:
    g = obj.vertex_groups[name]
    w = np.zeros(len(obj.data.vertices))
    for v in obj.data.vertices:
        for e in v.groups:
            if e.group == g.index:
                w[v.index] = e.weight
    return w


@pytest.mark.parametrize("rig", RIGS)
def test_paint_blend_shows_the_blend_while_painting(dq_skin, assets, rig):
    body, arm_mod = import_character(assets / "CesiumMan.glb")
    make_rig(arm_mod.object, rig)
    lbs, dqs = reference_copy(body, False), reference_copy(body, True)
    add_dq_skin(body, "BLEND")
    bpy.context.scene.frame_set(17)
    bpy.context.view_layer.objects.active = body
    with bpy.context.temp_override(object=body, active_object=body):
        assert bpy.ops.object.dq_skin_paint_blend() == {"FINISHED"}
    try:
        assert body.mode == "WEIGHT_PAINT"
        group = body.vertex_groups.active
        n = len(body.data.vertices)
        for at, weight in ((0, 0.0), (n // 2, 0.0), (n - 1, 0.6), (n // 3, 1.0)):
            stroke(body, group, under_brush(body, 0.25, at), weight)
            st = status(dq_skin, body)
            assert st.live and st.method == "Blend", st.message
            assert route_of(dq_skin, body) == "cache"  # brushes map through a deform-only carrier
            alpha = group_weights(body, group.name)[:, None]
            want = (1 - alpha) * evaluated_positions(lbs) + alpha * evaluated_positions(dqs)
            dev = deviation(evaluated_positions(body), want)
            assert dev <= REL_TOL, f"after painting {weight} at {at}: {dev:.2e} from the blend of the painted weights"
        assert np.ptp(group_weights(body, group.name)) == 1.0  # the strokes painted both ends
    finally:
        bpy.ops.object.mode_set(mode="OBJECT")


def computations(store, monkeypatch) -> list[bool]:
    """Each centers computation from now on, as whether it updated the last centers (True) or
    computed them anew (False)."""
    updates = []
    real = store.compute

    def compute(*args, **kwargs):
        updates.append(kwargs.get("previous") is not None)
        return real(*args, **kwargs)

    monkeypatch.setattr(store, "compute", compute)
    return updates


def _subdivided_character(assets, levels: int):
    """CesiumMan subdivided at rest (the weights interpolated, as Blender subdivides them)."""
    body, arm_mod = import_character(assets / "CesiumMan.glb")
    sub = body.modifiers.new("Subdivision", "SUBSURF")
    sub.levels = levels
    with bpy.context.temp_override(object=body, active_object=body):
        bpy.ops.object.modifier_move_to_index(modifier=sub.name, index=0)
        arm_mod.object.data.pose_position = "REST"
        bpy.context.view_layer.update()
        assert bpy.ops.object.modifier_apply(modifier=sub.name) == {"FINISHED"}
        arm_mod.object.data.pose_position = "POSE"
    return body


@pytest.mark.parametrize("levels", [0, 2])
def test_centers_follow_each_stroke(dq_skin, assets, monkeypatch, tmp_path, levels):
    """In Weight Paint with Optimized Centers each stroke updates the centers (levels 2: about
    52,000 vertices; the time the update takes is in the benchmark)."""
    # A disk cache of its own: the user folder's may hold this very stroke's centers already.
    monkeypatch.setattr(dq_skin.engine.centers, "_folder", lambda: tmp_path)
    dq_skin.SESSION.centers.forget_memory()
    body = _subdivided_character(assets, levels) if levels else import_character(assets / "CesiumMan.glb")[0]
    add_dq_skin(body, "CENTERS_OF_ROTATION")
    bpy.context.scene.frame_set(17)
    store = dq_skin.SESSION.centers
    updates = computations(store, monkeypatch)
    bpy.context.view_layer.objects.active = body
    bpy.ops.object.mode_set(mode="WEIGHT_PAINT")
    try:
        st = status(dq_skin, body)
        assert st.live and st.method == "Optimized Centers"
        before = dq_skin.SESSION.state_of(body, next(m for m in body.modifiers if m.type == "NODES")).binding.centers.copy()
        shown = evaluated_positions(body)
        group = max(body.vertex_groups, key=lambda g: (group_weights(body, g.name) > 0.5).sum())  # a well-used bone
        painted = under_brush(body, 0.15, int(np.argmax(group_weights(body, group.name))))
        stroke(body, group, painted, 1.0)
        st = status(dq_skin, body)
        assert st.live and st.method == "Optimized Centers", st.message
        assert updates == [True], updates  # updated from the last centers, not computed anew
        state = dq_skin.SESSION.state_of(body, next(m for m in body.modifiers if m.type == "NODES"))
        got = state.binding.centers
        # What a full computation on the painted weights gives, bit for bit.
        data = dq_skin.SESSION.meshes.get(body, dq_skin.SESSION.readers.mesh)
        triangles = dq_skin.engine.centers.triangles_of(body.data)
        full = dq_skin.dqskin.centers_of_rotation(data.positions, triangles, state.binding.centers_of)
        assert np.array_equal(got, full)
        assert np.abs(got - before).max() > 1e-4  # the stroke moved centers
        assert deviation(evaluated_positions(body), shown) > 1e-6  # and what shows
    finally:
        bpy.ops.object.mode_set(mode="OBJECT")


def test_centers_found_on_disk_follow_strokes_too(dq_skin, assets, tmp_path, monkeypatch):
    """Open a file in a new session (the centers come from the disk cache, not computed here),
    then paint: the first stroke updates those centers, it does not compute them anew."""
    # A disk cache of its own: the user folder's may hold this very stroke's centers already.
    (tmp_path / "centers").mkdir()
    monkeypatch.setattr(dq_skin.engine.centers, "_folder", lambda: tmp_path / "centers")
    dq_skin.SESSION.centers.forget_memory()  # (earlier tests computed these very centers)
    body = import_character(assets / "CesiumMan.glb")[0]
    add_dq_skin(body, "CENTERS_OF_ROTATION")
    bpy.context.scene.frame_set(17)
    assert list((tmp_path / "centers").iterdir()), "the centers were not kept on disk"
    name, path = body.name, tmp_path / "painted.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))
    dq_skin.SESSION.centers.forget_memory()  # as in a new Blender session: only the disk has them
    body = bpy.data.objects[name]
    bpy.context.scene.frame_set(17)
    assert status(dq_skin, body).live
    store = dq_skin.SESSION.centers
    updates = computations(store, monkeypatch)
    bpy.context.view_layer.objects.active = body
    bpy.ops.object.mode_set(mode="WEIGHT_PAINT")
    try:
        group = max(body.vertex_groups, key=lambda g: (group_weights(body, g.name) > 0.5).sum())
        stroke(body, group, under_brush(body, 0.15, int(np.argmax(group_weights(body, group.name)))), 1.0)
        assert status(dq_skin, body).live
        assert updates == [True], updates
    finally:
        bpy.ops.object.mode_set(mode="OBJECT")

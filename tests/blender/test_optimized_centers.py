"""The Optimized Centers method in Blender: the modifier equals the module's centers-of-rotation
skinning of the same mesh, its centers are computed once and kept (in memory, then on disk for the
next session), long precomputes run in the background with progress and can be cancelled, and
the comparison shows what it is for: no candy wrapper, no bulge."""

from __future__ import annotations

import math
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from dqtest import REL_TOL, add_dq_skin, animate, deviation, evaluated_positions, import_character, moved
from scenes import rig_tube

import bpy

from mathutils import Quaternion


def _mesh(dq_skin, obj):
    return dq_skin.SESSION.meshes.get(obj, dq_skin.SESSION.readers.mesh)


def expected(dq_skin, obj, arm):
    """Centers-of-rotation skinning of `obj` computed directly with the bundled module."""
    rig, centers = dq_skin.blender.rig, dq_skin.engine.centers
    mod = next(m for m in obj.modifiers if m.type == "ARMATURE")
    binding = rig.bind(_mesh(dq_skin, obj), arm, mod.vertex_group, mod.invert_vertex_group)
    positions = rig.mesh_positions(obj.data)
    c = dq_skin.dqskin.centers_of_rotation(positions, centers.triangles_of(obj.data), binding.influences)
    f = rig.frame(binding, obj, arm)
    return dq_skin.dqskin.skin(
        positions,
        binding.influences,
        f.deform,
        f.rest,
        method="centers_of_rotation",
        centers=c,
        premat=f.premat,
        postmat=f.postmat,
        mask=binding.mask,
    )


@pytest.fixture
def counted(dq_skin, monkeypatch):
    """Counts the centers actually computed (not found in memory or on disk)."""
    calls = []
    real = dq_skin.SESSION.centers.compute

    def compute(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(dq_skin.SESSION.centers, "compute", compute)
    return calls


def test_modifier_equals_the_module_on_a_character(dq_skin, assets):
    obj, arm_mod = import_character(assets / "CesiumMan.glb")
    arm = arm_mod.object
    add_dq_skin(obj, "CENTERS_OF_ROTATION")
    mod = dq_skin.engine.context.dq_skin_modifiers(obj)[0]
    assert dq_skin.blender.nodes.get_method(mod) == "Optimized Centers"
    for frame in (1, 12, 30):
        bpy.context.scene.frame_set(frame)
        ours = evaluated_positions(obj)
        assert deviation(ours, expected(dq_skin, obj, arm)) <= REL_TOL
    st = dq_skin.SESSION.status_of(obj, mod)
    assert st.live and st.method == "Optimized Centers"


def test_rest_pose_is_unchanged_and_translations_are_linear(dq_skin):
    obj, arm, _ = rig_tube(bones=3, length=6.0)
    rest = evaluated_positions(obj)
    add_dq_skin(obj, "CENTERS_OF_ROTATION")
    bpy.context.scene.frame_set(1)
    assert deviation(evaluated_positions(obj), rest) <= REL_TOL
    # Moving bones without rotating them: exactly what linear blend skinning does.
    arm.pose.bones["Bone1"].location = (0.3, -0.2, 0.5)
    arm.pose.bones["Bone2"].location = (-0.4, 0.1, 0.2)
    bpy.context.view_layer.update()
    ours = evaluated_positions(obj)
    rig = dq_skin.blender.rig
    linear = rig.skin(rig.bind(_mesh(dq_skin, obj), arm, "", False), obj, arm, rig.mesh_positions(obj.data), "linear")
    assert deviation(ours, linear) <= REL_TOL


def test_candy_wrapper_and_elbow_against_linear_and_dual_quaternion(dq_skin):
    """The point of the method, in the comparison's own measures on the built-in rigs."""
    compare = dq_skin.compare
    with bpy.context.temp_override(active_object=None, selected_objects=[]):
        assert bpy.ops.object.dq_skin_comparison_scene() == {"FINISHED"}
    collection = bpy.data.collections["DQ Skin Comparison"]
    rows = []
    for rig_name in ("Candy Wrapper Twist", "Elbow Bend", "Shoulder Raise"):
        meshes = sorted(
            (o for o in collection.objects if o.type == "MESH" and o.name.startswith(rig_name)), key=lambda o: o.matrix_world.translation.x
        )
        rows.append(dict(zip((v[0] for v in compare.VARIANTS), meshes)))
    result = compare.report(bpy.context, bpy.context.scene, rows, [compare.FRAMES[1]])
    twist, elbow, shoulder = (r["methods"] for r in result)
    ocor, lbs, dqs = "DQ Skin Optimized Centers", "DQ Skin Linear", "DQ Skin Dual Quaternion"
    # Candy wrapper at 180°: Linear collapses the middle (its edges shrink, 6 % on average over
    # the whole tube); the centers keep it (a twist about the axis: the centers are on the axis),
    # and keep the volume as Dual Quaternion does. Measured: Linear 0.0596, centers 0.0.
    assert twist[lbs]["edge_shrink_mean"] > 0.05
    assert twist[ocor]["edge_shrink_mean"] < 0.005
    assert twist[ocor]["volume_relative_to_rest"] > 0.95 > twist[lbs]["volume_relative_to_rest"]
    # Bent joints: less collapse than Linear and less bulge than Dual Quaternion. Measured
    # (shrink, stretch, volume): elbow 130° Linear 0.036/0.032/0.928, Dual Quaternion
    # 0.019/0.041/0.995, centers 0.022/0.039/0.985; shoulder 150° Linear 0.024/0.026/0.943,
    # Dual Quaternion 0.012/0.036/0.990, centers 0.012/0.033/0.981.
    for bend in (elbow, shoulder):
        assert bend[ocor]["edge_shrink_mean"] < bend[lbs]["edge_shrink_mean"]
        assert bend[ocor]["edge_stretch_mean"] < bend[dqs]["edge_stretch_mean"]
        assert abs(bend[ocor]["volume_relative_to_rest"] - 1) < abs(bend[lbs]["volume_relative_to_rest"] - 1)


def test_centers_are_computed_once_and_kept_across_duplicates_and_reloads(dq_skin, assets, tmp_path, counted, monkeypatch):
    folder = tmp_path / "cache"
    folder.mkdir()
    monkeypatch.setattr(dq_skin.engine.centers, "_folder", lambda: folder)  # a cache of its own
    obj, arm_mod = import_character(assets / "CesiumMan.glb")
    dq_skin.SESSION.centers.forget_memory()
    add_dq_skin(obj, "CENTERS_OF_ROTATION")
    bpy.context.scene.frame_set(5)
    evaluated_positions(obj)
    first = len(counted)
    assert first == 1 and len(list(folder.glob("*.npy"))) == 1
    # A duplicate shares the mesh and weights: the same centers, not computed again.
    with bpy.context.temp_override(active_object=obj, selected_objects=[obj], selected_editable_objects=[obj]):
        bpy.ops.object.duplicate()
    twin = bpy.context.active_object
    assert twin is not obj
    bpy.context.scene.frame_set(6)
    assert deviation(evaluated_positions(twin), evaluated_positions(obj)) <= REL_TOL
    assert len(counted) == first
    # Save, forget everything this session knew, open again: found on disk, not recomputed.
    path, name = tmp_path / "centers.blend", obj.name
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    dq_skin.SESSION.centers.forget_memory()
    bpy.ops.wm.open_mainfile(filepath=str(path))
    obj = bpy.data.objects[name]
    bpy.context.scene.frame_set(7)
    evaluated_positions(obj)
    mod = dq_skin.engine.context.dq_skin_modifiers(obj)[0]
    assert dq_skin.SESSION.status_of(obj, mod).live
    assert len(counted) == first
    # A weight change is a new binding: new centers.
    obj.vertex_groups[0].add([0], 0.5, "REPLACE")
    bpy.context.scene.frame_set(8)
    evaluated_positions(obj)
    assert len(counted) == first + 1 and len(list(folder.glob("*.npy"))) == 2


def hold_jobs(monkeypatch, centers) -> list:
    """From now on each background computation is a real `dqskin.centers_of_rotation_job` whose end is held
    back until its `release()` (surely still running when the test looks, or cancels it); returns
    the list of those made, in order."""
    real = centers.dqskin.centers_of_rotation_job
    made = []

    class Held:
        def __init__(self, *args, **kwargs):
            self.real = real(*args, **kwargs)
            self.held, self.cancelled = True, False
            made.append(self)

        def release(self):
            self.held = False

        done = property(lambda self: self.real.done)
        total = property(lambda self: self.real.total)
        finished = property(lambda self: not self.held and self.real.finished)

        def cancel(self):
            self.real.cancel()
            self.held, self.cancelled = False, True

        def result(self, **kwargs):
            return self.real.result(**kwargs)

    monkeypatch.setattr(centers.dqskin, "centers_of_rotation_job", Held)
    return made


def wait_until(condition, seconds: float = 30.0) -> None:
    end = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.02)


def test_large_meshes_compute_in_the_background_with_progress_and_can_be_cancelled(dq_skin, monkeypatch):
    centers = dq_skin.engine.centers
    store = dq_skin.SESSION.centers
    monkeypatch.setattr(centers, "INLINE_VERTICES", 10)
    monkeypatch.setattr(centers, "in_background", lambda: False)  # as in an interactive session
    store.forget_memory()
    obj, arm, _ = rig_tube(rings=80, segments=48, bones=3, length=6.0)
    monkeypatch.setattr(centers, "_folder", lambda: None)  # not found on disk either
    made = hold_jobs(monkeypatch, centers)
    threads = {t.ident for t in threading.enumerate()}
    add_dq_skin(obj, "CENTERS_OF_ROTATION")
    arm.pose.bones["Bone1"].rotation_quaternion = Quaternion((1, 0, 0), math.radians(90))
    bpy.context.view_layer.update()
    mod = dq_skin.engine.context.dq_skin_modifiers(obj)[0]
    st = dq_skin.SESSION.status_of(obj, mod)
    # Until the centers are ready, Blender's own deformation stands in and the modifier says so.
    assert st.mode.value == "fallback" and "Optimized Centers: computing" in st.message
    # No Python thread computes them (the core's own thread does, running no Python).
    assert {t.ident for t in threading.enumerate()} == threads
    job = store.jobs()[-1]
    assert obj.name in job.owners and not job.finished and len(made) == 1
    made[0].release()
    wait_until(lambda: job.finished)
    assert not job.error and job.fraction == 1.0
    store.poll()  # the timer: re-evaluates the waiting objects
    bpy.context.view_layer.update()
    evaluated_positions(obj)
    assert dq_skin.SESSION.status_of(obj, mod).live
    assert deviation(evaluated_positions(obj), expected(dq_skin, obj, arm)) <= REL_TOL

    # Cancelled: the modifier says so and Blender's deformation stays.
    store.forget_memory()
    obj.vertex_groups[0].add([0], 0.25, "REPLACE")  # new weights, new centers
    bpy.context.view_layer.update()
    evaluated_positions(obj)
    running = store.running()
    assert running, "a new computation started"
    assert obj.name in running[0].owners and not running[0].finished
    with bpy.context.temp_override(object=obj):
        assert bpy.ops.object.dq_skin_cancel_centers() == {"FINISHED"}
    wait_until(lambda: running[0].finished)
    assert running[0].error == "cancelled" and made[-1].cancelled  # the core's job was told
    store.poll()
    bpy.context.view_layer.update()
    evaluated_positions(obj)
    st = dq_skin.SESSION.status_of(obj, mod)
    assert st.mode.value == "fallback" and "cancelled" in st.message


def test_background_computations_run_one_at_a_time_and_each_object_gets_its_own(dq_skin, monkeypatch):
    centers = dq_skin.engine.centers
    store = dq_skin.SESSION.centers
    monkeypatch.setattr(centers, "INLINE_VERTICES", 10)
    monkeypatch.setattr(centers, "in_background", lambda: False)
    monkeypatch.setattr(centers, "_folder", lambda: None)
    made = hold_jobs(monkeypatch, centers)
    store.forget_memory()
    objs = []
    for i in range(3):
        obj, arm, _ = rig_tube(rings=20 + 4 * i, segments=16, bones=3, length=6.0)  # three meshes
        add_dq_skin(obj, "CENTERS_OF_ROTATION")
        objs.append((obj, arm))
    bpy.context.view_layer.update()
    jobs = [j for j in store.running() if any(o.name in j.owners for o, _ in objs)]
    assert len(jobs) == 3
    assert len(made) == 1  # one thread at a time, the others queued
    for k in range(3):
        made[k].release()
        wait_until(lambda k=k: jobs[k].finished)
        assert not jobs[k].error
        assert len(made) == min(k + 2, 3)  # collecting one starts the next
    for _, arm in objs:
        arm.pose.bones["Bone1"].rotation_quaternion = Quaternion((1, 0, 0), math.radians(60))
    store.poll()
    bpy.context.view_layer.update()
    for obj, arm in objs:
        mod = dq_skin.engine.context.dq_skin_modifiers(obj)[0]
        assert dq_skin.SESSION.status_of(obj, mod).live
        assert deviation(evaluated_positions(obj), expected(dq_skin, obj, arm)) <= REL_TOL


def test_on_a_character_the_centers_collapse_less_than_linear(dq_skin, assets):
    """CesiumMan's mesh is open (no volume to compare): its edges say how much each method
    collapses. Measured over the walk: Linear 1.35 %, Dual Quaternion 1.10 %, centers 1.16 %."""
    obj, _ = import_character(assets / "CesiumMan.glb")
    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(active_object=obj, object=obj, selected_objects=[obj]):
        assert bpy.ops.object.dq_skin_comparison_scene() == {"FINISHED"}
    collection = bpy.data.collections["DQ Skin Comparison"]
    meshes = sorted((o for o in collection.objects if o.type == "MESH"), key=lambda o: o.matrix_world.translation.x)
    row = dict(zip((v[0] for v in dq_skin.compare.VARIANTS), meshes))
    m = dq_skin.compare.report(bpy.context, bpy.context.scene, [row], list(range(1, 49, 4)))[0]["methods"]
    ocor, lbs = m["DQ Skin Optimized Centers"], m["DQ Skin Linear"]
    assert ocor["edge_shrink_mean"] < 0.9 * lbs["edge_shrink_mean"]
    assert ocor["max_deviation_from_armature_linear"] > 1e-3  # a different method, visibly


def test_files_from_before_the_method_get_it_on_load(dq_skin, tmp_path):
    """A node group saved without the Optimized Centers item (DQ Skin before it): on load the
    item is added, and the modifiers keep their methods."""
    obj, arm, _ = rig_tube(bones=2)
    add_dq_skin(obj, "LINEAR")
    mod = dq_skin.engine.context.dq_skin_modifiers(obj)[0]
    switch = mod.node_group.nodes["Method Items"]
    switch.enum_items.remove(switch.enum_items[-1])  # as 0.1 saved it
    for tag in (dq_skin.blender.nodes.IDS_TAG, dq_skin.blender.nodes.MENU_TAG):
        del mod.node_group[tag]  # nor did it store what later versions store on the group
    assert [i.name for i in switch.enum_items] == ["Linear", "Dual Quaternion", "Blend"]
    path, name = tmp_path / "old.blend", obj.name
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))
    obj = bpy.data.objects[name]
    mod = dq_skin.engine.context.dq_skin_modifiers(obj)[0]
    assert [i.name for i in mod.node_group.nodes["Method Items"].enum_items] == list(dq_skin.blender.nodes.METHODS)
    assert dq_skin.blender.nodes.get_method(mod) == "Linear"
    assert dq_skin.blender.nodes.put_method(mod, "Optimized Centers") is not False
    assert dq_skin.blender.nodes.get_method(mod) == "Optimized Centers"


def _references():
    """The float64 references of the module's tests (tests/python/centers_reference.py)."""
    here = str(Path(__file__).resolve().parents[1] / "python")
    if here not in sys.path:
        sys.path.insert(0, here)
    import centers_reference

    return centers_reference


@pytest.mark.parametrize("deformation", ["B-Bones", "envelopes", "B-Bones and envelopes"])
def test_centers_on_b_bones_and_envelopes_equal_the_brute_force(dq_skin, deformation):
    """With B-Bones and envelopes the centers come from the influences DQ Skin skins with (over
    the bones and the B-Bones' segment joints): the precompute equals the paper's formula on
    those influences, and each frame equals the float64 reference of the per-frame formula."""
    from test_pose_memory import bbone_rig

    ref = _references()
    obj, arm, arm_mod = bbone_rig(segments=4 if "B-Bones" in deformation else 1)
    animate(arm)
    if "envelopes" in deformation:
        arm_mod.use_bone_envelopes = True
        for b in arm.data.bones:
            b.envelope_distance, b.head_radius, b.tail_radius = 0.3, 0.5, 0.5
        group = obj.vertex_groups[0]
        group.remove(list(range(0, len(obj.data.vertices), 5)))  # some vertices by envelopes alone
    mod = add_dq_skin(obj, "CENTERS_OF_ROTATION")
    for frame in (1, 9, 14):
        bpy.context.scene.frame_set(frame)
        st = dq_skin.SESSION.state_of(obj, mod)
        assert st.status.live, st.status.message
        job = st.output.job
        infl = job.influences
        assert len(job.deform) > infl.bone_count - 1 and (infl.bone_count > len(arm.data.bones) or "B-Bones" not in deformation)
        positions = dq_skin.blender.rig.mesh_positions(obj.data)
        triangles = dq_skin.engine.centers.triangles_of(obj.data)
        want, has = ref.brute_force_centers(positions, triangles, infl)
        got = st.binding.centers
        diag = ref.diagonal(positions)
        assert has.any() and np.abs(got[has] - want[has]).max() <= 1e-5 * diag
        np.testing.assert_array_equal(got[~has], positions[~has])
        expected = ref.reference_skin(positions, got, infl, job.deform, job.rest, premat=job.premat, postmat=job.postmat)
        assert deviation(evaluated_positions(obj), expected) <= 5e-5
    assert moved(obj) > 0.1

"""DQ Skin's automatic weights and weight transfer in Blender, on the meshes where Blender's bone
heat fails (weight_scenes.py) and on the generated Rigify character (characters.py).

Tolerances: Blender stores weights as float32, so sums are checked to 1e-5; "strongest bone among
the nearest" means among the NEAREST bones by distance to the bone segments, for at least 95 % of
the vertices; edge stretch is compared at the 99.9th percentile over every edge and animated
frame.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from characters import open_rigify_character
from weight_scenes import (
    armature,
    bone_segments,
    copy_of,
    dense_weights,
    edge_stretch,
    figure_mesh,
    parent_with,
    rest_positions,
    segment_distances,
    skirt,
)

import bpy

K = 4
NEAREST = 2
PERCENTILE = 99.9
STRETCH_FRAMES = (8, 15, 22, 30)


def automatic(meshes, arm, **options):
    bpy.context.view_layer.update()  # objects linked since the last update join the view layer
    for o in bpy.context.view_layer.objects:
        o.select_set(o in (*meshes, arm))
    bpy.context.view_layer.objects.active = arm
    return bpy.ops.object.dq_skin_automatic_weights(**options)


def deform_names(arm) -> list[str]:
    return [b.name for b in arm.data.bones if b.use_deform]


def check_weights(obj, arm, k: int = K) -> np.ndarray:
    """Every vertex weighted, sums 1, at most `k` bones; strongest among the nearest bones for at
    least 95 % of vertices. Returns the dense weights."""
    names = deform_names(arm)
    w = dense_weights(obj, names)
    sums = w.sum(1)
    assert np.all(sums > 0), f"{int((sums == 0).sum())} vertices unweighted"
    assert np.abs(sums - 1).max() < 1e-5, np.abs(sums - 1).max()
    assert (w > 0).sum(1).max() <= k
    heads, tails = bone_segments(arm, names, obj)
    d = segment_distances(rest_positions(obj), heads, tails)
    nearest = np.argsort(d, axis=1)[:, :NEAREST]
    strongest = w.argmax(1)
    share = np.mean((nearest == strongest[:, None]).any(1))
    assert share >= 0.95, f"strongest bone among the {NEAREST} nearest for only {share:.1%} of vertices"
    return w


def heat_unweighted(obj, arm) -> int:
    """How many vertices Blender's own With Automatic Weights leaves unweighted on a copy."""
    c = copy_of(obj, obj.name + " heat")
    parent_with(c, arm, "ARMATURE_AUTO")
    left = int((dense_weights(c, deform_names(arm)).sum(1) == 0).sum())
    bpy.data.objects.remove(c)
    return left


@pytest.mark.parametrize("scale", [1.0, 0.01, 100.0])
def test_automatic_weights_never_fail_where_bone_heat_does(dq_skin, scale):
    fig = figure_mesh(scale)
    arm = armature(scale)
    # Blender's bone heat leaves vertices of this figure unweighted (and only warns).
    assert heat_unweighted(fig, arm) > 0
    assert automatic([fig], arm) == {"FINISHED"}
    check_weights(fig, arm)
    assert fig.parent == arm and fig.parent_type == "OBJECT"
    assert [m.object for m in fig.modifiers if m.type == "ARMATURE"] == [arm]


def test_open_cloth_is_weighted_directly(dq_skin):
    arm = armature()
    cloth = skirt()
    assert automatic([cloth], arm) == {"FINISHED"}
    check_weights(cloth, arm)


def test_several_meshes_mirror_and_options(dq_skin):
    fig, cloth = figure_mesh(), skirt()
    arm = armature()
    assert automatic([fig, cloth], arm, max_influences=3, smoothing=2, resolution=96) == {"FINISHED"}
    check_weights(fig, arm, k=3)
    check_weights(cloth, arm, k=3)
    assert automatic([fig], arm, mirror=True) == {"FINISHED"}
    w = check_weights(fig, arm)
    # Mirrored: a vertex and its mirror image have the same weights on mirrored bones.
    names = deform_names(arm)
    flip = [names.index(n[:-2] + {".L": ".R", ".R": ".L"}[n[-2:]]) if n[-2:] in (".L", ".R") else i for i, n in enumerate(names)]
    p = rest_positions(fig)
    key = {tuple(np.round(q, 5)): i for i, q in enumerate(p)}
    pairs = [(i, key.get(tuple(np.round(q * (-1, 1, 1), 5)))) for i, q in enumerate(p)]
    pairs = [(i, j) for i, j in pairs if j is not None]
    assert len(pairs) > 0.9 * len(p)
    diffs = [np.abs(w[i][flip] - w[j]).max() for i, j in pairs]
    worst = int(np.argmax(diffs))
    i, j = pairs[worst]
    assert diffs[worst] < 1e-5, (p[i], p[j], w[i][flip], w[j])


def test_stretch_is_no_worse_than_envelopes_nor_than_bone_heat_where_it_works(dq_skin):
    """One closed limb (bone heat succeeds) and the figure (it does not): posed through the
    animation, the 99.9th percentile of edge stretch with DQ Skin's weights is at most the
    envelope weights' and at most 1.1x bone heat's where bone heat weights every vertex."""
    arm = armature()
    limb = bpy.data.objects.new("Limb", bpy.data.meshes.new("Limb"))
    bpy.context.scene.collection.objects.link(limb)
    from weight_scenes import tube

    import bmesh

    bm = bmesh.new()
    tube(bm, (0.08, 0, 1.42), (0.86, 0, 1.42), 0.05, 60, 24)
    bm.to_mesh(limb.data)
    bm.free()
    for obj, heat_works in ((limb, True), (figure_mesh(), False)):
        heat, envelope = copy_of(obj, obj.name + " heat"), copy_of(obj, obj.name + " envelope")
        parent_with(heat, arm, "ARMATURE_AUTO")
        parent_with(envelope, arm, "ARMATURE_ENVELOPE")
        assert automatic([obj], arm) == {"FINISHED"}
        heat_ok = bool(np.all(dense_weights(heat, deform_names(arm)).sum(1) > 0))
        assert heat_ok == heat_works
        ours = np.percentile(edge_stretch(obj, STRETCH_FRAMES), PERCENTILE)
        env = np.percentile(edge_stretch(envelope, STRETCH_FRAMES), PERCENTILE)
        assert ours <= env, f"{obj.name}: {ours:.4f} with DQ Skin's weights, {env:.4f} with envelopes"
        if heat_ok:
            by_heat = np.percentile(edge_stretch(heat, STRETCH_FRAMES), PERCENTILE)
            assert ours <= 1.1 * by_heat, f"{obj.name}: {ours:.4f} with DQ Skin's weights, {by_heat:.4f} with bone heat"


def test_a_dq_skin_character_keeps_dq_skin_and_undo_restores_everything(dq_skin):
    fig, arm = figure_mesh(), armature()
    parent_with(fig, arm, "ARMATURE_ENVELOPE")
    for o in bpy.context.view_layer.objects:
        o.select_set(o is fig)
    bpy.context.view_layer.objects.active = fig
    assert bpy.ops.object.dq_skin_add() == {"FINISHED"}
    before = [(m.name, m.type) for m in fig.modifiers]
    groups_before = [g.name for g in fig.vertex_groups]
    weights_before = dense_weights(fig, deform_names(arm))
    bpy.ops.ed.undo_push(message="before")
    assert automatic([fig], arm) == {"FINISHED"}
    assert [(m.name, m.type) for m in fig.modifiers] == before
    check_weights(fig, arm)
    # Headless, operators run from Python push no undo step of their own; the UI's push comes after.
    bpy.ops.ed.undo_push(message="after")
    assert bpy.ops.ed.undo() == {"FINISHED"}
    fig = bpy.data.objects["Figure"]
    assert [(m.name, m.type) for m in fig.modifiers] == before
    assert [g.name for g in fig.vertex_groups] == groups_before
    assert np.array_equal(dense_weights(fig, deform_names(bpy.data.objects["Rig"])), weights_before)


def test_cancelling_changes_nothing(dq_skin):
    """Esc cancels the worker's running job: it stops with Cancelled on the core's thread (no
    Python thread runs it), the next step never starts, and the plan's finish (the only writer
    of Blender data) never runs."""
    background, weights_io = dq_skin.ops.background, dq_skin.blender.weights_io
    fig, arm = figure_mesh(), armature()
    rest, bones = weights_io.rest_mesh(fig, arm), weights_io.rest_bones(arm)
    finished, started = [], []

    def start():
        started.append(1)
        return dq_skin.dqskin.automatic_weights_job(rest.positions, rest.triangles, bones.heads, bones.tails, resolution=256)

    plan = background.Plan([(start, 1), (start, 1)], lambda context, results: finished.append(results) or "", "test")
    worker = background.Worker(plan)
    threads = threading.active_count()
    assert not worker.advance()  # the first job runs
    assert threading.active_count() == threads
    worker.cancel()
    end = time.monotonic() + 60
    while not worker.advance():
        assert time.monotonic() < end
        time.sleep(0.01)
    assert isinstance(worker.error, dq_skin.dqskin.Cancelled) and worker.results == [] and not finished
    assert len(started) == 1
    assert not fig.vertex_groups and fig.parent is None


def test_the_worker_runs_the_steps_in_order_and_reports_progress(dq_skin):
    background, weights_io = dq_skin.ops.background, dq_skin.blender.weights_io
    fig, arm = figure_mesh(), armature()
    rest, bones = weights_io.rest_mesh(fig, arm), weights_io.rest_bones(arm)
    plain = dq_skin.dqskin.automatic_weights(rest.positions, rest.triangles, bones.heads, bones.tails, resolution=64)

    def start(resolution):
        return lambda: dq_skin.dqskin.automatic_weights_job(rest.positions, rest.triangles, bones.heads, bones.tails, resolution=resolution)

    worker = background.Worker(background.Plan([(start(64), 3), (start(80), 1)], lambda context, results: "", "test"))
    seen = []
    end = time.monotonic() + 60
    while not worker.advance():
        assert time.monotonic() < end
        seen.append(worker.fraction())
        worker.job.wait(0.01)
    assert worker.error is None and len(worker.results) == 2
    assert worker.results[1][1]["grid"] != worker.results[0][1]["grid"]  # in order
    influences, report = worker.results[0]
    assert all(report[k] == plain[1][k] for k in ("unreached", "grid", "solid_voxels"))
    np.testing.assert_array_equal(report["outside_bones"], plain[1]["outside_bones"])
    np.testing.assert_array_equal(influences.weights, plain[0].weights)
    assert seen == sorted(seen) and all(0.0 <= f <= 1.0 for f in seen) and worker.fraction() == 1.0


def test_an_internal_error_in_a_job_is_reported_and_stops_the_plan(dq_skin):
    background = dq_skin.ops.background
    started = []
    plan = background.Plan(
        [(dq_skin.dqskin._panicking_job_for_tests, 1), (lambda: started.append(1), 1)], lambda context, results: "", "test"
    )
    worker = background.Worker(plan)
    end = time.monotonic() + 30
    while not worker.advance():  # raises nothing: the operator reports it
        assert time.monotonic() < end
        worker.job.wait(0.05)
    assert isinstance(worker.error, RuntimeError) and "deliberate panic" in str(worker.error)
    assert not started and worker.results == []


class FakeWindowManager:
    """What the modal operator calls on `context.window_manager` (no window in the bpy module)."""

    def __init__(self):
        self.calls = []

    def __getattr__(self, name):
        return lambda *args, **kwargs: self.calls.append(name)


def modal_operator(dq_skin, plan):
    """The modal path of a BackgroundOperator (what the UI runs), on stand-ins for the operator
    instance, the context and the events: the bpy module has no window to invoke it in."""
    from types import SimpleNamespace

    op_class = dq_skin.ops.background.BackgroundOperator
    reports = []
    op = SimpleNamespace(_worker=dq_skin.ops.background.Worker(plan), _timer=None, reports=reports)
    op.report = lambda kind, text: reports.append((set(kind), text))
    op._end = lambda context: op_class._end(op, context)
    op._finish = lambda context, plan, results: op_class._finish(op, context, plan, results)
    context = SimpleNamespace(window_manager=FakeWindowManager(), workspace=SimpleNamespace(status_text_set=lambda text: None))
    return op, context, lambda kind, value="NOTHING": op_class.modal(op, context, SimpleNamespace(type=kind, value=value))


def test_the_modal_operator_polls_the_jobs_and_esc_cancels_them(dq_skin):
    weights_io = dq_skin.blender.weights_io
    fig, arm = figure_mesh(), armature()
    rest, bones = weights_io.rest_mesh(fig, arm), weights_io.rest_bones(arm)
    finished = []

    def start(resolution):
        return lambda: dq_skin.dqskin.automatic_weights_job(rest.positions, rest.triangles, bones.heads, bones.tails, resolution=resolution)

    plan = dq_skin.ops.background.Plan(
        [(start(48), 1), (start(64), 1)], lambda context, results: finished.append(results) or "done", "test"
    )
    op, context, event = modal_operator(dq_skin, plan)
    assert event("MOUSEMOVE") == {"PASS_THROUGH"}  # the UI stays live
    end = time.monotonic() + 60
    while (state := event("TIMER")) == {"RUNNING_MODAL"}:
        assert time.monotonic() < end
        time.sleep(0.02)
    assert state == {"FINISHED"} and len(finished) == 1 and len(finished[0]) == 2
    assert op.reports == [({"INFO"}, "done")]
    assert {"progress_update", "event_timer_remove", "progress_end"} <= set(context.window_manager.calls)

    plan = dq_skin.ops.background.Plan([(start(256), 1), (start(256), 1)], lambda context, results: finished.append(results) or "", "test")
    op, context, event = modal_operator(dq_skin, plan)
    assert event("TIMER") == {"RUNNING_MODAL"}  # the first job runs
    end = time.monotonic() + 60
    state = event("ESC", "PRESS")
    while state == {"RUNNING_MODAL"}:
        assert time.monotonic() < end
        time.sleep(0.02)
        state = event("TIMER")
    assert state == {"CANCELLED"} and len(finished) == 1  # finish never ran again
    assert op.reports == [({"WARNING"}, "test cancelled, nothing changed")]
    assert not fig.vertex_groups and fig.parent is None


def test_transfer_equals_the_body_at_matched_points_and_fills_the_rest(dq_skin):
    from mathutils.bvhtree import BVHTree

    fig, arm = figure_mesh(), armature()
    assert automatic([fig], arm) == {"FINISHED"}
    cloth = skirt()
    bpy.context.view_layer.update()
    for o in bpy.context.view_layer.objects:
        o.select_set(o in (cloth, fig))
    bpy.context.view_layer.objects.active = fig
    assert bpy.ops.object.dq_skin_transfer_weights() == {"FINISHED"}
    names = deform_names(arm)
    w = dense_weights(cloth, names)
    assert np.all(w.sum(1) > 0) and np.abs(w.sum(1) - 1).max() < 1e-5 and (w > 0).sum(1).max() <= K
    assert [m.object for m in cloth.modifiers if m.type == "ARMATURE"] == [arm]
    # Which vertices matched (the operator's own inputs, through the module), then at those the
    # operator's weights must be the body's at the closest point of its surface, barycentric.
    wio = dq_skin.blender.weights_io
    body, garment = wio.rest_mesh(fig), wio.rest_mesh(cloth)
    _, report = dq_skin.dqskin.transfer_weights(
        body.positions, body.triangles, wio.body_influences(fig, names, None), garment.positions, garment.triangles
    )
    matched = report["matched"]
    assert matched.sum() > 0.3 * len(matched) and report["inpainted"] > 0, report
    body_w = dense_weights(fig, names)
    tris = body.triangles.astype(np.int64)
    bp = body.positions.astype(np.float64)
    tree = BVHTree.FromPolygons([tuple(q) for q in bp], [tuple(t) for t in tris])
    checked = 0
    for i in np.flatnonzero(matched):
        loc, _normal, t, _dist = tree.find_nearest(garment.positions[i].tolist())
        a, b, c = bp[tris[t]]
        uv = np.linalg.lstsq(np.array([b - a, c - a]).T, np.array(loc) - a, rcond=None)[0]
        want = (1 - uv.sum()) * body_w[tris[t][0]] + uv[0] * body_w[tris[t][1]] + uv[1] * body_w[tris[t][2]]
        want = want / want.sum()
        if (want > 0).sum() > K:
            continue  # the limit to K bones changes these
        assert np.abs(w[i] - want).max() < 1e-4, (i, w[i], want)
        checked += 1
    assert checked > 0.9 * matched.sum(), (checked, matched.sum())


def test_transfer_is_refused_without_weights(dq_skin):
    body, cloth = figure_mesh(), skirt()
    bpy.context.view_layer.update()
    for o in bpy.context.view_layer.objects:
        o.select_set(o in (cloth, body))
    bpy.context.view_layer.objects.active = body
    with pytest.raises(RuntimeError, match="no vertex groups"):
        bpy.ops.object.dq_skin_transfer_weights()


@pytest.fixture(scope="module")
def rigify_folder(tmp_path_factory):
    return tmp_path_factory.mktemp("rigify-weights")


def test_rigify_character_with_loose_eyes_and_teeth(dq_skin, rigify_folder):
    """The generated Rigify character (160 deforming bones) with eyes and teeth added as loose
    shells and a hat pushed into its head: every vertex weighted (the time is printed; the
    benchmark measures it)."""
    body, rig, _ = open_rigify_character(rigify_folder)
    from weight_scenes import sphere

    import bmesh
    from mathutils import Vector

    head = rig.data.bones["DEF-spine.006"]
    top = rig.matrix_world @ head.tail_local
    mid = rig.matrix_world @ ((head.head_local + head.tail_local) / 2)
    extra = bpy.data.objects.new("Extras", bpy.data.meshes.new("Extras"))
    bpy.context.scene.collection.objects.link(extra)
    bm = bmesh.new()
    for side in (1, -1):
        sphere(bm, mid + Vector((side * 0.03, -0.08, 0.03)), 0.015, 12)
    for k in range(8):
        sphere(bm, mid + Vector((-0.02 + 0.006 * k, -0.07, -0.02)), 0.004, 6)
    sphere(bm, top, 0.09, 32)
    bm.to_mesh(extra.data)
    bm.free()
    body.vertex_groups.clear()
    for m in list(body.modifiers):
        body.modifiers.remove(m)
    t = time.perf_counter()
    assert automatic([body, extra], rig) == {"FINISHED"}
    seconds = time.perf_counter() - t
    for obj in (body, extra):
        check_weights(obj, rig)
    vertices = len(body.data.vertices) + len(extra.data.vertices)
    print(f"Rigify character: {vertices} vertices, {len(deform_names(rig))} bones, {seconds:.2f} s")
    assert len(deform_names(rig)) >= 150

"""The benchmark's cases (as the issues name them), each a row of figures."""

from __future__ import annotations

import time

import numpy as np

import bpy

import addon_utils

from . import scenes
from .compare import add_dq_skin, compare, positions
from .timing import ADDON, addon, alternate, show_only, timed_s

FRAMES = (5, 12, 19, 26, 33)


def _rounds(quick: bool, vertices: int) -> tuple[int, int]:
    if quick:
        return 2, 5
    return (4, 7) if vertices >= 500_000 else (5, 9)


def case_grid(vertices: int, method: str, quick: bool, later: str = "", routes_too: bool = True) -> dict:
    scenes.empty_scene()
    grid, arm = scenes.grid_rig(vertices)
    n = len(grid.data.vertices)
    # The route's floor on every grid: on the large ones it bounds the speedup DQ Skin can reach.
    row = compare(
        [(grid, arm)],
        method,
        FRAMES,
        *_rounds(quick, n),
        routes_too=routes_too,
        floors=n <= 10_000,
        later=later,
        with_route_floor=not later,
    )
    label = f"grid {n // 1000}k, 64 bones{' + ' + later if later else ''}, {method.lower()}"
    return {"case": label, "vertices": n, "method": method, "later": later, **row}


def case_bbone_grid(vertices: int, method: str, quick: bool) -> dict:
    scenes.empty_scene()
    grid, arm = scenes.bbone_grid(vertices)
    n = len(grid.data.vertices)
    row = compare([(grid, arm)], method, FRAMES, *_rounds(quick, n), with_route_floor=True)
    return {"case": f"B-Bone grid {n // 1000}k, 16 bones x 8 segments, {method.lower()}", "vertices": n, "method": method, **row}


def case_cesium(method: str, quick: bool) -> dict:
    scenes.empty_scene()
    body, arm = scenes.cesium_man()
    row = compare([(body, arm)], method, FRAMES, *_rounds(quick, 3000), floors=True)
    return {
        "case": f"CesiumMan, {len(body.data.vertices)} vertices, {method.lower()}",
        "vertices": len(body.data.vertices),
        "method": method,
        **row,
    }


def case_crowd(count: int, quick: bool, later: str = "") -> dict:
    """`count` CesiumMen, each with its own armature; with `later`, each with that modifier after
    its skinning (only DQ Skin's chosen route then)."""
    scenes.empty_scene()
    pairs = scenes.crowd(count)
    rounds = (2, 5) if quick else (4, 7)
    row = compare(pairs, "DUAL_QUATERNION", (3, 9, 15, 21), *rounds, routes_too=not later, floors=not later, later=later)
    n = len(pairs[0][0].data.vertices)
    label = f"{count} characters x {n} vertices{' + ' + later if later else ''}, dual_quaternion"
    return {"case": label, "objects": count, "vertices": n * count, "later": later, **row}


def case_rigify(method: str, quick: bool) -> dict:
    """The Rigify character: the skinning share is each frame minus the rig alone's (`none`)."""
    scenes.empty_scene()
    t = time.perf_counter()
    body, rig = scenes.rigify()
    build_s = time.perf_counter() - t
    row = compare([(body, rig)], method, FRAMES, 2 if quick else 5, 5 if quick else 9, floors=True)
    deforming = [b for b in rig.data.bones if b.use_deform]
    return {
        "case": f"Rigify character, {len(body.data.vertices)} vertices, {method.lower()}",
        "vertices": len(body.data.vertices),
        "deforming_bones": len(deforming),
        "bbones": sum(b.bbone_segments > 1 for b in deforming),
        "build_s": build_s,
        "method": method,
        **row,
    }


def case_still(quick: bool) -> list[dict]:
    """Frame changes where nothing moves: the Rigify character holding its pose past its last
    key (Blender still evaluates its rig on every frame), and a crowd whose rigs have no
    animation (Blender evaluates none of it): the Armature modifier against DQ Skin, each on
    its own copy, alternating in one session, checked to show the same mesh first."""
    rows = []
    scenes.empty_scene()
    body, rig = scenes.rigify()
    rows.append(_still("Rigify character holding its pose, linear", [body], "LINEAR", (45, 50, 55, 58, 52), quick))
    scenes.empty_scene()
    pairs = scenes.crowd(50 if quick else 200)
    label = f"{len(pairs)} CesiumMen standing still, dual_quaternion"
    rows.append(_still(label, [m for m, _ in pairs], "DUAL_QUATERNION", (3, 9, 15, 21), quick, stop=[a for _, a in pairs]))
    return rows


def _still(label: str, meshes: list, method: str, frames, quick: bool, stop=()) -> dict:
    """`meshes` (with their Armature modifiers) against copies with DQ Skin on `frames`; the
    armatures `stop` lose their animation once DQ Skin is set up."""
    for m in meshes:
        next(x for x in m.modifiers if x.type == "ARMATURE").use_deform_preserve_volume = method == "DUAL_QUATERNION"
    ours = [scenes.copy_of(m, f"{m.name} DQ Skin") for m in meshes]
    show_only(*ours)
    add_dq_skin(ours, method)
    for f in FRAMES[:3]:
        bpy.context.scene.frame_set(f)
    for a in stop:
        a.animation_data.action = None
    bpy.context.scene.frame_set(frames[0])
    show_only(*meshes, *ours)
    deviation = max(float(np.abs(positions(m) - positions(o)).max()) for m, o in zip(meshes, ours))
    times = alternate({"armature": meshes, "dq_skin": ours}, frames, *((2, 5) if quick else (5, 9)))
    return {"case": f"still: {label}", "objects": len(meshes), "method": method, "max_deviation": deviation, **times}


def case_centers(quick: bool) -> list[dict]:
    """Optimized Centers: the precompute on the Rigify body (the goal: at most 1 s) and on
    CesiumMan subdivided twice (52k), and the update after a brush stroke there (at most 0.5 s),
    on the inputs the modifier gives them, in Weight Paint as an artist paints."""
    return [
        _centers("Rigify body", scenes.rigify, quick),
        _centers("CesiumMan subdivided x2", lambda: scenes.subdivided_cesium_man(2), quick),
    ]


def _centers(name: str, build, quick: bool) -> dict:
    a = addon()
    scenes.empty_scene()
    body, _ = build()
    a.SESSION.centers.forget_memory()
    folder = a.engine.centers._folder
    a.engine.centers._folder = lambda: None  # (the on-disk cache would hide the work)
    try:
        show_only(body)
        bpy.context.scene.frame_set(9)
        first = timed_s(lambda: add_dq_skin([body], "CENTERS_OF_ROTATION"))
        st = a.SESSION.state_of(body, a.engine.context.dq_skin_modifiers(body)[0])
        data = a.SESSION.meshes.get(body, a.SESSION.readers.mesh)
        triangles = a.engine.centers.triangles_of(body.data)
        influences = st.binding.centers_of
        runs = [timed_s(lambda: a.dqskin.centers_of_rotation(data.positions, triangles, influences)) for _ in range(1 if quick else 3)]
        bpy.context.view_layer.objects.active = body
        bpy.ops.object.mode_set(mode="WEIGHT_PAINT")
        strokes = []
        co = np.array([v.co for v in body.data.vertices])
        size = float(np.linalg.norm(np.ptp(co, axis=0)))
        rng = np.random.default_rng(5)
        for _ in range(3 if quick else 8):
            group = body.vertex_groups[int(rng.integers(len(body.vertex_groups)))]
            at = co[int(rng.integers(len(co)))]
            under = np.flatnonzero(np.linalg.norm(co - at, axis=1) < 0.05 * size).tolist()
            group.add(under, float(rng.uniform(0.2, 1.0)), "REPLACE")
            body.data.update()
            strokes.append((len(under), timed_s(bpy.context.view_layer.update)))
        bpy.ops.object.mode_set(mode="OBJECT")
    finally:
        a.engine.centers._folder = folder
    return {
        "case": f"Optimized Centers, {name} ({len(data.positions)} vertices, {len(triangles)} triangles)",
        "vertices": len(data.positions),
        "precompute_s": float(np.median(runs)),
        "add_and_first_frame_s": first,
        "stroke_vertices": [s[0] for s in strokes],
        "stroke_update_s": float(np.median([s[1] for s in strokes])),
        "stroke_update_max_s": float(max(s[1] for s in strokes)),
        "threads": a.dqskin.get_num_threads(),
    }


def case_binding(vertices: int) -> dict:
    """`dq_skin_add` until the first skinned frame is evaluated."""
    scenes.empty_scene()
    grid, _ = scenes.grid_rig(vertices)
    bpy.context.scene.frame_set(9)
    seconds = timed_s(lambda: (add_dq_skin([grid], "DUAL_QUATERNION"), grid.evaluated_get(bpy.context.evaluated_depsgraph_get()).data))
    return {
        "case": f"dq_skin_add + first frame, {len(grid.data.vertices) // 1000}k",
        "vertices": len(grid.data.vertices),
        "seconds": seconds,
    }


def case_weights(vertices: int, quick: bool) -> dict:
    """A weight change (`VertexGroup.add` on 1,000 vertices, like a brush stroke) until the
    evaluated mesh shows it, Armature modifier vs DQ Skin."""
    scenes.empty_scene()
    grid, _ = scenes.grid_rig(vertices)
    bpy.context.scene.frame_set(9)
    dq = scenes.copy_of(grid, "Grid DQ Skin")
    show_only(dq)
    add_dq_skin([dq], "DUAL_QUATERNION")
    variants = {"armature": grid, "dq_skin": dq}
    out = {"case": f"weight change, {len(grid.data.vertices) // 1000}k", "vertices": len(grid.data.vertices)}
    rng = np.random.default_rng(3)
    times = {k: [] for k in variants}
    for rnd in range(2 if quick else 4):
        for name, obj in variants.items():
            show_only(obj)
            for k in range(3 if quick else 7):
                idx = rng.choice(len(obj.data.vertices), 1000, replace=False).tolist()
                group = obj.vertex_groups[(k + rnd) % len(obj.vertex_groups)]
                t = time.perf_counter()
                group.add(idx, 0.3 + 0.05 * k, "REPLACE")
                bpy.context.view_layer.update()
                obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
                times[name].append(time.perf_counter() - t)
    for name, ts in times.items():
        out[f"{name}_ms"] = 1e3 * float(np.median(ts))
    out["ratio"] = out["dq_skin_ms"] / out["armature_ms"]
    return out


def case_regenerate(quick: bool) -> dict:
    """Rigify's *Re-Generate Rig* with two DQ Skin characters on the rig, then the next frame,
    with the extension enabled and disabled, alternating in one session."""
    scenes.empty_scene()
    addon_utils.enable("rigify", default_set=True)
    body, rig, metarig = scenes.characters.build_rigify_character()
    addon_utils.enable("rigify", default_set=True)  # (build_rigify_character restores its state)
    second = scenes.copy_of(body, "Body 2")
    add_dq_skin([body, second], "DUAL_QUATERNION")
    bpy.context.scene.frame_set(8)

    def regenerate(frame: int) -> float:
        bpy.data.orphans_purge(do_recursive=True)  # what the last rebuild left (its old widgets)
        scenes.characters.select_only_object(metarig)
        t = time.perf_counter()
        assert bpy.ops.pose.rigify_generate() == {"FINISHED"}
        bpy.context.scene.frame_set(frame)
        for o in (body, second):
            o.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
        return time.perf_counter() - t

    def live() -> bool:
        a = addon()
        return all(a.SESSION.state_of(o, a.engine.context.dq_skin_modifiers(o)[0]).status.live for o in (body, second))

    times = {"with_extension": [], "without_extension": []}
    skinned = []
    order = ("with_extension", "without_extension") * (1 if quick else 3)
    order = [name for k in range(0, len(order), 2) for name in (order[k : k + 2] if k % 4 == 0 else order[k : k + 2][::-1])]
    try:
        for k, name in enumerate(order):
            if name == "with_extension":
                times[name].append(regenerate(9 + k))
                skinned.append(live())
                continue
            addon_utils.disable(ADDON, default_set=True)
            try:
                times[name].append(regenerate(9 + k))
            finally:
                addon_utils.enable(ADDON, default_set=True)
                bpy.context.scene.frame_set(8)
    finally:
        addon_utils.disable("rigify", default_set=True)
    row = {f"{k}_s": float(np.median(v)) for k, v in times.items()}
    row.update(case="Rigify Re-Generate Rig, two DQ Skin characters on the rig, and the next frame", dq_skin_live_after_each=all(skinned))
    row["ratio"] = row["with_extension_s"] / row["without_extension_s"]
    return row

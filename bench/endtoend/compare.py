"""One character (or a crowd) with Blender's Armature modifier, without skinning, and with DQ
Skin on every route, each on its own copies, alternating in one session; checked to show the
same mesh before it is timed."""

from __future__ import annotations

import numpy as np

import bpy

from . import routes, scenes
from .timing import Parts, addon, alternate, kernel_ms, reevaluation_ms, resident_bytes, show_only

ROUTES = ("cache", "node", "result")


def add_dq_skin(objs, method: str) -> None:
    """DQ Skin on every object of `objs`, in one operator call (as for a selection)."""
    for o in bpy.context.view_layer.objects:
        o.select_set(o in objs)
    bpy.context.view_layer.objects.active = objs[0]
    with bpy.context.temp_override(active_object=objs[0], object=objs[0], selected_objects=list(objs)):
        assert bpy.ops.object.dq_skin_add(method=method, all_selected=len(objs) > 1) == {"FINISHED"}


def positions(obj) -> np.ndarray:
    mesh = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    out = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.attributes["position"].data.foreach_get("vector", out)
    return out.reshape(-1, 3)


def payload_bytes(objs) -> int:
    """The bytes of the meshes' positions (12 per vertex) and weights (8 per vertex-group entry)."""
    total = 0
    for o in objs:
        total += 12 * len(o.data.vertices) + 8 * sum(len(v.groups) for v in o.data.vertices)
    return total


def compare(
    pairs,
    method: str,
    frames,
    rounds: int,
    per_round: int,
    routes_too: bool = True,
    floors: bool = False,
    later: str = "",
    with_route_floor: bool = False,
) -> dict:
    """`pairs`: [(mesh with its Armature modifier, its armature)]. Returns a row: `armature_ms`,
    `none_ms`, `dq_skin_ms` (the route DQ Skin chooses, `dq_skin_route`), `route_<kind>_ms` for
    each route forced (and `route_import_ms` where Blender has file-import nodes), where DQ
    Skin's time goes (`dq_skin_<part>_ms`), the floors (`floors`: all of them, on one character;
    `with_route_floor`: `floor_route` alone), the memory DQ Skin adds, speedups."""
    meshes = [m for m, _ in pairs]
    rigs = [a for _, a in pairs]
    for m in meshes:
        scenes.later_modifier(m, later)
        next(x for x in m.modifiers if x.type == "ARMATURE").use_deform_preserve_volume = method == "DUAL_QUATERNION"
    none = [scenes.copy_of(m, f"{m.name} none") for m in meshes]
    for o in none:
        o.modifiers.remove(next(x for x in o.modifiers if x.type == "ARMATURE"))
    variants = {"armature": meshes, "none": none}
    hooks = {}
    # DQ Skin as it chooses, with the memory it adds.
    auto = [scenes.copy_of(m, f"{m.name} DQ Skin") for m in meshes]
    show_only(*auto)
    before = resident_bytes()
    add_dq_skin(auto, method)
    for f in frames[:3]:
        bpy.context.scene.frame_set(f)
    extra = resident_bytes() - before
    variants["dq_skin"] = auto
    chosen = routes.route_of(auto[0]) or addon().SESSION.status_of(auto[0], addon().engine.context.dq_skin_modifiers(auto[0])[0]).mode.value
    if routes_too:
        for kind in ROUTES:
            copies = [scenes.copy_of(m, f"{m.name} {kind}") for m in meshes]
            forced = routes.ForcedRoute(kind)
            forced.enter()
            try:
                show_only(*copies)
                add_dq_skin(copies, method)
                for f in frames[:2]:
                    bpy.context.scene.frame_set(f)
                assert routes.route_of(copies[0]) == kind, (kind, routes.route_of(copies[0]))
            finally:
                forced.leave()
            variants[f"route_{kind}"] = copies
            hooks[f"route_{kind}"] = forced.hooks
    imported = None
    if routes_too and routes.has_import_nodes() and not later:
        show_only(*auto)
        imported = routes.ImportRoute(auto, rigs)
        variants["route_import"] = imported.objects
    floor = route_floor = None
    if floors and len(pairs) == 1:
        st = addon().SESSION.state_of(auto[0], addon().engine.context.dq_skin_modifiers(auto[0])[0])
        floor = routes.Floors(rigs[0], meshes[0], st.binding.binding.bone_names)
        variants.update({k: [o] for k, o in floor.objects.items()})
    if floors or with_route_floor:
        route_floor = routes.RouteFloor()
        variants["floor_route"] = auto
        hooks["floor_route"] = route_floor.hooks
    try:
        row = {"dq_skin_route": chosen, "dq_skin_extra_bytes": int(extra), "payload_bytes": payload_bytes(meshes)}
        row["dq_skin_extra_per_payload"] = extra / max(row["payload_bytes"], 1)
        row["max_deviation"] = _check_same(variants, frames[-1], hooks)
        row.update(alternate(variants, frames, rounds, per_round, hooks))
        show_only(*auto)
        with Parts() as parts:
            row.update(parts.measure(auto, frames, per_round * 2))
        if chosen in ("cache", "node") and row["dq_skin_fed_ms"] == 0.0:
            raise RuntimeError(f"{chosen} route: the feed did not skin a frame (the figures would time its fallback)")
        if floor is not None:
            row["floor_python_driver_calls"] = floor.python_calls
        if route_floor is not None:
            row["floor_route_calls"] = route_floor.calls
    finally:
        if imported is not None:
            imported.remove()
        if floor is not None:
            floor.remove()
    show_only(*auto)
    row["reevaluation_floor_ms"] = reevaluation_ms(meshes[0])
    row.update(kernel_ms(auto[0], 15))
    row["speedup"] = row["armature_ms"] / row["dq_skin_ms"]
    row["armature_share_ms"] = row["armature_ms"] - row["none_ms"]
    for name in [k[: -len("_ms")] for k in list(row) if k.endswith("_ms") and (k.startswith("route_") or k == "dq_skin_ms")]:
        row[f"{name}_share_speedup"] = row["armature_share_ms"] / max(row[f"{name}_ms"] - row["none_ms"], 1e-6)
    return row


def _check_same(variants: dict, frame: int, hooks: dict) -> float:
    """The largest distance between what each DQ Skin variant shows and what DQ Skin shows on
    its own route (a route that showed something else would be timed for nothing)."""
    worst = 0.0
    show_only(*variants["dq_skin"])
    bpy.context.scene.frame_set(frame)
    want = [positions(o) for o in variants["dq_skin"]]
    for name, objs in variants.items():
        if not name.startswith("route_"):
            continue
        enter, leave = hooks.get(name, (None, None))
        if enter:
            enter()
        try:
            show_only(*objs)
            bpy.context.scene.frame_set(frame - 1)
            bpy.context.scene.frame_set(frame)
            got = [positions(o) for o in objs]
        finally:
            if leave:
                leave()
        dev = max(float(np.abs(g - w).max()) for g, w in zip(got, want))
        assert dev < 1e-3, f"{name} shows something else: {dev}"
        worst = max(worst, dev)
    return worst

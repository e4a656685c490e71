"""DQ Skin against Blender's Armature modifier, end to end, in one Blender session.

Every case builds the same scene three times (each object with its own copy of the mesh):
with the Armature modifier, with DQ Skin in its place, and without skinning. Only one of them is
in the depsgraph at a time (the others are hidden from the viewport); rounds alternate between
them and each keeps its median. A benchmark, not a test: it prints a table and writes JSON
(default: target/bench-blender.json).

Cases (as in the issues): a grid with 64 bones and 4 influences per vertex at 250k and 1M
vertices, plain stack and with Smooth (5 iterations) or Subdivision Surface (level 2) after the
skinning modifier, Linear and Dual Quaternion; `dq_skin_add` to the first skinned frame; a
weight change; 200 characters of 3,273 vertices (CesiumMan) and an edit elsewhere in that scene;
a 3k-vertex mesh; a 100k grid on 16 B-Bones of 8 segments (Straight and Curved mapping); a
generated Rigify character (`tests/blender/characters.py`), where the skinning share of a frame
is the frame minus the rig alone, and Rigify's Re-Generate Rig with two DQ Skin characters on
it, with the extension enabled and disabled. For DQ Skin it also reports where the time of a frame goes:
Blender's first evaluation (animation, pose), DQ Skin's frame handler (for B-Bones split into
reading the pose, the influences, the kernel and writing the result), and Blender's second
evaluation (DQ Skin result, modifiers after it). On the 3k grid, the crowd and Rigify it also
measures what Blender costs before any skinning (`Floors`, `reevaluation_ms`): a second
evaluation of the scene, a Mesh Cache ordered after the bones with and without Python, the
Armature modifier with nothing bound.

Usage: python bench/blender_bench.py [--out FILE] [--quick] [--only NAME...]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
os.environ.setdefault("BLENDER_USER_RESOURCES", str(ROOT / ".blender_user"))

import bpy  # noqa: E402  (after BLENDER_USER_RESOURCES)

import addon_utils  # noqa: E402  (importable once bpy is)

sys.path.insert(0, str(ROOT / "tests" / "blender"))
import characters  # noqa: E402  (the Rigify character the tests use too)

ADDON = "bl_ext.user_default.dq_skin"


# -- scenes ---------------------------------------------------------------------------------------


def grid_rig(vertices: int, bones_per_side: int = 8, influences: int = 4, seed: int = 1):
    """A square grid of about `vertices` vertices with an 8×8 grid of bones above it, each
    vertex weighted to its 4 nearest bones (weights quantized to 16 levels so that vertex groups
    can be filled with few calls); every bone keyed to bend and twist over frames 1-40."""
    side = max(2, int(round(math.sqrt(vertices))))
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=side - 1, y_subdivisions=side - 1, size=8.0)
    grid = bpy.context.active_object
    grid.name = "Grid"
    arm_data = bpy.data.armatures.new("Rig")
    arm = bpy.data.objects.new("Rig", arm_data)
    bpy.context.scene.collection.objects.link(arm)
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="EDIT")
    heads = []
    for i in range(bones_per_side):
        for j in range(bones_per_side):
            b = arm_data.edit_bones.new(f"B{i}_{j}")
            x = -4.0 + 8.0 * (i + 0.5) / bones_per_side
            y = -4.0 + 8.0 * (j + 0.5) / bones_per_side
            b.head = (x, y, 0.0)
            b.tail = (x, y + 0.5, 0.0)
            heads.append((x, y))
    bpy.ops.object.mode_set(mode="OBJECT")
    heads = np.array(heads, np.float32)
    co = np.empty(len(grid.data.vertices) * 3, np.float32)
    grid.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)[:, :2]
    d2 = ((co[:, None, :] - heads[None, :, :]) ** 2).sum(-1)
    nearest = np.argsort(d2, axis=1)[:, :influences]
    w = 1.0 / (np.take_along_axis(d2, nearest, 1) + 0.05)
    w /= w.sum(1, keepdims=True)
    levels = np.clip(np.round(w * 15), 1, 15).astype(np.int64)
    groups = [grid.vertex_groups.new(name=f"B{i}_{j}") for i in range(bones_per_side) for j in range(bones_per_side)]
    for k in range(influences):
        for b in range(len(groups)):
            sel = nearest[:, k] == b
            for level in np.unique(levels[sel, k]):
                idx = np.flatnonzero(sel & (levels[:, k] == level))
                groups[b].add(idx.tolist(), float(level) / 15.0, "REPLACE")
    rng = np.random.default_rng(seed)
    for pb in arm.pose.bones:
        pb.rotation_mode = "QUATERNION"
        axis = rng.normal(size=3)
        for frame, angle in ((1, 0.0), (20, 1.2), (40, 2.4)):
            pb.rotation_quaternion = (math.cos(angle / 2), *(math.sin(angle / 2) * axis / np.linalg.norm(axis)))
            pb.keyframe_insert("rotation_quaternion", frame=frame)
    m = grid.modifiers.new("Armature", "ARMATURE")
    m.object = arm
    return grid, arm


def three_ways(obj, method: str, later: str = ""):
    """`obj` (with its Armature modifier) plus two copies with their own mesh copies: one with
    DQ Skin in place of the Armature modifier, one without skinning; `later` adds the same
    modifier after the skinning modifier in each."""
    for o in [obj]:
        _later(o, later)
    obj.modifiers["Armature"].use_deform_preserve_volume = method == "DUAL_QUATERNION"
    dq = obj.copy()
    dq.data = obj.data.copy()
    dq.name = obj.name + " DQ Skin"
    bpy.context.scene.collection.objects.link(dq)
    none = obj.copy()
    none.data = obj.data.copy()
    none.name = obj.name + " none"
    bpy.context.scene.collection.objects.link(none)
    none.modifiers.remove(none.modifiers["Armature"])
    show_only(dq)
    t = time.perf_counter()
    add_dq_skin(dq, method)
    dq.evaluated_get(bpy.context.evaluated_depsgraph_get())
    bind_seconds = time.perf_counter() - t
    return {"armature": obj, "dq_skin": dq, "none": none}, bind_seconds


def _later(obj, later: str) -> None:
    if later == "smooth5":
        m = obj.modifiers.new("Smooth", "SMOOTH")
        m.iterations = 5
    elif later == "subsurf2":
        m = obj.modifiers.new("Subdivision", "SUBSURF")
        m.levels = 2


def add_dq_skin(obj, method: str):
    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.object.dq_skin_add(method=method) == {"FINISHED"}


def show_only(*objs) -> None:
    keep = set(objs)
    for o in bpy.context.scene.objects:
        if o.type == "MESH":
            o.hide_viewport = o not in keep
    bpy.context.view_layer.update()


# -- timing ---------------------------------------------------------------------------------------


class Phases:
    """Timestamps around DQ Skin's frame handler: Blender's first evaluation ends where the
    frame_change_post handlers start; the second evaluation starts where they end."""

    def __init__(self):
        self.t = {}
        self.rows = []

    def pre(self, *_):
        self.t["pre"] = time.perf_counter()

    def post_first(self, *_):
        self.t["post"] = time.perf_counter()

    def post_last(self, *_):
        self.t["handled"] = time.perf_counter()

    def install(self):
        h = bpy.app.handlers
        h.frame_change_pre.append(self.pre)
        h.frame_change_post.insert(0, self.post_first)
        h.frame_change_post.append(self.post_last)

    def remove(self):
        h = bpy.app.handlers
        for lst, fn in ((h.frame_change_pre, self.pre), (h.frame_change_post, self.post_first), (h.frame_change_post, self.post_last)):
            while fn in lst:
                lst.remove(fn)


def frames_ms(objs, frames, runs: int, phases: Phases | None = None) -> tuple[float, dict]:
    """Median ms of a frame change until every object's evaluated mesh is there."""
    scene = bpy.context.scene
    times, parts = [], []
    scene.frame_set(frames[-1])
    for k in range(runs):
        f = frames[k % len(frames)]
        if phases:
            phases.t.clear()
        start = time.perf_counter()
        scene.frame_set(f)
        dg = bpy.context.evaluated_depsgraph_get()
        for o in objs:
            o.evaluated_get(dg).data
        end = time.perf_counter()
        times.append(end - start)
        if phases and "post" in phases.t:
            t = phases.t
            parts.append((t["pre"] - start, t["post"] - t["pre"], t["handled"] - t["post"], end - t["handled"]))
    out = {}
    if parts:
        p = np.median(np.array(parts), axis=0) * 1e3
        out = {"before_ms": p[0], "first_evaluation_ms": p[1], "dq_skin_handler_ms": p[2], "second_evaluation_ms": p[3]}
    return 1e3 * float(np.median(times)), out


def alternate(variants: dict, frames, rounds: int, per_round: int, phases: Phases, hooks: dict | None = None) -> dict:
    """Rounds alternating the variants; median per variant over all rounds. `hooks`: variant
    name -> (enter, leave), called around each of its rounds (outside the timing)."""
    all_times = {k: [] for k in variants}
    parts = {}
    hooks = hooks or {}
    for _ in range(rounds):
        for name, objs in variants.items():
            enter, leave = hooks.get(name, (None, None))
            if enter:
                enter()
            show_only(*objs)
            bpy.context.scene.frame_set(frames[0])  # warm up after the switch
            bpy.context.scene.frame_set(frames[1])
            try:
                ms, p = frames_ms(objs, frames, per_round, phases if name.startswith("dq_skin") else None)
            finally:
                if leave:
                    leave()
            all_times[name].append(ms)
            if p:
                parts.setdefault(name, []).append(p)
    out = {f"{k}_ms": float(np.median(v)) for k, v in all_times.items()}
    for name, ps in parts.items():
        for key in ps[0]:
            out[f"{name}_{key}"] = float(np.median([p[key] for p in ps]))
    return out


class HandlerParts:
    """Time inside DQ Skin's frame handler on the envelope/B-Bone path: reading the pose from
    memory (in `pose.armature_signature`, once per armature and handler call), the frame's
    bones from it (`pose.frame`), this frame's influences (`pose.influences`), the kernel
    (`skin_many`) and writing the result (`results.write_positions`), per call."""

    PARTS = {
        "read_pose": ("blender.pose", "armature_signature"),
        "pose_frame": ("blender.pose", "frame"),
        "influences": ("blender.pose", "influences"),
        "kernel": ("dqskin", "skin_many"),
        "write": ("routes.results", "write_positions"),
    }

    def __init__(self):
        self.addon = sys.modules[ADDON]
        self.saved = []
        self.totals = {k: [] for k in self.PARTS}

    def install(self):
        for key, (module, name) in self.PARTS.items():
            owner = self.addon
            for part in module.split("."):
                owner = getattr(owner, part)
            original = getattr(owner, name)
            self.saved.append((owner, name, original))

            def timed(*a, _original=original, _key=key, **k):
                t = time.perf_counter()
                try:
                    return _original(*a, **k)
                finally:
                    self.totals[_key].append(time.perf_counter() - t)

            setattr(owner, name, timed)

    def remove(self):
        for owner, name, original in self.saved:
            setattr(owner, name, original)
        self.saved.clear()

    def medians(self, prefix: str) -> dict:
        return {f"{prefix}_handler_{k}_ms": 1e3 * float(np.median(v)) for k, v in self.totals.items() if v}


def reevaluation_ms(template, runs: int = 40) -> float:
    """Blender's own cost of evaluating the scene again after a change to one mesh that nothing
    depends on (a copy of `template`'s mesh on an object without modifiers, visible with what
    is shown now): the least any second evaluation costs in this scene, whatever it evaluates.
    Median ms of tagging that mesh and updating the view layer."""
    mesh = template.data.copy()
    o = bpy.data.objects.new(f"{template.name} re-evaluation", mesh)
    bpy.context.scene.collection.objects.link(o)
    bpy.context.view_layer.update()
    ts = []
    for _ in range(runs):
        t = time.perf_counter()
        mesh.update_tag()
        bpy.context.view_layer.update()
        ts.append(time.perf_counter() - t)
    bpy.data.objects.remove(o)
    bpy.data.meshes.remove(mesh)
    bpy.context.view_layer.update()
    return 1e3 * float(np.median(ts))


def kernel_ms(obj, runs: int) -> dict:
    """`dqskin.skin_many` alone on the job the modifier last ran (its inputs, spaces and
    output), Linear and Dual Quaternion."""
    addon = sys.modules[ADDON]
    mod = addon.engine.context.dq_skin_modifiers(obj)[0]
    job = addon.SESSION.state_of(obj, mod).output.job
    res = {}
    for method in ("linear", "dual_quaternion"):
        j = addon.dqskin.SkinJob(
            job.positions, job.influences, job.deform, job.rest, method=method, premat=job.premat, postmat=job.postmat, mask=job.mask
        )
        ts = []
        for _ in range(runs):
            t = time.perf_counter()
            addon.dqskin.skin_many([j])
            ts.append(time.perf_counter() - t)
        res[f"kernel_{method}_ms"] = 1e3 * float(np.median(ts))
    return res


# -- cases ----------------------------------------------------------------------------------------


def case_grid(vertices: int, later: str, method: str, quick: bool) -> dict:
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    grid, arm = grid_rig(vertices)
    variants, bind_s = three_ways(grid, method, later)
    frames = (5, 12, 19, 26, 33)
    # Small meshes: also the in-evaluation alternative (no second evaluation), on its own copy.
    in_evaluation = None
    if vertices <= 10_000 and not later:
        for f in frames[:2]:
            bpy.context.scene.frame_set(f)
        in_evaluation = InEvaluation(variants["dq_skin"], arm, grid)
        variants["in_evaluation"] = in_evaluation.obj
        floors = Floors(arm, grid, in_evaluation.bone_names)
        variants.update(floors.objects)
    phases = Phases()
    phases.install()
    try:
        row = alternate({k: [v] for k, v in variants.items()}, frames, 2 if quick else 5, 5 if quick else 9, phases)
        if in_evaluation is not None:
            show_only(grid, in_evaluation.obj)
            bpy.context.scene.frame_set(frames[-1])
            dg = bpy.context.evaluated_depsgraph_get()
            row["in_evaluation_max_deviation"] = float(np.abs(positions_of(in_evaluation.obj, dg) - positions_of(grid, dg)).max())
            row["in_evaluation_speedup"] = row["armature_ms"] / row["in_evaluation_ms"]
    finally:
        phases.remove()
        if in_evaluation is not None:
            in_evaluation.remove()
            floors.remove()
    show_only(variants["dq_skin"])
    row["reevaluation_floor_ms"] = reevaluation_ms(grid)
    row.update(kernel_ms(variants["dq_skin"], 5 if quick else 15))
    row.update(
        case=f"grid {len(grid.data.vertices) // 1000}k{' + ' + later if later else ''} {method.lower()}",
        vertices=len(grid.data.vertices),
        later=later,
        method=method,
        first_frame_s=bind_s,
        speedup=row["armature_ms"] / row["dq_skin_ms"],
    )
    return row


def bbone_grid(vertices: int, mapping: str):
    """`grid_rig` with 16 bones (4×4), all B-Bones of 8 segments with a curved rest shape and
    their curves and eases keyed along with the rotations (frames 1-40)."""
    grid, arm = grid_rig(vertices, bones_per_side=4)
    for b in arm.data.bones:
        b.bbone_segments = 8
        b.bbone_mapping_mode = mapping
        b.bbone_curveinx, b.bbone_curveoutz = 0.15, -0.1
    for i, pb in enumerate(arm.pose.bones):
        for frame, amount in ((1, 0.0), (20, 1.0), (40, 0.5)):
            pb.bbone_curveinx = 0.4 * amount * math.cos(i)
            pb.bbone_curveoutx = -0.3 * amount * math.sin(i)
            pb.bbone_easein = 1.0 + 0.8 * amount
            for prop in ("bbone_curveinx", "bbone_curveoutx", "bbone_easein"):
                pb.keyframe_insert(prop, frame=frame)
    return grid, arm


def case_bbone_grid(vertices: int, mapping: str, method: str, quick: bool) -> dict:
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    grid, arm = bbone_grid(vertices, mapping)
    variants, bind_s = three_ways(grid, method)
    phases, parts = Phases(), HandlerParts()
    phases.install()
    parts.install()
    try:
        row = alternate({k: [v] for k, v in variants.items()}, (5, 12, 19, 26, 33), 2 if quick else 5, 5 if quick else 9, phases)
    finally:
        phases.remove()
        parts.remove()
    row.update(parts.medians("dq_skin"))
    row.update(
        case=f"B-Bone grid {len(grid.data.vertices) // 1000}k, 16 bones x 8 segments, {mapping.lower()} {method.lower()}",
        vertices=len(grid.data.vertices),
        mapping=mapping,
        method=method,
        first_frame_s=bind_s,
        speedup=row["armature_ms"] / row["dq_skin_ms"],
    )
    return row


def positions_of(obj, depsgraph) -> np.ndarray:
    mesh = obj.evaluated_get(depsgraph).data
    out = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.attributes["position"].data.foreach_get("vector", out)
    return out


def deviation_from_preserve_volume(objs, meshes, frame: int) -> float:
    """The largest distance at `frame` between each of `objs` and its mesh of `meshes` with its
    Armature modifier's Preserve Volume on (as the crowd's DQ Skin is Dual Quaternion)."""
    armatures = [next(x for x in m.modifiers if x.type == "ARMATURE") for m in meshes]
    for a in armatures:
        a.use_deform_preserve_volume = True
    try:
        bpy.context.scene.frame_set(frame)
        dg = bpy.context.evaluated_depsgraph_get()
        return max(float(np.abs(positions_of(o, dg) - positions_of(m, dg)).max()) for o, m in zip(objs, meshes))
    finally:
        for a in armatures:
            a.use_deform_preserve_volume = False


def case_rigify(quick: bool) -> dict:
    """The Rigify character: the Armature modifier (Preserve Volume off and on) and DQ Skin
    (Linear and Dual Quaternion), each on its own copy of the mesh, and the rig alone (a copy
    without skinning); the skinning share is each frame minus the rig alone's."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    t = time.perf_counter()
    body, rig = characters.rigify_character()
    build_s = time.perf_counter() - t

    def copy(name):
        c = body.copy()
        c.data = body.data.copy()
        c.name = f"Body {name}"
        bpy.context.scene.collection.objects.link(c)
        return c

    variants = {
        "armature_linear": body,
        "armature_pv": copy("PV"),
        "dq_skin_linear": copy("DQ Linear"),
        "dq_skin_dqs": copy("DQ DQS"),
        "none": copy("none"),
    }
    variants["armature_pv"].modifiers["Armature"].use_deform_preserve_volume = True
    variants["none"].modifiers.remove(variants["none"].modifiers["Armature"])
    for name, method in (("dq_skin_linear", "LINEAR"), ("dq_skin_dqs", "DUAL_QUATERNION")):
        show_only(variants[name])
        add_dq_skin(variants[name], method)
    frames = (5, 12, 19, 26, 33)
    show_only(variants["dq_skin_linear"])
    for f in frames[:3]:
        bpy.context.scene.frame_set(f)
    in_evaluation = InEvaluation(variants["dq_skin_linear"], rig, body)
    variants["in_evaluation_linear"] = in_evaluation.obj
    floors = Floors(rig, body, in_evaluation.bone_names)
    variants.update(floors.objects)
    phases, parts = Phases(), HandlerParts()
    phases.install()
    parts.install()
    try:
        row = alternate({k: [v] for k, v in variants.items()}, frames, 2 if quick else 6, 5 if quick else 9, phases)
        # The alternative deforms as DQ Skin does (the same job): checked against the Armature modifier.
        show_only(body, in_evaluation.obj)
        bpy.context.scene.frame_set(frames[-1])
        dg = bpy.context.evaluated_depsgraph_get()
        row["in_evaluation_linear_max_deviation"] = float(np.abs(positions_of(in_evaluation.obj, dg) - positions_of(body, dg)).max())
        row["in_evaluation_driver_calls"] = in_evaluation.calls
        row["in_evaluation_driver_variables"] = in_evaluation.variables
        row["floor_simple_expression"] = floors.simple["floor_mesh_cache"]
    finally:
        phases.remove()
        parts.remove()
        in_evaluation.remove()
        floors.remove()
    row.update(parts.medians("dq_skin"))
    deforming = [b for b in rig.data.bones if b.use_deform]
    row.update(
        case=f"Rigify character, {len(body.data.vertices)} vertices",
        vertices=len(body.data.vertices),
        deforming_bones=len(deforming),
        bbones=sum(b.bbone_segments > 1 for b in deforming),
        build_s=build_s,
    )
    for skin, reference in (
        ("dq_skin_linear", "armature_linear"),
        ("dq_skin_dqs", "armature_pv"),
        ("in_evaluation_linear", "armature_linear"),
    ):
        row[f"{reference}_share_ms"] = row[f"{reference}_ms"] - row["none_ms"]
        row[f"{skin}_share_ms"] = row[f"{skin}_ms"] - row["none_ms"]
        row[f"{skin}_share_speedup"] = row[f"{reference}_share_ms"] / max(row[f"{skin}_share_ms"], 1e-6)
    for kind in floors.objects:
        row[f"{kind}_share_ms"] = row[f"{kind}_ms"] - row["none_ms"]
    show_only(variants["dq_skin_linear"])
    row["reevaluation_floor_ms"] = reevaluation_ms(body)
    return row


class InEvaluation:
    """A measured alternative to DQ Skin's second evaluation, for one DQ Skin object whose
    modifier is live: a copy of its mesh whose only modifier is a Mesh Cache reading a PC2 file
    on tmpfs, and a Python driver on that modifier (after every deforming bone in Blender's
    graph: one variable per bone) that skins with the DQ Skin modifier's own job and writes the
    file, inside Blender's first evaluation. The frame's bones come as the handler takes them:
    from memory with every B-Bone's joints (envelopes, B-Bones), else the bound bones' channel
    matrices. Not a product path: it needs Python drivers (blocked in untrusted files unless the
    function is known to Blender's secure-expression check) and a file per object."""

    def __init__(self, dq, rig, body):
        import struct
        import tempfile

        addon = sys.modules[ADDON]
        mod = addon.engine.context.dq_skin_modifiers(dq)[0]
        st = addon.SESSION.state_of(dq, mod)
        assert st.status.live and st.output.job is not None, st.status.message
        self.obj = body.copy()
        self.obj.data = body.data.copy()
        self.obj.name = f"{body.name} in-evaluation"
        bpy.context.scene.collection.objects.link(self.obj)
        for m in list(self.obj.modifiers):
            self.obj.modifiers.remove(m)
        n = len(body.data.vertices)
        folder = "/dev/shm" if os.path.isdir("/dev/shm") else tempfile.gettempdir()
        self.path = os.path.join(folder, f"dqskin-bench-{os.getpid()}-{self.obj.session_uid}.pc2")
        self.header = b"POINTCACHE2\0" + struct.pack("<iiffi", 1, n, 0.0, 1.0, 1)
        with open(self.path, "wb") as f:
            f.write(self.header + np.zeros(n * 3, np.float32).tobytes())
        self.fd = os.open(self.path, os.O_WRONLY)
        m = self.obj.modifiers.new("DQ Skin in evaluation", "MESH_CACHE")
        m.cache_format, m.filepath = "PC2", self.path
        m.time_mode, m.play_mode, m.eval_frame = "FRAME", "CUSTOM", 0.0
        m.deform_mode, m.interpolation = "OVERWRITE", "NONE"
        binding, segments = st.binding.binding, st.binding.segments
        self.bone_names = list(binding.bone_names)
        namespace = bpy.app.driver_namespace
        self.calls = 0
        frame, skin_many = addon.blender.pose.frame, addon.dqskin.skin_many  # (before `HandlerParts` wraps them)
        pose_matrices, live = addon.blender.rig.pose_matrices, st.needs_effective
        indices = binding.bone_indices
        all_bones = len(indices) == len(rig.pose.bones)

        def skin(*_):
            self.calls += 1
            arm_eval = rig.evaluated_get(namespace["depsgraph"])
            job = st.output.job
            if live:
                job.deform = frame(arm_eval, binding, segments).deform
            else:
                deform = pose_matrices(arm_eval)
                job.deform = deform if all_bones else np.ascontiguousarray(deform[indices])
            skin_many([job])
            os.pwrite(self.fd, memoryview(st.output.buffer).cast("B"), len(self.header))
            return 1.0

        self.name = f"dqskin_bench_skin_{self.obj.session_uid}"
        namespace[self.name] = skin
        self.variables = add_bone_driver(m, rig, binding.bone_names, f"{self.name}()")

    def remove(self):
        bpy.app.driver_namespace.pop(self.name, None)
        os.close(self.fd)
        os.unlink(self.path)


def add_bone_driver(modifier, rig, bone_names, expression: str) -> int:
    """A driver on `modifier`'s Factor ordered after every bone of `bone_names` in Blender's
    graph; returns its variable count. A Python driver costs about 0.6 µs per variable and
    evaluation, so only as many as order it after every bone the job reads: each B-Bone's
    segments (a B-Bone property links the driver after them), and the bones with no bound
    descendant (a bone is done before its children, so after those every bound bone is)."""
    driver = modifier.driver_add("factor").driver
    driver.type = "SCRIPTED"
    count = order_after_bones(driver, rig, bone_names)
    driver.expression = expression
    return count


def order_after_bones(driver, rig, bone_names, prefix: str = "b") -> int:
    """The add-on's own ordering of a driver after the bound bones (`feed.order_after_bones`)."""
    return sys.modules[ADDON].routes.feed.order_after_bones(driver, rig, list(bone_names), prefix)


class BatchedInEvaluation:
    """The in-evaluation alternative with one Python call per evaluation for many characters:
    a carrier object (in no scene; the characters' drivers pull it into the graph) whose custom
    property is driven by one Python driver ordered after every character's bound bones, which
    skins them all in one `skin_many` call and writes one PC2 file each; each character's copy
    has a Mesh Cache reading its file, whose driver (evaluated without Python) reads that
    property, so it runs after the batch. `dq`: DQ Skin objects whose modifiers are live on
    vertex groups, `pairs`: (body, rig) for each.

    `on_results`: the Mesh Caches go on DQ Skin's own result objects instead of on bare copies,
    so the DQ Skin objects themselves show the batch through their node groups: the add-on's
    structure (a result object and a node group per character) fed this way, with the add-on's
    handlers taken out while it is measured (`Unhandled`), the least a batched feed built into
    the add-on could cost before its handler checks anything."""

    def __init__(self, dq, pairs, on_results: bool = False):
        import struct
        import tempfile

        addon = sys.modules[ADDON]
        folder = "/dev/shm" if os.path.isdir("/dev/shm") else tempfile.gettempdir()
        self.carrier = bpy.data.objects.new("dqskin bench batch", None)
        self.carrier["go"] = 0.0
        self.name = f"dqskin_bench_batch_{self.carrier.session_uid}"
        self.objects, self.paths, self.fds, self.header_sizes = [], [], [], []
        states, plans = [], []
        batch = self.carrier.driver_add('["go"]').driver
        batch.type = "SCRIPTED"
        self.variables = 0
        for k, (d, (body, rig)) in enumerate(zip(dq, pairs)):
            st = addon.SESSION.state_of(d, addon.engine.context.dq_skin_modifiers(d)[0])
            assert st.status.live and st.output.job is not None and not st.needs_effective, st.status.message
            binding = st.binding.binding
            states.append(st)
            indices = binding.bone_indices
            plans.append((rig, None if len(indices) == len(rig.pose.bones) else indices))
            self.variables += order_after_bones(batch, rig, list(binding.bone_names), prefix=f"c{k}_")
            if on_results:
                o = st.output.result
            else:
                o = body.copy()
                o.data = body.data.copy()
                o.name = f"{body.name} batched"
                bpy.context.scene.collection.objects.link(o)
                for m in list(o.modifiers):
                    o.modifiers.remove(m)
            n = len(body.data.vertices)
            path = os.path.join(folder, f"dqskin-bench-batch-{os.getpid()}-{o.session_uid}.pc2")
            header = b"POINTCACHE2\0" + struct.pack("<iiffi", 1, n, 0.0, 1.0, 1)
            with open(path, "wb") as f:
                f.write(header + np.zeros(n * 3, np.float32).tobytes())
            self.paths.append(path)
            self.fds.append(os.open(path, os.O_WRONLY))
            self.header_sizes.append(len(header))
            m = o.modifiers.new("DQ Skin batched", "MESH_CACHE")
            m.cache_format, m.filepath = "PC2", path
            m.time_mode, m.play_mode, m.eval_frame = "FRAME", "CUSTOM", 0.0
            m.deform_mode, m.interpolation = "OVERWRITE", "NONE"
            drv = m.driver_add("factor").driver
            drv.type = "SCRIPTED"
            v = drv.variables.new()
            v.name, v.type = "go", "SINGLE_PROP"
            v.targets[0].id = self.carrier
            v.targets[0].data_path = '["go"]'
            drv.expression = "go"
            self.objects.append(o)
        self.on_results = on_results
        self.simple = all(o.animation_data.drivers[0].driver.is_simple_expression for o in self.objects)
        if on_results:
            self.objects = list(dq)  # what shows the batch: the DQ Skin objects
            self.results = [st.output.result for st in states]
        self.calls = 0
        namespace = bpy.app.driver_namespace
        skin_many, pose_matrices = addon.dqskin.skin_many, addon.blender.rig.pose_matrices
        fds, sizes = self.fds, self.header_sizes

        def skin(*_):
            self.calls += 1
            dg = namespace["depsgraph"]
            jobs = []
            for st, (rig, indices) in zip(states, plans):
                deform = pose_matrices(rig.evaluated_get(dg))
                job = st.output.job
                job.deform = deform if indices is None else np.ascontiguousarray(deform[indices])
                jobs.append(job)
            skin_many(jobs)
            for st, fd, size in zip(states, fds, sizes):
                os.pwrite(fd, memoryview(st.output.buffer).cast("B"), size)
            return 1.0

        namespace[self.name] = skin
        batch.expression = f"{self.name}()"

    def remove(self):
        bpy.app.driver_namespace.pop(self.name, None)
        if self.on_results:
            for r in self.results:
                r.driver_remove('modifiers["DQ Skin batched"].factor')
                r.modifiers.remove(r.modifiers["DQ Skin batched"])
        else:
            for o in self.objects:
                bpy.data.objects.remove(o)
        bpy.data.objects.remove(self.carrier)
        for fd, path in zip(self.fds, self.paths):
            os.close(fd)
            os.unlink(path)


class Unhandled:
    """DQ Skin's handlers taken out of Blender's handler lists (and put back where they were)."""

    NAMES = ("on_frame_change_pre", "on_frame_change_post", "on_depsgraph_update_post")

    def __init__(self):
        self.taken = []

    def __enter__(self):
        h = bpy.app.handlers
        for lst in (h.frame_change_pre, h.frame_change_post, h.depsgraph_update_post):
            for i, fn in reversed(list(enumerate(lst))):
                if getattr(fn, "__name__", "") in self.NAMES and getattr(fn, "__module__", "").startswith(ADDON):
                    self.taken.append((lst, i, fn))
                    lst.remove(fn)
        return self

    def __exit__(self, *exc):
        for lst, i, fn in reversed(self.taken):
            lst.insert(i, fn)
        self.taken.clear()


class Floors:
    """What Blender costs before any skinning, each on its own copy of `body` (which carries the
    Armature modifier on `rig`): `floor_mesh_cache`, a Mesh Cache modifier reading a fixed PC2
    file with a driver ordered after the bound bones whose expression Blender evaluates without
    Python (`is_simple_expression`): the mesh evaluated again after the pose, doing nothing;
    `floor_python_driver`, the same with a Python driver calling a function that does nothing
    (what entering Python from the evaluation costs); `floor_armature_idle`, the Armature modifier
    with vertex groups and envelopes off (Blender's own modifier visiting the vertices with no
    bone to add)."""

    def __init__(self, rig, body, bone_names):
        import struct
        import tempfile

        self.objects = {}
        folder = "/dev/shm" if os.path.isdir("/dev/shm") else tempfile.gettempdir()
        n = len(body.data.vertices)
        self.path = os.path.join(folder, f"dqskin-bench-floor-{os.getpid()}-{body.session_uid}.pc2")
        rest = np.empty(n * 3, np.float32)
        body.data.vertices.foreach_get("co", rest)
        with open(self.path, "wb") as f:
            f.write(b"POINTCACHE2\0" + struct.pack("<iiffi", 1, n, 0.0, 1.0, 1) + rest.tobytes())
        self.name = f"dqskin_bench_nothing_{body.session_uid}"
        bpy.app.driver_namespace[self.name] = lambda *_: 1.0
        self.simple = {}
        for kind in ("floor_mesh_cache", "floor_python_driver", "floor_armature_idle"):
            o = body.copy()
            o.data = body.data.copy()
            o.name = f"{body.name} {kind}"
            bpy.context.scene.collection.objects.link(o)
            self.objects[kind] = o
            if kind == "floor_armature_idle":
                a = o.modifiers["Armature"]
                a.use_vertex_groups = a.use_bone_envelopes = False
                continue
            for m in list(o.modifiers):
                o.modifiers.remove(m)
            m = o.modifiers.new("Floor", "MESH_CACHE")
            m.cache_format, m.filepath = "PC2", self.path
            m.time_mode, m.play_mode, m.eval_frame = "FRAME", "CUSTOM", 0.0
            m.deform_mode, m.interpolation = "OVERWRITE", "NONE"
            expression = "1.0" if kind == "floor_mesh_cache" else f"{self.name}()"
            add_bone_driver(m, rig, bone_names, expression)
            self.simple[kind] = o.animation_data.drivers[0].driver.is_simple_expression

    def remove(self):
        bpy.app.driver_namespace.pop(self.name, None)
        for o in self.objects.values():
            bpy.data.objects.remove(o)
        os.unlink(self.path)


def case_regenerate(quick: bool) -> dict:
    """Rigify's *Re-Generate Rig* with two DQ Skin characters on the rig, then the next frame,
    with the extension enabled and disabled (the same scene, as a file opened without it: the
    companions deform), alternating in one session."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    addon_utils.enable("rigify", default_set=True)
    body, rig, metarig = characters.build_rigify_character()
    addon_utils.enable("rigify", default_set=True)  # (build_rigify_character restores its state)
    second = body.copy()
    second.data = body.data.copy()
    bpy.context.scene.collection.objects.link(second)
    for o in (body, second):
        add_dq_skin(o, "DUAL_QUATERNION")
    bpy.context.scene.frame_set(8)

    def regenerate(frame: int) -> float:
        bpy.data.orphans_purge(do_recursive=True)  # what the last rebuild left (its old widgets)
        characters.select_only_object(metarig)
        t = time.perf_counter()
        assert bpy.ops.pose.rigify_generate() == {"FINISHED"}
        bpy.context.scene.frame_set(frame)
        for o in (body, second):
            o.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
        return time.perf_counter() - t

    def live() -> bool:
        addon = sys.modules[ADDON]
        return all(addon.SESSION.state_of(o, addon.engine.context.dq_skin_modifiers(o)[0]).status.live for o in (body, second))

    times = {"with_extension": [], "without_extension": []}
    skinned = []
    # Rebuilds drift (Rigify's data grows), so the order is balanced: with, without, without,
    # with, with, without.
    order = ("with_extension", "without_extension") * (1 if quick else 3)
    order = [name for k in range(0, len(order), 2) for name in (order[k : k + 2] if k % 4 == 0 else order[k : k + 2][::-1])]
    try:
        for k, name in enumerate(order):
            if name == "with_extension":
                times[name].append(regenerate(9 + k))
                skinned.append(live())  # DQ Skin deformed the frame after the rebuild
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
    row.update({f"{k}_each_s": [round(x, 3) for x in v] for k, v in times.items()})
    row.update(
        case="Rigify Re-Generate Rig, two DQ Skin characters on the rig, and the next frame",
        rounds=len(times["with_extension"]),
        dq_skin_live_after_each=all(skinned),
    )
    row["ratio"] = row["with_extension_s"] / row["without_extension_s"]
    return row


def case_binding(vertices: int) -> dict:
    """`dq_skin_add` until the first skinned frame is evaluated."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    grid, arm = grid_rig(vertices)
    bpy.context.scene.frame_set(9)
    t = time.perf_counter()
    add_dq_skin(grid, "DUAL_QUATERNION")
    grid.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    seconds = time.perf_counter() - t
    return {
        "case": f"dq_skin_add + first frame, {len(grid.data.vertices) // 1000}k",
        "vertices": len(grid.data.vertices),
        "seconds": seconds,
    }


def subdivided_cesium_man(levels: int):
    """CesiumMan with a Subdivision Surface applied (weights interpolated by Blender)."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.import_scene.gltf(filepath=str(ROOT.parent / "shared" / "assets" / "CesiumMan.glb"))
    obj = next(o for o in bpy.data.objects if o.type == "MESH")
    arm_mod = next(m for m in obj.modifiers if m.type == "ARMATURE")
    sub = obj.modifiers.new("Subdivision", "SUBSURF")
    sub.levels = sub.render_levels = levels
    while obj.modifiers[0] != sub:
        obj.modifiers.move(obj.modifiers.find(sub.name), 0)
    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(object=obj, active_object=obj):
        bpy.ops.object.modifier_apply(modifier=sub.name)
    return obj, arm_mod


def case_centers(levels: int) -> dict:
    """Optimized Centers on CesiumMan subdivided: the precompute, on the inputs the modifier
    gives it (the per-frame kernel is in the Rust benchmark, beside DQS)."""
    from bl_ext.user_default.dq_skin import centers, dqskin, rig

    obj, arm_mod = subdivided_cesium_man(levels)
    binding = rig.bind(obj, arm_mod.object, "", False)
    positions = rig.mesh_positions(obj.data)
    triangles = centers.triangles_of(obj.data)
    t = time.perf_counter()
    dqskin.centers_of_rotation(positions, triangles, binding.influences)
    precompute = time.perf_counter() - t
    return {
        "case": f"Optimized Centers precompute, CesiumMan subdivided ×{levels} ({len(positions) // 1000}k vertices)",
        "vertices": len(positions),
        "triangles": len(triangles),
        "seconds": precompute,
        "threads": dqskin.get_num_threads(),
    }


def case_weights(vertices: int, quick: bool) -> dict:
    """A weight change (`VertexGroup.add` on 1,000 vertices, like a brush stroke) until the
    evaluated mesh shows it, Armature modifier vs DQ Skin."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    grid, arm = grid_rig(vertices)
    bpy.context.scene.frame_set(9)
    variants, _ = three_ways(grid, "DUAL_QUATERNION")
    out = {"case": f"weight change, {len(grid.data.vertices) // 1000}k", "vertices": len(grid.data.vertices)}
    rng = np.random.default_rng(3)
    for rnd in range(2 if quick else 4):
        for name in ("armature", "dq_skin"):
            obj = variants[name]
            show_only(obj)
            ts = []
            for k in range(3 if quick else 7):
                idx = rng.choice(len(obj.data.vertices), 1000, replace=False).tolist()
                group = obj.vertex_groups[(k + rnd) % len(obj.vertex_groups)]
                t = time.perf_counter()
                group.add(idx, 0.3 + 0.05 * k, "REPLACE")
                bpy.context.view_layer.update()  # Blender evaluates, handlers run
                obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data  # and what they changed
                ts.append(time.perf_counter() - t)
            out.setdefault(f"{name}_ms", []).append(1e3 * float(np.median(ts)))
    for name in ("armature", "dq_skin"):
        out[f"{name}_ms"] = float(np.median(out[f"{name}_ms"]))
    out["ratio"] = out["dq_skin_ms"] / out["armature_ms"]
    return out


def crowd(count: int):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.import_scene.gltf(filepath=str(ROOT.parent / "shared" / "assets" / "CesiumMan.glb"))
    src = next(o for o in bpy.data.objects if o.type == "MESH" and any(m.type == "ARMATURE" for m in o.modifiers))
    arm0 = next(m for m in src.modifiers if m.type == "ARMATURE").object
    scene = bpy.context.scene
    pairs = [(src, arm0)]
    for i in range(count - 1):
        a = arm0.copy()
        scene.collection.objects.link(a)
        a.location.x += 1.0 + i
        m = src.copy()
        m.data = src.data.copy()
        scene.collection.objects.link(m)
        m.parent = a
        next(x for x in m.modifiers if x.type == "ARMATURE").object = a
        pairs.append((m, a))
    return pairs


def case_crowd(count: int, quick: bool) -> dict:
    """`count` CesiumMen, each with its own armature playing the walk: all with the Armature
    modifier, then all with DQ Skin (in the same session, alternating); then a move of an
    unrelated Empty in the DQ Skin scene, and DQ Skin's share of it."""
    pairs = crowd(count)
    meshes = [m for m, _ in pairs]
    dq = []
    for m in meshes:
        c = m.copy()
        c.data = m.data.copy()
        bpy.context.scene.collection.objects.link(c)
        dq.append(c)
    show_only(*dq)
    # One at a time (each add rebuilds the scene's relations, as adding any modifier does)...
    singles = dq[:10]
    t = time.perf_counter()
    for c in singles:
        add_dq_skin(c, "DUAL_QUATERNION")
    add_each_s = (time.perf_counter() - t) / len(singles)
    # ... or all selected objects in one operator call.
    rest = dq[10:]
    for o in bpy.context.view_layer.objects:
        o.select_set(o in rest)
    bpy.context.view_layer.objects.active = rest[0]
    t = time.perf_counter()
    with bpy.context.temp_override(active_object=rest[0], selected_objects=rest):
        assert bpy.ops.object.dq_skin_add(method="DUAL_QUATERNION", all_selected=True) == {"FINISHED"}
    add_rest_s = time.perf_counter() - t
    # The in-evaluation alternative, one Mesh Cache and driver per character (its own copies).
    show_only(*dq)
    for f in (3, 9):
        bpy.context.scene.frame_set(f)
    in_evaluation = [InEvaluation(c, a, m) for c, (m, a) in zip(dq, pairs)]
    floors = [Floors(a, m, e.bone_names) for e, (m, a) in zip(in_evaluation, pairs)]
    batched = BatchedInEvaluation(dq, pairs)
    # The same batch feeding DQ Skin's own results (built and taken down around each of its
    # rounds, with DQ Skin's handlers out meanwhile).
    on_results = {}

    def enter_on_results():
        on_results["unhandled"] = Unhandled().__enter__()
        on_results["batch"] = BatchedInEvaluation(dq, pairs, on_results=True)

    def leave_on_results():
        b = on_results.pop("batch")
        if "max_deviation" not in on_results:
            # What the DQ Skin objects showed is the batch's (as DQ Skin, Dual Quaternion).
            show_only(*dq, *meshes)
            on_results["max_deviation"] = deviation_from_preserve_volume(dq, meshes, 15)
        on_results["calls"] = on_results.get("calls", 0) + b.calls
        b.remove()
        on_results.pop("unhandled").__exit__()

    phases = Phases()
    phases.install()
    try:
        variants = {
            "armature": meshes,
            "dq_skin": dq,
            "in_evaluation": [e.obj for e in in_evaluation],
            "in_evaluation_batched": batched.objects,
            "in_evaluation_batched_on_results": dq,
        }
        for kind in floors[0].objects:
            variants[kind] = [f.objects[kind] for f in floors]
        hooks = {"in_evaluation_batched_on_results": (enter_on_results, leave_on_results)}
        row = alternate(variants, (3, 9, 15, 21), 2 if quick else 4, 5 if quick else 9, phases, hooks)
        row["in_evaluation_speedup"] = row["armature_ms"] / row["in_evaluation_ms"]
        row["in_evaluation_batched_speedup"] = row["armature_ms"] / row["in_evaluation_batched_ms"]
        row["in_evaluation_batched_on_results_speedup"] = row["armature_ms"] / row["in_evaluation_batched_on_results_ms"]
        row["in_evaluation_batched_on_results_calls"] = on_results.get("calls", 0)
        row["in_evaluation_batched_on_results_max_deviation"] = on_results.get("max_deviation")
        calls = sum(e.calls for e in in_evaluation)
        # The batch deforms as DQ Skin does (the same jobs): checked against the Armature
        # modifier with Preserve Volume, as the characters' DQ Skin is Dual Quaternion.
        show_only(*batched.objects, *meshes)
        batched.calls = 0
        row["in_evaluation_batched_max_deviation"] = deviation_from_preserve_volume(batched.objects, meshes, 15)
        row["in_evaluation_batched_calls_per_frame"] = batched.calls
        row["in_evaluation_batched_variables"] = batched.variables
        row["in_evaluation_batched_simple_expressions"] = batched.simple
    finally:
        phases.remove()
        for e in in_evaluation:
            e.remove()
        for e in in_evaluation:
            bpy.data.objects.remove(e.obj)
        for f in floors:
            f.remove()
        batched.remove()
    row["in_evaluation_driver_calls_per_character"] = calls / len(in_evaluation)
    show_only(*dq)
    row["reevaluation_floor_ms"] = reevaluation_ms(meshes[0])
    # An edit elsewhere: move an Empty, in each scene.
    empty = bpy.data.objects.new("Elsewhere", None)
    bpy.context.scene.collection.objects.link(empty)
    handler_time = []

    def timed(fn):
        def run(scene, depsgraph):
            t = time.perf_counter()
            fn(scene, depsgraph)
            handler_time.append(time.perf_counter() - t)

        return run

    dq_handler = next(h for h in bpy.app.handlers.depsgraph_update_post if h.__name__ == "on_depsgraph_update_post")
    wrapped = timed(dq_handler)
    for name, objs in (("armature", meshes), ("dq_skin", dq)):
        show_only(*objs)
        if name == "dq_skin":
            idx = bpy.app.handlers.depsgraph_update_post.index(dq_handler)
            bpy.app.handlers.depsgraph_update_post[idx] = wrapped
        ts = []
        for k in range(10 if quick else 30):
            t = time.perf_counter()
            empty.location.x = 0.01 * k
            bpy.context.view_layer.update()
            ts.append(time.perf_counter() - t)
        row[f"{name}_unrelated_edit_ms"] = 1e3 * float(np.median(ts))
    idx = bpy.app.handlers.depsgraph_update_post.index(wrapped)
    bpy.app.handlers.depsgraph_update_post[idx] = dq_handler
    row["dq_skin_unrelated_edit_handler_ms"] = 1e3 * float(np.median(handler_time)) if handler_time else 0.0
    row.update(
        case=f"{count} characters x {len(meshes[0].data.vertices)} vertices",
        objects=count,
        dq_skin_add_each_ms=1e3 * add_each_s,
        dq_skin_add_all_selected_ms=1e3 * add_rest_s,
        all_selected_objects=len(rest),
    )
    row["speedup"] = row["armature_ms"] / row["dq_skin_ms"]
    return row


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "target" / "bench-blender.json")
    parser.add_argument("--quick", action="store_true", help="smaller meshes, fewer rounds")
    parser.add_argument(
        "--only",
        nargs="*",
        default=None,
        help="case groups: grid, later, binding, weights, crowd, small, centers, bbones, rigify, regenerate",
    )
    args = parser.parse_args()
    if addon_utils.enable(ADDON, default_set=True) is None:
        raise SystemExit("the DQ Skin extension is not installed: run make setup")
    only = (
        set(args.only)
        if args.only
        else {"grid", "later", "binding", "weights", "crowd", "small", "centers", "bbones", "rigify", "regenerate"}
    )
    q = args.quick
    big = [250_000] if q else [250_000, 1_000_000]
    rows = []

    def report(row):
        rows.append(row)
        print(json.dumps({k: (round(v, 3) if isinstance(v, float) else v) for k, v in row.items()}), flush=True)

    if "grid" in only:
        for n in big:
            for method in ("LINEAR", "DUAL_QUATERNION"):
                report(case_grid(n, "", method, q))
    if "later" in only:
        for later in ("smooth5", "subsurf2"):
            for n in [250_000] if later == "subsurf2" or q else big:
                report(case_grid(n, later, "DUAL_QUATERNION", q))
    if "small" in only:
        for method in ("LINEAR", "DUAL_QUATERNION"):
            report(case_grid(3_000, "", method, q))
    if "binding" in only:
        for n in big:
            report(case_binding(n))
    if "weights" in only:
        report(case_weights(250_000, q))
    if "crowd" in only:
        report(case_crowd(50 if q else 200, q))
    if "centers" in only:
        for levels in [2] if q else [2, 3]:
            report(case_centers(levels))
    if "bbones" in only:
        for mapping in ("STRAIGHT", "CURVED"):
            for method in ("LINEAR", "DUAL_QUATERNION"):
                report(case_bbone_grid(100_000, mapping, method, q))
    if "rigify" in only:
        report(case_rigify(q))
    if "regenerate" in only:
        report(case_regenerate(q))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"blender": bpy.app.version_string, "threads": os.cpu_count(), "rows": rows}, indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

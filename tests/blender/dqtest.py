"""Shared helpers of the Blender tests (the only module test files import besides `scenes`, the
rig builders, and `conftest`).

- The same scene with Blender's own Armature modifier: `twin` (the object with each DQ Skin
  replaced by its companion set up as DQ Skin: Linear = Preserve Volume off, every other method
  on) and `plain_twin` (a new object with a plain Armature modifier, for linked data).
- Comparing evaluated meshes: `evaluated_positions`, `deviation` (relative to the bounding-box
  diagonal), `assert_same`, `check_frames`, `moved` (a test that moves nothing proves nothing).
- Building scenes: `add_dq_skin`, `import_character`, `animate`, `animated_tube`, `select_only`.
- Reading DQ Skin: `dq_skin_mods`, `get_input`, `get_attribute`, `method`, `status`, `draw_panel`,
  `assert_fed`.
"""

from __future__ import annotations

import json

import numpy as np
from scenes import rig_tube

import bpy

from mathutils import Quaternion

REL_TOL = 1e-5  # of the bounding-box diagonal (the bar of every exactness test)
FRAMES = (1, 4, 9, 13, 20, 2)
METHODS = ["LINEAR", "DUAL_QUATERNION"]


def dq_skin_mods(obj):
    return [m for m in obj.modifiers if m.type == "NODES" and m.node_group is not None and m.node_group.get("dq_skin_version")]


def _input(mod, name):
    ident = next(i.identifier for i in mod.node_group.interface.items_tree if getattr(i, "name", "") == name and i.in_out == "INPUT")
    if bpy.app.version >= (5, 2, 0):
        return getattr(mod.properties.inputs, ident)
    return ident


def get_input(mod, name):
    s = _input(mod, name)
    return s.value if not isinstance(s, str) else mod.get(s)


def get_attribute(mod, name):
    s = _input(mod, name)
    if not isinstance(s, str):
        return s.attribute_name if s.type == "ATTRIBUTE" else ""
    return mod.get(s + "_attribute_name", "") if mod.get(s + "_use_attribute") else ""


def method(mod) -> str:
    group = mod.node_group
    s = _input(mod, "Method")
    if not isinstance(s, str):
        return s.value
    switch = group.nodes["Method Items"]
    items = {int(x.identifier.split("_")[1]): x.name for x in switch.inputs if x.identifier.startswith("Item_")}
    return items[mod[s]]


def twin(obj, name: str | None = None, collection=None, share_mesh: bool = True):
    """`obj` with Blender's Armature modifier in place of each DQ Skin (see module doc). With
    `share_mesh` off the twin gets a copy of the mesh (objects sharing a mesh are evaluated
    together)."""
    plan = []
    for mod in dq_skin_mods(obj):
        info = json.loads(get_input(mod, "Companion") or "{}")
        plan.append(
            (
                mod.name,
                info.get("name"),
                dict(
                    object=get_input(mod, "Armature"),
                    use_vertex_groups=bool(get_input(mod, "Use Vertex Groups")),
                    use_bone_envelopes=bool(get_input(mod, "Use Envelopes")),
                    vertex_group=get_attribute(mod, "Mask"),
                    invert_vertex_group=bool(get_input(mod, "Invert Mask")),
                    use_deform_preserve_volume=method(mod) != "Linear",
                    use_multi_modifier=False,
                    show_viewport=mod.show_viewport,
                    show_render=mod.show_render,
                ),
            )
        )
    copy = obj.copy()
    if not share_mesh:
        copy.data = obj.data.copy()
    if name:
        copy.name = name
    (collection or bpy.context.scene.collection).objects.link(copy)
    used = set()
    for dq_name, arm_name, settings in plan:
        arm_mod = copy.modifiers.get(arm_name) if arm_name not in used else None
        if arm_mod is None:
            # A copy of a DQ Skin whose companion is its original's: an Armature modifier of
            # its own, in its place.
            arm_mod = copy.modifiers.new(f"{dq_name} twin", "ARMATURE")
            with bpy.context.temp_override(object=copy, active_object=copy):
                bpy.ops.object.modifier_move_to_index(modifier=arm_mod.name, index=copy.modifiers.find(dq_name))
        assert arm_mod.type == "ARMATURE", f"{obj.name}: no companion {arm_name!r} after {dq_name!r}"
        used.add(arm_mod.name)
        for k, v in settings.items():
            setattr(arm_mod, k, v)
        copy.modifiers.remove(copy.modifiers[dq_name])
    drop_carriers(copy)
    return copy


def is_carrier(mod) -> bool:
    """A Mesh Cache modifier DQ Skin keeps before its modifier (its positions, see the add-on's
    `routes.cache_route`): copies made here to hold Blender's own deformation drop it."""
    return mod.type == "MESH_CACHE" and mod.filepath.replace("\\", "/").rpartition("/")[2].startswith("dqskin-")


def stack(obj) -> list[str]:
    """The types of `obj`'s modifiers as the artist arranged them (DQ Skin's carriers left out)."""
    return [m.type for m in obj.modifiers if not is_carrier(m)]


def drop_carriers(obj) -> None:
    for m in [m for m in obj.modifiers if is_carrier(m)]:
        obj.modifiers.remove(m)


def plain_twin(obj, name: str | None = None):
    """A new local object using `obj`'s mesh, parent and transform, deformed only by Blender's
    Armature modifier set up like `obj`'s (first) DQ Skin. For linked and overridden objects,
    whose copies would be library data themselves."""
    mod = dq_skin_mods(obj)[0]
    copy = bpy.data.objects.new(name or f"{obj.name} twin", obj.data)
    bpy.context.scene.collection.objects.link(copy)
    copy.parent = obj.parent
    copy.matrix_parent_inverse = obj.matrix_parent_inverse.copy()
    copy.matrix_basis = obj.matrix_basis.copy()
    m = copy.modifiers.new("Armature", "ARMATURE")
    m.object = get_input(mod, "Armature")
    m.use_vertex_groups = bool(get_input(mod, "Use Vertex Groups"))
    m.use_bone_envelopes = bool(get_input(mod, "Use Envelopes"))
    m.vertex_group = get_attribute(mod, "Mask")
    m.invert_vertex_group = bool(get_input(mod, "Invert Mask"))
    m.use_deform_preserve_volume = method(mod) != "Linear"
    return copy


def evaluated_positions(obj, depsgraph=None) -> np.ndarray:
    dg = depsgraph or bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(dg)
    mesh = ev.to_mesh()
    try:
        flat = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", flat)
    finally:
        ev.to_mesh_clear()
    return flat.reshape(-1, 3)


def deviation(a: np.ndarray, b: np.ndarray) -> float:
    """Largest distance between matching vertices, relative to `b`'s bounding-box diagonal."""
    assert a.shape == b.shape, f"different vertex counts: {a.shape} vs {b.shape}"
    diag = float(np.linalg.norm(b.max(0) - b.min(0))) if len(b) else 1.0
    return float(np.abs(a - b).max(initial=0.0)) / diag


def assert_same(obj, reference, what: str = "", tol: float = REL_TOL) -> float:
    dev = deviation(evaluated_positions(obj), evaluated_positions(reference))
    assert dev <= tol, f"{what or obj.name}: {dev:.3e} of the diagonal from Blender's Armature modifier"
    return dev


def moved(obj, frames=(1, 10)) -> float:
    """How far the object's vertices move between two frames (a test that moves nothing proves
    nothing)."""
    scene = bpy.context.scene
    scene.frame_set(frames[0])
    a = evaluated_positions(obj)
    scene.frame_set(frames[1])
    b = evaluated_positions(obj)
    return float(np.abs(a - b).max()) if a.shape == b.shape else float("inf")


def names_of_calls(monkeypatch, module, function: str) -> list:
    """The names of the objects `module.function(obj, ...)` is called with from now on, in order
    (a list that grows as it is called)."""
    calls = []
    real = getattr(module, function)
    monkeypatch.setattr(module, function, lambda obj, *a: calls.append(obj.name) or real(obj, *a))
    return calls


def swap_armature(dq_skin, obj, reference, mod, arm):
    """A script's change between frames: DQ Skin of `obj` and the Armature modifier of its
    `reference` both given a copy of `arm`, one unit away (the same animation: the mesh follows
    it)."""
    other = arm.copy()
    bpy.context.scene.collection.objects.link(other)
    other.location.x += 1.0
    dq_skin.blender.nodes.put(mod, "Armature", other)
    next(m for m in reference.modifiers if m.type == "ARMATURE").object = other


def check_frames(pairs, frames=FRAMES):
    """Every (ours, twin) pair equal at every frame; returns the worst deviation."""
    worst = 0.0
    for f in frames:
        bpy.context.scene.frame_set(f)
        for ours, ref in pairs:
            worst = max(worst, assert_same(ours, ref, f"{ours.name} at frame {f}"))
    return worst


def add_dq_skin(obj, method: str = "AUTO"):
    """`object.dq_skin_add` on `obj`; returns its (last) DQ Skin modifier."""
    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.object.dq_skin_add(method=method) == {"FINISHED"}
    return dq_skin_mods(obj)[-1]


def import_character(path):
    """A glTF character: its skinned mesh and that mesh's Armature modifier."""
    bpy.ops.import_scene.gltf(filepath=str(path))
    mesh_obj = next(o for o in bpy.data.objects if o.type == "MESH" and any(m.type == "ARMATURE" for m in o.modifiers))
    mod = next(m for m in mesh_obj.modifiers if m.type == "ARMATURE")
    return mesh_obj, mod


def action_frames(action):
    start, end = (int(round(f)) for f in action.frame_range)
    return range(start, end + 1)


def animate(arm, seed: float = 0.0):
    """Keys on every bone over frames 1-20: bends and twists beyond 90° (where LBS and DQS
    differ a lot)."""
    for i, pb in enumerate(arm.pose.bones):
        pb.rotation_mode = "QUATERNION"
        for frame, angle in ((1, 0.0), (10, 1.4 + seed), (20, 2.6 - seed)):
            axis = (1.0, 0.3 * i, 0.2) if i % 2 else (0.1, 1.0, 0.4 + seed)
            pb.rotation_quaternion = Quaternion(axis, angle * (0.5 if i == 0 else 1.0))
            pb.keyframe_insert("rotation_quaternion", frame=frame)
    return arm


def animated_tube(seed: float = 0.0, **kw):
    obj, arm, mod = rig_tube(**kw)
    obj.parent = arm
    animate(arm, seed)
    return obj, arm, mod


def select_only(*objs):
    for o in bpy.context.view_layer.objects:
        o.select_set(o in objs)
    bpy.context.view_layer.objects.active = objs[0]


def status(dq_skin, obj, mod=None):
    """What DQ Skin's panel knows about a modifier (`state.Status`)."""
    return dq_skin.SESSION.status_of(obj, mod or dq_skin_mods(obj)[0])


def route_of(dq_skin, obj, mod=None) -> str:
    """How the modifier's positions reach Blender: "cache" (a Mesh Cache carrier, fed inside
    Blender's first evaluation), "node" (a result object, fed likewise), "result" (written after
    the first evaluation) or "" (nothing published)."""
    route = dq_skin.SESSION.state_of(obj, mod or dq_skin_mods(obj)[0]).output.route
    return route.value if route is not None else ""


def output_of(obj, mod):
    """Where a modifier's positions go: the file its carrier reads, or the result object its
    node group outputs (each modifier must have its own)."""
    mods = list(obj.modifiers)
    before = mods[: mods.index(mod)]
    while before and before[-1].type == "SOFT_BODY":
        before.pop()
    if before and is_carrier(before[-1]):
        return ("carrier", before[-1].filepath)
    result = get_input(mod, "Result")
    return ("result", result.session_uid if result is not None else None)


def fed_runs(dq_skin, obj, mod=None) -> int:
    """Frames the feed skinned this modifier inside Blender's evaluation."""
    key = dq_skin.engine.context.mod_key(obj, mod or dq_skin_mods(obj)[0])
    return dq_skin.SESSION.routes.feeds.runs(key)


def assert_fed(dq_skin, obj, route: str | None = None) -> None:
    """Every DQ Skin of `obj` is skinned inside Blender's first evaluation at a frame change
    (on `route` if given: "cache" or "node")."""
    scene = bpy.context.scene
    scene.frame_set(scene.frame_current)
    before = {m.name: fed_runs(dq_skin, obj, m) for m in dq_skin_mods(obj)}
    scene.frame_set(scene.frame_current + 1)
    scene.frame_set(scene.frame_current - 1)
    for mod in dq_skin_mods(obj):
        st = status(dq_skin, obj, mod)
        assert st.live, f"{obj.name}: {st.message}"
        assert route_of(dq_skin, obj, mod) in ((route,) if route else ("cache", "node")), f"{obj.name}: {route_of(dq_skin, obj, mod)!r}"
        assert fed_runs(dq_skin, obj, mod) >= before[mod.name] + 1, f"{obj.name}: not skinned by the feed"


class _Recorder:
    """Stands in for a panel layout and records the labels drawn."""

    def __init__(self, lines):
        self.lines = lines

    def row(self, **_):
        return self

    def box(self, **_):
        return self

    def column(self, **_):
        return self

    def separator(self, **_):
        pass

    def prop(self, data, name, text="", **_):
        self.lines.append(f"<{name}>")

    def label(self, text="", **_):
        self.lines.append(text)

    def progress(self, text="", **_):
        self.lines.append(text)

    def operator(self, idname, text="", **_):
        self.lines.append(f"[{idname}]")
        return type("Props", (), {})()


def draw_panel(dq_skin, obj):
    """The lines DQ Skin's panel draws for `obj`."""
    lines = []
    panel = type("P", (), {"layout": _Recorder(lines)})()
    context = type("C", (), {"object": obj})()
    dq_skin.panel.OBJECT_PT_dq_skin.draw(panel, context)
    return lines


def reference_copy(obj, preserve_volume: bool):
    """A copy of `obj` sharing its mesh, deformed by a plain Armature modifier (set up as before
    DQ Skin was added, if it was)."""
    original = {}
    for m in dq_skin_mods(obj):
        original = json.loads(get_input(m, "Companion") or "{}").get("original", {})
    copy = obj.copy()
    bpy.context.scene.collection.objects.link(copy)
    for m in list(copy.modifiers):
        if m.type == "NODES":
            copy.modifiers.remove(m)
    drop_carriers(copy)
    arm_mod = next(m for m in copy.modifiers if m.type == "ARMATURE")
    for name in ("use_vertex_groups", "use_bone_envelopes", "vertex_group", "invert_vertex_group"):
        if name in original:
            setattr(arm_mod, name, original[name])
    arm_mod.show_viewport = True
    arm_mod.show_render = True
    arm_mod.use_deform_preserve_volume = preserve_volume
    return copy


def perturbed(obj, relative: float = 2e-7, seed: int = 0):
    """A copy of `obj` whose deformed mesh is moved by random offsets (drawn with `seed`) of
    `relative` times its size, what two exact float32 skinnings differ by: how much a consumer
    amplifies that is the precision a comparison of consumers can expect."""
    copy = obj.copy()
    copy.data = obj.data.copy()
    bpy.context.scene.collection.objects.link(copy)
    group = bpy.data.node_groups.new("float noise", "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    i, o = group.nodes.new("NodeGroupInput"), group.nodes.new("NodeGroupOutput")
    sp, rnd = group.nodes.new("GeometryNodeSetPosition"), group.nodes.new("FunctionNodeRandomValue")
    rnd.data_type = "FLOAT_VECTOR"
    amp = relative * float(np.linalg.norm(np.ptp(np.array([list(c) for c in obj.bound_box]), axis=0)))
    rnd.inputs["Min"].default_value, rnd.inputs["Max"].default_value = (-amp,) * 3, (amp,) * 3
    rnd.inputs["Seed"].default_value = seed
    group.links.new(i.outputs[0], sp.inputs["Geometry"])
    group.links.new(rnd.outputs["Value"], sp.inputs["Offset"])
    group.links.new(sp.outputs[0], o.inputs[0])
    copy.modifiers.new("float noise", "NODES").node_group = group
    return copy

"""The same scene with Blender's own Armature modifier: a twin of a DQ Skin object whose stack
has each DQ Skin replaced by its companion Armature modifier, set up as DQ Skin (Linear:
Preserve Volume off; Dual Quaternion: on), enabled. The twin shares the object's mesh, shape
keys, parent, transform and every other modifier, so the two must evaluate to the same mesh."""

from __future__ import annotations

import json

import bpy
import numpy as np

REL_TOL = 1e-5  # of the bounding-box diagonal (the bar)


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
    for dq_name, arm_name, settings in plan:
        arm_mod = copy.modifiers.get(arm_name)
        assert arm_mod is not None and arm_mod.type == "ARMATURE", f"{obj.name}: no companion {arm_name!r} after {dq_name!r}"
        for k, v in settings.items():
            setattr(arm_mod, k, v)
        copy.modifiers.remove(copy.modifiers[dq_name])
    return copy


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

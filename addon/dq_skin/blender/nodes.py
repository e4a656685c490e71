# SPDX-License-Identifier: GPL-3.0-or-later
"""The node group behind every DQ Skin modifier.

A DQ Skin modifier is a Geometry Nodes modifier with this group, so it lives in the modifier
stack like any modifier (order, toggles, name, settings saved per modifier in the .blend).
What it outputs depends on its hidden *Result* object, which the add-on owns (one per object and
modifier, never saved in files) and whose transform says what to do (`results.set_mode`):

- *replace* (X location 1): the result is a full copy of the object's mesh with skinned
  positions, output as is (no per-vertex work at all; four nodes evaluated per frame);
- *positions* (scale 2): the result holds only points; the input gets their positions (when
  the point counts match);
- *pending* (Z location 1): the add-on is about to write this frame's result: output
  nothing, so the modifiers after this one cost nothing in the evaluation Blender runs before
  its frame handlers (the add-on's handler always follows with the real result);
- otherwise, or without a result object (files opened without the add-on, linked data,
  errors): the input passes through unchanged and the Armature modifier kept right after DQ
  Skin (its *companion*) deforms the mesh the way Blender does. A Warning node says so
  (Blender 4.3+).

With *Capture* on, the incoming positions are stored in the point attribute named by *Capture
Name* first: the add-on reads them back when modifiers before DQ Skin deform the mesh.
"""

from __future__ import annotations

import json
from types import MappingProxyType

import bpy

from . import compat

GROUP_NAME = "DQ Skin"
GROUP_TAG = "dq_skin_version"
VERSION = 2

# What a result object's transform asks the group to do (see `results.set_mode`).
RESULT_OFF = 0
RESULT_REPLACE = 1
RESULT_POSITIONS = 2
RESULT_PENDING = 3
RESULT_SCALE_POSITIONS = 2.0

METHODS = ("Linear", "Dual Quaternion", "Blend", "Optimized Centers")
METHOD_KEYS = MappingProxyType(
    {"Linear": "linear", "Dual Quaternion": "dual_quaternion", "Blend": "blend", "Optimized Centers": "centers_of_rotation"}
)
WARNING = (
    "DQ Skin is not deforming this mesh: the Armature modifier after it does, as Blender would "
    "(the DQ Skin panel says why; without the DQ Skin extension it always does)"
)

# (name, socket type, default, min, max, description, hidden)
SETTINGS = (
    (
        "Armature",
        "NodeSocketObject",
        None,
        None,
        None,
        "The armature whose bones deform this mesh (as the Armature modifier's Object)",
        False,
    ),
    (
        "Method",
        "NodeSocketMenu",
        "Dual Quaternion",
        None,
        None,
        "How bones bend the mesh: Linear (Preserve Volume off), Dual Quaternion (Preserve Volume on: no candy wrapper when twisting), Blend (a painted mix of both) or Optimized Centers (no candy wrapper and less bulging at bent joints)",
        False,
    ),
    (
        "Blend Amount",
        "NodeSocketFloat",
        1.0,
        0.0,
        1.0,
        "Blend method: how much Dual Quaternion each vertex gets, 0 = Linear, 1 = Dual Quaternion (pick a vertex group with the attribute toggle, or paint one from the DQ Skin panel)",
        False,
    ),
    ("Blend Factor", "NodeSocketFloat", 1.0, 0.0, 1.0, "Blend method: scales the Blend Amount everywhere (0 = all Linear)", False),
    (
        "Use Vertex Groups",
        "NodeSocketBool",
        True,
        None,
        None,
        "Vertex Groups: bones deform the vertices of the vertex groups named after them (as the Armature modifier's Vertex Groups)",
        False,
    ),
    (
        "Use Envelopes",
        "NodeSocketBool",
        False,
        None,
        None,
        "Bone Envelopes: bones deform the vertices inside their envelopes (as the Armature modifier's Bone Envelopes)",
        False,
    ),
    (
        "Mask",
        "NodeSocketFloat",
        1.0,
        0.0,
        1.0,
        "How strongly the armature deforms each vertex (pick a vertex group with the attribute toggle), as the Armature modifier's Vertex Group",
        False,
    ),
    (
        "Invert Mask",
        "NodeSocketBool",
        False,
        None,
        None,
        "Deform where the mask group is 0 instead of 1 (as the Armature modifier's Invert)",
        False,
    ),
    ("Result", "NodeSocketObject", None, None, None, "Internal: the skinned result DQ Skin writes (never saved)", True),
    ("Capture", "NodeSocketBool", False, None, None, "Internal: store the incoming positions for the add-on", True),
    ("Capture Name", "NodeSocketString", "", None, None, "Internal: the attribute the incoming positions are stored in", True),
    (
        "Companion",
        "NodeSocketString",
        "",
        None,
        None,
        "Internal: the Armature modifier kept for Blender without DQ Skin, and its settings before DQ Skin",
        True,
    ),
)
FIELDS = ("Blend Amount", "Mask")


def is_dq_skin(modifier) -> bool:
    group = modifier.node_group if modifier.type == "NODES" else None
    return group is not None and group.get(GROUP_TAG) is not None


def version_of(group) -> int:
    return int(group.get(GROUP_TAG, 0)) if group is not None else 0


IDS_TAG = "dq_skin_socket_ids"  # input name -> identifier, stored on the group (see `store_ids`)
MENU_TAG = "dq_skin_menu_values"  # menu value -> method name, stored on the group (up to 5.1)


def _read_socket_ids(group) -> dict[str, str]:
    return {item.name: item.identifier for item in group.interface.items_tree if item.item_type == "SOCKET" and item.in_out == "INPUT"}


def _read_menu_values(group) -> dict[str, str]:
    switch = group.nodes.get("Method Items")
    return {sock.identifier.split("_")[1]: sock.name for sock in switch.inputs if sock.identifier.startswith("Item_")}


def store_ids(group) -> None:
    """Stores the group's input identifiers and menu values on the group itself (when it is
    built or upgraded), so that reading a setting is a dictionary lookup."""
    if group.library is not None:
        return
    ids, menu = _read_socket_ids(group), _read_menu_values(group)
    if dict(group.get(IDS_TAG, {})) != ids:
        group[IDS_TAG] = ids
    if dict(group.get(MENU_TAG, {})) != menu:
        group[MENU_TAG] = menu


def socket_ids(group) -> dict[str, str]:
    """Input name -> identifier (the key of the modifier's value)."""
    stored = group.get(IDS_TAG)
    return stored if stored is not None else _read_socket_ids(group)


def menu_values(group) -> dict[int, str]:
    """Menu value stored in a modifier -> method item name (up to Blender 5.1)."""
    stored = group.get(MENU_TAG)
    values = stored if stored is not None else _read_menu_values(group)
    return {int(k): v for k, v in values.items()}


RAW = ("Armature", "Method", "Blend Amount", "Blend Factor", "Use Vertex Groups", "Use Envelopes", "Mask", "Invert Mask")


def raw_settings(mod) -> tuple:
    """The settings' stored values, cheap to read and compare (see `settings.cached`)."""
    ids = socket_ids(mod.node_group)
    if compat.RNA_INPUTS:
        inputs = mod.properties.inputs
        return tuple((s.value, s.type, getattr(s, "attribute_name", "")) for s in (getattr(inputs, ids[n]) for n in RAW))
    get = mod.get
    return tuple(get(ids[n]) for n in RAW) + tuple((get(ids[n] + "_use_attribute"), get(ids[n] + "_attribute_name")) for n in FIELDS)


# -- reading and writing a modifier's settings ---------------------------------------------------


def get(mod, name: str):
    return compat.get_input(mod, socket_ids(mod.node_group)[name])


def put(mod, name: str, value) -> bool:
    """Sets a setting; returns whether it changed."""
    return compat.set_input(mod, socket_ids(mod.node_group)[name], value)


def get_attribute(mod, name: str) -> str:
    return compat.get_attribute(mod, socket_ids(mod.node_group)[name])


def put_attribute(mod, name: str, group: str) -> None:
    compat.set_attribute(mod, socket_ids(mod.node_group)[name], group)


def get_method(mod) -> str:
    """'Linear', 'Dual Quaternion' or 'Blend'."""
    group = mod.node_group
    return compat.get_menu(mod, socket_ids(group)["Method"], menu_values(group)) or "Dual Quaternion"


def put_method(mod, item: str) -> bool:
    group = mod.node_group
    return compat.set_menu(mod, socket_ids(group)["Method"], menu_values(group), item)


def get_companion(mod) -> dict:
    """What DQ Skin remembers of its companion Armature modifier: ``{"name": ..., "original":
    {setting: value}}`` (empty if nothing)."""
    try:
        data = json.loads(get(mod, "Companion") or "{}")
    except (ValueError, TypeError):
        return {}
    return data if isinstance(data, dict) else {}


def put_companion(mod, data: dict) -> None:
    put(mod, "Companion", json.dumps(data, sort_keys=True))


# -- the group ------------------------------------------------------------------------------------


def ensure_group():
    """The DQ Skin node group, created on first use (shared by all DQ Skin modifiers)."""
    for group in bpy.data.node_groups:
        if group.bl_idname == "GeometryNodeTree" and group.get(GROUP_TAG) == VERSION and group.library is None:
            upgrade(group)
            return group
    return build_group()


def upgrade(group) -> None:
    """A group saved by an earlier DQ Skin 0.x, brought up to date in place (the modifiers'
    stored values stay valid): the newer methods, the current warning."""
    if group.library is not None:
        return
    add_missing_methods(group)
    descriptions = {name: description for name, *_rest, description, _hidden in SETTINGS}
    for item in group.interface.items_tree:
        if getattr(item, "item_type", "") == "SOCKET" and item.in_out == "INPUT" and item.name in descriptions:
            if item.description != descriptions[item.name]:
                item.description = descriptions[item.name]
    warning = next((n for n in group.nodes if n.bl_idname == "GeometryNodeWarning"), None)
    if warning is not None and warning.inputs["Message"].default_value != WARNING:
        warning.inputs["Message"].default_value = WARNING
    store_ids(group)


def add_missing_methods(group) -> None:
    """Groups saved by an earlier DQ Skin 0.x lack the newer methods: add them at the end (the
    stored values of the existing ones do not change)."""
    switch = group.nodes.get("Method Items")
    if switch is None or group.library is not None:
        return
    have = {item.name for item in switch.enum_items}
    missing = [m for m in METHODS if m not in have]
    for item in missing:
        switch.enum_items.new(item)


def build_group():
    group = bpy.data.node_groups.new(GROUP_NAME, "GeometryNodeTree")
    group[GROUP_TAG] = VERSION
    iface = group.interface
    iface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    iface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    method_socket = None
    for name, kind, default, lo, hi, description, hidden in SETTINGS:
        sock = iface.new_socket(name, in_out="INPUT", socket_type=kind)
        sock.description = description
        if lo is not None:
            sock.min_value, sock.max_value = lo, hi
        if default is not None and kind != "NodeSocketMenu":
            sock.default_value = default
        if kind == "NodeSocketBool" or (kind == "NodeSocketFloat" and name not in FIELDS):
            sock.force_non_field = True
        if hidden:
            sock.hide_in_modifier = True
        if kind == "NodeSocketMenu":
            method_socket = sock
    nodes, links = group.nodes, group.links

    def node(kind, **props):
        n = nodes.new(kind)
        for k, v in props.items():
            setattr(n, k, v)
        return n

    g_in = node("NodeGroupInput")
    g_out = node("NodeGroupOutput")
    # The Method menu's items live on a Menu Switch; its output is not used.
    switch = node("GeometryNodeMenuSwitch")
    switch.name = "Method Items"
    switch.enum_items.clear()
    for item in METHODS:
        switch.enum_items.new(item)
    links.new(g_in.outputs["Method"], switch.inputs["Menu"])
    # Set after the items exist (and not while iterating the interface: Blender 4.4.0 crashes).
    method_socket.default_value = "Dual Quaternion"

    # The result and what it asks for: X location 1 for "replace", Z location 1 for "pending",
    # scale 2 for "positions" (a number is true when positive, so the per-frame path, replace,
    # evaluates four nodes).
    info = node("GeometryNodeObjectInfo", transform_space="ORIGINAL")
    links.new(g_in.outputs["Result"], info.inputs["Object"])
    where = node("ShaderNodeSeparateXYZ")
    links.new(info.outputs["Location"], where.inputs[0])

    # Not replacing: positions mode, or pass through (with the warning), both after the
    # optional capture of the incoming positions. Evaluated only when needed (switches are lazy).
    position = node("GeometryNodeInputPosition")
    store = node("GeometryNodeStoreNamedAttribute", data_type="FLOAT_VECTOR", domain="POINT")
    links.new(g_in.outputs["Geometry"], store.inputs["Geometry"])
    links.new(g_in.outputs["Capture Name"], store.inputs["Name"])
    links.new(position.outputs["Position"], store.inputs["Value"])
    captured = geometry_switch(node, links, g_in.outputs["Capture"], g_in.outputs["Geometry"], store.outputs["Geometry"])
    scale = node("ShaderNodeSeparateXYZ")
    links.new(info.outputs["Scale"], scale.inputs[0])
    is_positions = equal(node, links, scale.outputs["X"], RESULT_SCALE_POSITIONS, "VALUE")
    size_in = node("GeometryNodeAttributeDomainSize", component="MESH")
    size_result = node("GeometryNodeAttributeDomainSize", component="MESH")
    links.new(g_in.outputs["Geometry"], size_in.inputs["Geometry"])
    links.new(info.outputs["Geometry"], size_result.inputs["Geometry"])
    same_points = equal(node, links, size_in.outputs["Point Count"], size_result.outputs["Point Count"], "INT")
    use_positions = boolean(node, links, "AND", is_positions, same_points)
    index = node("GeometryNodeInputIndex")
    sample = node("GeometryNodeSampleIndex", data_type="FLOAT_VECTOR", domain="POINT")
    links.new(info.outputs["Geometry"], sample.inputs["Geometry"])
    links.new(position.outputs["Position"], sample.inputs["Value"])
    links.new(index.outputs["Index"], sample.inputs["Index"])
    set_position = node("GeometryNodeSetPosition")
    links.new(captured, set_position.inputs["Geometry"])
    links.new(sample.outputs["Value"], set_position.inputs["Position"])
    passed = captured
    if compat.HAS_WARNING_NODE:
        # Reached only when DQ Skin is not deforming; a Warning node shows when its output is used.
        warning = node("GeometryNodeWarning", warning_type="WARNING")
        warning.inputs["Show"].default_value = True
        warning.inputs["Message"].default_value = WARNING
        passed = geometry_switch(node, links, warning.outputs["Show"], captured, captured)
    not_replacing = geometry_switch(node, links, use_positions, passed, set_position.outputs["Geometry"])

    out = geometry_switch(node, links, where.outputs["X"], not_replacing, info.outputs["Geometry"])
    out = geometry_switch(node, links, where.outputs["Z"], out, None)  # nothing while pending
    links.new(out, g_out.inputs["Geometry"])
    for i, n in enumerate(nodes):
        n.location = (180 * (i % 8), -200 * (i // 8))
    store_ids(group)
    return group


def geometry_switch(node, links, condition, if_false, if_true):
    s = node("GeometryNodeSwitch", input_type="GEOMETRY")
    links.new(condition, s.inputs["Switch"])
    if if_false is not None:
        links.new(if_false, s.inputs["False"])
    if if_true is not None:
        links.new(if_true, s.inputs["True"])
    return s.outputs[0]


def equal(node, links, a, b, socket_type: str):
    data_type = {"VALUE": "FLOAT", "INT": "INT"}[socket_type]
    c = node("FunctionNodeCompare", data_type=data_type, operation="EQUAL")
    sa, sb = compat.compare_sockets(c, socket_type)
    links.new(a, sa)
    if isinstance(b, float):
        sb.default_value = b
    else:
        links.new(b, sb)
    return c.outputs["Result"]


def boolean(node, links, operation: str, a, b=None):
    m = node("FunctionNodeBooleanMath", operation=operation)
    links.new(a, m.inputs[0])
    if b is not None:
        links.new(b, m.inputs[1])
    return m.outputs[0]

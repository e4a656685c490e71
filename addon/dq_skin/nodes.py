# SPDX-License-Identifier: GPL-3.0-or-later
"""The node group behind every DQ Skin modifier.

A DQ Skin modifier is a Geometry Nodes modifier with this group, so it lives in the modifier
stack like any modifier (order, toggles, name, settings saved per modifier in the .blend). The
group does two things the add-on relies on:
1. it stores the coordinates that reach it in the point attribute `dq_skin_input`, which the
   add-on reads from the evaluated mesh (shape keys and earlier deform modifiers included);
2. it sets each point's position to the same point of the modifier's *result* object, a
   vertex-only mesh outside any scene into which the add-on writes the skinned positions.
If the result does not have the same number of points, the input passes through unchanged.
"""

from __future__ import annotations

import bpy

GROUP_NAME = "DQ Skin"
GROUP_TAG = "dq_skin_version"
VERSION = 1
INPUT_ATTRIBUTE = "dq_skin_input"

METHODS = ("Linear", "Dual Quaternion", "Blend")
METHOD_KEYS = {"Linear": "linear", "Dual Quaternion": "dual_quaternion", "Blend": "blend"}

# (name, socket type, default, min, max, description)
SETTINGS = (
    ("Armature", "NodeSocketObject", None, None, None, "The armature object that deforms the mesh"),
    ("Method", "NodeSocketMenu", "Dual Quaternion", None, None, "Linear, Dual Quaternion, or a per-vertex blend of both"),
    ("Blend Amount", "NodeSocketFloat", 1.0, 0.0, 1.0, "Blend: how much Dual Quaternion per vertex (pick a vertex group with the attribute toggle)"),
    ("Blend Factor", "NodeSocketFloat", 1.0, 0.0, 1.0, "Blend: overall factor multiplied with the amount"),
    ("Use Vertex Groups", "NodeSocketBool", True, None, None, "Bind bones to vertex groups of the same name"),
    ("Use Envelopes", "NodeSocketBool", False, None, None, "Bind bones to vertices inside their envelopes"),
    ("Mask", "NodeSocketFloat", 1.0, 0.0, 1.0, "Strength per vertex (pick a vertex group with the attribute toggle), as the Armature modifier's vertex group"),
    ("Invert Mask", "NodeSocketBool", False, None, None, "Invert the mask"),
    ("Result", "NodeSocketObject", None, None, None, "Internal: where DQ Skin writes the skinned positions"),
)


def is_dq_skin(modifier) -> bool:
    return (
        modifier.type == "NODES"
        and modifier.node_group is not None
        and modifier.node_group.get(GROUP_TAG) is not None
    )


def socket_ids(group) -> dict[str, str]:
    """Input name -> identifier (the modifier's property key)."""
    return {
        item.name: item.identifier
        for item in group.interface.items_tree
        if item.item_type == "SOCKET" and item.in_out == "INPUT"
    }


def menu_values(group) -> dict[int, str]:
    """Menu value stored in a modifier -> method item name."""
    switch = group.nodes.get("Method Items")
    return {
        int(sock.identifier.split("_")[1]): sock.name
        for sock in switch.inputs
        if sock.identifier.startswith("Item_")
    }


def ensure_group():
    """The DQ Skin node group, created on first use (shared by all DQ Skin modifiers)."""
    for group in bpy.data.node_groups:
        if group.bl_idname == "GeometryNodeTree" and group.get(GROUP_TAG) == VERSION:
            return group
    group = bpy.data.node_groups.new(GROUP_NAME, "GeometryNodeTree")
    group[GROUP_TAG] = VERSION
    iface = group.interface
    iface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    iface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    for name, kind, default, lo, hi, description in SETTINGS:
        sock = iface.new_socket(name, in_out="INPUT", socket_type=kind)
        sock.description = description
        if lo is not None:
            sock.min_value, sock.max_value = lo, hi
        if kind in ("NodeSocketBool",) or (kind == "NodeSocketFloat" and name not in ("Blend Amount", "Mask")):
            sock.force_non_field = True
        if name == "Result":
            sock.hide_in_modifier = True
    nodes, links = group.nodes, group.links
    g_in = nodes.new("NodeGroupInput")
    g_out = nodes.new("NodeGroupOutput")
    # The Method menu's items live on a Menu Switch; its output is not used.
    switch = nodes.new("GeometryNodeMenuSwitch")
    switch.name = "Method Items"
    switch.enum_items.clear()
    for item in METHODS:
        switch.enum_items.new(item)
    links.new(g_in.outputs["Method"], switch.inputs["Menu"])
    for sock in iface.items_tree:
        if getattr(sock, "name", "") == "Method" and sock.in_out == "INPUT":
            sock.default_value = "Dual Quaternion"
    position = nodes.new("GeometryNodeInputPosition")
    store = nodes.new("GeometryNodeStoreNamedAttribute")
    store.data_type = "FLOAT_VECTOR"
    store.domain = "POINT"
    store.inputs["Name"].default_value = INPUT_ATTRIBUTE
    links.new(g_in.outputs["Geometry"], store.inputs["Geometry"])
    links.new(position.outputs["Position"], store.inputs["Value"])
    info = nodes.new("GeometryNodeObjectInfo")
    info.transform_space = "ORIGINAL"
    links.new(g_in.outputs["Result"], info.inputs["Object"])
    sample = nodes.new("GeometryNodeSampleIndex")
    sample.data_type = "FLOAT_VECTOR"
    sample.domain = "POINT"
    index = nodes.new("GeometryNodeInputIndex")
    links.new(info.outputs["Geometry"], sample.inputs["Geometry"])
    links.new(position.outputs["Position"], sample.inputs["Value"])
    links.new(index.outputs["Index"], sample.inputs["Index"])
    # Pass-through unless the result has exactly as many points as the input.
    count_in = nodes.new("GeometryNodeAttributeDomainSize")
    count_res = nodes.new("GeometryNodeAttributeDomainSize")
    links.new(store.outputs["Geometry"], count_in.inputs["Geometry"])
    links.new(info.outputs["Geometry"], count_res.inputs["Geometry"])
    same = nodes.new("FunctionNodeCompare")
    same.data_type = "INT"
    same.operation = "EQUAL"
    links.new(count_in.outputs["Point Count"], same.inputs[2])
    links.new(count_res.outputs["Point Count"], same.inputs[3])
    set_position = nodes.new("GeometryNodeSetPosition")
    links.new(store.outputs["Geometry"], set_position.inputs["Geometry"])
    links.new(same.outputs["Result"], set_position.inputs["Selection"])
    links.new(sample.outputs["Value"], set_position.inputs["Position"])
    links.new(set_position.outputs["Geometry"], g_out.inputs["Geometry"])
    for i, node in enumerate((g_in, position, store, info, index, sample, count_in, count_res, same, set_position, switch, g_out)):
        node.location = (200 * (i % 6), -220 * (i // 6))
    return group

# SPDX-License-Identifier: GPL-3.0-or-later
"""The DQ Skin node group (one per file, shared by every DQ Skin modifier): built on first use,
and a group saved by an earlier DQ Skin brought up to date in place when a file is loaded (the
modifiers' stored values stay valid). What it outputs is described in `nodes`."""

from __future__ import annotations

import bpy

from . import compat
from .nodes import (
    FIELDS,
    GROUP_NAME,
    GROUP_TAG,
    METHODS,
    OUTPUTS,
    OUTPUTS_TAG,
    SETTINGS,
    UPGRADABLE,
    VERSION,
    WARNING,
    store_ids,
    version_of,
)

MENU_NODE = "Method Items"
OUTPUT_MARK = ".dq_skin_output"  # the point attribute every output of DQ Skin has (Apply is told from removal by it)


def ensure_group():
    """The DQ Skin node group, created on first use."""
    for group in bpy.data.node_groups:
        if group.bl_idname == "GeometryNodeTree" and group.get(GROUP_TAG) == VERSION and group.library is None:
            upgrade(group)
            return group
    return build_group()


def build_group():
    group = bpy.data.node_groups.new(GROUP_NAME, "GeometryNodeTree")
    iface = group.interface
    iface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    iface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    _add_missing_inputs(group)
    g_in = group.nodes.new("NodeGroupInput")
    # The Method menu's items live on a Menu Switch; its output is not used.
    switch = group.nodes.new("GeometryNodeMenuSwitch")
    switch.name = MENU_NODE
    switch.enum_items.clear()
    for item in METHODS:
        switch.enum_items.new(item)
    group.links.new(g_in.outputs["Method"], switch.inputs["Menu"])
    # Set after the items exist (and not while iterating the interface: Blender 4.4.0 crashes).
    method = next(i for i in iface.items_tree if getattr(i, "item_type", "") == "SOCKET" and i.name == "Method")
    method.default_value = "Dual Quaternion"
    _build_outputs(group)
    group[GROUP_TAG] = VERSION
    store_ids(group)
    return group


def upgrade(group) -> None:
    """A group saved by an earlier DQ Skin 0.x (`UPGRADABLE`) brought up to date in place: the
    newer inputs and methods, the current descriptions and warning, and, from an older version or
    older outputs (`OUTPUTS`), the output nodes rebuilt (the method menu's items keep their stored
    values)."""
    if group.library is not None or version_of(group) not in UPGRADABLE:
        return
    _add_missing_inputs(group)
    add_missing_methods(group)
    descriptions = {name: description for name, *_rest, description, _hidden in SETTINGS}
    for item in group.interface.items_tree:
        if getattr(item, "item_type", "") == "SOCKET" and item.in_out == "INPUT" and item.name in descriptions:
            if item.description != descriptions[item.name]:
                item.description = descriptions[item.name]
    if version_of(group) != VERSION or group.get(OUTPUTS_TAG, 1) < OUTPUTS:
        _build_outputs(group)
        group[GROUP_TAG] = VERSION
    warning = next((n for n in group.nodes if n.bl_idname == "GeometryNodeWarning"), None)
    if warning is not None and warning.inputs["Message"].default_value != WARNING:
        warning.inputs["Message"].default_value = WARNING
    store_ids(group)


def add_missing_methods(group) -> None:
    """Groups saved by an earlier DQ Skin 0.x lack the newer methods: add them at the end (the
    stored values of the existing ones do not change)."""
    switch = group.nodes.get(MENU_NODE)
    if switch is None or group.library is not None:
        return
    have = {item.name for item in switch.enum_items}
    for item in [m for m in METHODS if m not in have]:
        switch.enum_items.new(item)


def _add_missing_inputs(group) -> None:
    """The inputs of `SETTINGS` the group lacks, added in order (existing ones keep their
    identifiers, so the modifiers' stored values stay theirs)."""
    iface = group.interface
    have = {i.name for i in iface.items_tree if getattr(i, "item_type", "") == "SOCKET" and i.in_out == "INPUT"}
    for name, kind, default, lo, hi, description, hidden in SETTINGS:
        if name in have:
            continue
        sock = iface.new_socket(name, in_out="INPUT", socket_type=kind)
        sock.description = description
        if lo is not None:
            sock.min_value, sock.max_value = lo, hi
        if default is not None and kind != "NodeSocketMenu":
            sock.default_value = default
        if kind == "NodeSocketBool" or (kind in ("NodeSocketFloat", "NodeSocketInt") and name not in FIELDS):
            sock.force_non_field = True
        if hidden:
            sock.hide_in_modifier = True


def _build_outputs(group) -> None:
    """Every node but the method menu, made anew: what the group outputs for each Mode."""
    nodes, links = group.nodes, group.links
    for n in [n for n in nodes if n.name != MENU_NODE]:
        nodes.remove(n)

    def node(kind, **props):
        n = nodes.new(kind)
        for k, v in props.items():
            setattr(n, k, v)
        return n

    g_in = node("NodeGroupInput")
    g_out = node("NodeGroupOutput")
    switch = nodes.get(MENU_NODE)
    if switch is not None:
        links.new(g_in.outputs["Method"], switch.inputs["Menu"])
    mode = g_in.outputs["Mode"]

    # The optional capture of the incoming positions comes first (switches are lazy: nothing of
    # a branch is evaluated unless it is used).
    position = node("GeometryNodeInputPosition")
    store = node("GeometryNodeStoreNamedAttribute", data_type="FLOAT_VECTOR", domain="POINT")
    links.new(g_in.outputs["Geometry"], store.inputs["Geometry"])
    links.new(g_in.outputs["Capture Name"], store.inputs["Name"])
    links.new(position.outputs["Position"], store.inputs["Value"])
    captured = geometry_switch(node, links, g_in.outputs["Capture"], g_in.outputs["Geometry"], store.outputs["Geometry"])

    # The result, used only with the incoming mesh's point count.
    info = node("GeometryNodeObjectInfo", transform_space="ORIGINAL")
    links.new(g_in.outputs["Result"], info.inputs["Object"])
    size_in = node("GeometryNodeAttributeDomainSize", component="MESH")
    size_result = node("GeometryNodeAttributeDomainSize", component="MESH")
    links.new(g_in.outputs["Geometry"], size_in.inputs["Geometry"])
    links.new(info.outputs["Geometry"], size_result.inputs["Geometry"])
    same_points = equal(node, links, size_in.outputs["Point Count"], size_result.outputs["Point Count"])
    replace = boolean(node, links, "AND", equal(node, links, mode, 1), same_points)
    positions = boolean(node, links, "AND", equal(node, links, mode, 2), same_points)
    quiet = equal(node, links, mode, 3)

    index = node("GeometryNodeInputIndex")
    sample = node("GeometryNodeSampleIndex", data_type="FLOAT_VECTOR", domain="POINT")
    links.new(info.outputs["Geometry"], sample.inputs["Geometry"])
    links.new(position.outputs["Position"], sample.inputs["Value"])
    links.new(index.outputs["Index"], sample.inputs["Index"])
    set_position = node("GeometryNodeSetPosition")
    links.new(captured, set_position.inputs["Geometry"])
    links.new(sample.outputs["Value"], set_position.inputs["Position"])

    # Every output is marked, so that a mesh this modifier was applied to says so, also where
    # Apply changes no position (Blender evaluates the modifier alone): the mesh carried (its
    # positions came through a carrier before the modifier) or passed to the companion, which
    # deforms where DQ Skin does not (and is then applied in its place, `removal`).
    marked = node("GeometryNodeStoreNamedAttribute", data_type="BOOLEAN", domain="POINT")
    links.new(captured, marked.inputs["Geometry"])
    marked.inputs["Name"].default_value = OUTPUT_MARK
    marked.inputs["Value"].default_value = True
    passed = marked.outputs["Geometry"]
    if compat.HAS_WARNING_NODE:
        # Reached only when DQ Skin is not deforming; a Warning node shows when its output is used.
        warning = node("GeometryNodeWarning", warning_type="WARNING")
        warning.inputs["Show"].default_value = True
        warning.inputs["Message"].default_value = WARNING
        passed = geometry_switch(node, links, warning.outputs["Show"], passed, passed)
    # The positions given are marked here; a whole-mesh result carries the mark in its own mesh
    # (`results.copy_mesh`), stored once rather than for every point of every frame.
    mark = node("GeometryNodeStoreNamedAttribute", data_type="BOOLEAN", domain="POINT")
    links.new(set_position.outputs["Geometry"], mark.inputs["Geometry"])
    mark.inputs["Name"].default_value = OUTPUT_MARK
    mark.inputs["Value"].default_value = True
    live = geometry_switch(node, links, positions, captured, mark.outputs["Geometry"])
    live = geometry_switch(node, links, replace, live, info.outputs["Geometry"])
    deforming = boolean(node, links, "OR", replace, positions)
    out = geometry_switch(node, links, deforming, passed, live)
    # Carried (the positions came through a deform-only carrier before the modifier): the mesh,
    # captured if asked, marked, and nothing else evaluated (switches are lazy; this is every
    # frame's path on the Mesh Cache route, where each node evaluated costs every character
    # every frame).
    out = geometry_switch(node, links, quiet, out, marked.outputs["Geometry"])
    links.new(out, g_out.inputs["Geometry"])
    group[OUTPUTS_TAG] = OUTPUTS
    for i, n in enumerate(nodes):
        n.location = (180 * (i % 8), -200 * (i // 8))


def geometry_switch(node, links, condition, if_false, if_true):
    s = node("GeometryNodeSwitch", input_type="GEOMETRY")
    links.new(condition, s.inputs["Switch"])
    if if_false is not None:
        links.new(if_false, s.inputs["False"])
    if if_true is not None:
        links.new(if_true, s.inputs["True"])
    return s.outputs[0]


def equal(node, links, a, b):
    """Integer equality of a socket and another socket or a constant."""
    c = node("FunctionNodeCompare", data_type="INT", operation="EQUAL")
    sa, sb = compat.compare_sockets(c, "INT")
    links.new(a, sa)
    if isinstance(b, int):
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

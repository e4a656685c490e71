# SPDX-License-Identifier: GPL-3.0-or-later
"""Everything that differs between the Blender versions DQ Skin supports (4.2 LTS and newer).

The rest of the add-on calls these helpers instead of testing versions itself.

- Geometry Nodes modifier inputs: up to 5.1 they are ID properties of the modifier
  (``mod["Socket_2"]``, ``mod["Socket_2_use_attribute"]``, ``mod["Socket_2_attribute_name"]``,
  menus stored as integers); from 5.2 they are RNA properties
  (``mod.properties.inputs.Socket_2.value``, ``.type`` = 'VALUE'/'ATTRIBUTE',
  ``.attribute_name``, menus as item names).
- The Compare node: up to 5.1 it has A/B sockets for every data type; from 5.2 only the active
  type's. Sockets are found by name and type.
- The Warning node exists from 4.3 on.
- Modifiers have a ``persistent_uid`` from 4.2 on (a fallback keeps older files working).
"""

from __future__ import annotations

import bpy

# 5.2 made modifier inputs RNA properties and dropped ID properties on modifiers.
RNA_INPUTS = bpy.app.version >= (5, 2, 0)
HAS_WARNING_NODE = hasattr(bpy.types, "GeometryNodeWarning")


def _rna_input(mod, identifier):
    return getattr(mod.properties.inputs, identifier)


def get_input(mod, identifier: str):
    """The value of a Geometry Nodes modifier input (objects, numbers, booleans, strings)."""
    if RNA_INPUTS:
        return _rna_input(mod, identifier).value
    return mod.get(identifier)


def set_input(mod, identifier: str, value) -> bool:
    """Sets a Geometry Nodes modifier input if it differs and makes Blender notice (an ID
    property write alone reaches neither the evaluated copy nor the dependency graph). Returns
    whether it changed."""
    if RNA_INPUTS:
        socket = _rna_input(mod, identifier)
        current = socket.value
        if current == value and (value is not None or current is None):
            return False
        socket.value = value
        _changed(mod, value, current)
        return True
    current = mod.get(identifier)
    if isinstance(current, float) and isinstance(value, int):
        value = float(value)  # keep the property's type (GN refuses an int in a float input)
    if current is not None and current == value and type(current) is type(value):
        return False
    if current is None and value is None and identifier in mod:
        return False
    mod[identifier] = value
    _changed(mod, value, current)
    return True


def _changed(mod, value, previous) -> None:
    if value is None or isinstance(value, bpy.types.ID) or isinstance(previous, bpy.types.ID):
        # A different object: the dependency graph needs new relations (reassigning the group
        # runs the modifier's relation update).
        mod.node_group = mod.node_group
    mod.id_data.update_tag()


def get_attribute(mod, identifier: str) -> str:
    """The attribute (vertex group) a field input reads, or "" when it uses its value."""
    if RNA_INPUTS:
        socket = _rna_input(mod, identifier)
        return socket.attribute_name if socket.type == "ATTRIBUTE" else ""
    if mod.get(identifier + "_use_attribute"):
        return mod.get(identifier + "_attribute_name", "") or ""
    return ""


def set_attribute(mod, identifier: str, name: str) -> None:
    """Makes a field input read the attribute `name` (a vertex group), or its value for ""."""
    if RNA_INPUTS:
        socket = _rna_input(mod, identifier)
        socket.type = "ATTRIBUTE" if name else "VALUE"
        socket.attribute_name = name
        mod.id_data.update_tag()
        return
    mod[identifier + "_use_attribute"] = bool(name)
    mod[identifier + "_attribute_name"] = name
    mod.id_data.update_tag()


def get_menu(mod, identifier: str, items: dict[int, str]) -> str | None:
    """The item name a menu input is set to. `items`: stored value -> name (up to 5.1)."""
    if RNA_INPUTS:
        return _rna_input(mod, identifier).value or None
    value = mod.get(identifier)
    return items.get(value) if value is not None else None


def set_menu(mod, identifier: str, items: dict[int, str], name: str) -> bool:
    if RNA_INPUTS:
        return set_input(mod, identifier, name)
    value = next(v for v, n in items.items() if n == name)
    return set_input(mod, identifier, value)


def compare_sockets(node, socket_type: str):
    """The A and B inputs of a Compare node for `socket_type` ('VALUE', 'INT')."""
    a = next(s for s in node.inputs if s.name == "A" and s.type == socket_type)
    b = next(s for s in node.inputs if s.name == "B" and s.type == socket_type)
    return a, b


def modifier_uid(mod) -> str:
    """An identifier of a modifier that survives renames (unique within its object)."""
    uid = getattr(mod, "persistent_uid", 0)
    return f"uid{uid}" if uid else f"name:{mod.name}"


def last_operator():
    """The last registered operator of the window manager (what the user did last), or None."""
    wm = bpy.context.window_manager
    ops = getattr(wm, "operators", None) if wm is not None else None
    try:
        return ops[-1] if ops else None
    except (IndexError, ReferenceError):
        return None


def new_fcurve(curves, data_path: str, index: int, group: str):
    """A new F-curve in `curves` (an action's or a channel bag's), in the channel group `group`.
    The group argument is `action_group` before slotted actions (4.2, 4.3), missing on channel
    bags in 4.4 and 4.5 (the group is made and assigned here), `group_name` from 5.0."""
    params = curves.bl_rna.functions["new"].parameters.keys()
    if "group_name" in params:
        return curves.new(data_path, index=index, group_name=group)
    if "action_group" in params:
        return curves.new(data_path, index=index, action_group=group)
    fc = curves.new(data_path, index=index)
    bag = getattr(curves, "data", None)  # the channel bag owning the collection
    if bag is not None and hasattr(bag, "groups"):
        fc.group = bag.groups.get(group) or bag.groups.new(group)
    return fc


def node_material(name: str):
    """A material with a node tree (always there from 5.0, where `use_nodes` is deprecated)."""
    mat = bpy.data.materials.get(name) or bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    return mat

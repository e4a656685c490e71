# SPDX-License-Identifier: GPL-3.0-or-later
"""A DQ Skin modifier's inputs: its settings, and the hidden inputs the add-on sets.

A DQ Skin modifier is a Geometry Nodes modifier with the DQ Skin node group (`node_group`), so
it lives in the modifier stack like any modifier (order, toggles, name, settings saved per
modifier in the .blend). What the group outputs is the hidden *Mode* input's choice:

- PASS_WARN (0): DQ Skin is not deforming; the input passes through and the companion (the
  Armature modifier kept after DQ Skin) deforms the mesh the way Blender does. A Warning node
  says so (Blender 4.3+). Files are saved so, and a file opened without the extension always
  shows this;
- REPLACE (1): the *Result* object (the add-on's, one per object and modifier, never saved) is
  a full copy of the mesh with skinned positions, output as is;
- POSITIONS (2): the result holds points whose positions the incoming mesh takes (which keeps
  its index layers);
- PASS (3): the input passes through because a deform-only carrier right before DQ Skin (a Mesh
  Cache modifier) already holds DQ Skin's positions.

REPLACE and POSITIONS fall back to PASS_WARN when the result does not have the incoming mesh's
point count. With *Capture* on, the incoming positions are first stored in the point attribute
named by *Capture Name*: the add-on reads them back when modifiers before DQ Skin deform the
mesh.
"""

from __future__ import annotations

import json
import sys
from types import MappingProxyType

from . import compat

GROUP_NAME = "DQ Skin"
GROUP_TAG = "dq_skin_version"
VERSION = 5
UPGRADABLE = (2, 3, 4, 5)  # group versions brought up to this one in place (`node_group.upgrade`)
# What the group's output nodes are within a version (its settings and modes do not change with
# it, so modifiers of linked groups saved before keep working): 2 marks the mesh it passes to its
# companion too. A local group with older outputs has them rebuilt (`node_group.upgrade`).
OUTPUTS_TAG = "dq_skin_outputs"
OUTPUTS = 2

# The Mode input's values (see above).
MODE_PASS_WARN = 0
MODE_REPLACE = 1
MODE_POSITIONS = 2
MODE_PASS = 3

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
    ("Mode", "NodeSocketInt", 0, 0, 3, "Internal: what the modifier outputs (set by DQ Skin)", True),
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


def raw_keys(group) -> tuple:
    """The stored keys of `RAW` in modifiers of `group` (a field input's value, whether it
    reads an attribute, and which), for `raw_settings` (up to Blender 5.1). Interned: every
    character keeps these, and they are the same few names for all."""
    ids = socket_ids(group)
    keys = (k for n in RAW for k in ((ids[n], ids[n] + "_use_attribute", ids[n] + "_attribute_name") if n in FIELDS else (ids[n],)))
    return tuple(sys.intern(k) for k in keys)


def raw_settings(mod, keys: tuple | None = None) -> tuple:
    """The settings' stored values, cheap to read and compare (see `settings.cached`): what
    `settings.read` reads, read on every frame of every character. `keys`: `raw_keys` of the
    modifier's group, if the caller keeps them."""
    if compat.RNA_INPUTS:
        ids = socket_ids(mod.node_group)
        inputs = mod.properties.inputs
        return tuple((s.value, s.type, getattr(s, "attribute_name", "")) for s in (getattr(inputs, ids[n]) for n in RAW))
    return tuple(map(mod.get, keys if keys is not None else raw_keys(mod.node_group)))


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
    return parse_companion(get_companion_text(mod))


def get_companion_text(mod) -> str:
    """The same as stored (what `parse_companion` reads)."""
    text = get(mod, "Companion")
    return text if isinstance(text, str) else ""


def parse_companion(text: str) -> dict:
    try:
        data = json.loads(text or "{}")
    except (ValueError, TypeError):
        return {}
    return data if isinstance(data, dict) else {}


def put_companion(mod, data: dict) -> None:
    put(mod, "Companion", json.dumps(data, sort_keys=True))

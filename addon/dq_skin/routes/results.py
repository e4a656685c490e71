# SPDX-License-Identifier: GPL-3.0-or-later
"""Result objects: where the add-on puts what a DQ Skin modifier outputs.

One per object and modifier (two DQ Skins on one object, or a copy of a character, never share
one), local to the current file even when the character is a library override, linked to no
scene (the modifier's reference keeps it evaluated), and runtime data: Blender never writes a
result, its mesh or anything of theirs to a file.

A result fed inside Blender's evaluation carries a *carrier*: a deform-only modifier doing
nothing (a Hook of no strength aimed at the feed's object, its strength driven by the feed),
which orders the result's evaluation after the feed and makes Blender copy the positions the
feed wrote into its own (with fresh caches: bounds, normals).

Each result records its owner (the object's session uid and the modifier's persistent id): a
copied object or modifier that still points at another modifier's result gets one of its own.
"""

from __future__ import annotations

import ctypes

import numpy as np

import bpy

from ..blender import compat
from ..blender.node_group import OUTPUT_MARK

TAG = "dq_skin_result"
OWNER_OBJECT = "dq_skin_owner_object"
OWNER_MODIFIER = "dq_skin_owner_modifier"


def is_result(obj) -> bool:
    try:
        return obj is not None and obj.get(TAG) is not None
    except ReferenceError:
        return False


def owned_by(result, obj, mod) -> bool:
    """Whether `result` is a local result of `mod` on `obj` (this session)."""
    return (
        is_result(result)
        and result.library is None
        and result.get(OWNER_OBJECT) == str(obj.session_uid)
        and result.get(OWNER_MODIFIER) == compat.modifier_uid(mod)
    )


def create(obj, mod):
    """A new, empty result object for `mod` on `obj`."""
    name = f".DQ Skin result {obj.name} {mod.name}"
    mesh = _runtime(bpy.data.meshes.new(name))
    result = _runtime(bpy.data.objects.new(name, mesh))
    result[TAG] = 1
    result[OWNER_OBJECT] = str(obj.session_uid)  # a string: uids exceed ID properties' int range
    result[OWNER_MODIFIER] = compat.modifier_uid(mod)
    return result


def _runtime(datablock):
    """Marks a data-block of ours as runtime data: Blender never writes it to a file."""
    datablock.is_runtime_data = True
    return datablock


def remove(result) -> None:
    """Deletes a result object and its mesh (its feed goes first, see `ResultRoute.release`)."""
    if not is_result(result) or result.library is not None:
        return
    mesh = result.data
    bpy.data.objects.remove(result)
    if mesh is not None and mesh.users == 0:
        bpy.data.meshes.remove(mesh)


def unused() -> list:
    """The results nothing uses any more (their modifier or object was deleted)."""
    return [o for o in bpy.data.objects if is_result(o) and o.users == 0 and o.library is None]


def copy_mesh(result, source_mesh) -> None:
    """Makes the result's mesh a copy of `source_mesh` (attributes, groups, topology, shared with
    it until written) without its shape keys: a copied shape-key data-block would be saved in
    the user's file, pointing at a mesh that is not."""
    old = result.data
    mesh = _runtime(source_mesh.copy())
    mesh.name = result.name
    if mesh.shape_keys is not None:
        bpy.data.batch_remove([mesh.shape_keys])
    # DQ Skin's output mark, which the node group stores on every output but a result's whole
    # mesh (which carries it here).
    mark = mesh.attributes.get(OUTPUT_MARK)
    if mark is not None and (mark.data_type, mark.domain) != ("BOOLEAN", "POINT"):
        mesh.attributes.remove(mark)
        mark = None
    if mark is None:
        mark = mesh.attributes.new(OUTPUT_MARK, "BOOLEAN", "POINT")
    mark.data.foreach_set("value", np.ones(len(mesh.vertices), bool))
    result.data = mesh
    if old is not None and old.users == 0:
        bpy.data.meshes.remove(old)


def points_mesh(result, count: int) -> None:
    """Makes the result's mesh `count` loose points (positions mode)."""
    mesh = result.data
    if len(mesh.vertices) == count and not len(mesh.polygons) and not len(mesh.edges):
        return
    old = mesh
    mesh = _runtime(bpy.data.meshes.new(result.name))
    mesh.vertices.add(count)
    result.data = mesh
    if old is not None and old.users == 0:
        bpy.data.meshes.remove(old)


def write_positions(result, positions) -> None:
    """New positions. The attribute write alone leaves Blender's caches of the mesh (bounds,
    normals, the BVH trees Shrinkwrap, Surface Deform and ray casts use) as they were; writing
    one vertex through `MeshVertex.co` makes Blender tag the positions as changed, which
    invalidates them and tells the dependency graph."""
    mesh = result.data
    mesh.attributes["position"].data.foreach_set("vector", positions.ravel())
    if len(mesh.vertices):
        v = mesh.vertices[0]
        v.co = v.co
    else:
        mesh.update()


CARRIER = "DQ Skin carrier"
# The carrier is a Hook of no strength: Blender runs it (it has a target object, the feed's), so
# the result's evaluated mesh gets positions of its own and fresh caches, and it returns before
# touching a vertex. (A zero SimpleDeform bend first finds the bounds, a pass over every vertex;
# a Laplacian Deform never bound would need an existing vertex group on every result.)
CARRIER_TYPE = "HOOK"
CARRIER_DRIVEN = "strength"


def ensure_carrier(result):
    """The result's carrier modifier (made if missing); returns it. Its target is set where it is
    driven (`point_carrier`)."""
    m = result.modifiers.get(CARRIER)
    if m is None or m.type != CARRIER_TYPE:
        if m is not None:
            remove_carrier(result)
        m = result.modifiers.new(CARRIER, CARRIER_TYPE)
        m.strength = 0.0
    return m


def point_carrier(carrier, target) -> None:
    """The carrier's target object (without one, Blender would skip it: stale caches)."""
    if carrier.object != target:
        carrier.object = target


def remove_carrier(result) -> None:
    m = result.modifiers.get(CARRIER)
    if m is not None:
        if result.animation_data is not None:
            for fc in [fc for fc in result.animation_data.drivers if fc.data_path.startswith(f'modifiers["{CARRIER}"].')]:
                result.animation_data.drivers.remove(fc)
        result.modifiers.remove(m)


def evaluated_positions(result, depsgraph) -> np.ndarray | None:
    """The position array of `result`'s mesh as `depsgraph` evaluates it (its copy-on-evaluation
    data, which the carrier copies from), as a writable `(V, 3)` float32 view of Blender's
    memory; None if it has no vertices. Valid until Blender evaluates that mesh again: taken anew
    every time it is written."""
    mesh = result.data.evaluated_get(depsgraph)
    n = len(mesh.vertices)
    if not n:
        return None
    # (Writable access: Blender gives the evaluated mesh an array of its own first if it shared
    # the original's.)
    address = mesh.attributes["position"].data[0].as_pointer()
    return np.ctypeslib.as_array((ctypes.c_float * (3 * n)).from_address(address)).reshape(n, 3)

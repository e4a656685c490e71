# SPDX-License-Identifier: GPL-3.0-or-later
"""Result objects: where the add-on puts what a DQ Skin modifier outputs.

One per object and modifier (two DQ Skins on one object, or a duplicate of a character, never
share one), local to the current file even when the character is a library override, linked to
no scene (the modifier's reference keeps it evaluated), and never saved: files are written
without them (see `handlers.on_save_pre`), so a file opened anywhere shows either a result the
add-on just computed or Blender's own deformation through the companion.

Each result records its owner; a duplicated object or copied modifier that still points at
another modifier's result gets a new one of its own.
"""

from __future__ import annotations

import bpy

from . import nodes

TAG = "dq_skin_result"
OWNER = "dq_skin_owner"


def owner_key(obj, mod_uid: str) -> str:
    return f"{obj.name_full}\x1f{mod_uid}"


def is_result(obj) -> bool:
    return obj is not None and obj.get(TAG) is not None


def usable(result, owner: str, claimed: set) -> bool:
    """Whether `result` can be written for `owner`: ours, local, a mesh object, not claimed by
    another modifier in this session."""
    return (
        result is not None
        and result.type == "MESH"
        and result.library is None
        and result.override_library is None
        and is_result(result)
        and result.session_uid not in claimed
    )


def create(obj, mod, owner: str):
    """A new, empty result object for `mod` on `obj` (its location says "pass through")."""
    name = f".DQ Skin result {obj.name} {mod.name}"
    mesh = runtime(bpy.data.meshes.new(name))
    result = runtime(bpy.data.objects.new(name, mesh))
    result[TAG] = 1
    result[OWNER] = owner
    return result


def runtime(datablock):
    """Marks a data-block of ours as runtime data: Blender never writes it to a file, so a saved
    file holds no copy of a result mesh (whose object is not saved either)."""
    datablock.is_runtime_data = True
    return datablock


def remove(result) -> None:
    """Deletes a result object and its mesh (if nothing else uses them)."""
    if result is None or not is_result(result) or result.library is not None:
        return
    mesh = result.data
    try:
        bpy.data.objects.remove(result)
    except ReferenceError:
        return
    if mesh is not None and mesh.users == 0:
        bpy.data.meshes.remove(mesh)


_TRANSFORMS = {
    # mode: (location, scale); see `nodes`
    nodes.RESULT_OFF: ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)),
    nodes.RESULT_REPLACE: ((1.0, 0.0, 0.0), (1.0, 1.0, 1.0)),
    nodes.RESULT_POSITIONS: ((0.0, 0.0, 0.0), (2.0, 2.0, 2.0)),
}


def set_mode(result, mode: int) -> None:
    """Tells the node group what to do with the result (writes only what changes)."""
    if mode == nodes.RESULT_PENDING:
        if result.location.z != 1.0:
            result.location.z = 1.0
        return
    loc, scale = _TRANSFORMS[mode]
    if tuple(result.location) != loc:
        result.location = loc
    if tuple(result.scale) != scale:
        result.scale = scale


def mode_of(result) -> int:
    if result is None:
        return nodes.RESULT_OFF
    if result.location.z > 0:
        return nodes.RESULT_PENDING
    if result.location.x > 0:
        return nodes.RESULT_REPLACE
    if result.scale.x == 2.0:
        return nodes.RESULT_POSITIONS
    return nodes.RESULT_OFF


def replace_mesh(result, source_mesh) -> None:
    """Makes the result's mesh a copy of `source_mesh` (its attributes, groups, topology, shared
    with it until written) without shape keys."""
    old = result.data
    mesh = runtime(source_mesh.copy())
    mesh.name = result.name
    result.data = mesh
    if mesh.shape_keys is not None:
        result.shape_key_clear()
    if old is not None and old.users == 0:
        bpy.data.meshes.remove(old)


def points_mesh(result, count: int) -> None:
    """Makes the result's mesh `count` loose points (positions mode)."""
    mesh = result.data
    if len(mesh.vertices) == count and not len(mesh.polygons) and not len(mesh.edges):
        return
    old = mesh
    mesh = runtime(bpy.data.meshes.new(result.name))
    mesh.vertices.add(count)
    result.data = mesh
    if old is not None and old.users == 0:
        bpy.data.meshes.remove(old)


def write_positions(result, positions) -> None:
    """New positions; `Mesh.update()` tells Blender they changed (normals and bounds are
    recomputed), which `foreach_set` alone does not."""
    mesh = result.data
    mesh.attributes["position"].data.foreach_set("vector", positions.ravel())
    mesh.update()


def orphans() -> list:
    """Result objects nothing uses any more (e.g. after their modifier or object was deleted)."""
    return [o for o in bpy.data.objects if is_result(o) and o.users == 0 and o.library is None]


def referenced(mod):
    return nodes.get(mod, "Result")

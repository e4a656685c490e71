# SPDX-License-Identifier: GPL-3.0-or-later
"""The companion: the Armature modifier kept right after each DQ Skin modifier.

`dq_skin_add` keeps the Armature modifier it replaces and moves it right after DQ Skin. It is
what deforms the mesh whenever DQ Skin cannot:
- in files opened where the extension is not installed (a render farm node): every file is
  saved with the companion *active* (enabled, set up like DQ Skin) and no DQ Skin result, so
  Blender shows its own deformation (the same as DQ Skin's for Linear and Dual Quaternion);
- in linked data without a library override, which the add-on cannot change;
- whenever DQ Skin reports an error.

While DQ Skin is deforming, the companion is *parked*: disabled, and with vertex groups and
envelopes off so that it does not make the mesh depend on the pose (a disabled modifier still
adds its relations, and with them the mesh would be evaluated again on every frame for nothing).

DQ Skin remembers the companion's name and its settings from before `dq_skin_add`; removing DQ
Skin puts them back exactly.
"""

from __future__ import annotations

from . import nodes

# What `dq_skin_add` may change on the companion, and removal restores.
SETTINGS = (
    "show_viewport",
    "show_render",
    "object",
    "use_vertex_groups",
    "use_bone_envelopes",
    "use_deform_preserve_volume",
    "use_multi_modifier",
    "vertex_group",
    "invert_vertex_group",
)


def snapshot(arm_mod) -> dict:
    """The companion's settings, as stored on the DQ Skin modifier (the object by name)."""
    out = {}
    for name in SETTINGS:
        value = getattr(arm_mod, name)
        out[name] = value.name if name == "object" and value is not None else value
    return out


def find(obj, mod, info: dict | None = None):
    """The companion of `mod`: the Armature modifier it names, else the Armature modifier right
    after it; None if there is none."""
    info = nodes.get_companion(mod) if info is None else info
    named = obj.modifiers.get(info.get("name", "")) if info.get("name") else None
    if named is not None and named.type == "ARMATURE":
        return named
    mods = obj.modifiers
    index = list(mods).index(mod) if mod.name in mods else -1
    if 0 <= index < len(mods) - 1 and mods[index + 1].type == "ARMATURE":
        return mods[index + 1]
    return None


def _set(arm_mod, name: str, value) -> None:
    if getattr(arm_mod, name) != value:
        setattr(arm_mod, name, value)


def park(arm_mod) -> None:
    """Disabled and without bone relations (DQ Skin is deforming)."""
    _set(arm_mod, "show_viewport", False)
    _set(arm_mod, "show_render", False)
    _set(arm_mod, "use_vertex_groups", False)
    _set(arm_mod, "use_bone_envelopes", False)
    _set(arm_mod, "use_multi_modifier", False)


def is_parked(arm_mod) -> bool:
    return not (arm_mod.show_viewport or arm_mod.show_render or arm_mod.use_vertex_groups or arm_mod.use_bone_envelopes)


def activate(arm_mod, mod, settings) -> None:
    """Deforming as DQ Skin would with Blender's own math: the same armature, groups, envelopes
    and mask, Preserve Volume for Dual Quaternion (and Blend, the closest Blender has), enabled
    where DQ Skin is."""
    _set(arm_mod, "object", settings.armature)
    _set(arm_mod, "use_vertex_groups", settings.use_vertex_groups)
    _set(arm_mod, "use_bone_envelopes", settings.use_envelopes)
    _set(arm_mod, "use_deform_preserve_volume", settings.method != "linear")
    _set(arm_mod, "use_multi_modifier", False)
    _set(arm_mod, "vertex_group", settings.mask_group)
    _set(arm_mod, "invert_vertex_group", settings.invert_mask)
    _set(arm_mod, "show_viewport", mod.show_viewport)
    _set(arm_mod, "show_render", mod.show_render)


def restore(arm_mod, original: dict) -> None:
    """Back to how it was before `dq_skin_add`."""
    import bpy

    for name in SETTINGS:
        if name not in original:
            continue
        value = original[name]
        if name == "object":
            value = bpy.data.objects.get(value) if value else None
        try:
            _set(arm_mod, name, value)
        except (TypeError, ValueError, AttributeError):
            pass  # e.g. the armature object was deleted since

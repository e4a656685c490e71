# SPDX-License-Identifier: GPL-3.0-or-later
"""The companion: the Armature modifier kept right after each DQ Skin modifier, Blender's own
deformation for wherever DQ Skin does not deform.

`dq_skin_add` keeps the Armature modifier it replaces and moves it right after DQ Skin. DQ Skin
and its companion are two ways of one deformation, and exactly one of them deforms the mesh in
each kind of evaluation (viewport, render):

- where DQ Skin deforms, the companion is switched off; while it is off in both, its vertex
  groups and envelopes are off too (*parked*): even a disabled Armature modifier makes Blender
  evaluate the mesh again whenever a bone moves, for nothing;
- where DQ Skin does not (switched off by the user, handed over to Blender's deformation for a
  reason the panel gives, an error), the companion is on, set up like DQ Skin: the same
  armature, vertex groups, envelopes and mask, Preserve Volume for every method but Linear;
- switching the companion on by hand where DQ Skin deforms switches DQ Skin off there (Blender's
  deformation shows, once), and switching DQ Skin back on switches the companion off;
- files are saved with the companion on wherever DQ Skin is on, so a file opened without the
  add-on (a render farm) shows Blender's deformation, and removing DQ Skin puts the companion
  back exactly as it was before `dq_skin_add`.
"""

from __future__ import annotations

import bpy

from . import nodes

# What `dq_skin_add` may change on the companion, and removal restores.
SETTINGS = (
    "show_viewport",
    "show_render",
    "show_in_editmode",
    "show_on_cage",
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
    index = mods.find(mod.name)
    if 0 <= index < len(mods) - 1 and mods[index + 1].type == "ARMATURE":
        return mods[index + 1]
    return None


def _set(arm_mod, name: str, value) -> None:
    if getattr(arm_mod, name) != value:
        setattr(arm_mod, name, value)


def shown(arm_mod) -> tuple[bool, bool]:
    return (arm_mod.show_viewport, arm_mod.show_render)


def configure(arm_mod, mod, settings, show: tuple[bool, bool]) -> None:
    """The companion on where `show` says (viewport, render), set up like DQ Skin; parked where
    it is on nowhere."""
    viewport, render = show
    if viewport or render:
        _set(arm_mod, "object", settings.armature)
        _set(arm_mod, "use_vertex_groups", settings.use_vertex_groups)
        _set(arm_mod, "use_bone_envelopes", settings.use_envelopes)
        _set(arm_mod, "use_deform_preserve_volume", settings.preserve_volume)
        _set(arm_mod, "use_multi_modifier", False)
        _set(arm_mod, "vertex_group", settings.mask_group)
        _set(arm_mod, "invert_vertex_group", settings.invert_mask)
        _set(arm_mod, "show_in_editmode", mod.show_in_editmode)
        _set(arm_mod, "show_on_cage", mod.show_on_cage)
    else:
        _set(arm_mod, "use_vertex_groups", False)
        _set(arm_mod, "use_bone_envelopes", False)
        _set(arm_mod, "use_multi_modifier", False)
    _set(arm_mod, "show_viewport", viewport)
    _set(arm_mod, "show_render", render)


def configure_without_settings(arm_mod, mod) -> None:
    """On where DQ Skin is on, as it is (the modifier's settings could not be read)."""
    _set(arm_mod, "show_viewport", mod.show_viewport)
    _set(arm_mod, "show_render", mod.show_render)


def restore(arm_mod, original: dict) -> None:
    """Back to how it was before `dq_skin_add`."""
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


def apply(obj, arm_mod) -> bool:
    """Blender's own Apply of the companion: the mesh takes the deformation it shows, bit for
    bit as Blender gives it. False where Blender refused (the companion is left as it is)."""
    try:
        with bpy.context.temp_override(object=obj, active_object=obj):
            return bpy.ops.object.modifier_apply(modifier=arm_mod.name) == {"FINISHED"}
    except (RuntimeError, TypeError):
        return False

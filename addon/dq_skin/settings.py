# SPDX-License-Identifier: GPL-3.0-or-later
"""A DQ Skin modifier's settings, read from its node group inputs, and the one table of
skinning methods every part of the add-on uses (menu, operators, batch commands, kernel)."""

from __future__ import annotations

from dataclasses import dataclass

from . import dqskin, nodes

# What each method does, in an artist's words (the tooltips of the menus).
DESCRIPTIONS = {
    dqskin.Method.LINEAR: "Linear blend skinning, as the Armature modifier with Preserve Volume off",
    dqskin.Method.DUAL_QUATERNION: "Dual quaternion skinning, as the Armature modifier with Preserve Volume on: no candy wrapper when twisting",
    dqskin.Method.BLEND: "Linear and Dual Quaternion mixed per vertex by the Blend Amount (a vertex group you paint)",
    dqskin.Method.CENTERS_OF_ROTATION: "Optimized Centers of Rotation (Le and Hodgins 2016): no candy wrapper and less bulge at bent joints than Dual Quaternion",
}
# The one list of methods: `dqskin.Method` (its name is what operators and the command line
# take, its label what the modifier's menu shows).
METHODS = tuple(dqskin.Method.members())
BY_NAME = {m.name: m for m in METHODS}
BY_LABEL = {m.label: m for m in METHODS}
# The methods Blender's Armature modifier has: it gives the same result (Preserve Volume off, on).
BLENDER_METHODS = (dqskin.Method.LINEAR, dqskin.Method.DUAL_QUATERNION)


@dataclass(frozen=True)
class Settings:
    armature: object
    method: object  # dqskin.Method
    blend_group: str
    blend_factor: float
    use_vertex_groups: bool
    use_envelopes: bool
    mask_group: str
    invert_mask: bool

    def key(self) -> tuple:
        arm = self.armature.session_uid if self.armature is not None else 0
        return (
            arm,
            self.method.name,
            self.blend_group,
            self.blend_factor,
            self.use_vertex_groups,
            self.use_envelopes,
            self.mask_group,
            self.invert_mask,
        )

    @property
    def preserve_volume(self) -> bool:
        """The Armature modifier's closest setting (Blend and Optimized Centers: on)."""
        return self.method != dqskin.Method.LINEAR


def read(mod) -> Settings:
    return Settings(
        armature=nodes.get(mod, "Armature"),
        method=BY_LABEL.get(nodes.get_method(mod), dqskin.Method.DUAL_QUATERNION),
        blend_group=nodes.get_attribute(mod, "Blend Amount"),
        blend_factor=float(nodes.get(mod, "Blend Factor")),
        use_vertex_groups=bool(nodes.get(mod, "Use Vertex Groups")),
        use_envelopes=bool(nodes.get(mod, "Use Envelopes")),
        mask_group=nodes.get_attribute(mod, "Mask"),
        invert_mask=bool(nodes.get(mod, "Invert Mask")),
    )


def cached(mod, cache) -> Settings:
    """`read(mod)`, again only when the modifier's stored values changed (they can be keyed, so
    they are compared on every evaluation). `cache`: the modifier's `state.SettingsCache`."""
    raw = nodes.raw_settings(mod)
    if cache.value is None or raw != cache.raw:
        cache.value = read(mod)
        cache.raw = raw
    return cache.value

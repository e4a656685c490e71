# SPDX-License-Identifier: GPL-3.0-or-later
"""The skinning methods, in one table every part of the add-on uses (menu, operators, batch
commands, kernel), and a DQ Skin modifier's settings as plain data."""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType

from .. import dqskin

# What each method does, in an artist's words (the tooltips of the menus).
DESCRIPTIONS = MappingProxyType(
    {
        dqskin.Method.LINEAR: "Linear blend skinning, as the Armature modifier with Preserve Volume off",
        dqskin.Method.DUAL_QUATERNION: "Dual quaternion skinning, as the Armature modifier with Preserve Volume on: no candy wrapper when twisting",
        dqskin.Method.BLEND: "Linear and Dual Quaternion mixed per vertex by the Blend Amount (a vertex group you paint)",
        dqskin.Method.CENTERS_OF_ROTATION: "Optimized Centers of Rotation (Le and Hodgins 2016): no candy wrapper and less bulge at bent joints than Dual Quaternion",
    }
)
# The one list of methods: `dqskin.Method` (its name is what operators and the command line
# take, its label what the modifier's menu shows).
METHODS = tuple(dqskin.Method.members())
BY_NAME = MappingProxyType({m.name: m for m in METHODS})
BY_LABEL = MappingProxyType({m.label: m for m in METHODS})
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
    blend_amount: float = 1.0  # the Blend Amount's value where no vertex group drives it

    def key(self) -> tuple:
        """What the result depends on, as plain values (made once: compared every frame)."""
        known = self.__dict__.get("_key")
        if known is not None:
            return known
        arm = self.armature.session_uid if self.armature is not None else 0
        key = (
            arm,
            self.method.name,
            self.blend_group,
            self.blend_factor,
            self.use_vertex_groups,
            self.use_envelopes,
            self.mask_group,
            self.invert_mask,
            self.blend_amount,
        )
        object.__setattr__(self, "_key", key)  # (a frozen dataclass: its fields never change)
        return key

    @property
    def preserve_volume(self) -> bool:
        """The Armature modifier's closest setting (Blend and Optimized Centers: on)."""
        return self.method != dqskin.Method.LINEAR

    @property
    def blender_method(self) -> bool:
        """Whether Blender's Armature modifier gives the same result."""
        return self.method in BLENDER_METHODS

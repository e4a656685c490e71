# SPDX-License-Identifier: GPL-3.0-or-later
"""A DQ Skin modifier's settings, read from its node group inputs (`methods.Settings`)."""

from __future__ import annotations

from .. import dqskin
from ..model.methods import BY_LABEL, Settings
from . import nodes


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
        blend_amount=float(nodes.get(mod, "Blend Amount")),
    )


def cached(mod, cache) -> Settings:
    """`read(mod)`, again only when the modifier's stored values changed (they can be keyed, so
    they are compared on every evaluation). `cache`: the modifier's `state.SettingsCache`."""
    group = mod.node_group
    of = (group.session_uid, nodes.version_of(group))
    if cache.raw_keys_of != of:  # (the keys of the group's inputs, once per group and version)
        cache.raw_keys, cache.raw_keys_of = nodes.raw_keys(group), of
    raw = nodes.raw_settings(mod, cache.raw_keys)
    if cache.value is None or raw != cache.raw:
        cache.value = read(mod)
        cache.raw = raw
    return cache.value

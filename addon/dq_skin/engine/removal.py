# SPDX-License-Identifier: GPL-3.0-or-later
"""A DQ Skin modifier that is gone (removed with its X button or `dq_skin_remove`, or applied):
its companion, what `dq_skin_add` changed, what the node group stored in the mesh, its route's
data-blocks and its state go or are put back."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..blender import companion, compat, nodes
from ..model.keys import ModKey
from . import inputs


@dataclass
class ModInfo:
    """What is needed to clean up after a DQ Skin modifier once it is gone."""

    name: str
    companion: dict
    capture: str


def info_of(mod) -> ModInfo:
    current = nodes.version_of(mod.node_group) == nodes.VERSION
    return ModInfo(mod.name, nodes.get_companion(mod) if current else {}, inputs.capture_name(mod))


def forget_modifier(session, obj, uid: str, info: ModInfo, applied: bool) -> None:
    """Everything of a DQ Skin modifier that is gone: its companion (removed too when the
    modifier was applied, since the mesh keeps the deformation, or when `dq_skin_add` made it;
    else put back as it was before `dq_skin_add`), the parent type `dq_skin_add` changed, what
    the node group stored in the mesh, its results and its state."""
    st = session.states.pop(ModKey(obj.session_uid, uid))
    c = obj.modifiers.get(info.companion.get("name", "")) if info.companion.get("name") else None
    if c is not None and c.type == "ARMATURE":
        if applied or info.companion.get("created"):
            obj.modifiers.remove(c)
        else:
            companion.restore(c, info.companion.get("original", {}))
    if not applied and info.companion.get("parent_type") and obj.parent is not None:
        obj.parent_type = info.companion["parent_type"]
    attr = obj.data.attributes.get(info.capture)
    if attr is not None:
        obj.data.attributes.remove(attr)
    if st is not None:
        session.route.release_result(st.output.result)
    session.route.remove_unused()


def was_applied(session, obj, info: ModInfo, st) -> bool:
    """Whether a vanished modifier was applied (Ctrl+A) rather than removed."""
    op = compat.last_operator()
    if op is not None and op.bl_idname == "OBJECT_OT_modifier_apply":
        try:
            if op.properties.modifier == info.name:
                return True
        except (AttributeError, ReferenceError):
            pass
    if st is None or st.output.buffer is None or len(st.output.buffer) != len(obj.data.vertices) or not st.status.live:
        return False
    # The mesh now holds what the modifier output (and that differs from what reached it).
    current = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.attributes["position"].data.foreach_get("vector", current)
    current = current.reshape(-1, 3)
    data = session.meshes.peek_any(obj)
    moved = data is None or not np.array_equal(data.positions, st.output.buffer)
    return moved and np.allclose(current, st.output.buffer, atol=1e-6, rtol=0)

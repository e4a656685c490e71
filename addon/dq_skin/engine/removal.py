# SPDX-License-Identifier: GPL-3.0-or-later
"""A DQ Skin modifier that is gone (removed with its X button or `dq_skin_remove`, or applied):
its companion, what `dq_skin_add` changed, what the node group stored in the mesh, its route's
data-blocks and its state go or are put back."""

from __future__ import annotations

from dataclasses import dataclass

from ..blender import companion, compat, node_group, nodes
from ..model.keys import ModKey
from ..model.state import RouteKind
from ..routes import cache_route
from ..routes.base import Target
from . import inputs


@dataclass
class ModInfo:
    """What is needed to clean up after a DQ Skin modifier once it is gone."""

    name: str
    companion_text: str
    """What the modifier stored of its companion (`nodes.get_companion_text`): kept as stored,
    since every DQ Skin object keeps one of these (the text is a fifth of its decoded dict)."""
    capture: str

    @property
    def companion(self) -> dict:
        return nodes.parse_companion(self.companion_text)


def info_of(mod) -> ModInfo:
    current = nodes.version_of(mod.node_group) == nodes.VERSION
    return ModInfo(mod.name, nodes.get_companion_text(mod) if current else "", inputs.capture_name(mod))


def forget_modifier(session, obj, uid: str, info: ModInfo, applied: bool) -> None:
    """Everything of a DQ Skin modifier that is gone: its companion (applied in its place when
    the modifier was applied where the companion was the one deforming; removed when it was
    applied where DQ Skin deformed, since the mesh keeps the deformation, or when `dq_skin_add`
    made it; else put back as it was before `dq_skin_add`), the parent type `dq_skin_add`
    changed, what the node group stored in the mesh, its results and its state."""
    st = session.states.pop(ModKey(obj.session_uid, uid))
    known = info.companion
    c = obj.modifiers.get(known.get("name", "")) if known.get("name") else None
    if c is not None and c.type == "ARMATURE":
        if applied and c.show_viewport:
            # DQ Skin was not deforming (handed over, an error): the companion showed the
            # deformation, and applying DQ Skin's pass-through changed no position. The companion
            # is applied in its place, so the mesh keeps what was shown; where Blender refuses,
            # it stays and keeps deforming.
            if not companion.apply(obj, c):
                print(
                    f"DQ Skin: {obj.name!r}: the Armature modifier {c.name!r} deformed it in DQ Skin's place and could not be applied: it stays"
                )
        elif applied or known.get("created"):
            obj.modifiers.remove(c)
        else:
            companion.restore(c, known.get("original", {}))
    if not applied and known.get("parent_type") and obj.parent is not None:
        obj.parent_type = known["parent_type"]
    for name in (info.capture, node_group.OUTPUT_MARK):
        attr = obj.data.attributes.get(name)
        if attr is not None:
            obj.data.attributes.remove(attr)
    if applied and st is not None and st.output.route is RouteKind.CACHE:
        _keep_carried(obj, st)
    if st is not None:
        session.routes.release(Target(obj, None, st, ModKey(obj.session_uid, uid)))
    cache_route.remove_orphans(obj)
    session.routes.remove_unused()


def _keep_carried(obj, st) -> None:
    """Applying a DQ Skin whose positions a carrier held (its node group passes the mesh through,
    so Blender's Apply changed nothing): the mesh takes the positions the carrier showed."""
    out = st.output.buffer
    mesh = obj.data
    if out is None or len(out) != len(mesh.vertices) or mesh.shape_keys is not None:
        return
    mesh.attributes["position"].data.foreach_set("vector", out.ravel())
    mesh.update()


def was_applied(session, obj, info: ModInfo, st) -> bool:
    """Whether a vanished modifier was applied (Ctrl+A) rather than removed."""
    op = compat.last_operator()
    if op is not None and op.bl_idname == "OBJECT_OT_modifier_apply":
        try:
            if op.properties.modifier == info.name:
                return True
        except (AttributeError, ReferenceError):
            pass
    # Every output of DQ Skin's is marked (`node_group.OUTPUT_MARK`), also where it passes the
    # mesh to its companion: a mesh it was applied to has the mark, a removal leaves none.
    return node_group.OUTPUT_MARK in obj.data.attributes

# SPDX-License-Identifier: GPL-3.0-or-later
"""Each DQ Skin modifier's companion (the Armature modifier kept after it, `blender.companion`):
which one it is, and switching it where DQ Skin's part changed (the decisions are
`decisions.companion_shown` and `decisions.switched_off_by_user`)."""

from __future__ import annotations

from ..blender import companion, nodes
from ..model import decisions
from ..model.state import ModifierState


def companion_of(obj, mod, st: ModifierState):
    """The modifier's companion (found once, then by name), or None."""
    c = obj.modifiers.get(st.companion.name) if st.companion.name else None
    if c is None or c.type != "ARMATURE":
        c = companion.find(obj, mod)
        if c is not None and _claimed_before(obj, mod, c):
            c = None  # a copy of a DQ Skin: the Armature modifier is its original's
        st.companion.name = c.name if c is not None else ""
    return c


def _claimed_before(obj, mod, c) -> bool:
    """Whether a DQ Skin earlier in the stack has `c` as its companion."""
    for other in obj.modifiers:
        if other == mod:
            return False
        if nodes.is_dq_skin(other) and nodes.version_of(other.node_group) == nodes.VERSION and companion.find(obj, other) == c:
            return True
    return False


def follow_the_user(obj, mod, st: ModifierState, exporting: bool) -> None:
    """The user switched the companion on where DQ Skin deforms: they asked for Blender's
    deformation there, so DQ Skin switches off there."""
    known = st.companion
    if known.shown is None or known.deforms is None or exporting:
        return
    c = companion_of(obj, mod, st)
    if c is None:
        return
    off = decisions.switched_off_by_user(known.shown, known.deforms, companion.shown(c), (mod.show_viewport, mod.show_render))
    for attr, switch in zip(("show_viewport", "show_render"), off):
        if switch:
            setattr(mod, attr, False)


def settle(obj, mod, st: ModifierState, s, deforms: tuple[bool, bool], render: bool = False) -> None:
    """Switches the companion where DQ Skin's part changed since the last decision: off where
    DQ Skin now deforms, on where it now does not; elsewhere as the user left it. A render
    evaluation only touches the render side."""
    c = companion_of(obj, mod, st)
    if c is None:
        return
    known = st.companion
    show, merged = decisions.companion_shown(known.deforms, deforms, companion.shown(c), render)
    if s is None:
        companion.configure_without_settings(c, mod)
        show = companion.shown(c)
    else:
        companion.configure(c, mod, s, show)
    known.deforms, known.shown = merged, tuple(show)


def switch_off(obj, mod, st: ModifierState, s) -> None:
    """DQ Skin and its companion both off, as the user would switch off an Armature modifier
    (a cache plays in their place, see `ops.bake`)."""
    mod.show_viewport = mod.show_render = False
    c = companion_of(obj, mod, st)
    if c is not None:
        companion.configure(c, mod, s, (False, False))
    st.companion.deforms = st.companion.shown = (False, False)

# SPDX-License-Identifier: GPL-3.0-or-later
"""Files hold nothing of DQ Skin's runtime: before a save every DQ Skin is put in the state files
are saved in (the companion on wherever DQ Skin is on, set up like it; the node group pointing at
no result), and put back after it. A file opened without the extension then shows Blender's
deformation."""

from __future__ import annotations

from ..blender import companion, settings
from . import companions
from .context import mod_key


def deactivate(session, obj, mod, detach: bool) -> None:
    """The state files are saved in (detached from its result with `detach`)."""
    if obj.library is not None:
        return
    try:
        s = settings.read(mod)
    except Exception:
        s = None
    c = companion.find(obj, mod)
    if c is not None:
        if s is not None:
            companion.configure(c, mod, s, (mod.show_viewport, mod.show_render))
        else:
            companion.configure_without_settings(c, mod)
    st = session.states.find(mod_key(obj, mod))
    session.route.pass_through_modifier(mod)
    if detach:
        session.route.detach(mod)
    if st is not None:
        st.output.invalidate()


def reactivate(session, obj, mod) -> None:
    """After a save: back to how it was before `deactivate` (the next evaluation writes again)."""
    st = session.states.find(mod_key(obj, mod))
    if st is None or obj.library is not None:
        return
    if st.output.result is not None:
        try:
            session.route.attach(mod, st.output.result)
        except ReferenceError:
            st.output.result = None
    c = companions.companion_of(obj, mod, st)
    known = st.companion
    if c is not None and known.shown is not None and st.settings.value is not None:
        companion.configure(c, mod, st.settings.value, known.shown)
    st.output.invalidate()


def deactivate_all(session, detach: bool) -> None:
    """Puts every DQ Skin in the state files are saved in."""
    session.tracker.ensure()
    for obj, mod in session.tracker.local_modifiers():
        deactivate(session, obj, mod, detach)


def reactivate_all(session) -> None:
    """Back from `deactivate_all` (after a save)."""
    for obj, mod in session.tracker.local_modifiers():
        reactivate(session, obj, mod)
    for rec in session.tracker.records.values():
        rec.pending = True

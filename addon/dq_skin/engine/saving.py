# SPDX-License-Identifier: GPL-3.0-or-later
"""Files hold nothing of DQ Skin's runtime: before a save every DQ Skin is put in the state files
are saved in (the companion on wherever DQ Skin is on, set up like it; the node group pointing at
no result), and put back after it. A file opened without the extension then shows Blender's
deformation."""

from __future__ import annotations

from ..blender import companion, settings
from ..routes.base import Target
from . import companions
from .context import mod_key


def deactivate(session, obj, mod) -> None:
    """The state files are saved in."""
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
    key = mod_key(obj, mod)
    st = session.states.get(key)
    session.routes.detach(Target(obj, mod, st, key))


def reactivate(session, obj, mod) -> None:
    """After a save: back to how it was before `deactivate` (the next frame evaluates fully)."""
    key = mod_key(obj, mod)
    st = session.states.find(key)
    if st is None or obj.library is not None:
        return
    session.routes.attach(Target(obj, mod, st, key), st.companion.deforms or (mod.show_viewport, mod.show_render))
    c = companions.companion_of(obj, mod, st)
    known = st.companion
    if c is not None and known.shown is not None and st.settings.value is not None:
        companion.configure(c, mod, st.settings.value, known.shown)


def deactivate_all(session) -> None:
    """Puts every DQ Skin in the state files are saved in."""
    session.tracker.ensure()
    for obj, mod in session.tracker.local_modifiers():
        deactivate(session, obj, mod)


def reactivate_all(session) -> None:
    """Back from `deactivate_all` (after a save)."""
    for obj, mod in session.tracker.local_modifiers():
        reactivate(session, obj, mod)
    for rec in session.tracker.records.values():
        rec.pending = True

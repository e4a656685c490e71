# SPDX-License-Identifier: GPL-3.0-or-later
"""The add-on's preferences (Edit > Preferences > Add-ons > DQ Skin): the threads the core
computes with and the size of the Optimized Centers cache on disk. Both act as soon as they
change, and when the add-on starts (`apply_saved`)."""

from __future__ import annotations

import os

import bpy

from .. import dqskin
from ..model.runtime import ISSUES_URL
from ..session import SESSION

# The add-on's own package (`bl_ext.REPOSITORY.dq_skin`), which names its preferences.
PACKAGE = __package__.rpartition(".")[0]
MEGABYTE = 1 << 20


def all_threads() -> int:
    """What 0 threads means: DQSKIN_NUM_THREADS if set, else every core this process may use."""
    env = os.environ.get("DQSKIN_NUM_THREADS", "").strip()
    if env.isdigit() and int(env) > 0:
        return int(env)
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def apply(prefs, threads: bool = True) -> None:
    """Puts the preferences into effect (`threads`: the thread count too)."""
    if threads:
        wanted = prefs.threads or all_threads()
        try:
            dqskin.set_num_threads(wanted)
        except ValueError:  # more than the core allows on this computer
            dqskin.set_num_threads(all_threads())
    SESSION.centers.set_disk_limit(prefs.centers_cache_mb * MEGABYTE)


def _changed(self, context) -> None:
    apply(self)


def current():
    """The add-on's preferences, or None (not enabled through Blender's add-on list)."""
    addon = bpy.context.preferences.addons.get(PACKAGE)
    return addon.preferences if addon is not None else None


def apply_saved() -> None:
    """At start: the saved preferences in effect (0 threads leaves the core's own default)."""
    prefs = current()
    if prefs is not None:
        apply(prefs, threads=prefs.threads > 0)


class DQSkinPreferences(bpy.types.AddonPreferences):
    """DQ Skin's settings for this computer: the threads its core computes with and the disk
    space the Optimized Centers may keep between sessions"""

    bl_idname = PACKAGE

    threads: bpy.props.IntProperty(
        name="Threads",
        description="Threads DQ Skin computes with (skinning, Optimized Centers, weights); 0: all of this computer's cores. "
        "Fewer leave more for other work",
        default=0,
        min=0,
        max=1024,
        update=_changed,
    )
    centers_cache_mb: bpy.props.IntProperty(
        name="Optimized Centers Cache (MB)",
        description="Disk space the Optimized Centers computed for your meshes may take in the extension's user folder, "
        "so reopening a file does not compute them again; the oldest go first beyond it (0: keep none)",
        default=1024,
        min=0,
        soft_max=16384,
        update=_changed,
    )

    def draw(self, context):
        layout = self.layout
        col = layout.column()
        col.prop(self, "threads")
        col.label(text=f"Now computing with {dqskin.get_num_threads()} threads", icon="INFO")
        col.prop(self, "centers_cache_mb")
        row = layout.row()
        row.label(text="Found a bug, or an internal error on the DQ Skin panel?")
        row.operator("wm.url_open", text="Report an Issue", icon="URL").url = ISSUES_URL


CLASSES = (DQSkinPreferences,)

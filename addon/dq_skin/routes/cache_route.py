# SPDX-License-Identifier: GPL-3.0-or-later
"""The cache route (CACHE): a Mesh Cache modifier on the character itself, right before its DQ
Skin modifier (the *carrier*), reads a point-cache file the add-on writes (`pointcache`); the
DQ Skin node group passes the mesh through. Mesh Cache is deform-only, so everything Blender
computes through deform-only modifiers sees DQ Skin's positions exactly as it would see a
baked cache: brushes and Edit Mode map through them (crazyspace), a Soft Body after them
simulates them, Apply as Shape Key takes them. The feed (`feed`) writes the file inside
Blender's first evaluation; outside it (a full evaluation in a handler or an operator) the file
is written and the object tagged, so that Blender reads it again.

The carrier goes right before the DQ Skin modifier, or before the Soft Bodies right before it
(Blender keeps a Soft Body before every modifier that is not deform-only): they then simulate
the skinned mesh. It is never saved in a file (`engine.saving` removes it before a save and puts
it back after).
"""

from __future__ import annotations

import os

import numpy as np

from ..blender.nodes import GROUP_TAG
from ..model.state import ResultMode, RouteKind
from . import pointcache
from .base import Target
from .feed_drivers import drive_carrier
from .result_route import set_mode

NAME = "DQ Skin positions"


def path_for(target: Target) -> str:
    key = target.key
    return os.path.join(pointcache.folder(), f"dqskin-{os.getpid()}-{key.object_uid}-{key.modifier_uid}.pc2")


def carrier_by_path(obj, path: str):
    """The Mesh Cache of `obj` reading `path` (a carrier found without its DQ Skin modifier)."""
    return next((m for m in obj.modifiers if m.type == "MESH_CACHE" and m.filepath == path), None)


def carrier_of(obj, mod):
    """The carrier of `mod`: the Mesh Cache reading a file of the add-on's right before it (or
    before the Soft Bodies right before it), or None."""
    mods = list(obj.modifiers)
    i = mods.index(mod) - 1
    while i >= 0 and mods[i].type == "SOFT_BODY":
        i -= 1
    if i >= 0 and mods[i].type == "MESH_CACHE" and pointcache.is_ours(mods[i].filepath):
        return mods[i]
    return None


def _place(obj, mod, carrier) -> None:
    """Moves `carrier` right before `mod`, or before the Soft Bodies right before it."""
    mods = list(obj.modifiers)
    at = mods.index(mod)
    while at > 0 and mods[at - 1].type == "SOFT_BODY":
        at -= 1
    now = mods.index(carrier)
    if now != at - 1:
        obj.modifiers.move(now, at if now > at else at - 1)


def show_like(carrier, mod) -> None:
    for attr in ("show_in_editmode", "show_on_cage"):
        if getattr(carrier, attr) != getattr(mod, attr):
            setattr(carrier, attr, getattr(mod, attr))


def remove_orphans(obj) -> None:
    """Carriers no DQ Skin modifier follows any more (a copy's, whose DQ Skin was removed before
    the add-on saw it) go."""
    if obj.library is not None or not hasattr(obj, "modifiers"):
        return
    mods = list(obj.modifiers)
    for i, m in enumerate(mods):
        if m.type != "MESH_CACHE" or not pointcache.is_ours(m.filepath):
            continue
        following = next((f for f in mods[i + 1 :] if f.type != "SOFT_BODY"), None)
        if following is None or following.type != "NODES" or following.node_group is None or following.node_group.get(GROUP_TAG) is None:
            _undrive(obj, m)
            obj.modifiers.remove(m)


class CacheRoute:
    def __init__(self, feeds):
        self.feeds = feeds

    def prepare(self, target: Target):
        """The modifier's carrier and file (made if missing; a copied carrier gets this
        modifier's own file)."""
        obj, mod = target.obj, target.mod
        path = self._file_of(target).path
        carrier = carrier_by_path(obj, path) or carrier_of(obj, mod)
        if carrier is None:
            carrier = obj.modifiers.new(NAME, "MESH_CACHE")
            carrier.cache_format = "PC2"
            carrier.time_mode, carrier.play_mode, carrier.eval_frame = "FRAME", "CUSTOM", 0.0
            carrier.deform_mode, carrier.interpolation = "OVERWRITE", "NONE"
            carrier.forward_axis, carrier.up_axis = "POS_Y", "POS_Z"
        _place(obj, mod, carrier)
        if carrier.filepath != path:
            carrier.filepath = path
        show_like(carrier, mod)
        return carrier

    def _file_of(self, target: Target) -> pointcache.PointCache:
        out = target.st.output
        path = path_for(target)
        if out.pointcache is None or out.pointcache.path != path:
            if out.pointcache is not None:
                out.pointcache.close()
            out.pointcache = pointcache.PointCache(path)
        return out.pointcache

    def buffer(self, target: Target, n: int) -> np.ndarray:
        """Where the kernel writes the modifier's `n` positions: its file's own memory (no copy
        of them is kept)."""
        return self._file_of(target).buffer(n)

    def _write_file(self, target: Target, positions: np.ndarray) -> None:
        out = target.st.output
        cache = out.pointcache
        cache.write(positions)
        if out.buffer is positions and not cache.is_buffer(positions) and pointcache.is_mapped(positions):
            # The file was made again (something deleted it): the kernel writes the new one's.
            out.buffer = cache.buffer(len(positions))

    def show_like_modifier(self, target: Target) -> None:
        """The carrier shows in Edit Mode and on the cage where its DQ Skin modifier does (the
        user may switch those while the carrier stays)."""
        carrier = carrier_of(target.obj, target.mod)
        if carrier is not None:
            show_like(carrier, target.mod)

    def write(self, target: Target, positions: np.ndarray, deforms: tuple[bool, bool]) -> None:
        """Publishes `positions` outside Blender's evaluation: the file, the carrier on where DQ
        Skin deforms (viewport, render), fed by the feed, and the object tagged so that
        Blender reads the file again."""
        obj, mod, st = target.obj, target.mod, target.st
        carrier = self.prepare(target)
        self._write_file(target, positions)
        _drive(obj, carrier, self.feeds.carrier_of(target.key))
        if (carrier.show_viewport, carrier.show_render) != tuple(deforms):
            carrier.show_viewport, carrier.show_render = deforms
        set_mode(mod, ResultMode.CARRIED)
        st.output.kind = ResultMode.CARRIED
        st.output.route = RouteKind.CACHE
        obj.update_tag(refresh={"DATA"})

    def reattach(self, target: Target, deforms: tuple[bool, bool]) -> None:
        """The carrier back in the stack, reading the file as it was (after a save)."""
        obj = target.obj
        carrier = self.prepare(target)
        _drive(obj, carrier, self.feeds.carrier_of(target.key))
        carrier.show_viewport, carrier.show_render = deforms
        set_mode(target.mod, ResultMode.CARRIED)

    def redrive(self, target: Target) -> None:
        """The carrier reads the batch that feeds the modifier now."""
        carrier = carrier_of(target.obj, target.mod)
        if carrier is not None:
            _drive(target.obj, carrier, self.feeds.carrier_of(target.key))

    def remove_carrier(self, target: Target) -> None:
        """The carrier out of the stack (its file stays)."""
        obj = target.obj
        if obj.library is not None:
            return
        carrier = carrier_by_path(obj, path_for(target)) or (carrier_of(obj, target.mod) if target.mod is not None else None)
        if carrier is not None:
            _undrive(obj, carrier)
            obj.modifiers.remove(carrier)

    def fed_done(self, target: Target, positions: np.ndarray) -> None:
        """The feed skinned `positions` inside the evaluation: the carrier reads them next."""
        cache = target.st.output.pointcache
        if cache is not None and not cache.holds(positions):
            self._write_file(target, positions)

    def pass_through(self, target: Target) -> None:
        """DQ Skin does not deform: no carrier, and the node group passes the mesh through."""
        self.release(target)
        set_mode(target.mod, ResultMode.OFF)

    def release(self, target: Target) -> None:
        out = target.st.output
        self.remove_carrier(target)
        if out.pointcache is not None:
            out.pointcache.close()
            out.pointcache = None


def _drive(obj, carrier, feed) -> None:
    """The carrier's Factor driven by the feed's property (always 1: the driver orders it)."""
    drive_carrier(obj, carrier, "factor", "go", feed)


def _undrive(obj, carrier) -> None:
    """The carrier's driver goes, and the object's animation data with it if the driver made it
    (nothing else in it)."""
    ad = obj.animation_data
    if ad is None:
        return
    fc = ad.drivers.find(f'modifiers["{carrier.name}"].factor')
    if fc is not None:
        ad.drivers.remove(fc)
    if not ad.drivers and ad.action is None and not ad.nla_tracks:
        obj.animation_data_clear()

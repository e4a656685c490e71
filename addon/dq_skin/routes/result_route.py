# SPDX-License-Identifier: GPL-3.0-or-later
"""The result routes: each DQ Skin modifier's node group outputs a result object the add-on owns
(`results`):

- RESULT: the result is written after Blender's first evaluation of a frame (in a handler), and
  Blender evaluates again what it changed (what reaches the modifier from other modifiers is
  only known then);
- NODE: the result is fed inside the first evaluation (`feed`): the feed writes the positions
  straight into the result mesh Blender evaluates, whose carrier copies them (see `results`).
"""

from __future__ import annotations

from types import MappingProxyType

import numpy as np

from ..blender import nodes
from ..model.state import ResultMode, RouteKind
from . import results
from .base import Target
from .feed_drivers import drive_carrier


class MeshSource:
    """What a whole-mesh result copies everything but the positions from: the object's mesh,
    its `MeshData` version and its revision (see `meshdata.MeshCache.revision`)."""

    def __init__(self, mesh, version: int, revision: int, counts: tuple):
        self.mesh, self.version, self.revision, self.counts = mesh, version, revision, counts


MODES = MappingProxyType(
    {
        ResultMode.OFF: nodes.MODE_PASS_WARN,
        ResultMode.REPLACE: nodes.MODE_REPLACE,
        ResultMode.POSITIONS: nodes.MODE_POSITIONS,
        ResultMode.CARRIED: nodes.MODE_PASS,
    }
)


def set_mode(mod, kind: ResultMode) -> None:
    """What the node group outputs (written only when it changes)."""
    value = MODES[kind]
    if nodes.get(mod, "Mode") != value:
        nodes.put(mod, "Mode", value)


class ResultRoute:
    def __init__(self, feeds):
        self.feeds = feeds

    def prepare(self, target: Target):
        """This modifier's result object: the one it wrote last, or the one its node group points
        at if that is its own (a copied modifier points at another's), else a new one. The node
        group is made to point at it."""
        obj, mod, st = target.obj, target.mod, target.st
        result = st.output.result
        try:
            if result is not None and not results.owned_by(result, obj, mod):
                result = None
        except ReferenceError:
            result = None
        if result is None:
            pointed = nodes.get(mod, "Result")
            result = pointed if results.owned_by(pointed, obj, mod) else results.create(obj, mod)
            st.output.result = result
        if nodes.get(mod, "Result") != result:
            nodes.put(mod, "Result", result)
        return result

    def write(self, target: Target, positions: np.ndarray, kind: ResultMode, mesh: MeshSource | None, fed: bool) -> None:
        """Publishes `positions` outside Blender's evaluation: the whole mesh (`kind` REPLACE, from
        `mesh`) or points (POSITIONS); without `mesh`, the positions alone (nothing else
        changed). With `fed`, the result also carries what makes the feed's frames reach it."""
        out = target.st.output
        result = out.result
        if mesh is not None:
            if kind is ResultMode.REPLACE:
                m = result.data
                counts = (len(m.vertices), len(m.edges), len(m.polygons), len(m.loops))
                if out.copied_version != mesh.version or out.copied_revision != mesh.revision or counts != mesh.counts:
                    # Everything but the positions comes from the mesh (materials, UV maps, colors...).
                    results.copy_mesh(result, mesh.mesh)
                    out.copied_version, out.copied_revision = mesh.version, mesh.revision
            else:
                results.points_mesh(result, len(positions))
                out.copied_version = 0
        if fed:
            carrier = results.ensure_carrier(result)
            _drive(result, carrier, self.feeds.carrier_of(target.key))
        else:
            results.remove_carrier(result)
        results.write_positions(result, positions)
        set_mode(target.mod, kind)
        out.kind = kind
        out.route = RouteKind.NODE if fed else RouteKind.RESULT

    def redrive(self, target: Target) -> None:
        """The result's carrier reads the batch that feeds the modifier now."""
        result = target.st.output.result
        carrier = result.modifiers.get(results.CARRIER) if result is not None else None
        if carrier is not None:
            _drive(result, carrier, self.feeds.carrier_of(target.key))

    def fed_out(self, target: Target, depsgraph) -> np.ndarray | None:
        """Where the feed's kernel writes this frame: the result mesh `depsgraph` evaluates."""
        result, bound = target.st.output.result, target.st.binding.binding
        view = results.evaluated_positions(result, depsgraph) if result is not None and bound is not None else None
        return view if view is not None and len(view) == bound.vertex_count else None

    def pass_through(self, target: Target) -> None:
        set_mode(target.mod, ResultMode.OFF)

    def release(self, target: Target) -> None:
        self.release_result(target.st.output.result)
        target.st.output.result = None

    def release_result(self, result) -> None:
        if result is None:
            return
        try:
            results.remove(result)
        except ReferenceError:
            pass

    @staticmethod
    def detach(mod) -> None:
        """The node group points at no result (files are saved so)."""
        if nodes.get(mod, "Result") is not None:
            nodes.put(mod, "Result", None)

    @staticmethod
    def attach(mod, result) -> None:
        try:
            nodes.put(mod, "Result", result)
        except ReferenceError:
            pass

    def remove_unused(self) -> None:
        """Deletes the results nothing uses any more (their modifier or object was deleted)."""
        for r in results.unused():
            self.release_result(r)

    @staticmethod
    def positions(target: Target, depsgraph) -> np.ndarray | None:
        """What the result shows in `depsgraph`, copied."""
        result = target.st.output.result
        view = results.evaluated_positions(result, depsgraph) if result is not None else None
        return None if view is None else view.copy()


def _drive(result, carrier, feed) -> None:
    """The carrier aims at the feed, and its driven property follows the feed's (always 0: the
    driver orders it)."""
    results.point_carrier(carrier, feed)
    drive_carrier(result, carrier, results.CARRIER_DRIVEN, "0 * go", feed)

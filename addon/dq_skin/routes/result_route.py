# SPDX-License-Identifier: GPL-3.0-or-later
"""The result route: each DQ Skin modifier's node group outputs a result object the add-on
owns (`results`), written after Blender's first evaluation of a frame (in a handler), which
Blender then evaluates again; for characters whose frames read the pose from memory, the result
is also fed inside the first evaluation (`feed`)."""

from __future__ import annotations

import numpy as np

from ..blender import nodes
from ..model.state import ResultMode
from . import results
from .base import Target
from .feed import Feeds


class MeshSource:
    """What a whole-mesh result copies everything but the positions from: the object's mesh,
    its `MeshData` version and its revision (see `meshdata.MeshCache.revision`)."""

    def __init__(self, mesh, version: int, revision: int, counts: tuple):
        self.mesh, self.version, self.revision, self.counts = mesh, version, revision, counts


class ResultRoute:
    def __init__(self, feeds: Feeds):
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

    def write(self, target: Target, positions: np.ndarray, kind: ResultMode, mesh: MeshSource | None = None) -> None:
        """Publishes `positions` in the modifier's result: the whole mesh (`kind` REPLACE, from
        `mesh`) or points (POSITIONS); None for `mesh` writes the positions alone (steady
        playback: nothing else changed)."""
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
        results.write_positions(result, positions)
        self.feeds.write(result, positions)
        if mesh is not None:
            results.set_mode(result, kind)
            out.kind = kind

    def feed(self, target: Target, feedable: bool) -> None:
        """Feeds the result inside Blender's first evaluation (or stops feeding it)."""
        st = target.st
        result = st.output.result
        if feedable:
            self.feeds.ensure(result, st, st.settings.value.armature, st.binding.binding, st.output.buffer)
        elif self.feeds.fed(result) is not None:
            self.feeds.remove(result)

    def pass_through(self, target: Target) -> None:
        self.pass_through_modifier(target.mod)

    @staticmethod
    def pass_through_modifier(mod) -> None:
        result = nodes.get(mod, "Result")
        if results.is_result(result) and result.library is None:
            results.set_mode(result, ResultMode.OFF)

    def pend(self, result) -> None:
        """The node group outputs nothing until the frame handler writes (see `tracker.frame_pre`)."""
        results.set_mode(result, ResultMode.PENDING)

    def release(self, target: Target) -> None:
        self.release_result(target.st.output.result)

    def release_result(self, result) -> None:
        if result is None:
            return
        try:
            self.feeds.remove(result)
            results.remove(result)
        except ReferenceError:
            pass

    def remove_unused(self) -> None:
        """Deletes the results nothing uses any more (their modifier or object was deleted)."""
        for r in results.unused():
            self.release_result(r)

    @staticmethod
    def detach(mod) -> None:
        """The node group points at no result (files are saved so)."""
        if nodes.get(mod, "Result") is not None:
            nodes.put(mod, "Result", None)

    @staticmethod
    def attach(mod, result) -> None:
        nodes.put(mod, "Result", result)

    @staticmethod
    def mode_of(result) -> ResultMode:
        return results.mode_of(result)

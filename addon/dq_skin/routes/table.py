# SPDX-License-Identifier: GPL-3.0-or-later
"""The routes of the session, behind one interface: publish a modifier's positions the way the
decisions chose (`decisions.route_for`), switching from the way they reached Blender before;
pass the mesh through; release everything a modifier's routes made."""

from __future__ import annotations

import numpy as np

from ..model.state import ResultMode, RouteKind
from .base import Target
from .cache_route import CacheRoute
from .feed import Feeds, Member
from .result_route import MeshSource, ResultRoute, set_mode


class Routes:
    def __init__(self, feeds: Feeds):
        self.feeds = feeds
        self.result = ResultRoute(feeds)
        self.cache = CacheRoute(feeds)
        feeds.retarget = self.redrive

    def redrive(self, member: Member) -> None:
        """`member`'s carriers read the batch that now feeds it (a character hidden or shown)."""
        target = member.target
        try:
            if member.kind is RouteKind.CACHE:
                self.cache.redrive(target)
            elif member.kind is RouteKind.NODE:
                self.result.redrive(target)
        except (ReferenceError, ValueError):
            pass  # (its object or modifier is gone: `prune` forgets it)

    def publish(
        self,
        target: Target,
        kind: RouteKind,
        positions: np.ndarray,
        mode: ResultMode,
        mesh: MeshSource | None,
        deforms: tuple[bool, bool],
        member: Member | None,
        scene,
    ) -> None:
        """Publishes a full evaluation's `positions` on the route `kind` (a result of `mode`
        from `mesh` for RESULT and NODE; `mesh` None: only the positions changed), fed by
        `scene`'s batch as `member` for NODE and CACHE."""
        previous = target.st.output.route
        if previous is not None and previous is not kind:
            self._leave(target, previous, kind)
        if kind is RouteKind.RESULT or member is None or scene is None:
            self.feeds.leave(target.key)
        else:
            self.feeds.join(member, scene)
        if kind is RouteKind.CACHE:
            self.cache.write(target, positions, deforms)
        else:
            self.result.write(target, positions, mode, mesh, fed=kind is RouteKind.NODE)

    def _leave(self, target: Target, previous: RouteKind, kind: RouteKind) -> None:
        if previous is RouteKind.CACHE:
            self.cache.release(target)
        elif kind is RouteKind.CACHE:
            self.result.release(target)

    def pass_through(self, target: Target) -> None:
        """DQ Skin does not deform: the node group passes the mesh through, no carrier deforms,
        the feed lets it go (the result object stays for when it deforms again)."""
        self.feeds.leave(target.key)
        if target.st.output.route is RouteKind.CACHE or target.st.output.pointcache is not None:
            self.cache.release(target)
        self.result.pass_through(target)
        target.st.output.route = None
        target.st.output.kind = ResultMode.OFF

    def release(self, target: Target) -> None:
        """Everything of the modifier's routes goes (the modifier is gone, or the file is saved)."""
        self.feeds.leave(target.key)
        self.cache.release(target)
        self.result.release(target)
        target.st.output.route = None

    def release_state(self, st) -> None:
        """What a modifier whose object is gone made (the object took its carrier with it)."""
        self.result.release_result(st.output.result)
        st.output.result = None
        if st.output.pointcache is not None:
            st.output.pointcache.close()
            st.output.pointcache = None
        st.output.route = None

    def remove_unused(self) -> None:
        self.result.remove_unused()

    def detach(self, target: Target) -> None:
        """The state files are saved in: the node group passes the mesh through and points at no
        result, and no carrier is in the stack (its file stays, for `attach`)."""
        self.cache.remove_carrier(target)
        set_mode(target.mod, ResultMode.OFF)
        self.result.detach(target.mod)

    def attach(self, target: Target, deforms: tuple[bool, bool]) -> None:
        """Back from `detach` (after a save): what showed before shows again."""
        out = target.st.output
        if out.route is RouteKind.CACHE and out.pointcache is not None:
            self.cache.reattach(target, deforms)
        elif out.route is not None and out.result is not None:
            self.result.attach(target.mod, out.result)
            set_mode(target.mod, out.kind)

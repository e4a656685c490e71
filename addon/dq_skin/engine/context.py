# SPDX-License-Identifier: GPL-3.0-or-later
"""What one evaluation shares between objects (`Context`), one skinning to run (`Plan`), and
the error a user can fix (`SkinError`)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import cached_property

from ..blender import compat, nodes
from ..blender.meshdata import MeshData
from ..blender.pose import PoseReads
from ..model.keys import FrameKey, ModKey
from ..model.methods import Settings
from ..model.state import ModifierState, ResultMode, RouteKind


class SkinError(Exception):
    """A problem the user can fix, shown on the panel and in operator reports."""


def dq_skin_modifiers(obj):
    return [m for m in obj.modifiers if nodes.is_dq_skin(m)] if obj.type == "MESH" else []


def mod_key(obj, mod) -> ModKey:
    return ModKey(obj.session_uid, compat.modifier_uid(mod))


@dataclass
class Context:
    """What one handler call (or operator) shares between objects. `session`: the add-on's
    session (its states, caches, readers, route...)."""

    session: object
    depsgraph: object
    structure: int = 0  # the tracker's structure version (see `consumers.Scan`)
    batch: list | None = None  # plans to skin together (see `pipeline.run_batch`)
    unchanged: set = field(default_factory=set)  # objects Blender did not update: cached settings hold
    unmoved: set = field(default_factory=set)  # objects whose transform did not change
    poses: dict = field(default_factory=dict)  # armature uid -> this evaluation's pose matrices
    reads: PoseReads | None = None  # poses read from memory in this call

    def __post_init__(self):
        if self.reads is None:
            readers = self.session.readers
            self.reads = PoseReads(readers.pose, readers.pose_error)

    @cached_property
    def render(self) -> bool:
        return self.depsgraph.mode == "RENDER"

    @cached_property
    def fed_stamp(self) -> tuple:
        """What a member the feed skinned in this frame change's evaluation of this depsgraph
        carries (`Feeds.stamp`)."""
        return self.session.routes.feeds.stamp(self.depsgraph)

    def state(self, obj, mod) -> ModifierState:
        return self.session.states.get(mod_key(obj, mod))


@dataclass
class Plan:
    """One skinning to run: the kernel's job and where its result goes."""

    target: object  # routes.base.Target
    s: Settings
    kind: ResultMode  # what a result route's node group outputs
    route: RouteKind
    key: FrameKey
    job: object  # dqskin.SkinJob
    deforms: tuple  # (viewport, render): where DQ Skin deforms (the companion is off there)
    start: float = field(default_factory=time.perf_counter)
    render: bool = False  # a render's evaluation (only the render side of the companion changes)
    data: MeshData | None = None  # the mesh's data as the full path read it
    previous: ModifierState | None = None  # the DQ Skin before it, whose output reaches it (a chain)
    scene: object = None  # the scene whose feed it joins

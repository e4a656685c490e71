# SPDX-License-Identifier: GPL-3.0-or-later
"""The fed frame: inside Blender's first evaluation, the feed's driver (`routes.feed`) skins its
members with this frame's bones, transforms and shape keys, on the job their last full
evaluation built, and writes each one's positions where its route's carrier reads them.

A member is skinned only when what the driver can read says the last full evaluation still
stands (the same bound bones, the mesh as read then); anything else is left to the frame
handler, which checks the rest and evaluates fully where needed (`playback.fed_frame_stands`).
Members of one object are skinned in stack order (a DQ Skin after another takes its output)."""

from __future__ import annotations

import numpy as np

from .. import dqskin
from ..blender import pose, rig
from ..model.keys import FrameKey, InputKey, PoseKey, Source
from ..model.state import Mode, RouteKind
from . import binding, inputs

# What `FedFrame._prepare` returns for a member whose carrier already holds this frame.
CURRENT = object()

# Vertices (over a level's jobs) from which the kernel shares its work with the pool's threads
# inside Blender's evaluation. Below, the driver's thread skins alone: Blender's own threads hold
# the other cores there, and waking a helper cost more than it gained (docs/performance.md).
SHARE_FROM = 40_000


class FedFrame:
    """One run of a batch's driver in one depsgraph."""

    def __init__(self, session, depsgraph):
        self.session = session
        self.depsgraph = depsgraph
        readers = session.readers
        self.reads = pose.PoseReads(readers.pose, readers.pose_error)
        self.poses: dict[int, np.ndarray] = {}

    def run(self, members: list) -> tuple[list, list]:
        """Skins what it can of `members`; returns the members it skinned and those whose
        carrier holds this frame already (a held pose)."""
        skinned, current = [], []
        levels: dict[int, list] = {}
        for m in members:
            levels.setdefault(m.order, []).append(m)
        outputs: dict = {}  # ModifierState -> this frame's output array (chains read it)
        for order in sorted(levels):
            ready = []
            for m in levels[order]:
                prepared = self._prepare(m, outputs)
                if prepared is CURRENT:
                    outputs[id(m.target.st)] = m.target.st.output.buffer
                    current.append(m)
                elif prepared is not None:
                    ready.append((m, *prepared))
            if not ready:
                continue
            errors = dqskin.skin_many([job for _m, job, _key, _out in ready], share_from=SHARE_FROM)
            for (m, job, key, out), error in zip(ready, errors):
                st = m.target.st
                if error is None and m.kind is RouteKind.NODE and m.alone:
                    # The result Blender evaluates holds this frame: no buffer of ours is kept
                    # until the next full evaluation (12 bytes a vertex; `pipeline` makes one).
                    st.output.buffer = None
                if out is not st.output.buffer:
                    job.out = st.output.buffer  # (the view of Blender's memory is not kept)
                if error is not None:
                    continue
                if m.kind is RouteKind.CACHE:
                    self.session.routes.cache.fed_done(m.target, out)
                st.output.written = key
                st.output.generation += 1
                outputs[id(st)] = out
                skinned.append(m)
        return skinned, current

    def _prepare(self, m, outputs: dict):
        """The member's job with this frame's inputs, the key of what it computes and where it
        writes; `CURRENT` where its carrier holds this frame already; None where the full
        evaluation must decide."""
        target, dg = m.target, self.depsgraph
        st = target.st
        out = st.output
        old, job, s = out.written, out.job, st.settings.value
        if st.status.mode is not Mode.LIVE or old is None or job is None or s is None or out.route is not m.kind:
            return None
        obj_eval = target.obj.evaluated_get(dg)
        if not obj_eval.is_evaluated:
            return None  # not in this graph
        arm = s.armature
        arm_eval = arm.evaluated_get(dg)
        positions, input_key = self._positions(m, obj_eval, old, outputs)
        if positions is None:
            return None
        worlds = (obj_eval.matrix_world, arm_eval.matrix_world)
        if out.spaces is None or out.spaces_of != worlds:
            out.spaces, out.spaces_of = rig.spaces(obj_eval, arm_eval), tuple(w.copy() for w in worlds)
        premat, postmat = out.spaces
        bound = st.binding.binding
        if bound is None:
            return None
        if st.needs_effective:
            data = self.reads.read(arm_eval)
            if data is None or not pose.same_bones(data, bound) or data.binding_signature != old.pose.binding_signature:
                return None
            # (The joints' rest matrices are made only where a new job needs them, below.)
            bones = pose.Bones(data.deform, None, pose.memory_key(data), data)
            cache = st.binding
            influences = pose.influences(
                bones, bound, arm_eval, positions, input_key, premat, s.use_vertex_groups, s.use_envelopes, cache.envelopes, cache.segments
            )
            deform, rest_of, pose_key = bones.deform, lambda: data.rest, bones.key
        else:
            deform = self._pose_matrices(arm, arm_eval, bound)
            influences, rest_of, pose_key = bound.influences, lambda: bound.rest, PoseKey.of_matrices(deform)
        key = FrameKey(old.settings, input_key, pose_key, premat.tobytes(), old.result, old.mesh_version)
        if key == old and m.kind is RouteKind.CACHE:
            # A held pose: the carrier's file holds this frame already. (A result object is
            # evaluated again with the batch, from its own mesh: it is written again below.)
            return CURRENT
        where = self.session.routes.result.fed_out(target, dg) if m.kind is RouteKind.NODE else out.buffer
        if where is None:
            return None
        if influences is not job.influences:
            if s.method == dqskin.Method.CENTERS_OF_ROTATION:
                return None  # other influences need their own centers: the full evaluation computes them
            job = out.job = binding.job(st, s, positions, influences, deform, rest_of(), premat, postmat, out=where)
        else:
            if job.positions is not positions:
                job.positions = positions
            job.deform = deform
            job.premat, job.postmat = premat, postmat
        if job.out is not where:
            job.out = where
        return job, key, where

    def _positions(self, m, obj_eval, old: FrameKey, outputs: dict):
        """What reaches the member this frame and its key: the mesh with its shape keys mixed,
        or the previous DQ Skin's output (None, None where the full evaluation must decide)."""
        target = m.target
        st = target.st
        source = old.source.source
        if source is Source.MESH:
            data = self.session.meshes.peek(target.obj)
            if data is None or data.version != old.source.version:
                return None, None
            try:
                positions, input_key = inputs.mesh_input(target.obj, obj_eval, st, data, self.depsgraph, old.source)
            except inputs.CaptureNeeded:
                return None, None
            # (Influences from B-Bones and envelopes depend on where the vertices are: an array.)
            return (inputs.as_array(positions, data) if st.needs_effective else positions), input_key
        if source is Source.CHAIN:
            previous = m.previous
            written = outputs.get(id(previous)) if previous is not None else None
            if written is None:
                return None, None
            return written, InputKey(Source.CHAIN, previous.output.generation, (id(previous),))
        return None, None

    def _pose_matrices(self, arm, arm_eval, bound) -> np.ndarray:
        deform = self.poses.get(arm.session_uid)
        if deform is None:
            deform = self.poses[arm.session_uid] = rig.pose_matrices(arm_eval, self.reads.reader)
        if len(bound.bone_indices) != len(deform):
            deform = np.ascontiguousarray(deform[bound.bone_indices])
        return deform


def skin_members(session):
    """The feed's skinning function for `session` (`Feeds.skin`)."""

    def skin(members, depsgraph):
        frame = FedFrame(session, depsgraph)
        try:
            return frame.run(members)
        finally:
            session.routes.feeds.keep(depsgraph, frame.reads)

    return skin

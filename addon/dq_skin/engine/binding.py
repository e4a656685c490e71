# SPDX-License-Identifier: GPL-3.0-or-later
"""What holds while the mesh, its weights, the armature's bones and the settings stay the same:
the influences (the *binding*), the mask and blend weights, the Optimized Centers of Rotation,
and the kernel's job built from them."""

from __future__ import annotations

import weakref

import numpy as np

from .. import dqskin
from ..blender import pose, rig
from ..blender.meshdata import MeshData
from ..model.keys import BindingKey
from ..model.methods import Settings
from ..model.state import ModifierState
from . import centers
from .context import Context, SkinError


class SharedInfluences:
    """Influences made once for every binding of the same weights on bones mapped the same way
    (a crowd of copies of one character, each on its own armature, binds to one: 87 KB a
    CesiumMan), kept while a binding uses them (owned by the session)."""

    def __init__(self):
        self._made = weakref.WeakValueDictionary()

    def __call__(self, key: tuple, make):
        got = self._made.get(key)
        if got is None:
            got = self._made[key] = make()
        return got

    def forget(self) -> None:
        self._made.clear()


def binding(obj, arm, arm_eval, st: ModifierState, s: Settings, data: MeshData, ctx: Context) -> rig.Binding:
    """The influences of this mesh on this armature, kept while what they depend on holds
    (the armature's bones are compared on every full evaluation, whatever changed them: from
    Blender's memory, see `pose.armature_signature`)."""
    cache = st.binding
    key = BindingKey(
        data.uid,
        data.version,
        arm.session_uid,
        pose.armature_signature(arm_eval, ctx.reads),
        s.mask_group,
        s.invert_mask,
        s.blend_group,
        s.use_vertex_groups,
    )
    if cache.binding is None or cache.key != key:
        cache.clear()
        interned = ctx.session.interned
        bound = rig.bind(data, arm, s.mask_group, s.invert_mask, s.use_vertex_groups, shared=ctx.session.influences, interned=interned)
        cache.binding = bound
        cache.envelopes = interned(rig.envelopes(arm, bound))
        cache.blend = data.group_weights(s.blend_group) if s.blend_group else None
        cache.segments = interned(rig.bbone_segments(arm, bound))
        cache.uses_envelopes = bool(cache.envelopes[:, 10].any())
        cache.uses_bbones = bool(cache.segments.max(initial=0) > 1)
        cache.key = key
        st.output.invalidate()
        data.release_groups()  # (bound: read again if the binding must be made again)
    st.needs_effective = s.use_envelopes or cache.uses_envelopes or cache.uses_bbones
    if s.method == dqskin.Method.CENTERS_OF_ROTATION and not st.needs_effective:
        centers_of(obj, st, data, cache.binding.influences, ctx)
    return cache.binding


def job(st: ModifierState, s: Settings, positions, influences, deform, rest, premat, postmat, out=None) -> dqskin.SkinJob:
    """The `dqskin.SkinJob` of one modifier: its settings, kept data and output (`out`, else
    the modifier's buffer; checked here: a bad input, a bone scaled to NaN say, is this
    modifier's error, shown on its panel)."""
    method = s.method
    # The Blend Amount is a vertex group, or one value for every vertex (scaled by the factor).
    factor = s.blend_factor if s.blend_group else s.blend_factor * s.blend_amount
    try:
        return dqskin.SkinJob(
            positions,
            influences,
            np.ascontiguousarray(deform),
            rest,
            method=method,
            premat=premat,
            postmat=postmat,
            mask=st.binding.binding.mask,
            blend=st.binding.blend if method == dqskin.Method.BLEND else None,
            blend_factor=factor,
            out=st.output.buffer if out is None else out,
            centers=st.binding.centers if method == dqskin.Method.CENTERS_OF_ROTATION else None,
        )
    except (TypeError, ValueError) as e:
        raise SkinError(str(e)) from None


def centers_of(obj, st: ModifierState, data: MeshData, influences, ctx: Context) -> None:
    """Puts the Optimized Centers of Rotation for `influences` (the binding's; with envelopes or
    B-Bones, the influences DQ Skin skins with, over the bones and the B-Bones' segment joints)
    in `st.binding.centers`: kept, found in the cache, computed now (small meshes, command line,
    renders), updated from the centers of the same mesh with other weights (a brush stroke:
    only what it reaches; in the background on large meshes, the last centers showing
    meanwhile), or started in the background (the SkinError that says so lets Blender's
    deformation stand in until they are ready)."""
    cache = st.binding
    if cache.centers is not None and cache.centers_of is influences and not cache.centers_pending:
        return
    store = ctx.session.centers
    triangles = centers.triangles_of(obj.data)
    key = centers.key_of(data.positions, triangles, influences)
    got = store.lookup(key, data.vertex_count)
    if got is not None:
        # Found (this session, or on disk from an earlier one): the next weight change updates
        # from these, as from centers computed here.
        store.remember_latest(centers.geometry_of(data.positions, triangles), influences, got)
        if cache.centers_pending:
            st.output.invalidate()  # the updated centers replace the last ones: skin again
        cache.centers, cache.centers_of, cache.centers_pending = got, influences, ""
        return
    running = store.job_of(key)
    if running is not None and running.finished and running.error:
        raise SkinError(f"Optimized Centers: {running.error} (change the method or any setting to try again)")
    geometry = centers.geometry_of(data.positions, triangles)
    previous = store.latest(geometry)
    spot = centers.in_background() or ctx.render
    if data.vertex_count <= (centers.UPDATE_INLINE_VERTICES if previous else centers.INLINE_VERTICES) or spot:
        label = f"Optimized Centers for {obj.name} ({data.vertex_count} vertices)" if centers.in_background() else ""
        try:
            got = store.compute(data.positions, triangles, influences, key, label=label, geometry=geometry, previous=previous)
        except centers.Cancelled:
            raise SkinError("Optimized Centers: cancelled") from None
        cache.centers, cache.centers_of, cache.centers_pending = got, influences, ""
        return
    running = store.start(data.positions, triangles, influences, key, obj.name, geometry=geometry, previous=previous)
    if previous is not None:
        # The last centers of this mesh keep showing until the update is in.
        cache.centers, cache.centers_of, cache.centers_pending = previous[1], influences, key
        return
    raise SkinError(
        f"Optimized Centers: computing for {data.vertex_count} vertices ({running.fraction:.0%}); "
        "Blender's deformation shows until they are ready"
    )

"""Builders for the synthetic rigs of the exactness tests, with Blender's data API."""

from __future__ import annotations

import math

import numpy as np

import bpy


def link(obj):
    bpy.context.scene.collection.objects.link(obj)
    return obj


def armature_chain(name: str, count: int, length: float, axis=(0.0, 0.0, 1.0)):
    """An armature with a connected chain of `count` bones along `axis`, total `length`."""
    data = bpy.data.armatures.new(name)
    arm = link(bpy.data.objects.new(name, data))
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="EDIT")
    axis = np.array(axis, float) / np.linalg.norm(axis)
    previous = None
    for i in range(count):
        bone = data.edit_bones.new(f"Bone{i}")
        bone.head = tuple(axis * length * i / count)
        bone.tail = tuple(axis * length * (i + 1) / count)
        if previous is not None:
            bone.parent = previous
            bone.use_connect = True
        previous = bone
    bpy.ops.object.mode_set(mode="OBJECT")
    for pb in arm.pose.bones:
        pb.rotation_mode = "QUATERNION"
    return arm


def tube(name: str, rings: int, segments: int, length: float, radius: float):
    """A closed cylinder along +Z: ring by ring, then the two cap centres."""
    verts = []
    for r in range(rings):
        z = length * r / (rings - 1)
        for s in range(segments):
            phi = 2 * math.pi * s / segments
            verts.append((radius * math.cos(phi), radius * math.sin(phi), z))
    bottom, top = len(verts), len(verts) + 1
    verts += [(0.0, 0.0, 0.0), (0.0, 0.0, length)]
    faces = []
    for r in range(rings - 1):
        for s in range(segments):
            a, b = r * segments + s, r * segments + (s + 1) % segments
            faces.append((a, b, b + segments, a + segments))
    for s in range(segments):
        faces.append((bottom, (s + 1) % segments, s))
        last = (rings - 1) * segments
        faces.append((top, last + s, last + (s + 1) % segments))
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    mesh.update()
    return link(bpy.data.objects.new(name, mesh))


def chain_weights(mesh_obj, arm, length: float, blend: float = 0.5, scale: float = 1.0, skip=()):
    """Vertex groups for a chain along Z: each vertex blends linearly between the two nearest
    bones over `blend` of a bone's length; weights multiplied by `scale` (unnormalized when not 1);
    vertices whose index is in `skip` get no weights at all."""
    bones = list(arm.data.bones)
    n = len(bones)
    groups = [mesh_obj.vertex_groups.new(name=b.name) for b in bones]
    for v in mesh_obj.data.vertices:
        if v.index in skip:
            continue
        u = max(0.0, min(n - 1e-6, v.co.z / length * n))  # position in bone units
        i = int(u)
        f = u - i  # 0..1 along bone i
        w_next = 0.0
        if f > 1 - blend / 2 and i + 1 < n:
            w_next = (f - (1 - blend / 2)) / blend
        w_prev = 0.0
        if f < blend / 2 and i > 0:
            w_prev = (blend / 2 - f) / blend
        own = 1.0 - w_next - w_prev
        # Stored order: own bone first, then the neighbour (the order matters for DQS signs).
        groups[i].add([v.index], own * scale, "REPLACE")
        if w_next > 0:
            groups[i + 1].add([v.index], w_next * scale, "REPLACE")
        if w_prev > 0:
            groups[i - 1].add([v.index], w_prev * scale, "REPLACE")


def armature_modifier(mesh_obj, arm, **settings):
    mod = mesh_obj.modifiers.new("Armature", "ARMATURE")
    mod.object = arm
    for k, v in settings.items():
        setattr(mod, k, v)
    return mod


def rig_tube(rings=24, segments=16, length=4.0, radius=0.4, bones=2, rig="vertex groups", **weights):
    arm = armature_chain("Rig", bones, length)
    mesh_obj = tube("Tube", rings, segments, length, radius)
    chain_weights(mesh_obj, arm, length, **weights)
    mod = armature_modifier(mesh_obj, arm)
    make_rig(arm, rig)
    return mesh_obj, arm, mod


# The rigs and routes DQ Skin is tested on: vertex groups only and B-Bones (skinned by the feed
# inside Blender's first evaluation, into a Mesh Cache carrier: the route of characters up to
# `decisions.CACHE_ROUTE_VERTICES`), and B-Bones on the result-object route (that of larger
# meshes; conftest makes these small test meshes take it). Tests of what artists do run on all
# three.
RIGS = ["vertex groups", "B-Bones", "B-Bones, node route"]


def make_rig(arm, rig: str, segments: int = 4) -> None:
    """For "B-Bones" and "B-Bones, node route": every deforming bone a B-Bone with `segments` segments,
    eased and with a slightly curved rest shape (as Rigify's deforming bones are)."""
    if rig == "vertex groups":
        return
    assert rig in ("B-Bones", "B-Bones, node route"), rig
    for b in arm.data.bones:
        if b.use_deform:
            b.bbone_segments = segments
            b.bbone_easein, b.bbone_easeout = 1.3, 0.8
            b.bbone_curveinx = 0.05 * b.length

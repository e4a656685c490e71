"""The kernel reads a mesh's positions where Blender keeps them (`dqskin.memory.MeshPositions`):
no copy of ours beside Blender's array, the result still equal to the Armature modifier's, and
a mesh that changed or went since a job was made fails that job alone, never a read of freed
memory. Where an array is needed (B-Bone and envelope influences, Blender 5.1+ whose attribute
storage the reader does not know), a copy is held as before.

Bar: max vertex distance ≤ 1e-5 × the mesh's bounding-box diagonal (REL_TOL); the kernel on
Blender's array equal to the kernel on a copy to the bit.
"""

from __future__ import annotations

import numpy as np
import pytest
from dqtest import REL_TOL, add_dq_skin, deviation, dq_skin_mods, evaluated_positions, reference_copy
from scenes import armature_chain, armature_modifier, chain_weights, tube

import bpy

from mathutils import Quaternion

LENGTH = 4.0
IN_PLACE = bpy.app.version < (5, 1, 0)  # (5.1+ keeps positions in its attribute storage)


def _character(name: str, bbones: bool = False):
    obj = tube(name, 40, 24, LENGTH, 0.5)
    arm = armature_chain(name + "Rig", 4, LENGTH)
    chain_weights(obj, arm, LENGTH)
    obj.parent = arm
    armature_modifier(obj, arm)
    if bbones:
        arm.data.bones["Bone1"].bbone_segments = 4
    for i, angle in enumerate((0.5, -0.7, 0.9)):
        pb = arm.pose.bones[f"Bone{i + 1}"]
        pb.rotation_mode = "QUATERNION"
        pb.rotation_quaternion = Quaternion((1, 0.3 * i, 0), angle)
    return obj, arm


def _positions(mesh) -> np.ndarray:
    flat = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.attributes["position"].data.foreach_get("vector", flat)
    return flat.reshape(-1, 3)


def test_the_kernel_reads_blenders_positions_and_holds_no_copy(dq_skin):
    """A vertex-group character: its mesh data holds no copy of the positions (where the reader
    knows this Blender), the job reads the handle, and a script that moves vertices and tells
    Blender sees them skinned at the next frame, equal to the Armature modifier."""
    obj, _arm = _character("InPlace")
    ref = reference_copy(obj, True)
    add_dq_skin(obj, "DUAL_QUATERNION")
    bpy.context.scene.frame_set(2)
    session = dq_skin.SESSION
    data = session.meshes.peek(obj)
    assert data is not None
    st = session.state_of(obj, dq_skin_mods(obj)[0])
    assert st.status.live, st.status.message
    if IN_PLACE:
        assert isinstance(data.source, dq_skin.dqskin.memory.MeshPositions), session.readers.positions_error
        assert data.held_positions is None and session.meshes.nbytes() == 0
        assert st.output.job.positions is data.source
    else:
        assert isinstance(data.source, np.ndarray) and session.meshes.nbytes() == data.source.nbytes
    assert deviation(evaluated_positions(obj), evaluated_positions(ref)) <= REL_TOL
    # A script moves vertices of the shared mesh and tells Blender.
    before = evaluated_positions(obj)
    for v in obj.data.vertices[:60]:
        v.co.x += 0.25
    obj.data.update()
    bpy.context.scene.frame_set(3)
    after = evaluated_positions(obj)
    assert deviation(after, evaluated_positions(ref)) <= REL_TOL
    assert deviation(after, before) > 100 * REL_TOL  # (the test moved something)
    assert session.meshes.peek(obj).held_positions is None or not IN_PLACE


def test_bbone_influences_hold_their_copy(dq_skin):
    """B-Bone influences depend on where the vertices are: the array they need is held, and the
    result equals the Armature modifier's."""
    obj, _arm = _character("InPlaceBBones", bbones=True)
    ref = reference_copy(obj, False)
    add_dq_skin(obj, "LINEAR")
    for frame in (2, 3):
        bpy.context.scene.frame_set(frame)
        assert deviation(evaluated_positions(obj), evaluated_positions(ref)) <= REL_TOL
    data = dq_skin.SESSION.meshes.peek(obj)
    assert data.held_positions is not None and np.array_equal(data.held_positions, _positions(obj.data))


def test_a_job_on_blenders_positions_fails_alone_when_its_mesh_changes_or_goes(dq_skin):
    """`SkinJob` over a `MeshPositions`: equal to the same job over a copy; a handle of an
    evaluated mesh is refused; after the mesh gained vertices, or was removed, that job's entry
    of `skin_many` says why and the other job still runs."""
    dqskin = dq_skin.dqskin
    reader = dq_skin.SESSION.readers.mesh
    assert reader is not None, dq_skin.SESSION.readers.mesh_error
    obj = tube("Handle", 12, 8, LENGTH, 0.5)
    mesh = obj.data
    handle = reader.positions_in_place(mesh)
    if not IN_PLACE:
        assert handle is None
        pytest.skip("Blender 5.1+ keeps positions in its attribute storage: DQ Skin holds a copy")
    want = _positions(mesh)
    n = len(want)
    assert len(handle) == n and handle.mesh == mesh
    assert np.array_equal(handle.read(), want)
    assert dqskin.memory.positions_digest(handle) == dqskin.memory.positions_digest(want)
    moved = want.copy()
    moved[5, 1] += 1e-3
    assert dqskin.memory.positions_digest(moved) != dqskin.memory.positions_digest(want)
    with pytest.raises(ValueError, match="original"):
        reader.positions_in_place(obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data)
    # One bone turning everything; the other job runs on a copy.
    influences = dqskin.Influences.from_dense(np.zeros((n, 1), np.int32), np.ones((n, 1), np.float32), 1)
    deform = np.eye(4, dtype=np.float32)[None].copy()
    deform[0, :3, 3] = (0.5, -1.0, 2.0)
    deform[0, :3, :3] = np.asarray(Quaternion((0, 0, 1), 0.7).to_matrix(), np.float32)
    rest = np.eye(4, dtype=np.float32)[None].copy()
    on_blender = dqskin.SkinJob(handle, influences, deform, rest, method="dual_quaternion")
    on_copy = dqskin.SkinJob(want.copy(), influences, deform, rest, method="dual_quaternion")
    assert dqskin.skin_many([on_blender, on_copy]) == [None, None]
    assert np.array_equal(on_blender.out, on_copy.out)
    assert not np.array_equal(on_blender.out, want)  # (it moved)
    # The mesh gains vertices: Blender's array is reallocated; the handle's job fails alone.
    mesh.vertices.add(3)
    errors = dqskin.skin_many([on_blender, on_copy])
    assert errors[1] is None and errors[0] is not None and f"{n + 3} vertices, expected {n}" in errors[0], errors
    with pytest.raises(ValueError, match=f"{n + 3} vertices, expected {n}"):
        dqskin.skin(handle, influences, deform, rest)
    with pytest.raises(ValueError, match="vertices"):
        on_copy.positions = reader.positions_in_place(mesh)  # (a mesh of n + 3 vertices)
    bpy.data.objects.remove(obj)
    bpy.data.meshes.remove(mesh)
    errors = dqskin.skin_many([on_blender, on_copy])
    assert errors[1] is None and errors[0] is not None and "removed" in errors[0], errors
    with pytest.raises(ValueError, match="removed"):
        handle.read()
    assert "MeshPositions" in repr(handle)

# SPDX-License-Identifier: GPL-3.0-or-later
"""The readers of Blender's memory (`dqskin.memory.MeshMemory` for vertex-group weights and positions,
`dqskin.memory.PoseMemory` for armature poses, `dqskin.memory.ObjectStateMemory` for what decides
whether an object's fed frame stands), built once per session from the SDNA of a tiny .blend
this Blender writes: the file describes the structs in memory whatever the version. Each reader's
first read in the session is checked against Blender's own data (`memory_check`). If a reader
cannot be built or its check fails, its error says why and the callers take their slow, safe
Python paths."""

from __future__ import annotations

import os
import tempfile

import bpy

from .. import dqskin
from . import memory_check
from .meshdata import Groups


class Readers:
    """The memory readers of this session (built on first use, owned by the session)."""

    def __init__(self):
        self._built = False
        self._mesh = None
        self._pose = None
        self._object_state = None
        self.mesh_error = ""
        self.pose_error = ""
        self.object_state_error = ""
        # Whether each reader's first read agreed with Blender's data (`memory_check`).
        self.mesh_checked = False
        self.positions_checked = False
        self.positions_refused = False  # the positions are not where the reader looks, or disagreed
        self.positions_error = ""
        self.pose_checked = False
        self.channels_checked = False
        self.object_state_checked = False

    def _build(self) -> None:
        if self._built:
            return
        self._built = True
        fd, path = tempfile.mkstemp(prefix="dq_skin_dna_", suffix=".blend")
        os.close(fd)
        try:
            bpy.data.libraries.write(path, set(), compress=False)
            with open(path, "rb") as f:
                blend_file = f.read()
        except Exception as e:  # any failure: both readers fall back to the slow, safe path
            self.mesh_error = self.pose_error = self.object_state_error = f"{type(e).__name__}: {e}"
            return
        finally:
            try:
                os.remove(path)
            except OSError:
                pass
        try:
            self._mesh = dqskin.memory.MeshMemory(blend_file)
        except Exception as e:
            self.mesh_error = f"{type(e).__name__}: {e}"
        try:
            self._pose = dqskin.memory.PoseMemory(blend_file)
        except Exception as e:
            self.pose_error = f"{type(e).__name__}: {e}"
        try:
            self._object_state = dqskin.memory.ObjectStateMemory(blend_file)
        except Exception as e:
            self.object_state_error = f"{type(e).__name__}: {e}"

    @property
    def mesh(self):
        """The vertex-group reader for this Blender, or None (then `mesh_error` says why)."""
        self._build()
        return self._mesh if self._mesh is None else CheckedMesh(self)

    @property
    def pose(self):
        """The pose reader for this Blender, or None (then `pose_error` says why)."""
        self._build()
        return self._pose if self._pose is None else CheckedPose(self)

    @property
    def object_state(self):
        """The object-state reader for this Blender, or None (then `object_state_error` says why)."""
        self._build()
        return self._object_state if self._object_state is None else CheckedObjectState(self)

    def refuse(self, which: str, what: str) -> None:
        """A reader that disagreed with Blender's data: gone for the session, with the reason."""
        message = f"the memory reader disagrees with Blender's data ({what}): the Python path reads instead"
        if which == "mesh":
            self._mesh, self.mesh_error = None, message
        elif which == "object_state":
            self._object_state, self.object_state_error = None, message
        else:
            self._pose, self.pose_error = None, message


class CheckedMesh:
    """`MeshMemory` whose first read of each kind in the session is checked
    (`memory_check.groups_differ`, `memory_check.positions_differ`)."""

    def __init__(self, readers: Readers):
        self.readers = readers

    def positions(self, mesh):
        """The mesh's `(V, 3)` positions, or None: read them through the Python API."""
        return self._positions(mesh, lambda reader: reader.positions(mesh), lambda got: got)

    def positions_in_place(self, mesh):
        """The mesh's positions where Blender keeps them (`dqskin.memory.MeshPositions`: the
        kernel reads them without a copy), or None: read them into an array instead."""
        return self._positions(mesh, lambda reader: reader.positions_in_place(mesh), lambda got: got.read())

    def _positions(self, mesh, read, as_array):
        """`read(reader)`, the first time in the session checked (`as_array(got)`) against
        Blender's data; None (the Python path reads) where the positions are not where the
        reader looks or the check failed."""
        readers = self.readers
        if readers._mesh is None or readers.positions_refused:
            return None
        got = read(readers._mesh)
        if got is None:
            readers.positions_refused = True  # (this Blender keeps them elsewhere)
            return None
        if not readers.positions_checked:
            what = memory_check.positions_differ(as_array(got), mesh)
            if what:  # (the weights' reader stays: it has its own check)
                readers.positions_refused = True
                readers.positions_error = f"the memory reader disagrees with Blender's data ({what}): the Python path reads instead"
                return None
            readers.positions_checked = True
        return got

    def deform_verts(self, mesh):
        readers = self.readers
        if readers._mesh is None:  # refused since this wrapper was handed out
            return False  # the caller reads through the Python API
        got = readers._mesh.deform_verts(mesh)
        if not readers.mesh_checked:
            what = memory_check.groups_differ(None if got is None else Groups(*got), mesh)
            if what:
                readers.refuse("mesh", what)
                return False
            readers.mesh_checked = True
        return got


class CheckedPose:
    """`PoseMemory` whose first read in the session is checked (`memory_check.pose_differs`)."""

    def __init__(self, readers: Readers):
        self.readers = readers

    def read(self, arm_eval):
        return self._checked(arm_eval, "read", "pose_checked", memory_check.pose_differs)

    def channel_matrices(self, arm_eval):
        """Every pose bone's `matrix_channel` (`(N, 4, 4)` row-major), read from memory."""
        return self._checked(arm_eval, "channel_matrices", "channels_checked", memory_check.channels_differ)

    def _checked(self, arm_eval, method: str, checked: str, differs):
        """The reader's `method` of `arm_eval`; its first call of the session compared with
        Blender's own data by `differs` (the reader is refused for the session if they differ;
        `checked`: the `Readers` flag that says it was done)."""
        readers = self.readers
        if readers._pose is None:
            raise ValueError(readers.pose_error)
        got = getattr(readers._pose, method)(arm_eval)
        if not getattr(readers, checked):
            what = differs(got, arm_eval)
            if what:
                readers.refuse("pose", what)
                raise ValueError(readers.pose_error)
            setattr(readers, checked, True)
        return got


class CheckedObjectState:
    """`ObjectStateMemory` whose first digest in the session is checked
    (`memory_check.object_state_differs`)."""

    def __init__(self, readers: Readers):
        self.readers = readers

    def digest(self, obj) -> bytes | None:
        """The digest of `obj`'s state, or None: the reader is refused (the caller checks through
        the Python API)."""
        readers = self.readers
        reader = readers._object_state
        if reader is None:
            return None
        try:
            got = reader.digest(obj)
            if not readers.object_state_checked:
                what = memory_check.object_state_differs(reader.describe(obj), obj)
                if what:
                    readers.refuse("object_state", what)
                    return None
                readers.object_state_checked = True
        except ValueError:  # (memory it refuses to read: this object takes the Python path)
            return None
        return got

    def unchanged(self, obj, digest: bytes) -> bool:
        reader = self.readers._object_state
        try:
            return reader is not None and reader.unchanged(obj, digest)
        except ValueError:
            return False

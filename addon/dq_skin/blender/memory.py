# SPDX-License-Identifier: GPL-3.0-or-later
"""The readers of Blender's memory (`dqskin.memory.MeshMemory` for vertex-group weights,
`dqskin.memory.PoseMemory` for armature poses), built once per session from the SDNA of a tiny .blend
this Blender writes: the file describes the structs in memory whatever the version. If a reader
cannot be built, its error says why and the callers take their slow, safe Python paths."""

from __future__ import annotations

import os
import tempfile

import bpy

from .. import dqskin


class Readers:
    """The memory readers of this session (built on first use, owned by the session)."""

    def __init__(self):
        self._built = False
        self._mesh = None
        self._pose = None
        self.mesh_error = ""
        self.pose_error = ""

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
            self.mesh_error = self.pose_error = f"{type(e).__name__}: {e}"
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

    @property
    def mesh(self):
        """The vertex-group reader for this Blender, or None (then `mesh_error` says why)."""
        self._build()
        return self._mesh

    @property
    def pose(self):
        """The pose reader for this Blender, or None (then `pose_error` says why)."""
        self._build()
        return self._pose

# SPDX-License-Identifier: GPL-3.0-or-later
"""The readers of Blender's memory (`dqskin._MeshMemory` for vertex-group weights,
`dqskin._PoseMemory` for armature poses), built once per session from the SDNA of a tiny .blend
this Blender writes: the file describes the structs in memory whatever the version. If a reader
cannot be built, its error says why and the callers take their slow, safe Python paths.
"""

from __future__ import annotations

import os
import tempfile

import bpy

from . import dqskin

_built = False
_mesh = None
_pose = None
mesh_error = ""
pose_error = ""


def _build() -> None:
    global _built, _mesh, _pose, mesh_error, pose_error
    if _built:
        return
    _built = True
    fd, path = tempfile.mkstemp(prefix="dq_skin_dna_", suffix=".blend")
    os.close(fd)
    try:
        bpy.data.libraries.write(path, set(), compress=False)
        with open(path, "rb") as f:
            blend_file = f.read()
    except Exception as e:  # any failure: both readers fall back to the slow, safe path
        mesh_error = pose_error = f"{type(e).__name__}: {e}"
        return
    finally:
        try:
            os.remove(path)
        except OSError:
            pass
    try:
        _mesh = dqskin._MeshMemory(blend_file)
    except Exception as e:
        mesh_error = f"{type(e).__name__}: {e}"
    try:
        _pose = dqskin._PoseMemory(blend_file)
    except Exception as e:
        pose_error = f"{type(e).__name__}: {e}"


def mesh_reader():
    """The vertex-group reader for this Blender, or None (then `mesh_error` says why)."""
    _build()
    return _mesh


def pose_reader():
    """The pose reader for this Blender, or None (then `pose_error` says why)."""
    _build()
    return _pose

# SPDX-License-Identifier: GPL-3.0-or-later
"""Blender data as DQ Skin reads it (meshes, weights, rigs, poses, settings, what reads the
skinned mesh) and DQ Skin's own settings on it (the node group's inputs, the companion). Nothing
here keeps state: caches and readers are the session's, passed in."""

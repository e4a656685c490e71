# SPDX-License-Identifier: GPL-3.0-or-later
"""The batch commands (`blender --command dq_skin ...`, `python -m dqskin.blender ...`)."""

# SPDX-License-Identifier: GPL-3.0-or-later
"""Evaluating DQ Skin modifiers: what reaches each, whether DQ Skin deforms, the binding and
the kernel's job, skinning, and publishing the result through a route (`pipeline`, the only
writer of results and of the panel's status); which objects to evaluate when (`tracker`); the
Optimized Centers precompute (`centers`). Everything mutable these work on belongs to the
session, which is passed in (`Context.session`)."""

# SPDX-License-Identifier: GPL-3.0-or-later
"""The add-on's decisions, as pure functions over plain data (the callers read Blender; these
decide): what reaches a modifier, where DQ Skin deforms and why it hands over, how the companion
is switched, whether a frame is skipped, taken cheaply or evaluated fully, what the node group
does with a result, and whether a result is fed inside Blender's first evaluation."""

from __future__ import annotations

import enum
from dataclasses import dataclass

from .keys import FrameKey, Source
from .methods import BLENDER_METHODS
from .state import ResultMode

# The feed (inside Blender's first evaluation) saves Blender's second evaluation, whose cost
# grows with the scene's graph, and costs more per vertex than the frame handler's route (its
# Mesh Cache reads a file a vertex at a time): a mesh is fed up to this many vertices per pose
# bone of its armature (docs/performance.md has the figures).
FEED_VERTICES_PER_BONE = 50


# -- what reaches a modifier ---------------------------------------------------------------------


def next_source(current: Source | None, is_dq_skin: bool, enabled: bool, live: bool) -> Source:
    """What reaches the modifier after this one in the stack, given what reached it (`None`
    before the first), whether it is a DQ Skin, enabled in this evaluation, and live."""
    if current is None:
        current = Source.MESH
    if is_dq_skin:
        return Source.CHAIN if live else Source.CAPTURE
    return Source.CAPTURE if enabled else current


def source_for(reaching: Source | None) -> Source:
    """What reaches a DQ Skin modifier: the mesh (nothing before it), the previous DQ Skin's output
    (only live DQ Skins before it), or what the node group captures (anything else)."""
    return Source.MESH if reaching is None else reaching


def result_kind(source: Source, read_by_index: bool) -> ResultMode:
    """A whole-mesh result output as is, or points whose positions the node group sets on the
    incoming mesh (what reaches the modifier is captured, or something finds the object's
    vertices by index and needs the incoming mesh's index layers kept)."""
    return ResultMode.POSITIONS if source is Source.CAPTURE or read_by_index else ResultMode.REPLACE


def already_written(key: FrameKey, written: FrameKey | None, live: bool, shown: ResultMode, kind: ResultMode, force: bool) -> bool:
    """Whether the result already is what `key` describes (nothing to compute or write)."""
    return not force and key == written and live and shown is kind


# -- where DQ Skin deforms, and why not ----------------------------------------------------------


@dataclass(frozen=True)
class Reasons:
    """Why DQ Skin hands over, per kind of evaluation ("" where it deforms)."""

    viewport: str = ""
    render: str = ""

    def for_render(self, render: bool) -> str:
        return self.render if render else self.viewport


def hand_over(exporting: str, armature_in_edit_mode: bool, simulation: str, mode: str) -> Reasons:
    """Why DQ Skin hands its object over to Blender's own deformation: an exporter that skins
    from the Armature modifier is running, the armature is in Edit Mode (Blender shows the rest
    pose), a simulation reads the deformed mesh (`simulation`: the reason, or ""), or, in the
    viewport only, the object is in a mode whose brushes map through the deformation (`mode`:
    the reason, or "")."""
    common = exporting
    if not common and armature_in_edit_mode:
        common = "The armature is in Edit Mode: Blender shows the rest pose"
    if not common:
        common = simulation
    return Reasons(viewport=common or mode, render=common)


def deforms_where(show_viewport: bool, show_render: bool, reasons: Reasons) -> tuple[bool, bool]:
    """Where DQ Skin deforms (viewport, render)."""
    return (show_viewport and not reasons.viewport, show_render and not reasons.render)


def instead(method) -> str:
    """What shows instead of a method Blender does not have, while Blender's deformation shows."""
    if method in BLENDER_METHODS:
        return ""
    return f" ({method.label} shows as Preserve Volume meanwhile)"


# -- the companion ------------------------------------------------------------------------------


def companion_shown(known_deforms, deforms: tuple[bool, bool], shown: tuple[bool, bool], render: bool) -> tuple[tuple, tuple]:
    """The companion's (viewport, render) toggles after a decision, and where DQ Skin deforms
    as remembered: where DQ Skin's part changed since the last decision (`known_deforms`, None
    before the first) the companion is off where DQ Skin now deforms and on where it does not;
    elsewhere as the user left it. A render's evaluation touches the render side only."""
    show = list(shown)
    for i in range(2):
        if render and i == 0:
            continue
        if known_deforms is None or known_deforms[i] != deforms[i] or (deforms[i] and show[i]):
            show[i] = not deforms[i]
    merged = list(deforms)
    if render and known_deforms is not None:
        merged[0] = known_deforms[0]
    return tuple(show), tuple(merged)


def switched_off_by_user(known_shown, known_deforms, now_shown: tuple[bool, bool], dq_shown: tuple[bool, bool]) -> tuple[bool, bool]:
    """Which of DQ Skin's toggles (viewport, render) to switch off because the user switched its
    companion on where DQ Skin deforms: they asked for Blender's deformation there (both would
    deform the mesh twice)."""
    if known_shown is None or known_deforms is None:
        return (False, False)
    return tuple(now_shown[i] and not known_shown[i] and known_deforms[i] and dq_shown[i] for i in range(2))


# -- frames --------------------------------------------------------------------------------------


class FramePath(enum.Enum):
    STEADY = "steady"  # only the pose changed: the last job with this frame's bones
    FED = "fed"  # the feed may have skinned it inside Blender's evaluation: check it stands
    FULL = "full"  # everything is read, compared and computed again as needed


def frame_path(steady: bool, forced: bool, unchanged: bool) -> FramePath:
    """How an object is evaluated at a frame change: `steady`, its one DQ Skin deforms the mesh's
    own coordinates with bones from vertex groups; `forced`, something it depends on changed in
    a way only the full path sees (bones edited, its result let go); `unchanged`, Blender did
    not update the object itself in this evaluation."""
    if forced:
        return FramePath.FULL
    if steady and unchanged:
        return FramePath.STEADY
    return FramePath.FED


def steady_candidate(modifier_count: int, live: bool, source: Source | None, needs_effective: bool) -> bool:
    """Whether an object's playback can take the steady path: one DQ Skin, live, on the mesh's own
    coordinates, with bones from vertex groups (envelopes and B-Bones read the pose from memory)."""
    return modifier_count == 1 and live and source is Source.MESH and not needs_effective


def feeds_faster(vertices: int, bones: int) -> bool:
    """Whether the feed is expected to beat the frame handler's route for a mesh of `vertices` on
    an armature of `bones` (see FEED_VERTICES_PER_BONE)."""
    return vertices <= FEED_VERTICES_PER_BONE * bones


def feedable(
    kind: ResultMode,
    needs_effective: bool,
    source: Source | None,
    has_shape_keys: bool,
    render: bool,
    pose_from_memory: bool,
    faster: bool,
) -> bool:
    """Whether a result can be skinned inside Blender's first evaluation: a whole-mesh result of
    the mesh itself (no shape keys), its frames' bones read from memory (envelopes, B-Bones), in
    the viewport, and worth it (`faster`, see `feeds_faster`)."""
    return (
        kind is ResultMode.REPLACE
        and needs_effective
        and source is Source.MESH
        and not has_shape_keys
        and not render
        and pose_from_memory
        and faster
    )

# SPDX-License-Identifier: GPL-3.0-or-later
"""The add-on's decisions, as pure functions over plain data (the callers read Blender; these
decide): what reaches a modifier, where DQ Skin deforms and why it hands over, how the companion
is switched, whether a frame is skipped, taken cheaply or evaluated fully, what the node group
does with a result, and whether a result is fed inside Blender's first evaluation."""

from __future__ import annotations

from dataclasses import dataclass

from .. import dqskin
from .keys import FrameKey, Source
from .methods import BLENDER_METHODS
from .state import ResultMode, RouteKind

# Up to this many vertices a character's positions go through a Mesh Cache carrier (deform-only,
# whose reader costs Blender about 20 ns a vertex); larger ones through a result object (a copy of
# the positions, about 2 ns a vertex), except where something needs deform-only modifiers
# (docs/performance.md has the figures).
CACHE_ROUTE_VERTICES = 20_000


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


def already_written(key: FrameKey, written: FrameKey | None, live: bool, shown: tuple, wanted: tuple, force: bool) -> bool:
    """Whether what Blender shows already is what `key` describes, the way it is wanted (route
    and result mode): nothing to compute or write."""
    return not force and key == written and live and shown == wanted


# -- which route ---------------------------------------------------------------------------------


def needs_deform_only(mode: str, simulation: str, by_index_or_soft_body: bool) -> bool:
    """Whether Blender needs DQ Skin's positions from a deform-only modifier: brushes and Edit
    Mode map through deform-only modifiers only (`mode`: the object's mode's reason, "" in
    Object Mode), simulations on or around the object (`simulation`: the reason, or ""), what
    finds the object's vertices by their index, and a Soft Body right before DQ Skin (it
    simulates only what deform-only modifiers before it make)."""
    return bool(mode or simulation or by_index_or_soft_body)


def route_for(source: Source, deform_only: bool, vertices: int) -> RouteKind:
    """How a modifier's positions reach Blender: what reaches it from other modifiers is only
    known after Blender's first evaluation (RESULT: written after it, a second one follows);
    otherwise inside the first evaluation, through a deform-only Mesh Cache carrier where that
    is needed or cheaper (CACHE), else through a result object (NODE)."""
    if source is Source.CAPTURE:
        return RouteKind.RESULT
    if deform_only or vertices <= CACHE_ROUTE_VERTICES:
        return RouteKind.CACHE
    return RouteKind.NODE


def shown_as(route: RouteKind, kind: ResultMode) -> tuple:
    """The (route, node group mode) a published result is shown with."""
    return (route, ResultMode.CARRIED if route is RouteKind.CACHE else kind)


# -- where DQ Skin deforms, and why not ----------------------------------------------------------


@dataclass(frozen=True)
class Reasons:
    """Why DQ Skin hands over, per kind of evaluation ("" where it deforms)."""

    viewport: str = ""
    render: str = ""

    def for_render(self, render: bool) -> str:
        return self.render if render else self.viewport


def hand_over(
    exporting: str, armature_in_edit_mode: bool, simulation: str, mode: str, blender_method: bool, magnifier: tuple[str, str] = ("", "")
) -> Reasons:
    """Why DQ Skin hands its object over to Blender's own deformation, where that is exactly DQ
    Skin's: the armature is in Edit Mode (the rest pose shows, which every method leaves as it
    is); and for Linear and Dual Quaternion, whatever Blender computes through its Armature
    modifier's own data or bits: an exporter that skins from it (`exporting`), a simulation on or
    around the object (`simulation`) or a modifier after it that magnifies the last float bits
    in which two exact skinnings differ (`magnifier`: viewport, render), and, in the viewport,
    brushes and Edit Mode (`mode`: they map through its deform matrices exactly). Each is the
    reason, or "". An exporter that writes a skin hands over every method: the file carries the
    rest mesh, the weights and the armature, which other programs skin with their own method
    (the export says so, see `exports`). DQ Skin's own methods are never handed over for
    anything else: Blender has no such deformation, and a deform-only carrier serves them
    (`route_for`)."""
    if armature_in_edit_mode:
        common = "The armature is in Edit Mode: the rest pose shows (the same for every method)"
        return Reasons(viewport=common, render=common)
    if not blender_method:
        return Reasons(viewport=exporting, render=exporting)
    common = exporting or simulation
    return Reasons(viewport=common or mode or magnifier[0], render=common or magnifier[1])


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


# -- where the extension is not installed ---------------------------------------------------------


def renders_elsewhere(method, blend_range: tuple[float, float] | None, baked: str) -> str:
    """How a DQ Skin modifier that renders here renders where the extension is not installed (a
    render farm node, a colleague's Blender), if that differs from its own result: the reason,
    or "". There the companion Armature modifier deforms (files are saved that way): Linear and
    Dual Quaternion are its own results; Blend (with `blend_range`, the lowest and highest
    amount of Dual Quaternion it mixes in) is Dual Quaternion only where every vertex takes all
    of it; Optimized Centers never is. `baked`: "" where DQ Skin renders itself, else what the
    bake that plays in its place lacks ("ok" when it plays)."""
    if baked:
        return "" if baked == "ok" else f"its bake does not play there: {baked}"
    if method in BLENDER_METHODS:
        return ""
    if method == dqskin.Method.BLEND and blend_range == (1.0, 1.0):
        return ""
    return f"renders as Blender's Preserve Volume there, not {method.label} (bake it to render it anywhere)"

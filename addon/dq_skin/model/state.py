# SPDX-License-Identifier: GPL-3.0-or-later
"""What the add-on knows about each DQ Skin modifier between evaluations.

Every piece of per-modifier state lives in a `ModifierState`, reached only through the
session's `States` (keyed by `keys.ModKey`, so renames keep it and a copied modifier or object
never shares it). It has named parts, each with one job:

- `status`: what the panel says (`Mode`, message, what reaches the modifier, timings);
- `binding`: the influences and everything else that holds while the mesh, its weights, the
  armature's bones and the settings stay the same (`BindingKey` says which);
- `output`: the result object, the buffers the kernel writes, and the `FrameKey` of what was
  last written (nothing is computed again while it holds);
- `companion`: the Armature modifier kept after DQ Skin, and which way DQ Skin last switched it
  (to tell the user's own toggles from the add-on's);
- `settings`: the modifier's settings, read again only when their stored values change.
"""

from __future__ import annotations

import enum
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from .keys import BindingKey, FrameKey, ModKey, Source


class Mode(enum.Enum):
    NEW = "new"  # not evaluated yet
    LIVE = "live"  # DQ Skin deforms the mesh
    HANDED_OVER = "handed over"  # Blender's Armature modifier deforms, for a reason on the panel
    FALLBACK = "fallback"  # an error: Blender's Armature modifier deforms (or nothing does)
    OFF = "off"  # switched off by the user (for this kind of evaluation)
    LINKED = "linked"  # library data without an override: the library's saved state shows


class ResultMode(enum.Enum):
    """What the node group outputs (its hidden Mode input, see `blender.nodes`)."""

    OFF = 0  # pass the mesh through (the companion deforms, or nothing does), with a warning
    REPLACE = 1  # the result object, a full copy of the mesh with skinned positions
    POSITIONS = 2  # the incoming mesh with the positions of the result's points
    CARRIED = 3  # pass the mesh through: a Mesh Cache carrier before DQ Skin holds its positions


class RouteKind(enum.Enum):
    """How a modifier's positions reach Blender (see `routes`)."""

    RESULT = "result"  # a result object written after Blender's first evaluation (a second one follows)
    NODE = "node"  # a result object fed inside the first evaluation
    CACHE = "cache"  # a Mesh Cache carrier on the character, fed inside the first evaluation (deform-only)


@dataclass
class Status:
    """What the panel shows about a modifier."""

    mode: Mode = Mode.NEW
    message: str = ""  # the reason (handed over, off, linked) or the error (fallback)
    instead: str = ""  # what deforms the mesh instead (fallback)
    notes: tuple = ()  # what the panel points out about the stack while DQ Skin deforms
    compared: str = ""  # after the A/B switch: how far DQ Skin's and Blender's deformations are apart
    source: Source | None = None  # what reaches the modifier
    method: str = ""  # the method label of the last result
    bones: int = 0
    influences: int = 0
    seconds: float = 0.0

    @property
    def live(self) -> bool:
        return self.mode is Mode.LIVE


@dataclass
class BindingCache:
    key: BindingKey | None = None
    binding: object = None  # rig.Binding
    blend: np.ndarray | None = field(default=None, repr=False)
    envelopes: np.ndarray | None = field(default=None, repr=False)
    segments: np.ndarray | None = field(default=None, repr=False)
    uses_envelopes: bool = False
    uses_bbones: bool = False
    centers: np.ndarray | None = field(default=None, repr=False)  # Optimized Centers of this binding
    centers_of: object = None  # the influences they were computed for (with B-Bones: this frame's)
    centers_pending: str = ""  # the key of the centers being updated (the last ones show meanwhile)

    def clear(self) -> None:
        self.key = self.binding = self.blend = self.envelopes = self.segments = self.centers = self.centers_of = None
        self.uses_envelopes = self.uses_bbones = False
        self.centers_pending = ""


@dataclass
class Output:
    result: object = None  # the result object written last
    kind: ResultMode = ResultMode.OFF  # what the node group outputs
    route: RouteKind | None = None  # how the positions reach Blender (None: nothing published)
    buffer: np.ndarray | None = field(default=None, repr=False)  # what the kernel writes
    mixed: np.ndarray | None = field(default=None, repr=False)  # the shape keys mixed
    mixed_key: tuple = ()
    written: FrameKey | None = None
    job: object = None  # the dqskin.SkinJob of the last full evaluation (steady playback resets its pose)
    copied_version: int = 0  # mesh version the replace-mode result mesh was copied from
    copied_revision: int = -1  # and its revision (see `meshdata.revision`)
    generation: int = 0  # counts the outputs (a following DQ Skin's input key)
    spaces: tuple | None = field(default=None, repr=False)  # (premat, postmat) last computed
    spaces_of: tuple = field(default=(), repr=False)  # the (object, armature) world matrices they are of
    pointcache: object = None  # the file a Mesh Cache carrier reads (`routes.pointcache.PointCache`)

    def invalidate(self) -> None:
        """The next evaluation computes and writes again."""
        self.written = None
        self.job = None


@dataclass
class CompanionState:
    name: str = ""  # the companion Armature modifier, once found
    deforms: tuple | None = None  # (viewport, render): where DQ Skin deformed at the last decision
    shown: tuple | None = None  # the companion's (show_viewport, show_render) as last set


@dataclass
class SettingsCache:
    raw: tuple = ()
    value: object = None  # settings.Settings
    raw_keys: tuple = ()  # `nodes.raw_keys` of the modifier's group...
    raw_keys_of: tuple = ()  # ...(its session uid and version) when they were read


@dataclass
class ModifierState:
    status: Status = field(default_factory=Status)
    binding: BindingCache = field(default_factory=BindingCache)
    output: Output = field(default_factory=Output)
    companion: CompanionState = field(default_factory=CompanionState)
    settings: SettingsCache = field(default_factory=SettingsCache)
    capture_on: bool | None = None  # whether the node group stores the incoming positions
    needs_effective: bool = False  # envelopes or B-Bones: influences change with the positions
    decided_structure: int = -1  # the registry's structure version at the last full decision
    # The last full evaluation left the deforming to the companion (viewport; switched off or
    # handed over): what that decision read and the companion as it left it
    # (`pipeline.step_aside_key`); None otherwise.
    stepped_aside: tuple | None = None


class States:
    """Every `ModifierState`, by `ModKey` (owned by the session)."""

    def __init__(self):
        self._by_key: dict[ModKey, ModifierState] = {}

    def get(self, key: ModKey) -> ModifierState:
        """The state of a modifier, created on first use."""
        st = self._by_key.get(key)
        if st is None:
            st = self._by_key[key] = ModifierState()
        return st

    def find(self, key: ModKey) -> ModifierState | None:
        return self._by_key.get(key)

    def pop(self, key: ModKey) -> ModifierState | None:
        return self._by_key.pop(key, None)

    def of_object(self, obj_uid: int) -> Iterator[tuple[str, ModifierState]]:
        for key, st in list(self._by_key.items()):
            if key.object_uid == obj_uid:
                yield key.modifier_uid, st

    def drop_object(self, obj_uid: int) -> list[ModifierState]:
        gone = [k for k in self._by_key if k.object_uid == obj_uid]
        return [self._by_key.pop(k) for k in gone]

    def items(self) -> list[tuple[ModKey, ModifierState]]:
        return list(self._by_key.items())

    def clear(self) -> None:
        self._by_key.clear()

    def __len__(self) -> int:
        return len(self._by_key)

# SPDX-License-Identifier: GPL-3.0-or-later
"""What reaches a DQ Skin modifier (its *source*, `keys.Source`):

- MESH: nothing enabled before it: the mesh's coordinates with its shape keys mixed as Blender
  mixes them (computed here, so the modifier needs no evaluation of its own first);
- CHAIN: only other live DQ Skin modifiers before it: the previous one's output;
- CAPTURE: other modifiers before it: the coordinates the node group stored on its way through,
  read from the evaluated mesh (which needs the modifiers after it to keep the vertex count,
  else the companion takes over and the panel says why).
"""

from __future__ import annotations

import numpy as np

from .. import dqskin
from ..blender import compat, nodes
from ..blender.meshdata import MeshData
from ..model.keys import InputKey, Source
from ..model.state import ModifierState
from .context import SkinError

# Modifiers that never add or remove vertices.
KEEP_VERTEX_COUNT = frozenset({
    "ARMATURE", "CAST", "CLOTH", "COLLISION", "CORRECTIVE_SMOOTH", "CURVE", "DATA_TRANSFER", "DISPLACE", "HOOK",
    "LAPLACIANDEFORM", "LAPLACIANSMOOTH", "LATTICE", "MESH_DEFORM", "NORMAL_EDIT", "SHRINKWRAP", "SIMPLE_DEFORM",
    "SMOOTH", "SOFT_BODY", "SURFACE_DEFORM", "UV_PROJECT", "UV_WARP", "VERTEX_WEIGHT_EDIT", "VERTEX_WEIGHT_MIX",
    "VERTEX_WEIGHT_PROXIMITY", "WARP", "WAVE", "WEIGHTED_NORMAL", "MESH_CACHE",
})  # fmt: skip


class CaptureNeeded(SkinError):
    """Shape keys DQ Skin cannot mix itself: it reads what reaches it from the evaluation."""


def mesh_input(obj, obj_eval, st: ModifierState, data: MeshData, depsgraph, known: InputKey | None = None) -> tuple[object, InputKey]:
    """The mesh's coordinates with its shape keys mixed (without shape keys, what the kernel
    reads of the mesh: `MeshData.source`, see `as_array`), and a key that changes with them
    (`known` itself where it is that key: the feed passes the last frame's)."""
    keys = data.keys
    if keys is None:
        if known is not None and known.source is Source.MESH and known.version == data.version and not known.detail:
            return data.source, known
        return data.source, InputKey(Source.MESH, data.version)
    if not keys.relative:
        raise CaptureNeeded("absolute shape keys")
    key_eval = obj.data.shape_keys.evaluated_get(depsgraph)
    blocks = key_eval.key_blocks
    if len(blocks) != len(keys.data):
        raise CaptureNeeded("shape keys changing")
    values = np.empty(len(blocks), np.float32)
    blocks.foreach_get("value", values)
    mutes = np.empty(len(blocks), bool)
    blocks.foreach_get("mute", mutes)
    shown = obj_eval.active_shape_key_index if obj_eval.show_only_shape_key else None
    input_key = InputKey(Source.MESH, data.version, (values.tobytes(), mutes.tobytes(), shown))
    out = st.output
    if out.mixed is not None and out.mixed_key == input_key:
        return out.mixed, input_key
    if out.mixed is None or len(out.mixed) != data.vertex_count:
        out.mixed = np.empty((data.vertex_count, 3), np.float32)
    blocks_in = [
        (
            keys.data[i],
            keys.relative_to[i],
            float(values[i]),
            bool(mutes[i]),
            data.group_weights(keys.vertex_groups[i]) if keys.vertex_groups[i] and data.has_groups else None,
        )
        for i in range(len(keys.data))
    ]
    try:
        dqskin.shape_key_mix(blocks_in, keys.reference, out.mixed, shown)
    except ValueError as e:
        raise CaptureNeeded(str(e)) from None
    out.mixed_key = input_key
    return out.mixed, input_key


def as_array(positions, data: MeshData) -> np.ndarray:
    """`positions` from `mesh_input` and the others as an array, for what reads them besides the
    kernel (B-Bone and envelope influences depend on where the vertices are)."""
    return data.positions if positions is data.source else positions


def chain_input(previous: ModifierState | None, vertex_count: int) -> tuple[np.ndarray, InputKey]:
    """The previous DQ Skin's output."""
    out = previous.output if previous is not None else None
    if out is None or out.buffer is None or len(out.buffer) != vertex_count:
        raise SkinError("The DQ Skin modifier before this one has no result")
    return out.buffer, InputKey(Source.CHAIN, out.generation, (id(previous),))


def set_capture(mod, on: bool) -> None:
    """Stores the incoming positions (or not) in the node group."""
    if bool(nodes.get(mod, "Capture")) != on:
        nodes.put(mod, "Capture", on)
    if on:
        nodes.put(mod, "Capture Name", capture_name(mod))


def capture_name(mod) -> str:
    return f"dq_skin_input_{compat.modifier_uid(mod)}"


def captured_input(obj, obj_eval, mod, st: ModifierState, data: MeshData) -> tuple[np.ndarray, InputKey]:
    """The coordinates the node group stored on their way through (modifiers before DQ Skin)."""
    set_capture(mod, True)
    st.capture_on = True
    name = capture_name(mod)
    mesh = obj_eval.data
    attribute = mesh.attributes.get(name) if mesh is not None else None
    if attribute is None:
        raise SkinError("Waiting for the modifier to be evaluated (modifiers before DQ Skin)")
    count = len(attribute.data)
    if count != data.vertex_count:
        mods = list(obj.modifiers)
        at = mods.index(mod)
        earlier = [m.name for m in mods[:at] if m.show_viewport and m.type not in KEEP_VERTEX_COUNT]
        if earlier:
            raise SkinError(
                f"An earlier modifier changed the vertex count ({data.vertex_count} → {count}): "
                f"put DQ Skin before {', '.join(earlier)}, which add or remove vertices"
            )
        later = [m.name for m in mods[at + 1 :] if m.show_viewport and m.type not in KEEP_VERTEX_COUNT]
        raise SkinError(
            f"Modifiers before DQ Skin deform the mesh, so it reads the coordinates reaching it from "
            f"the evaluated mesh, but {', '.join(later) or 'a later modifier'} changes the vertex count "
            f"({data.vertex_count} → {count}); move them before DQ Skin's modifiers or apply them"
        )
    positions = np.empty(count * 3, np.float32)
    attribute.data.foreach_get("vector", positions)
    positions = positions.reshape(-1, 3)
    return positions, InputKey(Source.CAPTURE, 0, positions.tobytes())

# SPDX-License-Identifier: GPL-3.0-or-later
"""What reads a DQ Skin object's deformed mesh in a way only a deform-only modifier serves:
the simulations on or around it and the modes whose brushes map through the deformation
(`decisions.route_for` then takes the Mesh Cache carrier), and what finds its vertices by index.

- simulations that use the mesh (Cloth, Soft Body, Collision, Dynamic Paint, particles, Fluid,
  force fields shaped by the surface, deforming rigid bodies), on this object or on another
  object that reads this one's geometry: they step in Blender's first evaluation, where the
  carrier has DQ Skin's positions, and Soft Body simulates only what deform-only modifiers
  before it make;
- brushes and Edit Mode on the object (Edit Mode, Sculpt, Weight, Vertex and Texture Paint,
  Particle Edit), which map strokes through deform-only modifiers (crazyspace);
- vertex parents and hair curves on the surface, which find the object's vertices by index.
"""

from __future__ import annotations

from types import MappingProxyType

import bpy

# Modifiers that step or cache in the first evaluation of a frame, or whose users do.
SIMULATIONS = MappingProxyType(
    {
        "CLOTH": "Cloth",
        "SOFT_BODY": "Soft Body",
        "COLLISION": "Collision",
        "DYNAMIC_PAINT": "Dynamic Paint",
        "PARTICLE_SYSTEM": "Particle System",
        "FLUID": "Fluid",
        "EXPLODE": "Explode",
    }
)
# Object modes whose tools map edits through the deformation (viewport only).
MODES = MappingProxyType(
    {
        "EDIT": "Edit Mode",
        "SCULPT": "Sculpt Mode",
        "WEIGHT_PAINT": "Weight Paint",
        "VERTEX_PAINT": "Vertex Paint",
        "TEXTURE_PAINT": "Texture Paint",
        "PARTICLE_EDIT": "Particle Edit",
    }
)


def _simulates(tree, known: dict) -> bool:
    """Whether a Geometry Nodes tree (or a group in it) simulates or bakes (caches per frame).
    `known`: tree uid -> answer, shared by one scan (trees are shared by many modifiers)."""
    if tree is None:
        return False
    uid = tree.session_uid
    if uid not in known:
        known[uid] = False  # also stops cycles
        known[uid] = any(
            node.bl_idname in ("GeometryNodeSimulationOutput", "GeometryNodeBake")
            or (node.bl_idname == "GeometryNodeGroup" and _simulates(node.node_tree, known))
            for node in tree.nodes
        )
    return known[uid]


def simulation_label(mod, known: dict | None = None) -> str:
    """The simulation a modifier runs ("" for none)."""
    label = SIMULATIONS.get(mod.type, "")
    if not label and mod.type == "NODES" and _simulates(mod.node_group, {} if known is None else known):
        label = f"simulation in '{mod.name}'"
    return label


def _object_pointers(mod, known: dict) -> tuple[str, ...]:
    """The Object pointer properties of a modifier's type (`known`: type -> names, a scan's)."""
    names = known.get(mod.type)
    if names is None:
        names = known[mod.type] = tuple(
            p.identifier
            for p in mod.bl_rna.properties
            if p.type == "POINTER" and getattr(p, "fixed_type", None) is not None and p.fixed_type.identifier == "Object"
        )
    return names


def _object_targets(owner, pointers: dict) -> set:
    """Objects whose evaluated geometry or transform `owner`'s evaluation reads: the object
    pointers of its modifiers and constraints, Geometry Nodes inputs, a vertex parent, a hair
    surface."""
    out = set()
    for mod in getattr(owner, "modifiers", ()):
        for name in _object_pointers(mod, pointers):
            target = getattr(mod, name, None)
            if target is not None:
                out.add(target.session_uid)
        if mod.type == "NODES":
            for value in _node_inputs(mod):
                if isinstance(value, bpy.types.Object):
                    out.add(value.session_uid)
    for con in getattr(owner, "constraints", ()):
        target = getattr(con, "target", None)
        if target is not None:
            out.add(target.session_uid)
    if owner.parent is not None and owner.parent_type in ("VERTEX", "VERTEX_3"):
        out.add(owner.parent.session_uid)
    surface = getattr(owner.data, "surface", None) if owner.type == "CURVES" else None
    if surface is not None:
        out.add(surface.session_uid)
    return out


def _node_inputs(mod):
    try:
        if hasattr(mod, "properties") and hasattr(mod.properties, "inputs"):  # Blender 5.2+
            inputs = mod.properties.inputs
            return [getattr(inputs, p.identifier).value for p in inputs.bl_rna.properties if p.identifier != "rna_type"]
        return [mod[k] for k in mod.keys()]
    except (AttributeError, TypeError, KeyError):
        return []


class Scan:
    """Which objects simulate on which others' geometry, built once per change of the scene's
    structure (objects, modifiers, constraints added or removed), not per frame."""

    def __init__(self):
        self.version = -1
        self.readers: dict[int, list[str]] = {}  # object uid -> "Object's Cloth" of the simulations reading it
        self.by_index: dict[int, list[str]] = {}  # object uid -> what reads its vertices by index
        self.pointers: dict[str, tuple[str, ...]] = {}  # modifier type -> its Object pointer properties

    def ensure(self, version: int) -> Scan:
        """Built for the scene's structure `version` (the tracker's)."""
        if self.version != version:
            self.build(version)
        return self

    def build(self, version: int) -> None:
        self.version = version
        readers: dict[int, list[str]] = {}
        by_index: dict[int, list[str]] = {}
        known: dict = {}
        for owner in bpy.data.objects:
            parent = owner.parent
            final = getattr(owner, "use_parent_final_indices", False)  # Blender 4.3+
            if parent is not None and owner.parent_type in ("VERTEX", "VERTEX_3") and not final:
                by_index.setdefault(parent.session_uid, []).append(f"{owner.name} (vertex parent)")
            surface = getattr(owner.data, "surface", None) if owner.type == "CURVES" else None
            if surface is not None:
                by_index.setdefault(surface.session_uid, []).append(f"{owner.name} (hair on the surface)")
            sims = [label for label in (simulation_label(m, known) for m in getattr(owner, "modifiers", ())) if label]
            if owner.rigid_body is not None:
                sims.append("Rigid Body")
            if not sims:
                continue
            what = f"{owner.name}'s {sims[0]}"
            for uid in _object_targets(owner, self.pointers):
                readers.setdefault(uid, []).append(what)
        self.readers = readers
        self.by_index = by_index


def index_readers(scan: Scan, obj) -> list[str]:
    """What finds the object's vertices by their original index (vertex parents, hair curves on
    the surface): Blender maps those through the mesh a modifier outputs only when it keeps the
    incoming mesh's index layers, so DQ Skin then sets the incoming mesh's positions instead of
    replacing the mesh (a little more work per vertex). `scan`: built for the current structure."""
    return scan.by_index.get(obj.session_uid, [])


def soft_body_before(obj, mod) -> bool:
    """Whether a Soft Body comes right before DQ Skin (where Blender puts one added to an object
    whose stack has modifiers that are not deform-only): it simulates what deform-only
    modifiers before it make, so DQ Skin's positions must come from one."""
    mods = list(obj.modifiers)
    at = mods.index(mod)
    while at > 0 and mods[at - 1].type in ("SOFT_BODY", "MESH_CACHE"):
        at -= 1
        if mods[at].type == "SOFT_BODY" and (mods[at].show_viewport or mods[at].show_render):
            return True
    return False


def _own_simulation(obj, mod) -> str:
    """A simulation in the object's own stack after DQ Skin, or one the object takes part in."""
    mods = list(obj.modifiers)
    for other in mods[mods.index(mod) + 1 :]:
        label = simulation_label(other)
        if label and (other.show_viewport or other.show_render):
            return label
    rb = obj.rigid_body
    if rb is not None and (rb.use_deform or rb.collision_shape in ("MESH", "CONVEX_HULL")):
        return "Rigid Body"
    field = obj.field
    if field is not None and field.type != "NONE" and field.shape in ("SURFACE", "POINTS"):
        return "force field shaped by the surface"
    return ""


# Modifiers whose result magnifies the last float bits of their input many times (Corrective
# Smooth's tangent frames on sliver triangles: 2e-7 of the size in, 5e-5 out).
MAGNIFIERS = MappingProxyType({"CORRECTIVE_SMOOTH": "Corrective Smooth"})


def magnifier_reason(obj, mod, render: bool) -> str:
    """A modifier after DQ Skin, on in the viewport (or renders), that magnifies the last float
    bits of what reaches it ("" if none): there only Blender's own deformation gives Blender's
    own result."""
    mods = list(obj.modifiers)
    for later in mods[mods.index(mod) + 1 :]:
        label = MAGNIFIERS.get(later.type)
        if label and (later.show_render if render else later.show_viewport):
            return f"{label} after it magnifies the last float bits of its input: Blender's Armature modifier deforms (the same deformation, bit for bit)"
    return ""


def simulation_reason(scan: Scan, obj, mod) -> str:
    label = _own_simulation(obj, mod)
    if label:
        return f"{label} simulates on the deformed mesh"
    readers = scan.readers.get(obj.session_uid)
    if readers:
        return f"{readers[0]} simulates on it"
    return ""


def mode_reason(obj) -> str:
    label = MODES.get(obj.mode)
    return f"{label}: brushes and edits map through Blender's deformation (the same)" if label else ""

"""Everything that reads a DQ Skin character's deformed mesh, each compared with the same scene
built with Blender's own Armature modifier on its own objects (the *reference* character: a copy
of the armature and the mesh, side by side, playing the same action), Linear and Dual
Quaternion, with CesiumMan's bones as they are (vertex groups) and made B-Bones, skinned by the
frame handler and by the feed (`scenes.RIGS`): simulations on and around the character, hair,
modifiers and constraints targeting it, brushes on the posed mesh, exporters, Apply as Shape
Key, bakes and ray casts (see docs/compatibility.md).

Bar: <= 1e-5 of the bounding-box diagonal, every frame (Shrinkwrap: 1e-4).
"""

from __future__ import annotations

import numpy as np
import pytest
from dqtest import (
    METHODS,
    REL_TOL,
    add_dq_skin,
    assert_fed,
    deviation,
    dq_skin_mods,
    evaluated_positions,
    import_character,
    perturbed,
    route_of,
    stack,
    status,
)
from scenes import RIGS, make_rig

import bpy

from mathutils import Vector

# Where the reference character stands: at the same place (simulations in world space round
# differently elsewhere; nothing here makes the two characters interact).
OFFSET = Vector((0.0, 0.0, 0.0))
SHRINKWRAP_TOL = 1e-4
PERTURBATIONS = 6  # draws of the float noise a consumer's amplification is measured with


def characters(dq_skin, assets, method: str, rig: str):
    """CesiumMan with DQ Skin (at the origin) and its reference with Blender's Armature modifier
    (offset by OFFSET, its own armature object sharing the action); with `rig` "B-Bones" or
    "B-Bones, node route" every deforming bone of both is a B-Bone (see `scenes.RIGS`)."""
    body, arm_mod = import_character(assets / "CesiumMan.glb")
    arm = arm_mod.object
    make_rig(arm, rig)
    ref_arm = arm.copy()
    ref_arm.data = arm.data.copy()
    ref_arm.location = arm.location + OFFSET
    bpy.context.scene.collection.objects.link(ref_arm)
    ref = body.copy()
    ref.data = body.data.copy()
    bpy.context.scene.collection.objects.link(ref)
    ref.parent = ref_arm
    ref_mod = next(m for m in ref.modifiers if m.type == "ARMATURE")
    ref_mod.object = ref_arm
    ref_mod.use_deform_preserve_volume = method != "LINEAR"
    add_dq_skin(body, method)
    if rig != "vertex groups":
        assert_fed(dq_skin, body)
    return body, ref


class rest_position:
    """Both armatures in their rest position, where DQ Skin and the Armature modifier give the
    undeformed mesh bit for bit: bindings made there (Surface Deform, hair on the surface) are
    the same for both characters, as artists make them."""

    def __init__(self, *objs):
        self.armatures = [o.parent.data for o in objs]

    def __enter__(self):
        for a in self.armatures:
            a.pose_position = "REST"
        bpy.context.view_layer.update()

    def __exit__(self, *exc):
        for a in self.armatures:
            a.pose_position = "POSE"
        bpy.context.view_layer.update()


def world_positions(obj, depsgraph=None) -> np.ndarray:
    p = evaluated_positions(obj, depsgraph)
    m = np.array(obj.matrix_world, np.float64)
    return (p @ m[:3, :3].T + m[:3, 3]).astype(np.float64)


def same(ours_world: np.ndarray, ref_world: np.ndarray, what: str, tol: float = REL_TOL) -> float:
    dev = deviation(ours_world + np.array(OFFSET), ref_world)
    assert dev <= tol, f"{what}: {dev:.3e} of the diagonal from the same scene with Blender's Armature modifier"
    return dev


def play(frames, check) -> None:
    scene = bpy.context.scene
    for f in frames:
        scene.frame_set(f)
        check(f)


def moves(frames, obj) -> float:
    """How far the object's vertices move over the frames (a test that moves nothing proves nothing)."""
    scene = bpy.context.scene
    scene.frame_set(frames[0])
    a = world_positions(obj)
    scene.frame_set(frames[-1])
    return float(np.abs(world_positions(obj) - a).max())


def link(obj, collection=None):
    (collection or bpy.context.scene.collection).objects.link(obj)
    return obj


def grid(name: str, size: float, cuts: int, location) -> bpy.types.Object:
    mesh = bpy.data.meshes.new(name)
    n = cuts + 1
    verts = [((i / cuts - 0.5) * size, (j / cuts - 0.5) * size, 0.0) for j in range(n) for i in range(n)]
    faces = [(j * n + i, j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i) for j in range(cuts) for i in range(cuts)]
    mesh.from_pydata(verts, [], faces)
    obj = link(bpy.data.objects.new(name, mesh))
    obj.location = location
    return obj


def upper_body_group(obj, name="Pin", below: float = 0.9) -> None:
    """A vertex group with the vertices above `below` (object space Z of the evaluated rest)."""
    co = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    z = co[:, 1] if np.ptp(co[:, 1]) > np.ptp(co[:, 2]) else co[:, 2]  # glTF meshes are Y-up
    g = obj.vertex_groups.new(name=name)
    g.add(np.flatnonzero(z > below * z.max()).tolist(), 1.0, "REPLACE")


# -- simulations ---------------------------------------------------------------------------------


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
def test_cloth_after_dq_skin_follows_the_skinned_pins(dq_skin, assets, method, rig):
    body, ref = characters(dq_skin, assets, method, rig)
    for obj in (body, ref):
        upper_body_group(obj, below=0.75)
        cloth = obj.modifiers.new("Cloth", "CLOTH")
        cloth.settings.vertex_group_mass = "Pin"
        cloth.settings.quality = 2
        cloth.point_cache.frame_end = 30
    st = status(dq_skin, body)
    play(range(1, 31), lambda f: same(world_positions(body), world_positions(ref), f"cloth at frame {f}"))
    st = status(dq_skin, body)
    assert st.mode.value == "handed over" and "Cloth" in st.message
    assert moves((1, 30), body) > 0.05


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
def test_a_cloth_collides_with_the_character(dq_skin, assets, method, rig):
    body, ref = characters(dq_skin, assets, method, rig)
    sheets = []
    # Both sheets at one height (from the reference: the two posed characters' boxes may differ
    # in the last bit, which the falling cloth would amplify).
    top = max((ref.matrix_world @ Vector(c)).z for c in ref.bound_box)
    for obj, dx in ((body, 0.0), (ref, OFFSET.x)):
        obj.modifiers.new("Collision", "COLLISION")
        own = bpy.data.collections.new(f"{obj.name} colliders")
        bpy.context.scene.collection.children.link(own)
        own.objects.link(obj)
        sheet = grid(f"Sheet {obj.name}", 1.2, 16, (dx, 0.0, top + 0.1))
        cloth = sheet.modifiers.new("Cloth", "CLOTH")
        cloth.settings.quality = 2
        cloth.collision_settings.collection = own
        cloth.point_cache.frame_end = 30
        sheets.append(sheet)
    play(range(1, 31), lambda f: same(world_positions(sheets[0]), world_positions(sheets[1]), f"falling cloth at frame {f}"))
    assert "Collision" in status(dq_skin, body).message
    assert moves((1, 30), sheets[0]) > 0.1


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
def test_particle_hair_on_the_character(dq_skin, assets, method, rig):
    body, ref = characters(dq_skin, assets, method, rig)
    for obj in (body, ref):
        obj.modifiers.new("Hair", "PARTICLE_SYSTEM")
        p = obj.particle_systems[0].settings
        p.type, p.count, p.hair_length = "HAIR", 300, 0.05

    def hair(obj):
        dg = bpy.context.evaluated_depsgraph_get()
        ev = obj.evaluated_get(dg)
        ps = ev.particle_systems[0]
        return np.array([ps.co_hair(ev, particle_no=i, step=s) for i in range(len(ps.particles)) for s in (0, 5)], np.float64)

    play((1, 8, 17, 30), lambda f: same(hair(body), hair(ref), f"hair roots and tips at frame {f}"))
    assert "Particle System" in status(dq_skin, body).message


# -- modifiers and constraints targeting the character ------------------------------------------


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
def test_shrinkwrap_onto_the_character(dq_skin, assets, method, rig):
    """Within 1e-4 of the Armature scene, or of twice what Shrinkwrap makes of 2e-7 perturbations
    of its target under Blender's own Armature modifier, where that is more (projections onto the
    nearest surface jump at folds: on Blender 4.2 up to 1.2e-4). Several perturbations, since
    one draw may miss a fold that another finds (at frame 10 on Linear, one draw of six jumps
    by 2e-4, the others by under 1e-5)."""
    body, ref = characters(dq_skin, assets, method, rig)
    noisy = [perturbed(ref, seed=seed) for seed in range(PERTURBATIONS)]
    wraps = []
    centre = sum((ref.matrix_world @ Vector(c) for c in ref.bound_box), Vector()) / 8  # one place for all
    for obj in (body, ref, *noisy):
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.6, location=centre)
        s = bpy.context.active_object
        s.modifiers.new("Shrinkwrap", "SHRINKWRAP").target = obj
        wraps.append(s)

    def check(f):
        expected = world_positions(wraps[1])
        amplified = max(deviation(world_positions(w), expected) for w in wraps[2:])
        same(world_positions(wraps[0]), expected, f"Shrinkwrap at frame {f}", max(SHRINKWRAP_TOL, 2 * amplified))

    play((1, 5, 10, 20, 30), check)
    assert status(dq_skin, body).live
    assert moves((1, 20), wraps[0]) > 0.01


# -- brushes and edit mode on the posed mesh ------------------------------------------------------


def crazyspace(obj, vertices) -> np.ndarray:
    dg = bpy.context.evaluated_depsgraph_get()
    obj.crazyspace_eval(dg, bpy.context.scene)
    try:
        return np.array(
            [
                obj.crazyspace_displacement_to_deformed(vertex_index=v, displacement=d)
                for v in vertices
                for d in (Vector((1, 0, 0)), Vector((0, 0, 1)))
            ],
            np.float64,
        )
    finally:
        obj.crazyspace_eval_clear()


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("mode", ["SCULPT", "WEIGHT_PAINT", "VERTEX_PAINT", "TEXTURE_PAINT", "EDIT"])
def test_brushes_map_through_the_deformation_as_through_the_armature_modifier(dq_skin, assets, method, rig, mode):
    body, ref = characters(dq_skin, assets, method, rig)
    bpy.context.scene.frame_set(17)
    vertices = list(range(0, len(body.data.vertices), 97))
    expected = crazyspace(ref, vertices)
    assert np.abs(expected - np.tile([[1, 0, 0], [0, 0, 1]], (len(vertices), 1))).max() > 0.3  # the pose rotates strokes
    bpy.context.view_layer.objects.active = body
    for o in bpy.context.view_layer.objects:
        o.select_set(o is body or (mode == "EDIT" and o is ref))  # Edit Mode takes both
    bpy.ops.object.mode_set(mode=mode)
    try:
        bpy.context.view_layer.update()
        got = crazyspace(body, vertices)
        assert np.abs(got - expected).max() <= 1e-5, f"{mode}: strokes map differently from the Armature modifier's"
        st = status(dq_skin, body)
        assert st.mode.value == "handed over", st.message
        same(world_positions(body), world_positions(ref), f"the posed mesh in {mode}")
    finally:
        bpy.ops.object.mode_set(mode="OBJECT")
    bpy.context.view_layer.update()
    bpy.context.scene.frame_set(18)
    assert status(dq_skin, body).live  # back in Object Mode, DQ Skin deforms again
    same(world_positions(body), world_positions(ref), "back in Object Mode")


# -- exporters ----------------------------------------------------------------------------------


def reimported(path, importer) -> dict:
    """What a fresh scene gets from importing `path`: each skinned mesh's rest positions (world),
    its vertex groups' weights, and its armature."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    importer(filepath=str(path))
    out = {}
    shapes = {pb.custom_shape for a in bpy.data.objects if a.type == "ARMATURE" for pb in a.pose.bones}
    for obj in bpy.data.objects:
        if obj.type != "MESH" or obj in shapes:  # the importers' bone shapes are not characters
            continue
        arm = next((m.object for m in obj.modifiers if m.type == "ARMATURE"), None) or (
            obj.parent if obj.parent and obj.parent.type == "ARMATURE" else None
        )
        co = np.empty(len(obj.data.vertices) * 3, np.float32)
        obj.data.vertices.foreach_get("co", co)
        m = np.array(obj.matrix_world, np.float64)
        weights = {}
        for g in obj.vertex_groups:
            w = np.zeros(len(obj.data.vertices), np.float32)
            for v in obj.data.vertices:
                for e in v.groups:
                    if e.group == g.index:
                        w[v.index] = e.weight
            weights[g.name] = w
        out[obj.name] = dict(
            rest=co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3],
            weights=weights,
            armature=arm.name if arm is not None else None,
            bones=len(arm.data.bones) if arm is not None else 0,
            skinned=any(m.type == "ARMATURE" for m in obj.modifiers),
        )
    return out


def export_both(dq_skin, tmp_path, assets, method, rig, exporter, suffix, **options):
    """The DQ Skin character and the reference, each exported alone (at the same place)."""
    body, ref = characters(dq_skin, assets, method, rig)
    ref_arm = ref.parent
    bpy.context.scene.frame_set(17)  # posed: the exported rest mesh must not be this pose
    paths = []
    for obj, dx in ((body, 0.0), (ref, OFFSET.x)):
        arm = obj.parent
        arm.location.x -= dx
        for o in bpy.context.view_layer.objects:
            o.select_set(o in (obj, arm))
        bpy.context.view_layer.update()
        path = tmp_path / f"{obj.name}{suffix}"
        exporter(filepath=str(path), use_selection=True, **options)
        arm.location.x += dx
        paths.append(path)
    assert ref_arm is not None
    return body.name, paths


def compare_exports(name, ours, theirs):
    assert len(ours) == len(theirs) == 1, (ours.keys(), theirs.keys())
    for (mesh_name, a), b in zip(ours.items(), theirs.values()):
        assert a["skinned"] and b["skinned"], f"{mesh_name}: exported without its skin"
        assert (a["armature"] is not None, a["bones"]) == (b["armature"] is not None, b["bones"])
        assert a["rest"].shape == b["rest"].shape, f"{mesh_name}: {a['rest'].shape[0]} vertices instead of {b['rest'].shape[0]}"
        assert deviation(a["rest"], b["rest"]) <= REL_TOL, f"{mesh_name}: the exported bind mesh is not the rest mesh"
        assert set(a["weights"]) == set(b["weights"])
        for g in a["weights"]:
            assert np.abs(a["weights"][g] - b["weights"][g]).max() <= 1e-6, g


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("apply_modifiers", [True, False])
def test_fbx_export_is_the_same_skinned_character(dq_skin, assets, tmp_path, method, rig, apply_modifiers):
    name, (ours, theirs) = export_both(
        dq_skin, tmp_path, assets, method, rig, bpy.ops.export_scene.fbx, ".fbx", use_mesh_modifiers=apply_modifiers
    )
    compare_exports(name, reimported(ours, bpy.ops.import_scene.fbx), reimported(theirs, bpy.ops.import_scene.fbx))


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("apply_modifiers", [True, False])
def test_gltf_export_is_the_same_skinned_character(dq_skin, assets, tmp_path, method, rig, apply_modifiers):
    name, (ours, theirs) = export_both(
        dq_skin, tmp_path, assets, method, rig, bpy.ops.export_scene.gltf, ".glb", export_apply=apply_modifiers
    )
    compare_exports(name, reimported(ours, bpy.ops.import_scene.gltf), reimported(theirs, bpy.ops.import_scene.gltf))


# -- more simulations on the character --------------------------------------------------------------


def _soft_body(obj):
    upper_body_group(obj, name="Goal", below=0.6)
    m = obj.modifiers.new("Softbody", "SOFT_BODY")
    m.settings.vertex_group_goal = "Goal"
    m.point_cache.frame_end = 20


def _dynamic_paint(obj):
    m = obj.modifiers.new("Dynamic Paint", "DYNAMIC_PAINT")
    with bpy.context.temp_override(object=obj, active_object=obj):
        bpy.ops.dpaint.type_toggle(type="CANVAS")
    m.canvas_settings.canvas_surfaces[0].frame_end = 20


def _fluid_effector(obj):
    m = obj.modifiers.new("Fluid", "FLUID")
    m.fluid_type = "EFFECTOR"


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("what", ["Dynamic Paint", "Fluid"])
def test_other_simulations_on_the_character(dq_skin, assets, method, rig, what):
    body, ref = characters(dq_skin, assets, method, rig)
    setup = {"Dynamic Paint": _dynamic_paint, "Fluid": _fluid_effector}[what]
    for obj in (body, ref):
        setup(obj)
    play(range(1, 13), lambda f: same(world_positions(body), world_positions(ref), f"{what} at frame {f}"))
    st = status(dq_skin, body)
    assert st.mode.value == "handed over" and what in st.message, st.message


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
def test_soft_body_simulates_the_skinned_mesh(dq_skin, assets, tmp_path, method, rig):
    """Blender keeps a Soft Body before every modifier that is not deform-only (so before the DQ
    Skin modifier): DQ Skin's positions then come from its deform-only carrier, which goes
    before the Soft Body, so that the Soft Body simulates the skinned mesh, as after Blender's
    Armature modifier."""
    body, ref = characters(dq_skin, assets, method, rig)
    for obj in (body, ref):
        _soft_body(obj)
    bpy.context.view_layer.update()
    bpy.context.scene.frame_set(1)
    assert status(dq_skin, body).live
    assert [m.type for m in body.modifiers] == ["MESH_CACHE", "SOFT_BODY", "NODES", "ARMATURE"]
    assert route_of(dq_skin, body) == "cache"
    # What the Soft Body simulates on is the skinned mesh, as with the Armature modifier. (What
    # it makes of it is not compared: a simulation amplifies the last float bits, in which DQ
    # Skin's positions may differ from the Armature modifier's, to 1e-3 within a few frames;
    # the hand-over tests show the same simulation bit for bit.)
    assert moves((1, 12), body) > 0.01
    for o in (body, ref):
        o.modifiers["Softbody"].show_viewport = False
    play((1, 6, 12), lambda f: same(world_positions(body), world_positions(ref), f"the Soft Body's input at frame {f}"))


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
def test_a_garment_bound_by_surface_deform(dq_skin, assets, method, rig):
    """Surface Deform clothing follows DQ Skin itself (nothing caches): DQ Skin stays live. With
    a Cloth after the Surface Deform, the garment simulates on the character in Blender's first
    evaluation of a frame: DQ Skin hands over."""
    body, ref = characters(dq_skin, assets, method, rig)
    garments = []
    bpy.context.scene.frame_set(1)
    with rest_position(body, ref):
        centre = sum((ref.matrix_world @ Vector(c) for c in ref.bound_box), Vector()) / 8  # one place for both
        for obj in (body, ref):
            bpy.ops.mesh.primitive_cylinder_add(radius=0.25, depth=0.5, location=centre, vertices=24)
            g = bpy.context.active_object
            m = g.modifiers.new("Surface Deform", "SURFACE_DEFORM")
            m.target = obj
            with bpy.context.temp_override(object=g, active_object=g):
                assert bpy.ops.object.surfacedeform_bind(modifier=m.name) == {"FINISHED"}
            garments.append(g)
    play((1, 6, 12, 20, 30), lambda f: same(world_positions(garments[0]), world_positions(garments[1]), f"Surface Deform at frame {f}"))
    assert status(dq_skin, body).live
    assert moves((1, 20), garments[0]) > 0.01
    for g in garments:
        g.modifiers.new("Cloth", "CLOTH").point_cache.frame_end = 30
    bpy.context.view_layer.update()
    play(range(1, 13), lambda f: same(world_positions(garments[0]), world_positions(garments[1]), f"a simulated garment at frame {f}"))
    st = status(dq_skin, body)
    assert st.mode.value == "handed over" and garments[0].name in st.message, st.message


# -- objects that read the character ---------------------------------------------------------------


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
def test_objects_reading_the_character(dq_skin, assets, method, rig):
    """A prop parented to three vertices, an Empty with a Shrinkwrap constraint, a Geometry
    Nodes object that takes the character's geometry (Object Info), and ray casts (what snapping
    uses) all see DQ Skin's deformation, as they see the Armature modifier's."""
    body, ref = characters(dq_skin, assets, method, rig)
    readers = []
    for obj in (body, ref):
        prop = link(bpy.data.objects.new(f"Prop {obj.name}", None))
        prop.parent = obj
        prop.parent_type = "VERTEX_3"
        prop.parent_vertices = (10, 400, 1500)
        empty = link(bpy.data.objects.new(f"Wrapped {obj.name}", None))
        empty.location = (0.5, -1.0, 1.0)
        con = empty.constraints.new("SHRINKWRAP")
        con.target = obj
        copy = link(bpy.data.objects.new(f"Copy {obj.name}", bpy.data.meshes.new("empty")))
        group = bpy.data.node_groups.new(f"Info {obj.name}", "GeometryNodeTree")
        group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
        info = group.nodes.new("GeometryNodeObjectInfo")
        info.transform_space = "RELATIVE"
        info.inputs["Object"].default_value = obj
        out = group.nodes.new("NodeGroupOutput")
        group.links.new(info.outputs["Geometry"], out.inputs[0])
        copy.modifiers.new("Info", "NODES").node_group = group
        readers.append((prop, empty, copy))

    def check(f):
        (p1, e1, c1), (p2, e2, c2) = readers
        for a, b in ((p1, p2), (e1, e2)):
            d = (a.matrix_world.translation - b.matrix_world.translation).length
            assert d <= REL_TOL * 2.0, f"{a.name} at frame {f}: {d}"
        same(world_positions(c1), world_positions(c2), f"Object Info at frame {f}")
        dg = bpy.context.evaluated_depsgraph_get()
        for origin in ((0.0, -2.0, 0.9), (0.2, -2.0, 1.3), (-0.1, -2.0, 0.4)):
            hit1 = bpy.context.scene.ray_cast(dg, Vector(origin), Vector((0, 1, 0)))
            hit2 = bpy.context.scene.ray_cast(dg, Vector(origin) + OFFSET, Vector((0, 1, 0)))
            assert hit1[0] == hit2[0]
            if hit1[0]:
                assert (hit1[1] + OFFSET - hit2[1]).length <= 1e-5, f"ray cast at frame {f}"

    body.hide_set(False)
    play((1, 7, 15, 24), check)
    assert status(dq_skin, body).live


def hair_curves(obj):
    """Hair curves on `obj` as the Add menu makes them (Surface Deform node group, the mesh as
    surface), a few short curves rooted at its vertices and attached to the surface."""
    for o in bpy.context.view_layer.objects:
        o.select_set(o is obj)
    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(active_object=obj, object=obj, selected_objects=[obj]):
        assert bpy.ops.object.curves_empty_hair_add() == {"FINISHED"}
    hair = bpy.context.active_object
    roots = well_shaped_triangle_centres(obj.data, 60)
    hair.data.add_curves([4] * len(roots))
    points = (roots[:, None, :] + np.array([0.0, 0.0, 0.02], np.float32) * np.arange(4)[None, :, None]).reshape(-1, 3)
    hair.data.attributes["position"].data.foreach_set("vector", points.ravel())
    bpy.ops.object.mode_set(mode="SCULPT_CURVES")
    assert bpy.ops.curves.snap_curves_to_surface(attach_mode="NEAREST") == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    return hair


def well_shaped_triangle_centres(mesh, count: int) -> np.ndarray:
    """Centres of the `count` largest, near-equilateral triangles: hair rooted there turns with
    its triangle as the surface deforms, and slivers (whose orientation the last float bits
    decide) are avoided, so that the comparison measures skinning, not rounding."""
    mesh.calc_loop_triangles()
    tris = np.empty(len(mesh.loop_triangles) * 3, np.int32)
    mesh.loop_triangles.foreach_get("vertices", tris)
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    p = co.reshape(-1, 3)[tris.reshape(-1, 3)].astype(np.float64)
    edges = np.linalg.norm(p - np.roll(p, 1, axis=1), axis=2)
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    shape = 4 * np.sqrt(3) * area / (edges**2).sum(1)  # 1 for equilateral, 0 for slivers
    chosen = np.argsort(-(area * (shape > 0.8)))[:count]
    return p[chosen].mean(1).astype(np.float32)


def curve_points(hair) -> np.ndarray:
    ev = hair.evaluated_get(bpy.context.evaluated_depsgraph_get())
    co = np.empty(len(ev.data.points) * 3, np.float32)
    ev.data.attributes["position"].data.foreach_get("vector", co)
    m = np.array(hair.matrix_world, np.float64)
    return co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
def test_hair_curves_on_the_surface(dq_skin, assets, method, rig):
    """Hair curves attached to the character (Deform Curves on Surface) follow it. From Blender
    5.2 new hair also simulates (a Hair Dynamics modifier with a simulation zone): DQ Skin then
    hands over, as for any simulation on it."""
    body, ref = characters(dq_skin, assets, method, rig)
    bpy.context.scene.frame_set(1)
    with rest_position(body, ref):
        curves = [hair_curves(obj) for obj in (body, ref)]
    play((1, 8, 17, 30), lambda f: same(curve_points(curves[0]), curve_points(curves[1]), f"hair curves at frame {f}"))
    simulates = any(dq_skin.blender.consumers.simulation_label(m) for m in curves[0].modifiers if m.show_viewport)
    assert status(dq_skin, body).mode.value == ("handed over" if simulates else "live")
    bpy.context.scene.frame_set(1)
    a = curve_points(curves[0])
    bpy.context.scene.frame_set(17)
    assert np.abs(curve_points(curves[0]) - a).max() > 0.01


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
def test_data_transfer_from_the_character(dq_skin, assets, method, rig):
    """Vertex-group weights transferred from the posed character by nearest face (the mapping
    follows its deformed surface)."""
    body, ref = characters(dq_skin, assets, method, rig)
    targets = []
    centre = sum((ref.matrix_world @ Vector(c) for c in ref.bound_box), Vector()) / 8  # one place for both
    for obj in (body, ref):
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.4, location=centre, segments=24, ring_count=12)
        s = bpy.context.active_object
        m = s.modifiers.new("Data Transfer", "DATA_TRANSFER")
        m.object = obj
        m.use_vert_data = True
        m.data_types_verts = {"VGROUP_WEIGHTS"}
        m.vert_mapping = "POLYINTERP_NEAREST"
        with bpy.context.temp_override(object=s, active_object=s):
            bpy.ops.object.datalayout_transfer(modifier=m.name)
        targets.append(s)

    def weights(obj):
        ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
        mesh = ev.to_mesh()
        try:
            w = np.zeros((len(mesh.vertices), len(obj.vertex_groups)), np.float32)
            for v in mesh.vertices:
                for g in v.groups:
                    w[v.index, g.group] = g.weight
            return w
        finally:
            ev.to_mesh_clear()

    def check(f):
        a, b = weights(targets[0]), weights(targets[1])
        # Weights interpolated over the nearest face move with the last float bits of the
        # surface as Shrinkwrap does (see SHRINKWRAP_TOL), by up to about 1e-4.
        assert a.shape == b.shape and np.abs(a - b).max() <= 1e-3, f"weights at frame {f}: {np.abs(a - b).max()}"

    play((1, 9, 17), check)
    bpy.context.scene.frame_set(1)
    first = weights(targets[0])
    bpy.context.scene.frame_set(17)
    assert np.abs(weights(targets[0]) - first).max() > 0.05  # the transfer follows the pose
    assert status(dq_skin, body).live


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("keep", [True, False])
def test_apply_as_shape_key(dq_skin, assets, method, rig, keep):
    """DQ Skin's own Apply / Save as Shape Key (Blender's only takes deform-only modifiers)
    gives the shape key Blender's gives for its Armature modifier."""
    body, ref = characters(dq_skin, assets, method, rig)
    bpy.context.scene.frame_set(17)
    with bpy.context.temp_override(object=ref, active_object=ref):
        assert bpy.ops.object.modifier_apply_as_shapekey(
            modifier=next(m.name for m in ref.modifiers if m.type == "ARMATURE"), keep_modifier=keep
        ) == {"FINISHED"}
    mod = dq_skin_mods(body)[0]
    bpy.context.view_layer.objects.active = body
    with bpy.context.temp_override(object=body, active_object=body):
        assert bpy.ops.object.dq_skin_apply_as_shape_key(modifier=mod.name, keep_modifier=keep) == {"FINISHED"}
    ours, theirs = body.data.shape_keys.key_blocks, ref.data.shape_keys.key_blocks
    assert [k.name for k in ours][0] == [k.name for k in theirs][0] == "Basis" and len(ours) == len(theirs) == 2
    a = np.empty(len(body.data.vertices) * 3, np.float32)
    b = np.empty_like(a)
    ours[1].data.foreach_get("co", a)
    theirs[1].data.foreach_get("co", b)
    assert deviation(a.reshape(-1, 3), b.reshape(-1, 3)) <= REL_TOL
    assert (ours[1].value, ours[1].relative_key.name) == (theirs[1].value, theirs[1].relative_key.name)
    assert bool(dq_skin_mods(body)) == keep
    assert stack(body) == (["NODES", "ARMATURE"] if keep else [])
    if keep:
        play((3, 17), lambda f: same(world_positions(body), world_positions(ref), f"kept, at frame {f}"))


def _import_positions(path, importer) -> np.ndarray:
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    importer(str(path))
    meshes = [o for o in bpy.data.objects if o.type == "MESH"]
    assert len(meshes) == 1, [o.name for o in meshes]
    return world_positions(meshes[0])


FILE_EXPORTS = {
    "OBJ": (
        "obj",
        lambda p, sel: bpy.ops.wm.obj_export(filepath=p, export_selected_objects=sel),
        lambda p: bpy.ops.wm.obj_import(filepath=p),
    ),
    "PLY": (
        "ply",
        lambda p, sel: bpy.ops.wm.ply_export(filepath=p, export_selected_objects=sel),
        lambda p: bpy.ops.wm.ply_import(filepath=p),
    ),
    "STL": (
        "stl",
        lambda p, sel: bpy.ops.wm.stl_export(filepath=p, export_selected_objects=sel),
        lambda p: bpy.ops.wm.stl_import(filepath=p),
    ),
    "USD": (
        "usdc",
        lambda p, sel: bpy.ops.wm.usd_export(filepath=p, selected_objects_only=sel, export_armatures=False),
        lambda p: bpy.ops.wm.usd_import(filepath=p),
    ),
}


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("fmt", list(FILE_EXPORTS))
def test_file_exports_hold_the_posed_mesh(dq_skin, assets, tmp_path, method, rig, fmt):
    """Exporters that write the evaluated mesh (modifiers applied, their default) write DQ
    Skin's posed mesh, as they write the Armature modifier's."""
    suffix, export, import_ = FILE_EXPORTS[fmt]
    body, ref = characters(dq_skin, assets, method, rig)
    bpy.context.scene.frame_set(17)
    paths = []
    for obj in (body, ref):
        for o in bpy.context.view_layer.objects:
            o.select_set(o is obj)
        bpy.context.view_layer.objects.active = obj
        path = str(tmp_path / f"{obj.name}.{suffix}")
        assert export(path, True) == {"FINISHED"}
        paths.append(path)
    ours = _import_positions(paths[0], import_)
    theirs = _import_positions(paths[1], import_)
    assert ours.shape == theirs.shape
    assert deviation(ours, theirs) <= REL_TOL, f"{fmt}: {deviation(ours, theirs):.3e}"


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
def test_usd_export_with_its_defaults_holds_the_posed_mesh(dq_skin, assets, tmp_path, method, rig):
    """USD's skeleton export (on by default) takes the skin from an enabled Armature modifier and
    has no extension point before it writes: a DQ Skin character is written with DQ Skin's
    deformation in its mesh (every frame, with animation), as Alembic writes it; the pose is the
    Armature modifier's (see docs/compatibility.md)."""
    body, ref = characters(dq_skin, assets, method, rig)
    bpy.context.scene.frame_set(17)
    expected = world_positions(ref)
    for o in bpy.context.view_layer.objects:
        o.select_set(o in (body, body.parent))
    path = tmp_path / "body.usdc"
    assert bpy.ops.wm.usd_export(filepath=str(path), selected_objects_only=True) == {"FINISHED"}
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.wm.usd_import(filepath=str(path))
    mesh = next(o for o in bpy.data.objects if o.type == "MESH")
    assert deviation(world_positions(mesh), expected) <= REL_TOL


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", METHODS)
def test_texture_bake_from_the_posed_mesh(dq_skin, assets, tmp_path, method, rig):
    """Cycles bakes from the evaluated (posed) mesh: an object-space normal map of DQ Skin's
    pose equals the Armature modifier's."""
    body, ref = characters(dq_skin, assets, method, rig)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 1
    scene.cycles.device = "CPU"
    scene.render.bake.normal_space = "OBJECT"
    scene.frame_set(17)
    pictures = []
    for obj in (body, ref):
        image = bpy.data.images.new(f"bake {obj.name}", 64, 64, float_buffer=True)
        mat = bpy.data.materials.new(f"bake {obj.name}")
        if bpy.app.version < (5, 0, 0):
            mat.use_nodes = True  # always on from 5.0, where it is deprecated
        node = mat.node_tree.nodes.new("ShaderNodeTexImage")
        node.image = image
        mat.node_tree.nodes.active = node
        obj.data.materials.clear()
        obj.data.materials.append(mat)
        for o in bpy.context.view_layer.objects:
            o.select_set(o is obj)
        bpy.context.view_layer.objects.active = obj
        assert bpy.ops.object.bake(type="NORMAL") == {"FINISHED"}
        pictures.append(np.array(image.pixels[:]).reshape(64, 64, 4))
    assert np.abs(pictures[0] - pictures[1]).max() <= 1e-3
    assert pictures[0][..., :3].std() > 0.01  # something was baked

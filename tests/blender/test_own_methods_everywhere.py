"""DQ Skin's own methods (Blend, Optimized Centers) where artists work: simulations on and around
the character, brushes and Edit Mode, exporters, Apply and Apply as Shape Key. Blender has no
such method, so the reference is DQ Skin's own result for that method baked with DQ Skin's bake
(`object.dq_skin_bake`) on a copy of the character and played by Blender's Mesh Cache modifier:
whatever Blender computes from the live character must equal what it computes from the baked one,
with DQ Skin deforming live all the while (no hand-over to the Armature modifier).

Simulations amplify the last float bits; their tolerance is sized from a third copy of the scene
whose baked positions are moved by about one float ulp (`ULP_NOISE` of the size): the live
character must be at least as close to the reference as that copy (and within REL_TOL where the
consumer does not amplify).
"""

from __future__ import annotations

import numpy as np
import pytest
from dqtest import REL_TOL, add_dq_skin, deviation, dq_skin_mods, evaluated_positions, import_character, reference_copy, route_of, status
from scenes import RIGS, make_rig
from test_render import setup_scene

import bpy

from mathutils import Vector

OWN_METHODS = ["BLEND", "CENTERS_OF_ROTATION"]
FRAMES = (1, 30)  # the frames baked (the tests play within them)
ULP_NOISE = 2e-7  # of the size: about one float32 ulp of CesiumMan's coordinates
# What the pose must make of the method for a test to mean something: the method's result this
# far (of the size) from both of Blender's at frame 17.
METHOD_MATTERS = 1e-4


def world_positions(obj, depsgraph=None) -> np.ndarray:
    p = evaluated_positions(obj, depsgraph).astype(np.float64)
    m = np.array(obj.matrix_world, np.float64)
    return p @ m[:3, :3].T + m[:3, 3]


def _size(obj) -> float:
    return float(np.linalg.norm(np.ptp(np.array([list(c) for c in obj.bound_box]), axis=0)))


def _blend_gradient(obj) -> None:
    """A Blend Amount that goes from 0 at the feet to 1 at the head (glTF meshes are Y-up)."""
    co = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    up = co[:, 1] if np.ptp(co[:, 1]) > np.ptp(co[:, 2]) else co[:, 2]
    t = (up - up.min()) / np.ptp(up)
    g = obj.vertex_groups.new(name="Blend")
    for i, w in enumerate(t):
        g.add([i], float(w), "REPLACE")


class Scene:
    """CesiumMan with DQ Skin's `method` live (`body`), the same character baked by DQ Skin's
    bake and played by a Mesh Cache modifier (`ref`), and a copy of the reference whose cache
    is moved by about one ulp (`noisy`): all at the same place, sharing the armature."""

    def __init__(self, dq_skin, assets, tmp_path, method: str, rig: str, noisy: bool = False):
        from bl_ext.user_default.dq_skin.dqskin import pc2
        from bl_ext.user_default.dq_skin.ops.modifiers import set_attribute, set_input

        self.dq_skin = dq_skin
        body, arm_mod = import_character(assets / "CesiumMan.glb")
        make_rig(arm_mod.object, rig)
        if method == "BLEND":
            _blend_gradient(body)
        mod = add_dq_skin(body, method)
        if method == "BLEND":
            set_attribute(mod, "Blend Amount", "Blend")
            set_input(mod, "Blend Factor", 1.0)
        scene = bpy.context.scene
        scene.frame_start, scene.frame_end = FRAMES
        ref = body.copy()
        ref.data = body.data.copy()
        ref.name = f"{body.name} baked"
        scene.collection.objects.link(ref)
        bpy.context.view_layer.update()
        path = tmp_path / f"{method} {rig}.pc2"
        bpy.context.view_layer.objects.active = ref
        with bpy.context.temp_override(object=ref, active_object=ref):
            assert bpy.ops.object.dq_skin_bake(filepath=str(path), frame_start=FRAMES[0], frame_end=FRAMES[1]) == {"FINISHED"}
        assert [m.type for m in ref.modifiers if m.show_viewport] == ["MESH_CACHE"], [(m.name, m.show_viewport) for m in ref.modifiers]
        self.body, self.ref, self.path, self.method = body, ref, path, method
        self.noisy = None
        if noisy:
            header, samples = pc2.read(path)
            rng = np.random.default_rng(7)
            amp = ULP_NOISE * _size(body)
            moved = samples + rng.uniform(-amp, amp, samples.shape).astype(np.float32)
            noisy_path = tmp_path / f"{method} {rig} noisy.pc2"
            pc2.write(noisy_path, moved, header.start_frame, header.sample_rate)
            self.noisy = ref.copy()
            self.noisy.data = ref.data.copy()
            self.noisy.name = f"{body.name} noisy"
            scene.collection.objects.link(self.noisy)
            self.noisy.modifiers["DQ Skin Cache"].filepath = str(noisy_path)
        scene.frame_set(FRAMES[0])

    @property
    def all(self):
        return [o for o in (self.body, self.ref, self.noisy) if o is not None]

    def live(self, where: str) -> None:
        """DQ Skin deforms `body` itself with the chosen method (no hand-over, nothing switched)."""
        st = status(self.dq_skin, self.body)
        assert st.live, f"{where}: {st.mode.value}: {st.message}"
        assert st.method in ("Blend", "Optimized Centers"), f"{where}: {st.method!r}"

    def same(self, ours, theirs, noisy, what: str, tol: float = REL_TOL) -> float:
        """`ours` within `tol`, or within twice what the ulp-moved scene differs by, of `theirs`."""
        amplified = deviation(noisy, theirs) if noisy is not None else 0.0
        bar = max(tol, 2.0 * amplified)
        dev = deviation(ours, theirs)
        assert dev <= bar, f"{what}: {dev:.3e} of the size from the baked scene (bar {bar:.1e}, the ulp-moved scene {amplified:.1e})"
        return dev


def play(frames, check) -> None:
    for f in frames:
        bpy.context.scene.frame_set(f)
        check(f)


def moves(frames, obj) -> float:
    bpy.context.scene.frame_set(frames[0])
    a = world_positions(obj)
    bpy.context.scene.frame_set(frames[-1])
    return float(np.abs(world_positions(obj) - a).max())


def grid(name: str, size: float, cuts: int, location) -> bpy.types.Object:
    mesh = bpy.data.meshes.new(name)
    n = cuts + 1
    verts = [((i / cuts - 0.5) * size, (j / cuts - 0.5) * size, 0.0) for j in range(n) for i in range(n)]
    faces = [(j * n + i, j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i) for j in range(cuts) for i in range(cuts)]
    mesh.from_pydata(verts, [], faces)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    obj.location = location
    return obj


def upper_body_group(obj, name="Pin", below: float = 0.75) -> None:
    co = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    z = co[:, 1] if np.ptp(co[:, 1]) > np.ptp(co[:, 2]) else co[:, 2]
    g = obj.vertex_groups.get(name) or obj.vertex_groups.new(name=name)
    g.add(np.flatnonzero(z > below * z.max()).tolist(), 1.0, "REPLACE")


# -- the reference -------------------------------------------------------------------------------


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", OWN_METHODS)
def test_the_baked_reference_is_the_method_not_blenders(dq_skin, assets, tmp_path, method, rig):
    """The live character plays its own bake to 1e-6, and the method is neither of Blender's
    (a test where they agree would prove nothing)."""
    s = Scene(dq_skin, assets, tmp_path, method, rig)
    bpy.context.scene.frame_set(17)
    lbs, dqs = reference_copy(s.body, False), reference_copy(s.body, True)
    bpy.context.view_layer.update()
    ours = world_positions(s.body)
    assert deviation(ours, world_positions(s.ref)) <= 1e-6
    for other, name in ((lbs, "Linear"), (dqs, "Dual Quaternion")):
        assert deviation(ours, world_positions(other)) > METHOD_MATTERS, f"{method} equals {name} here"
    s.live("at frame 17")


# -- simulations on and around the character ----------------------------------------------------


def pinned_cloth(obj) -> None:
    """A cloth on the character, pinned by its upper body, simulated over the baked frames."""
    upper_body_group(obj)
    cloth = obj.modifiers.new("Cloth", "CLOTH")
    cloth.settings.vertex_group_mass = "Pin"
    cloth.settings.quality = 2
    cloth.point_cache.frame_end = FRAMES[1]


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", OWN_METHODS)
def test_a_pinned_cloth_on_the_character(dq_skin, assets, tmp_path, method, rig):
    s = Scene(dq_skin, assets, tmp_path, method, rig, noisy=True)
    for obj in s.all:
        pinned_cloth(obj)

    def check(f):
        s.same(world_positions(s.body), world_positions(s.ref), world_positions(s.noisy), f"cloth at frame {f}")
        s.live(f"cloth at frame {f}")

    play(range(1, 21), check)
    assert route_of(dq_skin, s.body) == "cache"
    assert moves((1, 20), s.body) > 0.05


@pytest.mark.parametrize("method", OWN_METHODS)
def test_a_pinned_cloth_on_a_character_disabled_in_viewports_renders(dq_skin, assets, tmp_path, method):
    """Disabled in viewports (kept out of the viewport's graph, as heavy characters often are),
    rendered with its pinned cloth unbaked: the step a render's graph takes starts from the
    method's positions at that frame, as in the baked scene. Read in the render's own graph,
    right after its first evaluation of each frame (a frame handler before DQ Skin's). The two
    scenes give the cloth the same input there, so the default bar holds (measured: equal to
    the bit; fed from the frame before, the body was 3 % of its size off)."""
    s = Scene(dq_skin, assets, tmp_path, method, RIGS[0])
    for obj in s.all:
        pinned_cloth(obj)
        obj.hide_viewport = True
    scene = setup_scene()
    bpy.context.view_layer.update()
    seen = {}

    def first_evaluation(scene, depsgraph):
        if depsgraph is not None and depsgraph.mode == "RENDER":
            for o in s.all:
                if o.evaluated_get(depsgraph).is_evaluated:
                    seen[(o.name, scene.frame_current)] = world_positions(o, depsgraph)

    frames = (1, 4)
    bpy.app.handlers.frame_change_post.insert(0, first_evaluation)
    try:
        for obj in s.all:
            for o in s.all:
                o.hide_render = o is not obj
            scene.frame_set(1)
            scene.frame_start, scene.frame_end = frames
            scene.render.filepath = str(tmp_path / f"{obj.name}_####")
            bpy.ops.render.render(animation=True)
    finally:
        bpy.app.handlers.frame_change_post.remove(first_evaluation)
    ours, theirs = ({f: seen[(o.name, f)] for f in range(frames[0], frames[1] + 1)} for o in (s.body, s.ref))
    assert deviation(theirs[frames[1]], theirs[frames[0]]) > 0.01, "the character should move"
    for f in theirs:
        dev = deviation(ours[f], theirs[f])
        assert dev <= REL_TOL, f"the render's frame {f}: {dev:.3e} of the size from the baked scene"


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", OWN_METHODS)
def test_a_cloth_collides_with_the_character(dq_skin, assets, tmp_path, method, rig):
    s = Scene(dq_skin, assets, tmp_path, method, rig, noisy=True)
    top = max((s.ref.matrix_world @ Vector(c)).z for c in s.ref.bound_box)
    sheets = []
    for obj in s.all:
        obj.modifiers.new("Collision", "COLLISION")
        own = bpy.data.collections.new(f"{obj.name} colliders")
        bpy.context.scene.collection.children.link(own)
        own.objects.link(obj)
        sheet = grid(f"Sheet {obj.name}", 1.2, 16, (0.0, 0.0, top + 0.1))
        cloth = sheet.modifiers.new("Cloth", "CLOTH")
        cloth.settings.quality = 2
        cloth.collision_settings.collection = own
        cloth.point_cache.frame_end = FRAMES[1]
        sheets.append(sheet)

    def check(f):
        s.same(*(world_positions(x) for x in sheets), f"falling cloth at frame {f}")
        s.live(f"falling cloth at frame {f}")

    play(range(1, 25), check)
    assert moves((1, 24), sheets[0]) > 0.1


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", OWN_METHODS)
def test_a_soft_body_simulates_the_method(dq_skin, assets, tmp_path, method, rig):
    """The Soft Body (which Blender keeps before non-deform modifiers) simulates DQ Skin's result:
    its carrier goes before the Soft Body, as the bake's Mesh Cache does."""
    s = Scene(dq_skin, assets, tmp_path, method, rig, noisy=True)
    for obj in s.all:
        upper_body_group(obj, name="Goal", below=0.6)
        m = obj.modifiers.new("Softbody", "SOFT_BODY")
        m.settings.vertex_group_goal = "Goal"
        m.point_cache.frame_end = FRAMES[1]

    def check(f):
        s.same(world_positions(s.body), world_positions(s.ref), world_positions(s.noisy), f"soft body at frame {f}")
        s.live(f"soft body at frame {f}")

    play(range(1, 13), check)
    assert moves((1, 12), s.body) > 0.01


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", OWN_METHODS)
def test_particle_hair_and_emitted_particles(dq_skin, assets, tmp_path, method, rig):
    s = Scene(dq_skin, assets, tmp_path, method, rig)
    # An emitter evaluates its parents' animation at each particle's birth sub-frame on its own
    # graph thread (`reset_particle`). The baked copy does not wait for the armature's bones (its
    # Mesh Cache needs none), so as the armature's child it would pose the shared armature between
    # frames while Blender evaluates its bones for the frame: a race in Blender that gives any
    # skinning of that armature (the Armature modifier too) a pose between frames, now and then
    # (4.2 and 4.3; docs/compatibility.md). The copy keeps its place without the parent.
    for obj in s.all[1:]:
        world = obj.matrix_world.copy()
        obj.parent = None
        obj.matrix_world = world
    for obj in s.all:
        obj.modifiers.new("Hair", "PARTICLE_SYSTEM")
        hair = obj.particle_systems[-1].settings
        hair.type, hair.count, hair.hair_length = "HAIR", 200, 0.05
        obj.modifiers.new("Emitter", "PARTICLE_SYSTEM")
        emit = obj.particle_systems[-1].settings
        emit.type, emit.count, emit.frame_start, emit.frame_end, emit.lifetime = "EMITTER", 200, 1, 10, 50
        emit.normal_factor, emit.effector_weights.gravity = 0.2, 0.0
        obj.particle_systems[-1].point_cache.frame_end = FRAMES[1]

    def hair_points(obj):
        ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
        ps = ev.particle_systems[0]
        return np.array([ps.co_hair(ev, particle_no=i, step=k) for i in range(len(ps.particles)) for k in (0, 5)], np.float64)

    def emitted(obj):
        ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
        ps = ev.particle_systems[1]
        co = np.empty(len(ps.particles) * 3, np.float32)
        ps.particles.foreach_get("location", co)
        alive = np.array([p.alive_state == "ALIVE" for p in ps.particles])
        return co.reshape(-1, 3)[alive].astype(np.float64), alive

    def check(f):
        s.same(hair_points(s.body), hair_points(s.ref), None, f"hair roots and tips at frame {f}")
        (a, alive_a), (b, alive_b) = emitted(s.body), emitted(s.ref)
        assert (alive_a == alive_b).all(), f"frame {f}: other particles alive"
        if len(b):
            worst = float(np.abs(a - b).max()) / _size(s.body)
            assert worst <= REL_TOL, f"emitted particles at frame {f}: {worst:.3e} of the size"
        s.live(f"particles at frame {f}")

    play(range(1, 18), check)
    assert len(emitted(s.body)[0]) > 50


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", OWN_METHODS)
def test_dynamic_paint_and_fluid_on_the_character(dq_skin, assets, tmp_path, method, rig):
    """The character as a Dynamic Paint canvas and a Fluid effector (both read the mesh in
    Blender's first evaluation of a frame): they get the method's mesh, DQ Skin stays live."""
    s = Scene(dq_skin, assets, tmp_path, method, rig)
    for obj in s.all:
        m = obj.modifiers.new("Dynamic Paint", "DYNAMIC_PAINT")
        with bpy.context.temp_override(object=obj, active_object=obj):
            bpy.ops.dpaint.type_toggle(type="CANVAS")
        m.canvas_settings.canvas_surfaces[0].frame_end = FRAMES[1]
        obj.modifiers.new("Fluid", "FLUID").fluid_type = "EFFECTOR"

    def check(f):
        s.same(world_positions(s.body), world_positions(s.ref), None, f"the canvas at frame {f}")
        s.live(f"Dynamic Paint and Fluid at frame {f}")

    play(range(1, 13), check)
    assert route_of(dq_skin, s.body) == "cache"
    assert moves((1, 12), s.body) > 0.01


# -- brushes and Edit Mode on the posed mesh -----------------------------------------------------


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
@pytest.mark.parametrize("method", OWN_METHODS)
@pytest.mark.parametrize("mode", ["SCULPT", "WEIGHT_PAINT", "VERTEX_PAINT", "TEXTURE_PAINT", "EDIT", "EDIT, shown on the pose"])
def test_brushes_map_strokes_through_the_method(dq_skin, assets, tmp_path, method, rig, mode):
    """In the paint and sculpt modes and Edit Mode, the mesh shows the method and strokes map
    through it as through its bake. Edit Mode shows the pose where the modifier's Edit Mode
    display is on (the imported character has it off: the rest mesh shows, as with its bake)."""
    s = Scene(dq_skin, assets, tmp_path, method, rig)
    if mode == "EDIT, shown on the pose":
        for m in (dq_skin_mods(s.body)[0], s.ref.modifiers["DQ Skin Cache"]):
            m.show_in_editmode = True
    bpy.context.scene.frame_set(17)
    vertices = list(range(0, len(s.body.data.vertices), 97))
    expected = crazyspace(s.ref, vertices)
    assert np.abs(expected - np.tile([[1, 0, 0], [0, 0, 1]], (len(vertices), 1))).max() > 0.3  # the pose rotates strokes
    bpy.context.view_layer.objects.active = s.body
    for o in bpy.context.view_layer.objects:
        o.select_set(o is s.body or (mode.startswith("EDIT") and o is s.ref))  # Edit Mode takes both
    bpy.ops.object.mode_set(mode=mode.split(",")[0])
    try:
        bpy.context.view_layer.update()
        if mode.startswith("EDIT"):
            expected = crazyspace(s.ref, vertices)  # as the reference maps in Edit Mode
        got = crazyspace(s.body, vertices)
        assert np.abs(got - expected).max() <= 1e-5, (
            f"{mode}: strokes map differently from the baked method's: {np.abs(got - expected).max():.2e}"
        )
        s.live(mode)
        s.same(world_positions(s.body), world_positions(s.ref), None, f"the mesh shown in {mode}")
        if mode.startswith("EDIT"):
            note = " ".join(status(dq_skin, s.body).notes)
            assert ("pose" if s.body.modifiers[dq_skin_mods(s.body)[0].name].show_in_editmode else "rest mesh") in note, note
    finally:
        bpy.ops.object.mode_set(mode="OBJECT")
    bpy.context.scene.frame_set(18)
    s.live("back in Object Mode")
    s.same(world_positions(s.body), world_positions(s.ref), None, "back in Object Mode")


# -- Apply and Apply as Shape Key ---------------------------------------------------------------


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", OWN_METHODS)
def test_apply_keeps_the_method(dq_skin, assets, tmp_path, method, rig):
    s = Scene(dq_skin, assets, tmp_path, method, rig)
    bpy.context.scene.frame_set(17)
    expected = world_positions(s.ref)
    mod = dq_skin_mods(s.body)[0]
    bpy.context.view_layer.objects.active = s.body
    with bpy.context.temp_override(object=s.body, active_object=s.body):
        assert bpy.ops.object.modifier_apply(modifier=mod.name) == {"FINISHED"}
    bpy.context.view_layer.update()
    co = np.array([v.co for v in s.body.data.vertices], np.float64)
    m = np.array(s.body.matrix_world, np.float64)
    assert deviation(co @ m[:3, :3].T + m[:3, 3], expected) <= REL_TOL
    assert not dq_skin_mods(s.body) and not [m for m in s.body.modifiers if m.show_viewport]


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", OWN_METHODS)
@pytest.mark.parametrize("keep", [True, False])
def test_apply_as_shape_key_keeps_the_method(dq_skin, assets, tmp_path, method, rig, keep):
    """DQ Skin's Apply as Shape Key gives the shape key Blender's gives for the bake's Mesh Cache."""
    s = Scene(dq_skin, assets, tmp_path, method, rig)
    bpy.context.scene.frame_set(17)
    with bpy.context.temp_override(object=s.ref, active_object=s.ref):
        assert bpy.ops.object.modifier_apply_as_shapekey(modifier="DQ Skin Cache", keep_modifier=True) == {"FINISHED"}
    mod = dq_skin_mods(s.body)[0]
    bpy.context.view_layer.objects.active = s.body
    with bpy.context.temp_override(object=s.body, active_object=s.body):
        assert bpy.ops.object.dq_skin_apply_as_shape_key(modifier=mod.name, keep_modifier=keep) == {"FINISHED"}
    ours, theirs = s.body.data.shape_keys.key_blocks, s.ref.data.shape_keys.key_blocks
    assert len(ours) == len(theirs) == 2
    a = np.empty(len(s.body.data.vertices) * 3, np.float32)
    b = np.empty_like(a)
    ours[1].data.foreach_get("co", a)
    theirs[1].data.foreach_get("co", b)
    assert deviation(a.reshape(-1, 3), b.reshape(-1, 3)) <= REL_TOL
    assert bool(dq_skin_mods(s.body)) == keep


# -- exporters ----------------------------------------------------------------------------------


def _reimported_mesh(path, importer) -> np.ndarray:
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    importer(str(path))
    meshes = [o for o in bpy.data.objects if o.type == "MESH"]
    assert len(meshes) == 1, [o.name for o in meshes]
    bpy.context.scene.frame_set(17)
    return world_positions(meshes[0])


EXPORTS = {
    "OBJ": ("obj", lambda p: bpy.ops.wm.obj_export(filepath=p, export_selected_objects=True), lambda p: bpy.ops.wm.obj_import(filepath=p)),
    "USD": (
        "usdc",
        lambda p: bpy.ops.wm.usd_export(filepath=p, selected_objects_only=True, export_armatures=False, export_animation=True),
        lambda p: bpy.ops.wm.usd_import(filepath=p),
    ),
    "Alembic": (
        "abc",
        lambda p: bpy.ops.wm.alembic_export(filepath=p, selected=True, start=FRAMES[0], end=20),
        lambda p: bpy.ops.wm.alembic_import(filepath=p),
    ),
    "glTF without skins": (
        "glb",
        lambda p: bpy.ops.export_scene.gltf(filepath=p, use_selection=True, export_skins=False, export_animations=False),
        lambda p: bpy.ops.import_scene.gltf(filepath=p),
    ),
}


@pytest.mark.parametrize("rig", RIGS)
@pytest.mark.parametrize("method", OWN_METHODS)
@pytest.mark.parametrize("fmt", list(EXPORTS))
def test_mesh_exports_hold_the_method(dq_skin, assets, tmp_path, method, rig, fmt):
    """Exporters that write the evaluated mesh (every frame for Alembic and USD) write the
    method's result, as they write its bake."""
    suffix, export, import_ = EXPORTS[fmt]
    s = Scene(dq_skin, assets, tmp_path, method, rig)
    bpy.context.scene.frame_set(17)
    paths = []
    for obj in (s.body, s.ref):
        for o in bpy.context.view_layer.objects:
            o.select_set(o is obj)
        bpy.context.view_layer.objects.active = obj
        path = str(tmp_path / f"{obj.name}.{suffix}")
        assert export(path) == {"FINISHED"}
        paths.append(path)
    ours, theirs = (_reimported_mesh(p, import_) for p in paths)
    assert ours.shape == theirs.shape
    assert deviation(ours, theirs) <= REL_TOL, f"{fmt}: {deviation(ours, theirs):.3e}"


def _skin_of(path, importer):
    """The rest mesh (world) and weights of the one skinned mesh imported from `path`."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    importer(filepath=str(path))
    obj = next(o for o in bpy.data.objects if o.type == "MESH" and any(m.type == "ARMATURE" for m in o.modifiers))
    co = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.vertices.foreach_get("co", co)
    m = np.array(obj.matrix_world, np.float64)
    weights = np.zeros((len(obj.data.vertices), len(obj.vertex_groups)), np.float32)
    names = [g.name for g in obj.vertex_groups]
    for v in obj.data.vertices:
        for e in v.groups:
            weights[v.index, e.group] = e.weight
    order = np.argsort(names)
    return co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3], weights[:, order], sorted(names)


SKIN_EXPORTS = {
    "FBX": (
        ".fbx",
        lambda p, apply: bpy.ops.export_scene.fbx(filepath=p, use_selection=True, use_mesh_modifiers=apply),
        bpy.ops.import_scene.fbx,
    ),
    "glTF": (
        ".glb",
        lambda p, apply: bpy.ops.export_scene.gltf(filepath=p, use_selection=True, export_apply=apply),
        bpy.ops.import_scene.gltf,
    ),
}


@pytest.mark.parametrize("rig", ["vertex groups", "B-Bones"])
@pytest.mark.parametrize("method", OWN_METHODS)
@pytest.mark.parametrize("fmt", list(SKIN_EXPORTS))
@pytest.mark.parametrize("apply_modifiers", [True, False])
def test_skin_exports_carry_the_skin_and_say_the_method_stays(dq_skin, assets, tmp_path, capfd, method, rig, fmt, apply_modifiers):
    """FBX and glTF carry a skin (the rest mesh, the armature, the weights) that other programs
    deform with their own Linear or Dual Quaternion skinning: a DQ Skin character with its own
    method exports the same skin as the character under Blender's Armature modifier (never its
    posed mesh as the rest mesh, never without its skin), and the export warns that the method
    stays behind."""
    suffix, export, importer = SKIN_EXPORTS[fmt]
    s = Scene(dq_skin, assets, tmp_path, method, rig)
    plain = reference_copy(s.body, True)
    plain.name = "Armature character"
    bpy.context.scene.frame_set(17)
    paths = []
    for obj in (s.body, plain):
        for o in bpy.context.view_layer.objects:
            o.select_set(o in (obj, obj.parent))
        bpy.context.view_layer.objects.active = obj
        path = str(tmp_path / f"{obj.name}{suffix}")
        capfd.readouterr()
        assert export(path, apply_modifiers) == {"FINISHED"}
        said = "".join(capfd.readouterr())
        assert ("not DQ Skin's method" in said) == (obj is s.body), said[-400:]
        paths.append(path)
    s.live("after the exports")
    (ra, wa, na), (rb, wb, nb) = (_skin_of(p, importer) for p in paths)
    assert na == nb and ra.shape == rb.shape
    assert deviation(ra, rb) <= REL_TOL, f"{fmt}: the exported rest mesh is not the rest mesh"
    assert np.abs(wa - wb).max() <= 1e-6

"""Renders see DQ Skin's result for the frame being rendered (no one-frame lag): an animation
render of CesiumMan with DQ Skin gives the same image as one with the Armature modifier."""

from __future__ import annotations

import numpy as np
from dqtest import add_dq_skin, import_character, reference_copy

import bpy

# Two renders of the same geometry differ at most by rounding (1/255); a pixel that differs by
# more counts as changed. Allowed share of changed pixels for "the same image"; a pose from
# another frame changes far more (checked below, so the test can fail).
CHANGED = 2.5 / 255
SAME_IMAGE = 1e-3


def changed(a: np.ndarray, b: np.ndarray) -> float:
    return float((np.abs(a - b) > CHANGED).mean())


def setup_scene():
    scene = bpy.context.scene
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    cam.location = (0.0, -3.2, 0.9)
    cam.rotation_euler = (1.45, 0.0, 0.0)
    scene.camera = cam
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = 4.0
    sun.rotation_euler = (0.6, 0.2, 0.4)
    scene.collection.objects.link(sun)
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 2
    scene.cycles.seed = 7
    scene.render.resolution_x = scene.render.resolution_y = 96
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    return scene


def render_frame(scene, frame: int, path) -> np.ndarray:
    """An animation render of the single frame `frame`, started from another frame."""
    scene.frame_set(1)
    scene.frame_start = scene.frame_end = frame
    scene.render.filepath = str(path) + "_####"
    bpy.ops.render.render(animation=True)
    image = bpy.data.images.load(f"{path}_{frame:04d}.png")
    try:
        pixels = np.array(image.pixels[:], np.float32)
    finally:
        bpy.data.images.remove(image)
    return pixels


def test_animation_render_uses_the_rendered_frame(dq_skin, assets, tmp_path):
    obj, arm_mod = import_character(assets / "CesiumMan.glb")
    scene = setup_scene()
    reference = reference_copy(obj, True)
    add_dq_skin(obj, "DUAL_QUATERNION")

    def show(which):
        obj.hide_render = which is not obj
        reference.hide_render = which is not reference

    show(obj)
    ours = render_frame(scene, 30, tmp_path / "ours")
    show(reference)
    theirs = render_frame(scene, 30, tmp_path / "theirs")
    other = render_frame(scene, 20, tmp_path / "other")
    assert changed(theirs, other) > 10 * SAME_IMAGE, "frames 20 and 30 should look different"
    assert changed(ours, theirs) < SAME_IMAGE, changed(ours, theirs)

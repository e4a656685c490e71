"""Batch command line for Blender files: ``python -m dqskin.blender COMMAND ...``.

Works with the ``bpy`` module and inside Blender
(``blender -b --python-expr "import dqskin.blender as c; c.main()" -- COMMAND ...`` or
``blender -b --python path/to/blender.py -- COMMAND ...``). The DQ Skin extension must be
installed in the Blender user folder named by ``BLENDER_USER_RESOURCES`` (or
``--user-resources``), as ``make setup`` does into ``.blender_user/``.

Commands:
- ``bake FILE --object NAME [--frames A-B] [--method M] --out FILE.pc2``: bake the object's DQ
  Skin result (added from its Armature modifier if missing) to a PC2 cache.
- ``apply FILE --out FILE.blend``: replace every Armature modifier with DQ Skin and save.
- ``merge OUT IN [IN ...]``: join PC2 chunks of consecutive frame ranges (farm bakes).
- ``compare [FILE] [--frames A-B] [--out DIR]``: a comparison scene (the file's first rigged
  mesh, or built-in test rigs) with the Armature modifier (Linear, Preserve Volume) and DQ Skin
  (Linear, Dual Quaternion, Blend) side by side: ``report.json`` and ``report.md`` (deviations
  from each built-in method, volume relative to rest, per-frame time) and ``comparison.png``.

On failure the exit code is non-zero with a one-line reason, and no output file is written (all
outputs go to a temporary file that is renamed into place).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

EXTENSION = "bl_ext.user_default.dq_skin"


class Failure(Exception):
    """A one-line reason to stop with a non-zero exit code."""


def _frames(text: str | None, scene) -> tuple[int, int]:
    if not text:
        return scene.frame_start, scene.frame_end
    try:
        a, b = (int(x) for x in text.split("-", 1))
    except ValueError:
        raise Failure(f"--frames must look like A-B, got {text!r}") from None
    if b < a:
        raise Failure(f"--frames {text}: the end is before the start")
    return a, b


def _bpy(user_resources: str | None):
    if user_resources:
        os.environ["BLENDER_USER_RESOURCES"] = str(Path(user_resources).resolve())
    import bpy  # noqa: F401  (after BLENDER_USER_RESOURCES)
    import addon_utils

    if addon_utils.enable(EXTENSION, default_set=True) is None:
        raise Failure(
            f"the DQ Skin extension is not installed in {os.environ.get('BLENDER_USER_RESOURCES', 'the default user folder')}"
        )
    return bpy


def _load(bpy, path: str) -> None:
    p = Path(path)
    if not p.is_file():
        raise Failure(f"{path}: no such file")
    ext = p.suffix.lower()
    if ext == ".blend":
        bpy.ops.wm.open_mainfile(filepath=str(p))
        return
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    if ext in (".glb", ".gltf"):
        bpy.ops.import_scene.gltf(filepath=str(p))
    elif ext == ".fbx":
        bpy.ops.import_scene.fbx(filepath=str(p))
    else:
        raise Failure(f"{path}: unsupported file type {ext} (use .blend, .glb, .gltf or .fbx)")


def _skinned(bpy):
    return [o for o in bpy.data.objects if o.type == "MESH" and any(m.type == "ARMATURE" for m in o.modifiers)]


def _add_dq_skin(bpy, obj, method: str):
    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(object=obj, active_object=obj):
        bpy.ops.object.dq_skin_add(method=method)
    return next(m for m in obj.modifiers if m.type == "NODES" and m.node_group and m.node_group.get("dq_skin_version"))


def cmd_bake(args) -> str:
    bpy = _bpy(args.user_resources)
    _load(bpy, args.file)
    obj = bpy.data.objects.get(args.object)
    if obj is None or obj.type != "MESH":
        raise Failure(f"{args.file}: no mesh object named {args.object!r}")
    from bl_ext.user_default.dq_skin import modifier

    if not modifier.dq_skin_modifiers(obj):
        if not any(m.type == "ARMATURE" for m in obj.modifiers):
            raise Failure(f"{obj.name} has neither a DQ Skin nor an Armature modifier")
        _add_dq_skin(bpy, obj, args.method)
    start, end = _frames(args.frames, bpy.context.scene)
    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(object=obj, active_object=obj):
        try:
            bpy.ops.object.dq_skin_bake(filepath=str(Path(args.out).resolve()), frame_start=start, frame_end=end)
        except RuntimeError as e:
            raise Failure(str(e).strip().splitlines()[-1]) from None
    return f"baked {obj.name} frames {start}-{end} to {args.out}"


def cmd_apply(args) -> str:
    bpy = _bpy(args.user_resources)
    _load(bpy, args.file)
    objects = _skinned(bpy)
    if not objects:
        raise Failure(f"{args.file}: no object has an Armature modifier")
    for obj in objects:
        _add_dq_skin(bpy, obj, args.method)
    out = Path(args.out).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.stem}.", suffix=".blend", dir=out.parent)
    os.close(fd)
    try:
        bpy.ops.wm.save_as_mainfile(filepath=tmp, copy=True)
        os.replace(tmp, out)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return f"replaced {len(objects)} Armature modifier(s) with DQ Skin in {out}"


def cmd_merge(args) -> str:
    from . import pc2

    try:
        header = pc2.merge([Path(p) for p in args.inputs], Path(args.out))
    except (pc2.PC2Error, OSError) as e:
        raise Failure(str(e)) from None
    return f"merged {len(args.inputs)} caches into {args.out}: frames {header.start_frame:g}-{header.end_frame:g}"


def cmd_compare(args) -> str:
    bpy = _bpy(args.user_resources)
    from bl_ext.user_default.dq_skin import compare

    if args.file:
        _load(bpy, args.file)
        sources = _skinned(bpy)[:1]
        if not sources:
            raise Failure(f"{args.file}: no object has an Armature modifier")
        name = Path(args.file).name
    else:
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        sources = compare.builtin_rigs(bpy.context.scene)
        bpy.context.scene.frame_start, bpy.context.scene.frame_end = compare.FRAMES
        name = "built-in test rigs"
    scene = bpy.context.scene
    arm = next(m for m in sources[0].modifiers if m.type == "ARMATURE").object
    action = arm.animation_data.action if arm and arm.animation_data else None
    if args.file and action is not None and not args.frames:
        # The animation's own range rather than the scene's default 1-250.
        scene.frame_start, scene.frame_end = (int(round(f)) for f in action.frame_range)
    start, end = _frames(args.frames, scene)
    _, rows = compare.build(bpy.context, sources)
    result = compare.report(bpy.context, scene, rows, list(range(start, end + 1)))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    picture = None
    if not args.no_render:
        scene.frame_set(end)
        tmp = out / ".comparison.render.png"
        compare.render(scene, tmp, width=args.width, height=args.height, samples=args.samples)
        os.replace(tmp, out / "comparison.png")
        picture = "comparison.png"
    compare.write_report(result, out, name, [start, end], picture)
    return f"compared {name} over frames {start}-{end}: {out / 'report.md'}"


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m dqskin.blender", description=__doc__.splitlines()[0])
    p.add_argument("--user-resources", help="Blender user folder with DQ Skin installed (sets BLENDER_USER_RESOURCES)")
    sub = p.add_subparsers(dest="command", required=True)
    methods = ["AUTO", "LINEAR", "DUAL_QUATERNION", "BLEND"]
    b = sub.add_parser("bake", help="bake DQ Skin to a PC2 cache")
    b.add_argument("file")
    b.add_argument("--object", required=True)
    b.add_argument("--frames")
    b.add_argument("--method", choices=methods, default="AUTO")
    b.add_argument("--out", required=True)
    b.set_defaults(run=cmd_bake)
    a = sub.add_parser("apply", help="replace Armature modifiers with DQ Skin and save")
    a.add_argument("file")
    a.add_argument("--method", choices=methods, default="AUTO")
    a.add_argument("--out", required=True)
    a.set_defaults(run=cmd_apply)
    m = sub.add_parser("merge", help="join PC2 chunks")
    m.add_argument("out")
    m.add_argument("inputs", nargs="+")
    m.set_defaults(run=cmd_merge)
    c = sub.add_parser("compare", help="a comparison scene, its report and a render")
    c.add_argument("file", nargs="?", help="a rigged file (default: the built-in test rigs)")
    c.add_argument("--frames")
    c.add_argument("--out", default="out")
    c.add_argument("--no-render", action="store_true", help="skip the PNG")
    c.add_argument("--width", type=int, default=960)
    c.add_argument("--height", type=int, default=540)
    c.add_argument("--samples", type=int, default=8)
    c.set_defaults(run=cmd_compare)
    return p


def main(argv: list[str] | None = None) -> int:
    if argv is None:
        argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    args = parser().parse_args(argv)
    try:
        print(args.run(args))
        return 0
    except Failure as e:
        print(f"dqskin.blender {args.command}: {e}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    raise SystemExit(main())

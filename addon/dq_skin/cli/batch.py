# SPDX-License-Identifier: GPL-3.0-or-later
"""The batch commands: ``blender -b --command dq_skin COMMAND ...`` (registered by `cli`) and, with
the ``bpy`` module, ``python -m dqskin.blender COMMAND ...`` (a launcher that enables this
extension and calls `main`).

Commands:
- ``bake FILE --object NAME [--object NAME ...] [--frames A-B] [--method M] --out OUT``: bake
  each object's DQ Skin result (added from its Armature modifier if missing; set to M if given,
  in the loaded file, which no command saves) to a PC2 cache: OUT is FILE.pc2 (one object),
  FOLDER/ (FOLDER/NAME.pc2 each) or a pattern with ``{object}``.
- ``apply FILE --out FILE.blend``: replace every Armature modifier with DQ Skin and save.
- ``merge OUT IN [IN ...]``: join PC2 chunks of consecutive frame ranges (farm bakes).
- ``preflight FILE``: name every object that would render differently on a node without the
  extension (one of DQ Skin's own methods, unbaked, or a bake that would not play there): exit
  code 3 if any, 0 if none.
- ``compare [FILE] [--frames A-B] [--out DIR]``: a comparison scene (the file's first rigged
  mesh, or built-in test rigs) with the Armature modifier (Linear, Preserve Volume) and DQ Skin
  (Linear, Dual Quaternion, Blend, Optimized Centers) side by side: ``report.json`` and
  ``report.md`` (deviations from each built-in method, volume relative to rest, per-frame time),
  ``comparison.png`` (the variants, labelled) and ``deviation.png`` (each variant coloured by its
  distance from Armature Linear, with a legend).

``--threads N`` (before or after the command) sizes DQ Skin's thread pool; without it, inside
Blender, Blender's own ``-t N`` does.

Wrong usage (an unknown option, a value out of range) exits with 2 and argparse's message naming
the option. On failure the exit code is 1 with a one-line reason (``DQSKIN_DEBUG=1`` adds the
traceback), and no output file is written: all outputs go to a temporary file
``.NAME.dqskin-PID.tmp`` that is renamed into place. Ctrl-C (SIGINT) and SIGTERM stop any command
between two frames (a Cycles render in progress finishes its image first), remove the temporary
files, leave existing outputs untouched and exit with 130 and 143. SIGKILL cannot be caught: the
next run writing the same output removes the temporaries of processes that no longer run.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import traceback
from pathlib import Path

import bpy

from .. import dqskin
from ..blender import nodes
from ..dqskin import pc2
from ..engine.context import dq_skin_modifiers
from ..model.methods import BY_NAME
from ..ops import bake
from ..progress import Progress
from ..tools import compare
from . import interrupts, outputs, preflight
from .errors import Failure
from .interrupts import check, deferred

LAUNCHER = "python -m dqskin.blender"
METHODS = ("AUTO", *BY_NAME)  # the operators' method values (`dqskin.Method` names)
# Blender's own limits: RenderSettings.resolution_x/y, Cycles' samples, MINAFRAME..MAXFRAME.
PICTURE_SIZE = (4, 65536)
SAMPLES = (1, 16777216)
FRAMES = (-1048574, 1048574)
THREADS = 1024  # Blender's own limit for -t (BLENDER_MAX_THREADS)


def _whole_number(low: int, high: int):
    """An argparse type: an integer in [low, high], else a usage error naming the option."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a whole number, got {text!r}") from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"must be from {low} to {high}, got {value}")
        return value

    return parse


def _frame_range(text: str) -> tuple[int, int]:
    """An argparse type for ``A-B`` (negative frames too: ``--frames=-5-10``)."""
    m = re.fullmatch(r"\s*(-?\d+)\s*-\s*(-?\d+)\s*", text)
    if m is None:
        raise argparse.ArgumentTypeError(f"must look like A-B (e.g. 1-48), got {text!r}")
    a, b = int(m[1]), int(m[2])
    if not (FRAMES[0] <= a <= FRAMES[1] and FRAMES[0] <= b <= FRAMES[1]):
        raise argparse.ArgumentTypeError(f"{text}: frames must be from {FRAMES[0]} to {FRAMES[1]}")
    if b < a:
        raise argparse.ArgumentTypeError(f"{text}: the end is before the start")
    return a, b


def _frames(chosen: tuple[int, int] | None, scene) -> tuple[int, int]:
    return chosen if chosen else (scene.frame_start, scene.frame_end)


def _load(path: str) -> None:
    p = Path(path)
    if not p.is_file():
        raise Failure(f"{path}: {'not a file' if p.exists() else 'no such file'}")
    ext = p.suffix.lower()
    if ext not in (".blend", ".glb", ".gltf", ".fbx"):
        raise Failure(f"{path}: unsupported file type {ext} (use .blend, .glb, .gltf or .fbx)")
    try:
        if ext == ".blend":
            bpy.ops.wm.open_mainfile(filepath=str(p))
        else:
            bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
            if ext in (".glb", ".gltf"):
                bpy.ops.import_scene.gltf(filepath=str(p))
            else:
                bpy.ops.import_scene.fbx(filepath=str(p))
    except (RuntimeError, OSError, ValueError) as e:
        raise Failure(f"{path}: cannot be read ({_last_line(e)})") from None
    interrupts.watch()


def _last_line(e: BaseException) -> str:
    lines = [line.strip() for line in str(e).strip().splitlines() if line.strip()]
    return lines[-1] if lines else type(e).__name__


def _skinned():
    return [o for o in bpy.data.objects if o.type == "MESH" and any(m.type == "ARMATURE" for m in o.modifiers)]


def _add_dq_skin(obj, method: str) -> None:
    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(object=obj, active_object=obj):
        bpy.ops.object.dq_skin_add(method=method)


def _mesh(path: str, name: str):
    obj = bpy.data.objects.get(name)
    if obj is None:
        raise Failure(f"{path}: no mesh object named {name!r}")
    if obj.type != "MESH":
        kind = obj.type.lower().replace("_", " ")
        raise Failure(f"{path}: {name!r} is {'an' if kind[0] in 'aeiou' else 'a'} {kind} object, not a mesh")
    return obj


def _check_rigged(obj) -> None:
    """A Failure naming what the object lacks for DQ Skin to deform it."""
    mods = dq_skin_modifiers(obj)
    if mods:
        if nodes.get(mods[0], "Armature") is None:
            raise Failure(f"{obj.name}: its DQ Skin modifier has no armature")
        return
    armatures = [m for m in obj.modifiers if m.type == "ARMATURE"]
    if not armatures:
        raise Failure(f"{obj.name} has neither a DQ Skin nor an Armature modifier")
    if armatures[0].object is None or armatures[0].object.type != "ARMATURE":
        raise Failure(f"{obj.name}: its Armature modifier {armatures[0].name!r} has no armature object")


def cmd_bake(args) -> str:
    _load(args.file)
    objects = [_mesh(args.file, name) for name in dict.fromkeys(args.object)]
    for obj in objects:
        _check_rigged(obj)
    outs = outputs.outputs(args, objects)
    scene = bpy.context.scene
    start, end = _frames(args.frames, scene)
    # One object: written in place (a temporary renamed at its end, as every output). Several:
    # each staged in its output's temporary, all renamed once every one is baked.
    temporaries = [outputs.staging(out) for out in outs] if len(outs) > 1 else outs
    try:
        for obj, tmp, out in zip(objects, temporaries, outs, strict=True):
            check()
            try:
                with deferred():
                    _dq_skin_with_method(obj, args.method)
            except (RuntimeError, ValueError) as e:
                raise Failure(f"{obj.name}: DQ Skin cannot be added ({_last_line(e)})") from None
            try:
                with deferred():
                    bake.bake(bpy.context, obj, tmp, start, end, check=check)  # every DQ Skin modifier
            except OSError as e:
                raise Failure(f"{out}: cannot be written ({e.strerror or _last_line(e)})") from None
            except (RuntimeError, ValueError) as e:
                raise Failure(f"{obj.name}: {_last_line(e)}") from None
        check()
        if len(outs) > 1:
            for tmp, out in zip(temporaries, outs, strict=True):
                try:
                    os.replace(tmp, out)
                except OSError as e:
                    raise Failure(f"{out}: cannot be written ({_last_line(e)})") from None
    finally:
        if len(outs) > 1:
            for tmp in temporaries:
                if tmp.exists():
                    tmp.unlink()
    threads = dqskin.get_num_threads()
    where = args.out if len(objects) == 1 and not outputs.is_pattern_or_folder(args.out) else ", ".join(map(str, outs))
    return f"baked {', '.join(o.name for o in objects)} frames {start}-{end} to {where} ({threads} thread{'s' if threads > 1 else ''})"


def _dq_skin_with_method(obj, method: str):
    """The object's first DQ Skin modifier, added from its Armature modifier if it has none, set
    to `method` (AUTO: as it is, or from the Armature modifier's Preserve Volume) in the loaded
    file only: the batch commands never save the file they read."""
    if not dq_skin_modifiers(obj):
        _add_dq_skin(obj, method)
        return dq_skin_modifiers(obj)[0]
    mod = dq_skin_modifiers(obj)[0]
    if method != "AUTO" and nodes.get_method(mod) != BY_NAME[method].label:
        if not nodes.put_method(mod, BY_NAME[method].label):
            raise RuntimeError(f"its DQ Skin modifier cannot be set to {BY_NAME[method].label}")
        bpy.context.view_layer.update()
    return mod


def cmd_apply(args) -> str:
    _load(args.file)
    objects = _skinned()
    if not objects:
        raise Failure(f"{args.file}: no object has an Armature modifier")
    for obj in objects:
        _check_rigged(obj)
    with Progress(bpy.context, len(objects) + 1, f"Adding DQ Skin to {len(objects)} object(s)") as progress:
        for obj in objects:
            check()
            try:
                with deferred():
                    _add_dq_skin(obj, args.method)
            except (RuntimeError, ValueError) as e:
                raise Failure(f"{obj.name}: DQ Skin cannot be added ({_last_line(e)})") from None
            progress.step()
        _save(Path(args.out).resolve())
        progress.step()
    return f"replaced {len(objects)} Armature modifier(s) with DQ Skin in {Path(args.out).resolve()}"


def _save(out: Path) -> None:
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = outputs.temporary(out)
        try:
            check()
            with deferred():
                bpy.ops.wm.save_as_mainfile(filepath=str(tmp), copy=True)
            check()
            os.replace(tmp, out)
        finally:
            if tmp.exists():
                tmp.unlink()
    except (RuntimeError, OSError) as e:
        raise Failure(f"{out}: cannot be written ({_last_line(e)})") from None


def cmd_merge(args) -> str:
    try:
        header = pc2.merge([Path(p) for p in args.inputs], Path(args.out))
    except (pc2.PC2Error, OSError) as e:
        raise Failure(_last_line(e)) from None
    return f"merged {len(args.inputs)} caches into {args.out}: frames {header.start_frame:g}-{header.end_frame:g}"


def cmd_preflight(args) -> str:
    _load(args.file)
    return preflight.run(args.file)


def cmd_compare(args) -> str:
    if args.file:
        _load(args.file)
        sources = _skinned()[:1]
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
    with deferred():
        _, rows = compare.build(bpy.context, sources)
        result = compare.report(bpy.context, scene, rows, list(range(start, end + 1)), check=check)
    check()
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise Failure(f"{out}: cannot be written ({_last_line(e)})") from None
    pictures = {}
    if not args.no_render:
        with deferred():
            scene.frame_set(end)
        check()
        views = (
            ("comparison.png", f"the variants at frame {end}", compare.render, (scene,)),
            ("deviation.png", f"distance from Armature Linear at frame {end}", compare.render_deviation, (bpy.context, scene, rows)),
        )
        for filename, caption, draw, first_args in views:
            tmp = outputs.temporary(out / filename).with_suffix(".png")
            try:
                check()
                print(f"rendering {filename} ({args.samples} samples)", file=sys.stderr, flush=True)
                with deferred():
                    draw(*first_args, tmp, width=args.width, height=args.height, samples=args.samples)
                check()
                os.replace(tmp, out / filename)
            except (RuntimeError, OSError) as e:
                raise Failure(f"{out}: cannot write {filename} ({_last_line(e)})") from None
            finally:
                if tmp.exists():
                    tmp.unlink()
            pictures[caption] = filename
    try:
        compare.write_report(result, out, name, [start, end], pictures)
    except OSError as e:
        raise Failure(f"{out}: cannot write the report ({_last_line(e)})") from None
    return f"compared {name} over frames {start}-{end}: {out / 'report.md'}"


def parser(prog: str) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description=__doc__.splitlines()[0])
    p.add_argument("--user-resources", help=f"Blender user folder with DQ Skin installed (sets BLENDER_USER_RESOURCES; `{LAUNCHER}` only)")
    p.add_argument(
        "--threads",
        type=_whole_number(1, THREADS),
        metavar="N",
        help="threads of DQ Skin's pool (default: Blender's -t N, else DQSKIN_NUM_THREADS, else one per core)",
    )
    sub = p.add_subparsers(dest="command", required=True)
    # --threads after the command too (there it does not reset a value given before it).
    threads_after = argparse.ArgumentParser(add_help=False)
    threads_after.add_argument(
        "--threads", type=_whole_number(1, THREADS), metavar="N", default=argparse.SUPPRESS, help="as before the command"
    )
    frames = {"type": _frame_range, "metavar": "A-B", "help": "first and last frame (default: the scene's)"}
    b = sub.add_parser("bake", parents=[threads_after], help="bake DQ Skin to a PC2 cache")
    b.add_argument("file")
    b.add_argument(
        "--object",
        required=True,
        action="append",
        metavar="NAME",
        help="the mesh to bake; repeat it for several (then --out is a FOLDER/ or has {object} in it)",
    )
    b.add_argument("--frames", **frames)
    b.add_argument("--method", choices=METHODS, default="AUTO")
    b.add_argument("--out", required=True, help="FILE.pc2, FOLDER/ (one NAME.pc2 per object) or a pattern with {object}")
    b.set_defaults(run=cmd_bake)
    p.bake_parser = b
    a = sub.add_parser("apply", parents=[threads_after], help="replace Armature modifiers with DQ Skin and save")
    a.add_argument("file")
    a.add_argument("--method", choices=METHODS, default="AUTO")
    a.add_argument("--out", required=True)
    a.set_defaults(run=cmd_apply)
    m = sub.add_parser("merge", parents=[threads_after], help="join PC2 chunks")
    m.add_argument("out")
    m.add_argument("inputs", nargs="+")
    m.set_defaults(run=cmd_merge)
    f = sub.add_parser(
        "preflight", parents=[threads_after], help="name the objects that would render differently without the extension (exit code 3)"
    )
    f.add_argument("file")
    f.set_defaults(run=cmd_preflight)
    c = sub.add_parser("compare", parents=[threads_after], help="a comparison scene, its report and a render")
    c.add_argument("file", nargs="?", help="a rigged file (default: the built-in test rigs)")
    c.add_argument("--frames", **frames)
    c.add_argument("--out", default="out")
    c.add_argument("--no-render", action="store_true", help="skip the PNG")
    size = _whole_number(*PICTURE_SIZE)
    c.add_argument("--width", type=size, default=1600, help="picture width in pixels (default 1600)")
    c.add_argument("--height", type=size, help="picture height (default: from the comparison's shape)")
    c.add_argument("--samples", type=_whole_number(*SAMPLES), default=8, help="render samples (default 8)")
    c.set_defaults(run=cmd_compare)
    return p


def _use_blender_threads(threads: int) -> None:
    """Blender's `-t N` for DQ Skin's pool too, at most DQ Skin's own limit (4 per core, at
    least 16); if the system refuses, the pool keeps its default size."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # macOS and Windows have no sched_getaffinity
        cores = os.cpu_count() or 1
    try:
        dqskin.set_num_threads(min(threads, max(16, min(1024, 4 * cores))))
    except ValueError:
        pass


def main(argv: list[str], prog: str, launched: bool = False, threads: int | None = None) -> int:
    """Runs one command; returns its exit code. `launched`: from `python -m dqskin.blender`, which
    has applied `--user-resources` before importing bpy (inside Blender it cannot be changed).
    `threads`: Blender's own `-t N` (`--threads N` of the command line goes first)."""
    interrupts.watch()
    try:
        p = parser(prog)
        args = p.parse_args(argv)
        if args.command == "bake" and len(set(args.object)) > 1 and not outputs.is_pattern_or_folder(args.out):
            p.bake_parser.error(f"argument --out: several objects need a folder (ending with /) or a pattern with {outputs.OBJECT_FIELD}")
        if args.threads:
            try:
                dqskin.set_num_threads(args.threads)
            except ValueError as e:
                p.error(f"argument --threads: {e}")
        elif threads:
            _use_blender_threads(threads)
    except SystemExit as e:  # --help, or a usage error (printed): argparse's own exit code
        return int(e.code or 0)
    try:
        if args.user_resources and not launched:
            raise Failure(f"--user-resources is for `{LAUNCHER}`; Blender has its user folder already")
        print(args.run(args))
        return 0
    except preflight.Differs as e:
        print(e)
        return preflight.DIFFERS
    except interrupts.Interrupted as e:
        print(f"{prog} {args.command}: interrupted ({e}); nothing written", file=sys.stderr)
        return 128 + e.signum
    except Failure as e:
        print(f"{prog} {args.command}: {e}", file=sys.stderr)
        return 1
    except Exception as e:  # a bug: one line, the traceback on request
        if os.environ.get("DQSKIN_DEBUG"):
            traceback.print_exc()
        print(f"{prog} {args.command}: {type(e).__name__}: {_last_line(e)} (DQSKIN_DEBUG=1 shows where)", file=sys.stderr)
        return 1

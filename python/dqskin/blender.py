"""Batch command line for Blender files: ``python -m dqskin.blender COMMAND ...``.

Works with the ``bpy`` module and inside Blender, where the installed extension registers the
same commands with Blender's own command line: ``blender -b --command dq_skin COMMAND ...``
(Blender 4.2+; the extension bundles this file). With the ``bpy`` module the DQ Skin extension
must be installed in the Blender user folder named by ``BLENDER_USER_RESOURCES`` (or
``--user-resources``), as ``make setup`` does into ``.blender_user/``.

Commands:
- ``bake FILE --object NAME [--frames A-B] [--method M] --out FILE.pc2``: bake the object's DQ
  Skin result (added from its Armature modifier if missing) to a PC2 cache.
- ``apply FILE --out FILE.blend``: replace every Armature modifier with DQ Skin and save.
- ``merge OUT IN [IN ...]``: join PC2 chunks of consecutive frame ranges (farm bakes).
- ``compare [FILE] [--frames A-B] [--out DIR]``: a comparison scene (the file's first rigged
  mesh, or built-in test rigs) with the Armature modifier (Linear, Preserve Volume) and DQ Skin
  (Linear, Dual Quaternion, Blend, Optimized Centers) side by side: ``report.json`` and ``report.md`` (deviations
  from each built-in method, volume relative to rest, per-frame time), ``comparison.png`` (the
  variants, labelled) and ``deviation.png`` (each variant coloured by its distance from
  Armature Linear, with a legend).

On failure the exit code is 1 with a one-line reason (``DQSKIN_DEBUG=1`` adds the traceback),
and no output file is written: all outputs go to a temporary file ``.NAME.dqskin-PID.tmp`` that
is renamed into place. Ctrl-C (SIGINT) and SIGTERM stop any command between two frames (a
Cycles render in progress finishes its image first), remove the temporary files, leave existing
outputs untouched and exit with 130 and 143. SIGKILL cannot be caught: the next run writing the
same output removes the temporaries of processes that no longer run.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import traceback
from pathlib import Path

EXTENSION = "bl_ext.user_default.dq_skin"


def _embedded_in() -> str | None:
    """The extension's package when this file runs from inside it (bundled as
    `<extension>.dqskin.blender`: `blender --command dq_skin`), else None."""
    parts = __name__.split(".")
    return ".".join(parts[:-2]) if len(parts) > 2 and parts[-2:] == ["dqskin", "blender"] else None


def _addon(module: str):
    """A module of the DQ Skin extension (`modifier`, `bake`, ...), wherever it is installed."""
    return importlib.import_module(f"{_embedded_in() or EXTENSION}.{module}")


class Failure(Exception):
    """A one-line reason to stop with a non-zero exit code."""


class Interrupted(BaseException):
    """Ctrl-C or SIGTERM: stop now (a BaseException, so no `except Exception` swallows it)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


_signalled: list[int] = []
_deferred = [0]


def _on_signal(signum, _frame):
    _signalled.append(signum)
    if not _deferred[0]:
        raise Interrupted(signum)


class deferred:
    """While Blender runs Python callbacks (frame handlers), a signal is only recorded: raised
    there, Blender would print it as a handler error and go on. `check()` raises it after."""

    def __enter__(self):
        _deferred[0] += 1

    def __exit__(self, *exc):
        _deferred[0] -= 1


def watch_signals() -> None:
    """Ctrl-C and SIGTERM raise `Interrupted` (Blender's own handlers would ignore them)."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _on_signal)


def check() -> None:
    """Raises `Interrupted` if a signal came while Blender was running Python handlers (which
    print exceptions instead of raising them)."""
    if _signalled:
        raise Interrupted(_signalled[0])


def _temporary(path: Path) -> Path:
    from . import pc2

    pc2.remove_stale_temporaries(path)
    return pc2.temporary_path(path)


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
    embedded = _embedded_in()
    if not embedded and user_resources:
        os.environ["BLENDER_USER_RESOURCES"] = str(Path(user_resources).resolve())
    import bpy  # noqa: F401  (after BLENDER_USER_RESOURCES; inside Blender, already loaded)
    import addon_utils

    watch_signals()  # again: importing bpy installs Blender's handlers
    # Inside Blender the extension this runs from is loaded already.
    if not embedded and addon_utils.enable(EXTENSION, default_set=True) is None:
        raise Failure(
            f"the DQ Skin extension is not installed in {os.environ.get('BLENDER_USER_RESOURCES', 'the default user folder')}"
        )
    # A long precompute (Optimized Centers) stops at Ctrl-C instead of finishing first.
    _addon("centers").interrupted = lambda: bool(_signalled)
    return bpy


def _load(bpy, path: str) -> None:
    p = Path(path)
    if not p.is_file():
        raise Failure(f"{path}: no such file")
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
    watch_signals()


def _last_line(e: BaseException) -> str:
    lines = [line.strip() for line in str(e).strip().splitlines() if line.strip()]
    return lines[-1] if lines else type(e).__name__


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
    modifier = _addon("modifier")
    if not modifier.dq_skin_modifiers(obj):
        if not any(m.type == "ARMATURE" for m in obj.modifiers):
            raise Failure(f"{obj.name} has neither a DQ Skin nor an Armature modifier")
        _add_dq_skin(bpy, obj, args.method)
    start, end = _frames(args.frames, bpy.context.scene)
    bake = _addon("bake")
    mod = modifier.dq_skin_modifiers(obj)[0]
    out = Path(args.out).resolve()
    try:
        with deferred():
            bake.bake(bpy.context, obj, mod, out, start, end, check=check)
    except (RuntimeError, ValueError, OSError) as e:
        raise Failure(_last_line(e)) from None
    bake.add_cache_modifier(obj, mod, out, start)
    return f"baked {obj.name} frames {start}-{end} to {args.out}"


def cmd_apply(args) -> str:
    bpy = _bpy(args.user_resources)
    _load(bpy, args.file)
    objects = _skinned(bpy)
    if not objects:
        raise Failure(f"{args.file}: no object has an Armature modifier")
    with _addon("progress").Progress(bpy.context, len(objects) + 1, f"Adding DQ Skin to {len(objects)} object(s)") as progress:
        for obj in objects:
            check()
            with deferred():
                _add_dq_skin(bpy, obj, args.method)
            progress.step()
        _save(bpy, Path(args.out).resolve())
        progress.step()
    return f"replaced {len(objects)} Armature modifier(s) with DQ Skin in {Path(args.out).resolve()}"


def _save(bpy, out: Path) -> None:
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = _temporary(out)
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
    from . import pc2

    try:
        header = pc2.merge([Path(p) for p in args.inputs], Path(args.out))
    except (pc2.PC2Error, OSError) as e:
        raise Failure(_last_line(e)) from None
    return f"merged {len(args.inputs)} caches into {args.out}: frames {header.start_frame:g}-{header.end_frame:g}"


def cmd_compare(args) -> str:
    bpy = _bpy(args.user_resources)
    compare = _addon("compare")

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
            tmp = _temporary(out / filename).with_suffix(".png")
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


def parser(prog: str = "python -m dqskin.blender") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description=__doc__.splitlines()[0])
    p.add_argument("--user-resources", help="Blender user folder with DQ Skin installed (sets BLENDER_USER_RESOURCES)")
    sub = p.add_subparsers(dest="command", required=True)
    methods = ["AUTO", "LINEAR", "DUAL_QUATERNION", "BLEND", "CENTERS"]
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
    c.add_argument("--width", type=int, default=1600, help="picture width in pixels (default 1600)")
    c.add_argument("--height", type=int, help="picture height (default: from the comparison's shape)")
    c.add_argument("--samples", type=int, default=8)
    c.set_defaults(run=cmd_compare)
    return p


def main(argv: list[str] | None = None, prog: str = "python -m dqskin.blender") -> int:
    if argv is None:
        argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    watch_signals()
    try:
        args = parser(prog).parse_args(argv)
    except SystemExit as e:  # --help, or a usage error (printed): argparse's own exit code
        return int(e.code or 0)
    try:
        if _embedded_in() and args.user_resources:
            raise Failure("--user-resources is for `python -m dqskin.blender`; Blender has its user folder already")
        print(args.run(args))
        return 0
    except Interrupted as e:
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


if __name__ == "__main__":
    raise SystemExit(main())

# SPDX-License-Identifier: GPL-3.0-or-later
"""Where the batch commands write: each baked object's cache (`--out` as a file, a folder or a
pattern with ``{object}``), and the temporaries outputs go through before they are renamed into
place (see `batch`)."""

from __future__ import annotations

import os
import re
from pathlib import Path

from ..dqskin import pc2
from .errors import Failure


def temporary(path: Path) -> Path:
    pc2.remove_stale_temporaries(path)
    return pc2.temporary_path(path)


# Characters no file name may hold on some system: an object's name becomes `_` for each.
_UNSAFE = re.compile(r'[\\/:*?"<>|\x00-\x1f]')
OBJECT_FIELD = "{object}"


def file_name(name: str) -> str:
    return _UNSAFE.sub("_", name)


def is_pattern_or_folder(out: str) -> bool:
    return OBJECT_FIELD in out or out.endswith(("/", os.sep)) or Path(out).is_dir()


def outputs(args, objects) -> list[Path]:
    """Each object's cache: `--out` with `{object}` replaced by its name, or FOLDER/NAME.pc2, or
    (one object) `--out` itself. Two objects never share a file, and no cache is the input."""
    if OBJECT_FIELD in args.out:
        outs = [Path(args.out.replace(OBJECT_FIELD, file_name(o.name))).resolve() for o in objects]
    elif is_pattern_or_folder(args.out):
        outs = [(Path(args.out) / f"{file_name(o.name)}.pc2").resolve() for o in objects]
    else:
        outs = [Path(args.out).resolve()]
    seen: dict[Path, str] = {}
    for obj, out in zip(objects, outs, strict=True):
        if out in seen:
            raise Failure(f"{seen[out]!r} and {obj.name!r} would both be baked to {out}: use {OBJECT_FIELD} in --out")
        if out.exists() and out.samefile(args.file):
            raise Failure(f"{out}: that is the input file; a cache needs a file of its own")
        if out.is_dir():
            raise Failure(f"{out}: is a folder (end --out with / to bake into a folder)")
        seen[out] = obj.name
    return outs


def staging(out: Path) -> Path:
    """Where one of several caches is baked before it is renamed to `out`: its temporary path,
    which the bake writes through a temporary of its own (``..NAME.dqskin-PID.tmp.dqskin-PID.tmp``).
    Both kinds left by processes that no longer run (SIGKILL) are removed first."""
    stale = re.compile(rf"\.\.{re.escape(out.name)}\.dqskin-\d+\.tmp\.dqskin-(\d+)\.tmp")
    try:
        entries = list(out.parent.iterdir())
    except OSError:
        entries = []
    for p in entries:
        m = stale.fullmatch(p.name)
        if m and not pc2._alive(int(m[1])):
            p.unlink(missing_ok=True)
    return temporary(out)

"""Makes a folder of DQ Skin extension zips an extension repository: the `index.json` (and a
browsable `index.html`) that Blender's own `extension server-generate` writes for the zips it
finds there. Blender adds the repository by the address of that `index.json` (an https:// or a
file:// URL) and installs and upgrades DQ Skin from it.

Only one version may be in the folder, one zip per platform (Blender lists every zip it finds,
and two versions of one platform would offer both). The index must list exactly the zips present.
Usage: python addon/repository.py [DIR] (default: dist)
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

from build import ROOT, blender_ext

ZIP_NAME = re.compile(r"^dq_skin-(?P<version>[^-]+)-(?P<platform>[a-z0-9_]+)\.zip$")


def check_zips(folder: Path) -> list[Path]:
    """The folder's extension zips, after checking they are one version, one per platform."""
    zips = sorted(folder.glob("*.zip"))
    if not zips:
        raise SystemExit(f"{folder}: no extension zip (run make addon or make platforms first)")
    versions = {}
    for z in zips:
        m = ZIP_NAME.match(z.name)
        if m is None:
            raise SystemExit(f"{z}: not a DQ Skin extension zip name (dq_skin-VERSION-PLATFORM.zip)")
        versions.setdefault(m["version"], []).append(z.name)
    if len(versions) > 1:
        raise SystemExit(f"{folder}: zips of several versions {sorted(versions)}; a repository offers one: remove the old ones")
    return zips


def generate(folder: Path) -> Path:
    """Writes `folder/index.json` (and `index.html`) with Blender's tool; returns the index."""
    zips = check_zips(folder)
    subprocess.run(
        [sys.executable, str(blender_ext()), "server-generate", "--repo-dir", str(folder), "--html"],
        check=True,
    )
    index = folder / "index.json"
    listed = sorted(entry["archive_url"] for entry in json.loads(index.read_text())["data"])
    wanted = sorted(f"./{z.name}" for z in zips)
    if listed != wanted:
        raise SystemExit(f"{index} lists {listed}, but the folder has {wanted} (a zip Blender's validator refused?)")
    return index


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, nargs="?", default=ROOT / "dist")
    args = parser.parse_args()
    index = generate(args.folder.resolve())
    print(f"{index}: {len(json.loads(index.read_text())['data'])} zip(s); add it in Blender as {index.as_uri()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Builds the DQ Skin extension zips with Blender's own builder, one per platform, from the
compiled `dqskin` wheels given on the command line.

Each wheel is the file a release uploads to PyPI (`dqskin-VERSION-cp311-abi3-TAG.whl`), bundled
unmodified, as the extension platform asks: it must be one that `blender_manifest.toml` lists
under `wheels`, its compiled module must pass addon/native_check.py (glibc, DLL imports and
exports, linked libraries, minimum macOS) for the platform its tag names, and it is copied byte
for byte to OUT/ beside the zips. The staged manifest keeps only the given wheels and their
platforms; `blender_ext.py build --split-platforms` then writes `dq_skin-VERSION-PLATFORM.zip`
for each, and `blender_ext.py validate` checks every zip.
Usage: python addon/build.py WHEEL [WHEEL ...] [--out dist] [--version X.Y.Z]
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
import zipfile
from pathlib import Path

import native_check

ROOT = Path(__file__).resolve().parent.parent
SOURCE = ROOT / "addon" / "dq_skin"
MANIFEST = SOURCE / "blender_manifest.toml"
# A wheel tag names one Blender platform: manylinux2014 (Linux x86-64), win_amd64, macOS arm64/x86-64.
WHEEL_NAME = re.compile(r"^dqskin-(?P<version>[^-]+)-cp311-abi3-(?P<tag>[A-Za-z0-9_.]+)\.whl$")


def blender_ext() -> Path:
    """Blender's extension command line tool, shipped in the bpy wheel."""
    import importlib.util

    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        raise SystemExit("the bpy wheel is not installed (run make setup)")
    found = sorted(Path(spec.origin).parent.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not found:
        raise SystemExit("blender_ext.py not found in the bpy wheel")
    return found[-1]


def platform_of_tag(tag: str) -> str:
    """The Blender platform of a wheel platform tag (`manylinux_2_17_x86_64.manylinux2014_x86_64`
    -> `linux-x64`)."""
    if "manylinux" in tag and tag.endswith("x86_64"):
        return "linux-x64"
    if tag.startswith("macosx_"):
        return "macos-arm64" if tag.endswith("_arm64") else "macos-x64" if tag.endswith("_x86_64") else ""
    return "windows-x64" if tag == "win_amd64" else ""


def check_wheel(wheel: Path, listed: list[str]) -> str:
    """The wheel's Blender platform, after checking its name, the manifest and its module."""
    m = WHEEL_NAME.match(wheel.name)
    if m is None:
        raise SystemExit(f"{wheel.name}: not a dqskin cp311-abi3 wheel name")
    platform = platform_of_tag(m["tag"])
    if not platform:
        raise SystemExit(f"{wheel.name}: tag {m['tag']} is no platform Blender ships for")
    if f"./wheels/{wheel.name}" not in listed:
        raise SystemExit(f"{wheel.name} is not listed under `wheels` in {MANIFEST.relative_to(ROOT)} (listed: {listed})")
    with zipfile.ZipFile(wheel) as z, tempfile.TemporaryDirectory() as tmp:
        modules = [n for n in z.namelist() if re.fullmatch(r"dqskin/_dqskin\.[^/]*(so|pyd)", n)]
        if len(modules) != 1:
            raise SystemExit(f"{wheel.name} has {len(modules)} compiled dqskin modules, expected one")
        module = Path(tmp) / Path(modules[0]).name
        module.write_bytes(z.read(modules[0]))
        limit = min(native_check.BLENDER_GLIBC, native_check.glibc_of_tag(m["tag"]) or native_check.BLENDER_GLIBC)
        try:
            report = native_check.check(module, glibc_limit=limit)
        except native_check.NativeError as e:
            raise SystemExit(f"error: {wheel.name}: {e}") from None
    if report.platform != platform:
        raise SystemExit(f"{wheel.name} is tagged {platform} but its module is built for {report.platform}")
    print(f"{wheel.name}: {report.summary}")
    return platform


def stage(wheels: list[Path], into: Path, version: str | None = None) -> dict[str, Path]:
    """The add-on with the given wheels under wheels/ and a manifest naming exactly them and their
    platforms (and `version` instead of the manifest's, if given); returns platform -> wheel."""
    manifest = tomllib.loads(MANIFEST.read_text())
    chosen: dict[str, Path] = {}
    for wheel in wheels:
        platform = check_wheel(wheel, manifest["wheels"])
        if platform in chosen:
            raise SystemExit(f"two wheels for {platform}: {chosen[platform].name}, {wheel.name}")
        chosen[platform] = wheel
    shutil.copytree(SOURCE, into, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    (into / "wheels").mkdir()
    for wheel in chosen.values():
        shutil.copyfile(wheel, into / "wheels" / wheel.name)
    names = {f"./wheels/{w.name}" for w in chosen.values()}
    lines = []
    for line in MANIFEST.read_text().splitlines():
        if line.startswith("platforms"):
            line = "platforms = [" + ", ".join(f'"{p}"' for p in manifest["platforms"] if p in chosen) + "]"
        elif line.startswith("version") and version is not None:
            line = f'version = "{version}"'
        elif line.startswith('  "./wheels/') and line.strip().strip(",").strip('"') not in names:
            continue
        lines.append(line)
    (into / "blender_manifest.toml").write_text("\n".join(lines) + "\n")
    staged = tomllib.loads((into / "blender_manifest.toml").read_text())
    assert sorted(staged["wheels"]) == sorted(names) and sorted(staged["platforms"]) == sorted(chosen), staged
    return chosen


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("wheels", type=Path, nargs="+")
    parser.add_argument("--out", type=Path, default=ROOT / "dist")
    # An update's zip (the extension repository's upgrade test): the extension's version only;
    # the bundled wheels stay the files they are.
    parser.add_argument("--version", help="the extension version to write (default: the manifest's)")
    args = parser.parse_args()
    tool = blender_ext()
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        staged = Path(tmp) / "dq_skin"
        chosen = stage(args.wheels, staged, args.version)
        version = tomllib.loads((staged / "blender_manifest.toml").read_text())["version"]
        for platform, wheel in chosen.items():
            for old in args.out.glob(f"dq_skin-*-{platform.replace('-', '_')}.zip"):
                old.unlink()
            if wheel.resolve() != (args.out / wheel.name).resolve():
                shutil.copyfile(wheel, args.out / wheel.name)
        subprocess.run(
            [sys.executable, str(tool), "build", "--split-platforms", "--source-dir", str(staged), "--output-dir", str(args.out)],
            check=True,
        )
    for platform in chosen:
        target = args.out / f"dq_skin-{version}-{platform.replace('-', '_')}.zip"
        subprocess.run([sys.executable, str(tool), "validate", str(target)], check=True)
        print(target)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Builds the installable DQ Skin extension zip for one platform and validates it with Blender's tool.

The compiled `dqskin` package (from the maturin wheel given on the command line) is bundled as a
sub-package, `dq_skin.dqskin`, so it cannot collide with anything in Blender's shared wheel
folder. The compiled module is checked first (addon/native_check.py: glibc, DLL imports, linked
libraries), and the zip's manifest lists exactly the platform it was built for:
`dq_skin-VERSION-PLATFORM.zip`, as Blender names split-platform packages.
Usage: python addon/build.py WHEEL [--out dist]
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import native_check

ROOT = Path(__file__).resolve().parent.parent
SOURCE = ROOT / "addon" / "dq_skin"
# What of the wheel's `dqskin/` package goes into the extension.
BUNDLED = ("__init__.py", "_dqskin.pyi", "py.typed", "pc2.py", "blender.py")


def blender_ext() -> Path:
    """Blender's extension command line tool, shipped in the bpy wheel."""
    import importlib.util

    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        raise SystemExit("the bpy wheel is not installed (run make setup)")
    base = Path(spec.origin).parent
    found = sorted(base.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not found:
        raise SystemExit("blender_ext.py not found in the bpy wheel")
    return found[-1]


def platform_of(wheel: Path) -> str:
    tag = wheel.name.rsplit("-", 1)[-1].removesuffix(".whl")
    if "linux" in tag and "x86_64" in tag:
        return "linux-x64"
    if "macosx" in tag:
        return "macos-arm64" if "arm64" in tag else "macos-x64"
    if "win_amd64" in tag:
        return "windows-x64"
    raise SystemExit(f"cannot tell the Blender platform of {wheel.name}")


def stage(wheel: Path, into: Path) -> str:
    """Copies the add-on and the wheel's module into `into`; returns the platform, checked."""
    shutil.copytree(SOURCE, into, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    native = into / "dqskin"
    native.mkdir()
    with zipfile.ZipFile(wheel) as z:
        for name in z.namelist():
            parts = name.split("/")
            if len(parts) == 2 and parts[0] == "dqskin" and (parts[1] in BUNDLED or parts[1].startswith("_dqskin.")):
                (native / parts[1]).write_bytes(z.read(name))
    modules = [*native.glob("_dqskin.*.so"), *native.glob("_dqskin*.pyd")]
    if len(modules) != 1:
        raise SystemExit(f"{wheel} has {len(modules)} compiled dqskin modules, expected one")
    platform = platform_of(wheel)
    tag = wheel.name.rsplit("-", 1)[-1].removesuffix(".whl")
    limit = min(native_check.BLENDER_GLIBC, native_check.glibc_of_tag(tag) or native_check.BLENDER_GLIBC)
    try:
        report = native_check.check(modules[0], glibc_limit=limit)
    except native_check.NativeError as e:
        raise SystemExit(f"error: {e}") from None
    if report.platform != platform:
        raise SystemExit(f"{wheel.name} is tagged {platform} but its module is built for {report.platform}")
    print(f"{modules[0].name}: {report.summary}")
    manifest = into / "blender_manifest.toml"
    text = manifest.read_text()
    lines = [f'platforms = ["{platform_of(wheel)}"]' if line.startswith("platforms") else line for line in text.splitlines()]
    manifest.write_text("\n".join(lines) + "\n")
    return platform


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("wheel", type=Path)
    parser.add_argument("--out", type=Path, default=ROOT / "dist")
    args = parser.parse_args()
    tool = blender_ext()
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        staged = Path(tmp) / "dq_skin"
        platform = stage(args.wheel, staged)
        version = next(line.split('"')[1] for line in (staged / "blender_manifest.toml").read_text().splitlines()
                       if line.startswith("version"))
        target = args.out / f"dq_skin-{version}-{platform.replace('-', '_')}.zip"
        for old in args.out.glob(f"dq_skin-*-{platform.replace('-', '_')}.zip"):
            old.unlink()
        subprocess.run(
            [sys.executable, str(tool), "build", "--source-dir", str(staged), "--output-filepath", str(target)],
            check=True,
        )
    subprocess.run([sys.executable, str(tool), "validate", str(target)], check=True)
    print(target)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

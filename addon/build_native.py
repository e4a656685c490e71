"""Builds the compiled dqskin wheel for one Blender platform: the file a release uploads to PyPI.

From Linux every platform links through zig (the `ziglang` package, pinned in
requirements-dev.txt), so no other toolchain is needed:
- linux-x64: manylinux2014 (glibc 2.17), older than Blender's own manylinux_2_28, so the module
  loads wherever Blender does (a plain build would need this machine's glibc);
- windows-x64: Rust's GNU target, linked by zig against its MinGW-w64 UCRT runtime, with an
  import library for python3.dll (the stable ABI);
- macos-arm64, macos-x64: zig's macOS linker (the module looks Python up in the process).
The Rust standard library of a cross target comes from `rustup target add`. On a Windows or
macOS machine (the hosted runners of .github/workflows/platforms.yml) its own platform is built
natively, with the system's linker.

Usage: python addon/build_native.py PLATFORM --out DIR
"""

from __future__ import annotations

import argparse
import os
import platform as host
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ZIG_WRAPPERS = ROOT / "addon" / "zig"
TARGETS = {
    "linux-x64": "x86_64-unknown-linux-gnu",
    "windows-x64": "x86_64-pc-windows-gnu",
    "macos-arm64": "aarch64-apple-darwin",
    "macos-x64": "x86_64-apple-darwin",
}


def native_platform() -> str:
    """This machine's Blender platform name (linux-x64, windows-x64, macos-arm64, macos-x64)."""
    system = {"Linux": "linux", "Windows": "windows", "Darwin": "macos"}.get(host.system(), host.system().lower())
    machine = {"x86_64": "x64", "amd64": "x64", "arm64": "arm64", "aarch64": "arm64"}.get(host.machine().lower(), host.machine())
    return f"{system}-{machine}"


def ensure_target(triple: str) -> None:
    installed = subprocess.run(["rustup", "target", "list", "--installed"], capture_output=True, text=True, check=True)
    if triple not in installed.stdout.split():
        subprocess.run(["rustup", "target", "add", triple], check=True)


def build(platform: str, out: Path) -> Path:
    native = platform == native_platform() and platform != "linux-x64"
    # On Windows itself: the MSVC target, its C runtime linked in (no VCRUNTIME140.dll to import).
    triple = "x86_64-pc-windows-msvc" if native and platform == "windows-x64" else TARGETS[platform]
    ensure_target(triple)
    maturin = shutil.which("maturin", path=str(Path(sys.executable).parent)) or "maturin"
    command = [maturin, "build", "--release", "--quiet", "--target", triple, "--out", str(out)]
    env = dict(os.environ, VIRTUAL_ENV=str(Path(sys.executable).parent.parent))
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    if native:
        if platform == "windows-x64":
            env["RUSTFLAGS"] = f"{env.get('RUSTFLAGS', '')} -C target-feature=+crt-static".strip()
    elif platform == "windows-x64":
        # maturin's own zig mode writes a wrong export for a dotted module name (dqskin._dqskin);
        # zig as a plain linker with these wrappers gets it right.
        env["DQSKIN_ZIG_PYTHON"] = sys.executable
        env["PATH"] = f"{ZIG_WRAPPERS}{os.pathsep}{env['PATH']}"
        env["CARGO_TARGET_X86_64_PC_WINDOWS_GNU_LINKER"] = str(ZIG_WRAPPERS / "windows-gnu-cc")
    else:
        command.append("--zig")
        if platform == "linux-x64":
            command += ["--compatibility", "manylinux2014"]
    for old in out.glob("dqskin-*.whl"):
        old.unlink()
    subprocess.run(command, cwd=ROOT, env=env, check=True)
    wheels = sorted(out.glob("dqskin-*.whl"))
    if len(wheels) != 1:
        raise SystemExit(f"expected one wheel in {out}, found {wheels}")
    return wheels[0]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("platform", choices=sorted(TARGETS))
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    print(build(args.platform, args.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

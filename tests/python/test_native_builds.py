"""The extension zips: each carries one compiled module for exactly the platform its manifest names,
and that module loads where Blender runs (glibc no newer than Blender's, only system DLLs or
libraries). `make addon` builds the Linux zip (which the Blender tests install and use);
`make platforms` builds the others into dist/unverified/ (CI runs both)."""

from __future__ import annotations

import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "addon"))
import native_check  # noqa: E402

LINUX_ZIPS = sorted((ROOT / "dist").glob("dq_skin-*.zip"))
OTHER_ZIPS = sorted((ROOT / "dist" / "unverified").glob("dq_skin-*.zip"))


def module_of(zip_path: Path, into: Path) -> tuple[Path, list[str]]:
    with zipfile.ZipFile(zip_path) as z:
        manifest = tomllib.loads(z.read("blender_manifest.toml").decode())
        names = [n for n in z.namelist() if n.startswith("dqskin/_dqskin") and n.endswith((".so", ".pyd"))]
        assert len(names) == 1, names
        target = into / Path(names[0]).name
        target.write_bytes(z.read(names[0]))
    return target, manifest["platforms"]


def test_the_linux_zip_is_built_for_every_linux_blender_runs_on(tmp_path):
    assert [z.name for z in LINUX_ZIPS] == ["dq_skin-0.1.0-linux_x64.zip"], "run make addon"
    module, platforms = module_of(LINUX_ZIPS[0], tmp_path)
    report = native_check.check(module, glibc_limit=(2, 17))  # its wheel's tag: manylinux2014
    assert platforms == ["linux-x64"] == [report.platform]


@pytest.mark.skipif(not OTHER_ZIPS, reason="no dist/unverified/ zips (make platforms builds them; CI does)")
@pytest.mark.parametrize("zip_path", OTHER_ZIPS, ids=lambda p: p.name)
def test_other_platform_zips_name_their_one_platform(zip_path, tmp_path):
    module, platforms = module_of(zip_path, tmp_path)
    report = native_check.check(module)
    assert platforms == [report.platform]
    assert zip_path.name.endswith(f"-{report.platform.replace('-', '_')}.zip")


def test_make_platforms_covers_windows_and_both_macs():
    if not OTHER_ZIPS:
        pytest.skip("make platforms has not run")
    assert {z.name.split("-")[-1] for z in OTHER_ZIPS} == {"windows_x64.zip", "macos_arm64.zip", "macos_x64.zip"}


def test_a_module_needing_a_newer_glibc_is_refused():
    # The module `maturin develop` builds links against this machine's glibc; every build of it
    # needs at least GLIBC_2.14 (memcpy), newer than manylinux1's 2.5.
    built = next((ROOT / "python" / "dqskin").glob("_dqskin*.so"))
    with pytest.raises(native_check.NativeError, match=r"needs GLIBC_2\.\d+, newer than the 2\.5"):
        native_check.check(built, glibc_limit=(2, 5))


@pytest.mark.skipif(not any("windows" in z.name for z in OTHER_ZIPS), reason="no Windows zip (make platforms)")
def test_a_windows_module_importing_a_versioned_python_dll_is_refused(tmp_path):
    windows = next(z for z in OTHER_ZIPS if "windows" in z.name)
    module, _ = module_of(windows, tmp_path)
    data = module.read_bytes()
    assert data.count(b"python3.dll") == 1
    module.write_bytes(data.replace(b"python3.dll", b"python9.dll"))
    with pytest.raises(native_check.NativeError, match="must import python3.dll"):
        native_check.check(module)


def test_glibc_of_wheel_tags():
    assert native_check.glibc_of_tag("manylinux2014_x86_64.manylinux_2_17_x86_64") == (2, 17)
    assert native_check.glibc_of_tag("manylinux_2_34_x86_64") == (2, 34)
    assert native_check.glibc_of_tag("linux_x86_64") is None
    assert native_check.glibc_of_tag("win_amd64") is None


def test_not_a_module_is_refused(tmp_path):
    junk = tmp_path / "junk.so"
    junk.write_bytes(b"#!/bin/sh\n")
    with pytest.raises(native_check.NativeError, match="not an ELF, PE or 64-bit Mach-O"):
        native_check.check(junk)

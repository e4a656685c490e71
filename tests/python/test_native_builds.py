"""The release files in dist/: the `dqskin` wheels (what a release uploads to PyPI) and the
extension zips Blender's builder makes from them, one per platform. Each zip carries exactly the
wheel of the platform it is split for, byte for byte the one in dist/, and that wheel's module
loads where Blender runs (glibc no newer than its tag and Blender's, only system DLLs or
libraries, the minimum macOS). `make addon` builds this machine's platform (which the Blender
tests install and use); `make platforms` builds all four (CI runs both)."""

from __future__ import annotations

import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "addon"))
import build  # noqa: E402
import build_native  # noqa: E402
import native_check  # noqa: E402

DIST = ROOT / "dist"
ZIPS = sorted(DIST.glob("dq_skin-*.zip"))
WHEELS = sorted(DIST.glob("dqskin-*.whl"))
MANIFEST = tomllib.loads((ROOT / "addon" / "dq_skin" / "blender_manifest.toml").read_text())
TAGS = {
    "linux-x64": "manylinux2014_x86_64",
    "windows-x64": "win_amd64",
    "macos-arm64": "macosx_11_0_arm64",
    "macos-x64": "macosx_10_12_x86_64",
}


def module_of(wheel: bytes, into: Path) -> Path:
    """The compiled module inside a wheel, written to `into`."""
    path = into / "wheel.whl"
    path.write_bytes(wheel)
    with zipfile.ZipFile(path) as z:
        names = [n for n in z.namelist() if n.startswith("dqskin/_dqskin.") and n.endswith((".so", ".pyd"))]
        assert len(names) == 1, names
        target = into / Path(names[0]).name
        target.write_bytes(z.read(names[0]))
    return target


def test_the_manifest_lists_one_pypi_wheel_per_platform():
    version = MANIFEST["version"]
    tags = {build.platform_of_tag(build.WHEEL_NAME.match(w.removeprefix("./wheels/"))["tag"]): w for w in MANIFEST["wheels"]}
    assert sorted(tags) == sorted(MANIFEST["platforms"]) == sorted(TAGS)
    for platform, wheel in tags.items():
        assert wheel.startswith(f"./wheels/dqskin-{version}-cp311-abi3-") and TAGS[platform] in wheel


def test_dist_has_the_zip_and_wheel_of_this_machine():
    assert ZIPS and WHEELS, "run make addon"
    assert all(f"./wheels/{w.name}" in MANIFEST["wheels"] for w in WHEELS)


@pytest.mark.parametrize("zip_path", ZIPS, ids=lambda p: p.name)
def test_each_zip_carries_exactly_its_platforms_wheel_as_built(zip_path, tmp_path):
    with zipfile.ZipFile(zip_path) as z:
        manifest = tomllib.loads(z.read("blender_manifest.toml").decode())
        generated = manifest["build"]["generated"]
        (platform,) = generated["platforms"]
        assert zip_path.name == f"dq_skin-{MANIFEST['version']}-{platform.replace('-', '_')}.zip"
        (wheel,) = generated["wheels"]
        assert wheel in MANIFEST["wheels"] and TAGS[platform] in wheel
        # The core comes only as the wheel: nothing of it vendored into the add-on's folder.
        assert sorted(n for n in z.namelist() if n.startswith("wheels/")) == [wheel.removeprefix("./")]
        assert not [n for n in z.namelist() if n.startswith("dqskin/") or n.endswith((".so", ".pyd"))]
        inside = z.read(wheel.removeprefix("./"))
    assert inside == (DIST / Path(wheel).name).read_bytes()
    glibc = native_check.glibc_of_tag(build.WHEEL_NAME.match(Path(wheel).name)["tag"]) or native_check.BLENDER_GLIBC
    report = native_check.check(module_of(inside, tmp_path), glibc_limit=glibc)
    assert report.platform == platform
    if platform == "linux-x64":
        assert glibc == (2, 17)


def test_make_platforms_covers_windows_and_both_macs():
    if len(ZIPS) == 1:
        pytest.skip("make platforms has not run")
    assert {z.name.rsplit("-", 1)[-1] for z in ZIPS} == {"linux_x64.zip", "windows_x64.zip", "macos_arm64.zip", "macos_x64.zip"}
    assert sorted(f"./wheels/{w.name}" for w in WHEELS) == sorted(MANIFEST["wheels"])


def test_each_zip_passes_blenders_validator():
    tool = build.blender_ext()
    for zip_path in ZIPS:
        r = subprocess.run([sys.executable, str(tool), "validate", str(zip_path)], capture_output=True, text=True, timeout=120)
        assert r.returncode == 0, r.stdout + r.stderr


def test_the_pypi_wheel_gives_the_numpy_api_without_blender(tmp_path):
    """`pip install dqskin` from the wheel in dist/: the module works with numpy alone, and nothing
    in it imports bpy (the batch commands' launcher does only when run)."""
    wheel = next(w for w in WHEELS if build.platform_of_tag(build.WHEEL_NAME.match(w.name)["tag"]) == build_native.native_platform())
    target = tmp_path / "site"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            "--no-deps",
            "--target",
            str(target),
            str(wheel),
        ],
        check=True,
        timeout=300,
    )
    code = (
        "import sys, numpy as np, dqskin, dqskin.blender, dqskin.pc2, dqskin.demo\n"
        f"assert dqskin.__file__.startswith({str(target)!r}), dqskin.__file__\n"
        "cyl = dqskin.TwistCylinder(); out = np.empty_like(cyl.positions)\n"
        "dqskin.skin(cyl.positions, cyl.influences, cyl.twist(1.0), cyl.rest, method='dual_quaternion', out=out)\n"
        "assert np.isfinite(out).all() and not np.allclose(out, cyl.positions)\n"
        "assert not [m for m in sys.modules if m == 'bpy' or m.startswith(('bpy.', 'bl_ext'))]\n"
        "print('ok')\n"
    )
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env={"PYTHONPATH": str(target), "PATH": ""}
    )
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stdout + r.stderr


def test_a_wheel_is_refused_unless_listed_and_built_for_its_tag(tmp_path):
    wheel = WHEELS[0]
    unlisted = tmp_path / wheel.name.replace("0.1.0", "9.9.9")
    unlisted.write_bytes(wheel.read_bytes())
    with pytest.raises(SystemExit, match="not listed under `wheels`"):
        build.check_wheel(unlisted, MANIFEST["wheels"])
    # A module of one platform in a wheel named for another.
    other = "win_amd64" if "win_amd64" not in wheel.name else "macosx_11_0_arm64"
    mislabelled = tmp_path / f"dqskin-{MANIFEST['version']}-cp311-abi3-{other}.whl"
    mislabelled.write_bytes(wheel.read_bytes())
    with pytest.raises(SystemExit, match="but its module is built for"):
        build.check_wheel(mislabelled, MANIFEST["wheels"])


def test_a_module_needing_a_newer_glibc_is_refused():
    # The module `maturin develop` builds links against this machine's glibc; every build of it
    # needs at least GLIBC_2.14 (memcpy), newer than manylinux1's 2.5.
    built = next(p for p in (ROOT / "python" / "dqskin").glob("_dqskin*") if p.suffix in (".so", ".pyd"))
    if built.read_bytes()[:4] != b"\x7fELF":
        pytest.skip("not a Linux build")
    with pytest.raises(native_check.NativeError, match=r"needs GLIBC_2\.\d+, newer than the 2\.5"):
        native_check.check(built, glibc_limit=(2, 5))


@pytest.mark.skipif(not any("win_amd64" in w.name for w in WHEELS), reason="no Windows wheel (make platforms)")
def test_a_windows_module_importing_a_versioned_python_dll_is_refused(tmp_path):
    windows = next(w for w in WHEELS if "win_amd64" in w.name)
    module = module_of(windows.read_bytes(), tmp_path)
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


def test_the_modules_kernels_inline_every_intrinsic():
    """No SIMD intrinsic of the module this run imports is a function of its own: one that is
    (generic code such as `Option::map_or` around vector operations is compiled without the
    kernel's instruction sets) is called with its vectors passed through memory. In the Python
    module, not in the benchmark binary, `_mm256_fmadd_ps` and `_mm256_set1_ps` once were, from
    the object and armature space transforms every Blender job has: 35 % of a Rigify frame's
    kernel time. (The development build keeps its symbols; release builds are stripped.)"""
    import shutil

    import dqskin

    nm = shutil.which("nm")
    if nm is None:
        pytest.skip("nm is not installed")
    module = Path(dqskin._dqskin.__file__)
    listing = subprocess.run([nm, "-C", str(module)], capture_output=True, text=True)
    if listing.returncode != 0 or "no symbols" in listing.stderr:
        pytest.skip(f"{module.name} has no symbol table")
    outlined = [line.split(" ", 2)[-1] for line in listing.stdout.splitlines() if "core_arch::" in line]
    outlined = [name for name in outlined if not name.endswith(("_xgetbv", "is_x86_feature_detected"))]
    assert not outlined, outlined

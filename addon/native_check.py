"""Checks a compiled dqskin module against what its platform's Blender can load.

- Linux (ELF): every versioned glibc symbol it needs is at most the wheel's manylinux tag (or
  Blender's own baseline, glibc 2.28), and it links only libraries every Linux has.
- Windows (PE): it imports only python3.dll (the stable ABI, so any CPython 3.11+ Blender ships)
  and system DLLs, and exports its PyInit function.
- macOS (Mach-O): it links only system libraries (no libpython: Blender's Python is static) and
  targets a macOS no newer than Blender's minimum.

Nothing here runs the module: it reads the file. Usage: python addon/native_check.py FILE...
"""

from __future__ import annotations

import re
import struct
import sys
from dataclasses import dataclass
from pathlib import Path

# Blender 4.2+ is built for manylinux_2_28 (Rocky 8) and macOS 11.2.
BLENDER_GLIBC = (2, 28)
BLENDER_MACOS = (11, 2)
LINUX_LIBRARIES = {"libc.so.6", "libm.so.6", "libpthread.so.0", "libdl.so.2", "librt.so.1", "libgcc_s.so.1", "ld-linux-x86-64.so.2"}
WINDOWS_SYSTEM = re.compile(r"^(kernel32|ntdll|bcryptprimitives|advapi32|userenv|ws2_32|api-ms-win-[a-z0-9-]+)\.dll$", re.I)
MACOS_SYSTEM = re.compile(r"^/usr/lib/lib[A-Za-z0-9_.+-]+\.dylib$|^/System/Library/Frameworks/")


class NativeError(Exception):
    """The module would not load (or not everywhere its tag claims)."""


@dataclass(frozen=True)
class Report:
    platform: str  # Blender's name: linux-x64, windows-x64, macos-arm64, macos-x64
    summary: str


def check(path: Path, glibc_limit: tuple[int, int] = BLENDER_GLIBC) -> Report:
    data = path.read_bytes()
    if data[:4] == b"\x7fELF":
        return _check_elf(path.name, data, glibc_limit)
    if data[:2] == b"MZ":
        return _check_pe(path.name, data)
    if data[:4] == b"\xcf\xfa\xed\xfe":
        return _check_macho(path.name, data)
    raise NativeError(f"{path.name}: not an ELF, PE or 64-bit Mach-O file")


def glibc_of_tag(tag: str) -> tuple[int, int] | None:
    """The glibc a wheel platform tag promises (manylinux2014 → 2.17), or None for other tags."""
    legacy = {"manylinux1": (2, 5), "manylinux2010": (2, 12), "manylinux2014": (2, 17)}
    best = None
    for part in tag.split("."):
        m = re.match(r"manylinux_(\d+)_(\d+)_", part)
        found = (int(m[1]), int(m[2])) if m else next((v for k, v in legacy.items() if part.startswith(k + "_")), None)
        if found and (best is None or found < best):
            best = found
    return best


# --- ELF -------------------------------------------------------------------------------------


def _check_elf(name: str, data: bytes, glibc_limit: tuple[int, int]) -> Report:
    if data[4] != 2 or data[5] != 1:
        raise NativeError(f"{name}: not a 64-bit little-endian ELF file")
    machine = struct.unpack_from("<H", data, 18)[0]
    if machine != 62:
        raise NativeError(f"{name}: ELF machine {machine} is not x86-64")
    (shoff,) = struct.unpack_from("<Q", data, 40)
    shentsize, shnum = struct.unpack_from("<HH", data, 58)
    sections = [struct.unpack_from("<IIQQQQIIQQ", data, shoff + i * shentsize) for i in range(shnum)]

    def strings(index: int) -> bytes:
        s = sections[index]
        return data[s[4] : s[4] + s[5]]

    def cstr(table: bytes, at: int) -> str:
        return table[at : table.index(b"\0", at)].decode()

    needed, versions = [], set()
    for _, kind, _, _, offset, size, link, _, _, _ in sections:
        if kind == 6:  # SHT_DYNAMIC: DT_NEEDED entries
            table = strings(link)
            for at in range(offset, offset + size, 16):
                tag, value = struct.unpack_from("<qQ", data, at)
                if tag == 1:
                    needed.append(cstr(table, value))
        elif kind == 0x6FFFFFFE:  # SHT_GNU_verneed: the symbol versions needed per library
            table = strings(link)
            at = offset
            while True:
                _, count, _, aux, nxt = struct.unpack_from("<HHIII", data, at)
                a = at + aux
                for _ in range(count):
                    _, _, _, vname, anext = struct.unpack_from("<IHHII", data, a)
                    versions.add(cstr(table, vname))
                    a += anext
                if not nxt:
                    break
                at += nxt
    glibc = sorted(tuple(int(x) for x in v[6:].split(".")[:2]) for v in versions if v.startswith("GLIBC_2."))
    newest = glibc[-1] if glibc else (0, 0)
    if newest > glibc_limit:
        raise NativeError(
            f"{name} needs GLIBC_{newest[0]}.{newest[1]}, newer than the {glibc_limit[0]}.{glibc_limit[1]} it must run on "
            "(build it with `make addon`, which links against an old glibc through zig)"
        )
    foreign = sorted(set(needed) - LINUX_LIBRARIES)
    if foreign:
        raise NativeError(f"{name} links libraries Blender's Linux machines may not have: {', '.join(foreign)}")
    return Report("linux-x64", f"ELF x86-64, newest glibc symbol {newest[0]}.{newest[1]}, links {', '.join(sorted(needed))}")


# --- PE --------------------------------------------------------------------------------------


def _check_pe(name: str, data: bytes) -> Report:
    (pe,) = struct.unpack_from("<I", data, 0x3C)
    if data[pe : pe + 4] != b"PE\0\0":
        raise NativeError(f"{name}: no PE header")
    machine, nsections, _, _, _, opt_size, _ = struct.unpack_from("<HHIIIHH", data, pe + 4)
    if machine != 0x8664:
        raise NativeError(f"{name}: PE machine {machine:#x} is not x64")
    opt = pe + 24
    if struct.unpack_from("<H", data, opt)[0] != 0x20B:
        raise NativeError(f"{name}: not a PE32+ image")
    sections = [struct.unpack_from("<8sIIII", data, opt + opt_size + i * 40) for i in range(nsections)]

    def at(rva: int) -> int:
        for _, vsize, vaddr, rawsize, rawptr in sections:
            if vaddr <= rva < vaddr + max(vsize, rawsize):
                return rawptr + rva - vaddr
        raise NativeError(f"{name}: address {rva:#x} is in no section")

    def cstr(offset: int) -> str:
        return data[offset : data.index(b"\0", offset)].decode()

    export_rva, _ = struct.unpack_from("<II", data, opt + 112)
    import_rva, _ = struct.unpack_from("<II", data, opt + 120)
    imports = []
    desc = at(import_rva)
    while True:
        lookup, _, _, name_rva, thunk = struct.unpack_from("<IIIII", data, desc)
        if not (lookup or name_rva or thunk):
            break
        imports.append(cstr(at(name_rva)))
        desc += 20
    exports = []
    if export_rva:
        count, names_rva = struct.unpack_from("<I", data, at(export_rva) + 24)[0], struct.unpack_from("<I", data, at(export_rva) + 32)[0]
        exports = [cstr(at(struct.unpack_from("<I", data, at(names_rva) + 4 * i)[0])) for i in range(count)]
    pythons = [d for d in imports if d.lower().startswith("python")]
    if pythons != ["python3.dll"]:
        raise NativeError(f"{name} must import python3.dll (the stable ABI) and no other Python DLL, imports {pythons}")
    foreign = sorted(d for d in imports if d.lower() != "python3.dll" and not WINDOWS_SYSTEM.match(d))
    if foreign:
        raise NativeError(f"{name} imports DLLs Windows does not ship: {', '.join(foreign)}")
    if "PyInit__dqskin" not in exports:
        raise NativeError(f"{name} does not export PyInit__dqskin (exports {exports})")
    return Report("windows-x64", f"PE x64, imports {', '.join(imports)}, exports {', '.join(exports)}")


# --- Mach-O ----------------------------------------------------------------------------------


def _check_macho(name: str, data: bytes) -> Report:
    cpu, _, _, ncmds, _, _ = struct.unpack_from("<iiIIII", data, 4)
    platform = {0x0100000C: "macos-arm64", 0x01000007: "macos-x64"}.get(cpu)
    if platform is None:
        raise NativeError(f"{name}: Mach-O CPU type {cpu:#x} is neither arm64 nor x86-64")
    dylibs, minos, at = [], None, 32
    for _ in range(ncmds):
        cmd, size = struct.unpack_from("<II", data, at)
        if cmd in (0xC, 0x80000018, 0x8000001F):  # LC_LOAD_DYLIB, LC_LOAD_WEAK_DYLIB, LC_REEXPORT_DYLIB
            (offset,) = struct.unpack_from("<I", data, at + 8)
            dylibs.append(data[at + offset : at + size].split(b"\0")[0].decode())
        elif cmd in (0x32, 0x24):  # LC_BUILD_VERSION (minos after the platform), LC_VERSION_MIN_MACOSX
            v = struct.unpack_from("<I", data, at + (12 if cmd == 0x32 else 8))[0]
            minos = (v >> 16, (v >> 8) & 0xFF)
        at += size
    if any("python" in d.lower() for d in dylibs):
        raise NativeError(f"{name} links a Python library ({dylibs}); it must look Python up in the process")
    foreign = sorted(d for d in dylibs if not MACOS_SYSTEM.match(d))
    if foreign:
        raise NativeError(f"{name} links libraries macOS does not ship: {', '.join(foreign)}")
    if minos is None or minos > BLENDER_MACOS:
        raise NativeError(f"{name} targets macOS {minos}, newer than Blender's minimum {BLENDER_MACOS}")
    return Report(platform, f"Mach-O {platform}, macOS ≥ {minos[0]}.{minos[1]}, links {', '.join(dylibs)}")


def main(argv: list[str]) -> int:
    status = 0
    for arg in argv:
        try:
            report = check(Path(arg))
            print(f"{arg}: {report.platform}: {report.summary}")
        except NativeError as e:
            print(f"error: {e}", file=sys.stderr)
            status = 1
    return status


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

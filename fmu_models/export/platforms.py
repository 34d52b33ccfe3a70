"""Binaries for other platforms, cross-compiled on one Linux machine from the FMU's own C sources with
zig's clang (the ``cross`` extra) and checked with lief (layout, flags and checks: the user guide's page
"Taking the estimator to another tool")."""
from __future__ import annotations

import functools
import importlib.util
import os
import re
import shutil
import struct
import sys
import threading
import zipfile
from collections.abc import Sequence
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from xml.etree import ElementTree as ET

from ..errors import CompilerNotFoundError, ConfigurationError, FMUError
from ..infra.cache import build_cached
from ..infra.compiler import run_compiler
from ..infra.files import atomic_copy, private_tempdir
from .pack import FMI_HEADERS, OPT_FLAGS

__all__ = ["PLATFORMS", "BinaryCheck", "add_platforms", "check_binary", "parse_platforms", "zig_command"]

#: The platforms ``--platforms`` accepts.
PLATFORMS = ("linux64", "win64", "darwin", "aarch64-linux")
_INSTALL = "pip install -e '.[cross]' (or: pip install 'ziglang>=0.11' lief)"
_COMMON = ("-shared", *OPT_FLAGS, "-std=c99", "-fvisibility=hidden", "-ffp-contract=off")


@dataclass(frozen=True)
class _Target:
    """One zig target: its ``-target``, flags besides ``_COMMON``, library suffix, FMI 3.0 and
    2.0 binaries folders (None: FMI 2.0 has none), binary format and architecture."""

    zig: str
    flags: tuple[str, ...]
    suffix: str
    fmi3: str
    fmi2: str | None
    fmt: str
    arch: str

    def folder(self, fmi_version: int) -> str | None:
        return self.fmi2 if fmi_version == 2 else self.fmi3


_LINUX = ("-fPIC", "-s", "-lm")
_TARGETS = {
    "linux64": (_Target("x86_64-linux-gnu.2.17", _LINUX, ".so", "x86_64-linux", "linux64", "ELF", "x86_64"),),
    "win64": (_Target("x86_64-windows-gnu", ("-DCASADI_SYMBOL_EXPORT=", "-s"), ".dll", "x86_64-windows", "win64",
                      "PE", "x86_64"),),
    "darwin": (_Target("x86_64-macos.11.0", ("-fPIC", "-s"), ".dylib", "x86_64-darwin", "darwin64", "MachO",
                       "x86_64"),
               _Target("aarch64-macos.11.0", ("-fPIC", "-s"), ".dylib", "aarch64-darwin", "darwin64", "MachO",
                       "aarch64")),
    "aarch64-linux": (_Target("aarch64-linux-gnu.2.17", _LINUX, ".so", "aarch64-linux", None, "ELF", "aarch64"),),
}
#: Symbols Apple's linker defines in every dylib (not the FMU's own).
_MACHO_LINKER = frozenset({"__dso_handle", "_mh_dylib_header"})
#: Shared libraries a binary may import (the system's C library and runtime).
_SYSTEM_LIBRARIES = {
    "ELF": re.compile(r"^(libc\.so\.6|libm\.so\.6|ld-linux[-\w.]*\.so\.\d)$"),
    "PE": re.compile(r"^(kernel32\.dll|api-ms-win-crt-[\w-]+\.dll|ucrtbase\.dll)$", re.IGNORECASE),
    "MachO": re.compile(r"^/usr/lib/libSystem\.B\.dylib$"),
}


def parse_platforms(text: str | Sequence[str] | None) -> tuple[str, ...]:
    """The platforms named by ``text`` (``--platforms``: ``"linux64,win64"``, or a sequence of names),
    checked; ``()`` for None.

    Raises
    ------
    ConfigurationError
        An unknown or repeated name (the known ones are listed).
    """
    if text is None:
        return ()
    names = [s.strip() for s in (text.split(",") if isinstance(text, str) else text)]
    bad = [n for n in names if n not in PLATFORMS] if any(names) else []
    if bad or not any(names):
        raise ConfigurationError(f"unknown platform(s) {', '.join(map(repr, bad)) or '(none given)'}: "
                                 f"choose from {', '.join(PLATFORMS)} (comma-separated)")
    if len(set(names)) != len(names):
        raise ConfigurationError(f"platform listed twice in {','.join(names)}")
    return tuple(names)


def zig_command() -> list[str]:
    """The cross-compiler command (``python -m ziglang cc``).

    Raises
    ------
    CompilerNotFoundError
        The ``ziglang`` package (or ``lief``, which checks the binaries) is missing; says what to install.
    """
    missing = [m for m in ("ziglang", "lief") if importlib.util.find_spec(m) is None]
    if missing:
        raise CompilerNotFoundError(f"building for other platforms needs the package(s) {', '.join(missing)} "
                                    f"(the cross-compiler and the binary checker): {_INSTALL}")
    return [sys.executable, "-m", "ziglang", "cc"]


@dataclass(frozen=True)
class BinaryCheck:
    """What :func:`check_binary` found in one binary.

    Attributes
    ----------
    format, architectures, exports, libraries, problems
        ``ELF``, ``PE`` or ``MachO``; ``x86_64`` / ``aarch64`` (two for a universal Mach-O file); the
        exported function names (Mach-O's leading underscore removed); the imported libraries; what is
        wrong (empty when the binary is what an FMU of this FMI version needs).
    """

    format: str
    architectures: tuple[str, ...]
    exports: frozenset
    libraries: tuple[str, ...]
    problems: tuple[str, ...]


@functools.cache
def fmi_functions(fmi_version: int) -> frozenset:
    """Every function of the FMI ``fmi_version`` C API, read from the standard's header
    ``fmi<v>Functions.h`` (fmpy ships it)."""
    header = FMI_HEADERS / f"fmi{fmi_version}Functions.h"
    names = re.findall(rf"FMI{fmi_version}_Export\s+\w+TYPE\s+(\w+);", header.read_text())
    if not names:
        raise FMUError(f"no FMI {fmi_version} functions found in {header}")
    return frozenset(names)


def _arch_name(value) -> str:
    text = str(value).upper()
    if "ARM64" in text or "AARCH64" in text:
        return "aarch64"
    if "X86_64" in text or "AMD64" in text:
        return "x86_64"
    return text.rsplit(".", 1)[-1].lower()


def check_binary(path: Path, fmi_version: int, fmt: str, architectures: Sequence[str]) -> BinaryCheck:
    """Check the FMU binary ``path``: its format ``fmt`` and ``architectures``, that it exports
    every function of FMI ``fmi_version`` (fmpy loads them all) and nothing else, and that it
    imports only the system's C library (and, on Windows, the C runtime).

    Raises
    ------
    FMUError
        The file cannot be read as a binary at all.
    """
    import lief

    lief.logging.disable()
    parsed = lief.MachO.parse(str(path)) if fmt == "MachO" else lief.parse(str(path))
    if parsed is None:
        raise FMUError(f"{path}: not a readable shared library")
    binaries = list(parsed) if isinstance(parsed, lief.MachO.FatBinary) else [parsed]
    problems, archs, exports, libraries = [], [], set(), []
    for b in binaries:
        kind = {lief.ELF.Binary: "ELF", lief.PE.Binary: "PE", lief.MachO.Binary: "MachO"}.get(type(b), "?")
        if kind != fmt:
            problems.append(f"{path.name}: a {kind} file, expected {fmt}")
            continue
        if kind == "ELF":
            arch, names = b.header.machine_type, {s.name for s in b.exported_symbols if s.is_function}
            libs = list(b.libraries)
        elif kind == "PE":
            arch, names = b.header.machine, {e.name for e in b.get_export().entries} if b.has_exports else set()
            libs = [i.name for i in b.imports]
        else:
            arch, names = b.header.cpu_type, {s.name.removeprefix("_") for s in b.exported_symbols} - _MACHO_LINKER
            libs = [lib.name for lib in b.libraries if lib.command != lief.MachO.LoadCommand.TYPE.ID_DYLIB]
        archs.append(_arch_name(arch))
        if kind == "MachO" and archs[-1] == "aarch64" and not b.has_code_signature:
            problems.append(f"{path.name} (aarch64): no code signature (macOS refuses to load it)")
        exports |= names
        libraries += [lib for lib in libs if lib not in libraries]
    if sorted(archs) != sorted(architectures):
        problems.append(f"{path.name}: architectures {', '.join(archs) or 'none'}, expected "
                        f"{', '.join(architectures)}")
    wanted = fmi_functions(fmi_version)
    if wanted - exports:
        problems.append(f"{path.name}: missing FMI functions {', '.join(sorted(wanted - exports)[:8])}"
                        f"{' ...' if len(wanted - exports) > 8 else ''}")
    if exports - wanted:
        problems.append(f"{path.name}: exports {len(exports - wanted)} symbols besides the FMI functions "
                        f"({', '.join(sorted(exports - wanted)[:8])})")
    foreign = [lib for lib in libraries if not _SYSTEM_LIBRARIES[fmt].match(Path(lib).name if fmt != "MachO"
                                                                                  else lib)]
    if foreign:
        problems.append(f"{path.name}: links libraries other than the system's: {', '.join(foreign)}")
    return BinaryCheck(fmt, tuple(archs), frozenset(exports), tuple(libraries), tuple(problems))


def _universal(slices: Sequence[tuple[Path, str]], out: Path) -> None:
    """Write a universal (fat) Mach-O file of the thin ``(file, arch)`` slices (fat header:
    big-endian magic 0xcafebabe, then cputype, cpusubtype, offset, size, align of each,
    slices 2^14-aligned); each slice's bytes are kept, so zig's ad-hoc signature holds."""
    cpu = {"x86_64": (0x01000007, 3), "aarch64": (0x0100000C, 0)}
    align = 14
    header = struct.pack(">II", 0xCAFEBABE, len(slices))
    offset = 1 << align
    blobs = []
    for f, arch in slices:
        data = f.read_bytes()
        header += struct.pack(">iiIII", *cpu[arch], offset, len(data), align)
        blobs.append((offset, data))
        offset = (offset + len(data) + (1 << align) - 1) // (1 << align) * (1 << align)
    with open(out, "wb") as o:
        o.write(header)
        for off, data in blobs:
            o.seek(off)
            o.write(data)


def _compile(target: _Target, src: Path, c_files: list[str], identifier: str, out: Path,
             cancel: threading.Event | None = None) -> None:
    """Cross-compile the library ``out`` through the compiled-code cache."""
    flags = [*_COMMON, *target.flags]
    if target.fmt == "MachO":
        flags.append(f"-Wl,-install_name,@rpath/{identifier}.dylib")
    zig = zig_command()

    def build(dst: Path) -> None:
        with private_tempdir("pendulum_cosim_zig_") as scratch:   # zig's .lib/.pdb
            lib = Path(scratch) / f"{identifier}{target.suffix}"
            run_compiler([*zig, "-target", target.zig, *flags, f"-I{src}", f"-I{FMI_HEADERS}",
                          *[str(src / f) for f in c_files], "-o", str(lib)],
                         f"{identifier} for {target.zig}", cwd=scratch, cancel=cancel)
            shutil.copyfile(lib, dst)

    build_cached("cross", "|".join([*zig[1:], zig_version(), target.zig, *flags]), src, build, out,
                 "cross-built FMU binaries are compiled without caching")


def _compile_all(libs: dict[tuple[str, _Target], Path], src: Path, c_files: list[str]) -> None:
    """Compile every library ``libs[identifier, target]`` in worker threads; Ctrl-C (or any
    error) in the main thread ends every running compiler before it goes on."""
    cancel = threading.Event()
    pool = ThreadPoolExecutor(max_workers=min(len(libs), os.cpu_count() or 1))
    try:
        pending = [pool.submit(_compile, t, src, c_files, ident, lib, cancel) for (ident, t), lib in libs.items()]
        while pending:                              # short waits: the main thread sees Ctrl-C
            done, pending = wait(pending, timeout=0.2, return_when=FIRST_EXCEPTION)
            for f in done:
                f.result()
    except BaseException:
        cancel.set()
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def zig_version() -> str:
    """The installed ziglang package's version ("" if absent)."""
    try:
        return version("ziglang")
    except PackageNotFoundError:
        return ""


def add_platforms(fmu: Path, platforms: Sequence[str]) -> list[str]:
    """Add binaries for ``platforms`` (names of :data:`.PLATFORMS`) to the project's FMU
    ``fmu``, cross-compiled from its ``sources/`` and checked with :func:`.check_binary`; the
    FMU file is replaced atomically. Returns notes on what was left out (an FMI 2.0 FMU has
    no aarch64-linux folder).

    Raises
    ------
    CompilerNotFoundError, BuildError
        The ``cross`` extra is not installed (the message says what to install); the cross-compiler failed.
    FMUError
        The FMU has no (complete) sources, or a built binary fails its check.
    """
    fmu = Path(fmu)
    platforms = parse_platforms(platforms)
    try:
        z = zipfile.ZipFile(fmu)
    except (OSError, zipfile.BadZipFile) as e:
        raise FMUError(f"{fmu}: not a readable FMU ({e})") from None
    with z, private_tempdir("pendulum_cosim_platforms_") as tmp:
        tmp = Path(tmp)
        fmi_version, identifiers, c_files = _read_fmu(z, fmu.name, tmp / "sources")
        notes, jobs, present = [], [], set(z.namelist())
        for plat in platforms:
            targets = _TARGETS[plat]
            folders = {t.folder(fmi_version) for t in targets}
            if None in folders:
                notes.append(f"{fmu.name}: FMI 2.0 defines no binaries folder for {plat}; build an FMI 3.0 FMU "
                             "(--fmi-version 3) for it")
                continue
            jobs += [(plat, ident, targets) for ident in identifiers
                     if not all(f"binaries/{f}/{ident}{targets[0].suffix}" in present for f in folders)]
        added = _binaries(jobs, fmi_version, tmp, c_files, fmu.name)
        if added:
            out = tmp / "with-platforms.fmu"
            with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as o:
                for info in z.infolist():
                    if info.filename not in added:
                        o.writestr(info, z.read(info.filename))
                for name, lib in sorted(added.items()):
                    o.write(lib, name)
            atomic_copy(out, fmu)
    return notes


def _read_fmu(z: zipfile.ZipFile, where: str, src: Path) -> tuple[int, list[str], list[str]]:
    """The FMI version, model identifiers and C files of the FMU ``z``, its sources extracted to ``src``."""
    try:
        md = ET.fromstring(z.read("modelDescription.xml"))
    except (KeyError, ET.ParseError) as e:
        raise FMUError(f"{where}: no readable modelDescription.xml ({e})") from None
    fmi_version = 3 if md.get("fmiVersion", "").startswith("3") else 2
    identifiers = sorted({e.get("modelIdentifier") for e in md if e.get("modelIdentifier")})
    if not identifiers:
        raise FMUError(f"{where}: its modelDescription.xml names no modelIdentifier")
    if fmi_version == 2:
        c_files = [f.get("name") for f in md.iter("File") if f.get("name")]
    else:
        try:
            build = ET.fromstring(z.read("sources/buildDescription.xml"))
        except KeyError:
            raise FMUError(f"{where}: no sources/buildDescription.xml (an FMI 3.0 FMU lists its C sources there)"
                           ) from None
        c_files = [f.get("name") for f in build.iter("SourceFile") if f.get("name")]
    c_files = list(dict.fromkeys(c_files))
    if not c_files:
        raise FMUError(f"{where}: lists no C source files; it cannot be rebuilt for another platform")
    for n in c_files:
        if f"sources/{n}" not in z.namelist() or "/" in n or "\\" in n or n.startswith("."):
            raise FMUError(f"{where}: source file {n!r} is not in its sources/ folder")
    src.mkdir()
    for name in z.namelist():
        if name.startswith("sources/") and not name.endswith("/") and "/" not in name[len("sources/"):]:
            (src / name[len("sources/"):]).write_bytes(z.read(name))
    return fmi_version, identifiers, c_files


def _binaries(jobs: list[tuple], fmi_version: int, tmp: Path, c_files: list[str], where: str) -> dict[str, Path]:
    """The binaries of ``jobs`` (``(platform, identifier, targets)``) compiled in parallel from
    ``tmp/sources`` and checked, by their path in the FMU (one universal file for FMI 2.0's darwin64)."""
    libs = {(ident, t): tmp / f"{ident}-{t.zig}{t.suffix}" for _, ident, targets in jobs for t in targets}
    if libs:
        zig_command()                           # the missing extra named before anything starts
        _compile_all(libs, tmp / "sources", c_files)
    added: dict[str, Path] = {}
    for plat, ident, targets in jobs:
        built = [(t, libs[ident, t], [t.arch]) for t in targets]
        if fmi_version == 2 and len(built) > 1:        # darwin64: one universal file
            universal = tmp / f"{ident}-universal{targets[0].suffix}"
            _universal([(lib, t.arch) for t, lib, _ in built], universal)
            built = [(targets[0], universal, [t.arch for t in targets])]
        for t, lib, archs in built:
            check = check_binary(lib, fmi_version, t.fmt, archs)
            if check.problems:
                raise FMUError(f"the {plat} binary of {where} fails its check: " + "; ".join(check.problems))
            added[f"binaries/{t.folder(fmi_version)}/{ident}{t.suffix}"] = lib
    return added

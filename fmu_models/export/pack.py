"""Compile and pack an FMU (plant, estimator or signal) from generated C code, one of the model cores
and the shared FMI wrappers of ``c/``, its sources shipped in ``sources/``; the GUID is a hash of the
model's fingerprint and of every source, so equal FMUs get equal GUIDs."""
from __future__ import annotations

import contextlib
import hashlib
import os
import platform
import shutil
import sys
import uuid
import zipfile
from collections.abc import Callable
from pathlib import Path

import fmpy

from ..errors import ConfigurationError
from ..infra.cache import build_cached
from ..infra.compiler import find_compiler, run_compiler
from ..infra.files import atomic_copy, private_tempdir
from ..infra.resources import shipped_files

__all__ = ["CORES", "C_DIR", "FMI_HEADERS", "FMI_VERSIONS", "OPT_FLAGS", "SHARED_HEADERS", "find_compiler",
           "library_suffix", "pack_fmu", "platform_dir"]

#: The generic C files shipped with the package (FMI wrappers and the model cores).
C_DIR = Path(__file__).parent / "c"
FMI_VERSIONS = (2, 3)
CORES = ("plant", "filter", "signal")
#: The headers of ``C_DIR`` every FMU's sources include (whatever its core and FMI version).
SHARED_HEADERS = ("core_api.h", "core_common.h", "wrapper_modes.h", "wrapper_common.h", "wrapper_functions.h")
#: fmpy's copy of the FMI standard's C headers, which every build of FMI code includes.
FMI_HEADERS = Path(fmpy.__file__).parent / "c-code"
_PLACEHOLDER = "{00000000-0000-0000-0000-000000000000}"


def platform_dir(fmi_version: int) -> str:
    """The binaries folder of this platform for ``fmi_version`` 2 or 3 (``linux64`` in FMI 2.0,
    ``x86_64-linux`` in 3.0)."""
    machine = platform.machine().lower()
    system = {"linux": "linux", "darwin": "darwin", "win32": "win"}.get(sys.platform, sys.platform)
    if fmi_version == 2:
        return f"{system}{'64' if sys.maxsize > 2**32 else '32'}"
    arch = {"amd64": "x86_64", "arm64": "aarch64"}.get(machine, machine)
    return f"{arch}-{system if system != 'win' else 'windows'}"


def library_suffix() -> str:
    """The shared-library file suffix of this platform (``.so``, ``.dylib``, ``.dll``)."""
    return {"darwin": ".dylib", "win32": ".dll"}.get(sys.platform, ".so")


#: The optimisation flags of every FMU build, native and cross. -O3 and -fno-math-errno (the
#: C code reads no errno) change no bit of the results and took the seed 000 SSP's serial
#: step from 2.60 to 2.48 µs (measured; -O3 alone 2.51).
OPT_FLAGS = ("-O3", "-fno-math-errno")
#: Flags of the native build (the binary for this machine's platform).
_CFLAGS = ("-shared", "-fPIC", *OPT_FLAGS, "-fvisibility=hidden", "-std=c99", "-D_POSIX_C_SOURCE=200809L")


def _compile_library(cc: str, src: Path, c_files: list[str], lib: Path, identifier: str) -> None:
    """Compile the FMU's library ``lib`` from the sources in ``src`` through the compiled-code cache."""
    def build(out: Path) -> None:
        run_compiler([cc, *_CFLAGS, f"-I{src}", f"-I{FMI_HEADERS}", *[str(src / f) for f in c_files], "-o",
                      str(out), "-lm"], identifier)

    key = "|".join([cc, *_CFLAGS, platform_dir(3)])
    with contextlib.suppress(OSError):
        st = os.stat(cc)
        key += f"{st.st_size}|{st.st_mtime_ns}"
    build_cached("fmu", key, src, build, lib, "FMUs are compiled without caching")


def _build_description(identifier: str, c_files: list[str]) -> str:
    files = "".join(f'<SourceFile name="{f}"/>' for f in c_files)
    return ('<?xml version="1.0" encoding="UTF-8"?>\n<fmiBuildDescription fmiVersion="3.0">'
            f'<BuildConfiguration modelIdentifier="{identifier}">'
            f'<SourceFileSet language="C99">{files}</SourceFileSet></BuildConfiguration>'
            "</fmiBuildDescription>\n")


def _write_sources(src: Path, core: str, fmi_version: int, write_generated: Callable[[Path, str], list[str]],
                   identity: str) -> tuple[str, list[str]]:
    """Write the FMU's sources into ``src``; returns the GUID (a hash of ``identity`` and of every
    source) and the C files to compile."""
    generic = [*SHARED_HEADERS, f"{core}_core.h", f"{core}_core.c", f"fmi{fmi_version}_wrapper.c"]
    for g, path in zip(generic, shipped_files(__package__, "c", generic)):
        shutil.copy(path, src / g)
    (src / "core.h").write_text(f'/* Generated: this FMU\'s model core. */\n#include "{core}_core.h"\n')
    write_generated(src, _PLACEHOLDER)
    h = hashlib.sha256(identity.encode())
    for f in sorted(src.iterdir()):
        h.update(f.read_bytes())
    guid = "{" + str(uuid.UUID(h.hexdigest()[:32])) + "}"
    generated = write_generated(src, guid)          # again, now with the final GUID
    return guid, [f"{core}_core.c", f"fmi{fmi_version}_wrapper.c", *generated]


def pack_fmu(identifier: str, core: str, fmi_version: int, write_generated: Callable[[Path, str], list[str]],
             model_description: Callable[[str, list[str]], str], out_dir, fingerprint: str,
             file_name: str | None = None) -> Path:
    """Generate, compile and pack one FMU; returns the ``.fmu`` path.

    Parameters
    ----------
    identifier, core, fmi_version : str, str, {2, 3}
        The model identifier (library name, a C identifier); the model core (plant, filter, signal); the FMI version.
    write_generated, model_description : callable
        ``write_generated(folder, guid) -> [generated C files to compile]`` writes ``model_config.h``
        and the generated code into ``folder``; ``model_description(guid, c_files) -> XML text``.
    out_dir, file_name : path, str
        Where to write the FMU (created if missing); its file name (default ``<identifier>.fmu``).
    fingerprint : str
        What identifies the model's content beyond its sources (names, values).

    Raises
    ------
    CompilerNotFoundError, BuildError
        No C compiler; the compiler failed (its output is in the message).
    """
    if fmi_version not in FMI_VERSIONS:
        raise ConfigurationError(f"fmi_version must be one of {FMI_VERSIONS}, got {fmi_version!r}")
    if core not in CORES:
        raise ConfigurationError(f"core must be one of {CORES}, got {core!r}")
    cc = find_compiler()
    out_dir = Path(out_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ConfigurationError(f"cannot create the output folder {out_dir}: "
                                 f"{'a file is in the way' if isinstance(e, FileExistsError) else e.strerror or e}"
                                 ) from None
    with private_tempdir(f"{identifier}_") as tmp:
        tmp = Path(tmp)
        src = tmp / "sources"
        src.mkdir()
        guid, c_files = _write_sources(src, core, fmi_version, write_generated,
                                       f"{identifier}|{core}|{fmi_version}|{fingerprint}")
        lib = tmp / "binaries" / platform_dir(fmi_version) / (identifier + library_suffix())
        lib.parent.mkdir(parents=True)
        _compile_library(cc, src, c_files, lib, identifier)
        if fmi_version == 3:
            (src / "buildDescription.xml").write_text(_build_description(identifier, c_files))
        (tmp / "modelDescription.xml").write_text(model_description(guid, c_files))
        partial = tmp / "packed.fmu"
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as z:
            z.write(tmp / "modelDescription.xml", "modelDescription.xml")
            z.write(lib, f"binaries/{lib.parent.name}/{lib.name}")
            for f in sorted(src.iterdir()):
                z.write(f, f"sources/{f.name}")
        fmu = out_dir / (file_name or f"{identifier}.fmu")
        atomic_copy(partial, fmu)
    return fmu

"""Compile and pack the plant FMUs: ``python -m fmu_models build --out DIR``.

Each FMU holds a native shared library compiled here from CasADi-generated C code and
this project's FMI wrapper (``fmu_models/c``), its ``modelDescription.xml`` and its C
sources (so that other platforms can rebuild it). No Python runs inside the FMU.
"""
from __future__ import annotations

import contextlib
import hashlib
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import uuid
import zipfile
from pathlib import Path

import fmpy

from . import MODEL_NAMES, get_model
from .codegen import C_DIR, write_sources
from .errors import BuildError, CompilerNotFoundError, ConfigurationError
from .model_description import build_description_xml, fmi2_xml, fmi3_xml
from .plant import PlantModel

__all__ = ["build_fmu", "build_fmus", "find_compiler", "CompilerNotFoundError", "FMI_VERSIONS"]

FMI_VERSIONS = (2, 3)
_FMI_HEADERS = Path(fmpy.__file__).parent / "c-code"


def find_compiler() -> str:
    """Return the C compiler to use: ``$CC``, else ``cc``, ``gcc`` or ``clang`` on the PATH."""
    candidates = [os.environ["CC"]] if os.environ.get("CC") else ["cc", "gcc", "clang"]
    for cand in candidates:
        path = shutil.which(cand)
        if path:
            return path
    raise CompilerNotFoundError(
        "no C compiler found (looked for " + ", ".join(candidates) + "). Building an FMU "
        "compiles generated C code: install gcc (Debian/Ubuntu: 'apt-get install gcc', "
        "Fedora: 'dnf install gcc', macOS: 'xcode-select --install') or set CC.")


def _platform_dir(fmi_version: int) -> str:
    machine = platform.machine().lower()
    system = {"linux": "linux", "darwin": "darwin", "win32": "win"}.get(sys.platform, sys.platform)
    if fmi_version == 2:
        return f"{system}{'64' if sys.maxsize > 2**32 else '32'}"
    arch = {"amd64": "x86_64", "arm64": "aarch64"}.get(machine, machine)
    return f"{arch}-{system if system != 'win' else 'windows'}"


def _library_suffix() -> str:
    return {"darwin": ".dylib", "win32": ".dll"}.get(sys.platform, ".so")


def _guid(model: PlantModel, fmi_version: int, sources: list[Path]) -> str:
    """Deterministic GUID: a hash of the model, its parameters and the C sources."""
    h = hashlib.sha256(f"{model.fmu_name}|{fmi_version}|{model.p.tolist()}".encode())
    for src in sorted(sources):
        h.update(src.read_bytes())
    return "{" + str(uuid.UUID(h.hexdigest()[:32])) + "}"


def build_fmu(model: PlantModel | str, out_dir: str | Path = ".", fmi_version: int = 2) -> Path:
    """Build the FMU of one plant model into ``out_dir``; returns the ``.fmu`` path.

    Parameters
    ----------
    model : PlantModel or str
        The model (its current parameter values become the FMU's start values) or a name
        for :func:`fmu_models.get_model`.
    out_dir : path
        Directory to write ``<fmu_name>.fmu`` into (created if missing).
    fmi_version : int
        2 or 3; either way Model Exchange and Co-Simulation in one FMU.

    Raises
    ------
    CompilerNotFoundError
        No C compiler is available.
    BuildError
        The compiler failed (its output is in the message).
    """
    if fmi_version not in FMI_VERSIONS:
        raise ConfigurationError(f"fmi_version must be one of {FMI_VERSIONS}, got {fmi_version!r}")
    if isinstance(model, str):
        model = get_model(model)
    cc = find_compiler()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    generic = [C_DIR / n for n in ("plant_core.h", "plant_core.c", "wrapper_modes.h", "wrapper_common.h",
                                   f"fmi{fmi_version}_wrapper.c")]
    with tempfile.TemporaryDirectory(prefix=f"{model.fmu_name}_") as tmp:
        tmp = Path(tmp)
        src = tmp / "sources"
        write_sources(model, "{00000000-0000-0000-0000-000000000000}", src)
        for g in generic:
            shutil.copy(g, src / g.name)
        guid = _guid(model, fmi_version, sorted(src.iterdir()))
        write_sources(model, guid, src)          # again, now with the final GUID
        c_files = ["plant_core.c", f"fmi{fmi_version}_wrapper.c", "model_funcs.c"]
        bindir = tmp / "binaries" / _platform_dir(fmi_version)
        bindir.mkdir(parents=True)
        lib = bindir / (model.fmu_name + _library_suffix())
        cmd = [cc, "-shared", "-fPIC", "-O2", "-fvisibility=hidden", "-std=c99",
               "-D_POSIX_C_SOURCE=200809L", f"-I{src}", f"-I{_FMI_HEADERS}",
               *[str(src / f) for f in c_files], "-o", str(lib), "-lm"]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            raise BuildError(f"compiling {model.fmu_name} failed:\n{' '.join(cmd)}\n{proc.stderr}")
        if fmi_version == 2:
            xml = fmi2_xml(model, guid, c_files)
        else:
            xml = fmi3_xml(model, guid)
            (src / "buildDescription.xml").write_text(build_description_xml(model, c_files))
        (tmp / "modelDescription.xml").write_text(xml)
        fmu = out_dir / f"{model.fmu_name}.fmu"
        # write beside the target, then rename: a reader (or a second build running at
        # the same time) never sees half a zip
        partial = tmp / "packed.fmu"
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as z:
            z.write(tmp / "modelDescription.xml", "modelDescription.xml")
            z.write(lib, f"binaries/{bindir.name}/{lib.name}")
            for f in sorted(src.iterdir()):
                z.write(f, f"sources/{f.name}")
        atomic_copy(partial, fmu)
    return fmu


def atomic_copy(src: Path, dst: Path) -> None:
    """Copy ``src`` to ``dst`` through a temporary file in ``dst``'s folder and an atomic
    rename, so that ``dst`` is at every instant either absent, the old file or the new one."""
    fd, tmp = tempfile.mkstemp(dir=dst.parent, prefix=f".{dst.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as out, open(src, "rb") as inp:
            shutil.copyfileobj(inp, out)
        os.replace(tmp, dst)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def build_fmus(out_dir: str | Path = ".", fmi_version: int = 2,
               models: tuple[str, ...] = MODEL_NAMES) -> list[Path]:
    """Build ``CartPole.fmu`` and ``InertiaWheelPendulum.fmu`` (default models) into ``out_dir``.

    Parameters
    ----------
    out_dir : path
        Output directory (created if missing).
    fmi_version : int
        2 or 3 (see :func:`build_fmu`).
    models : tuple of str
        Registry names of the models to build.
    """
    return [build_fmu(get_model(name), out_dir, fmi_version) for name in models]

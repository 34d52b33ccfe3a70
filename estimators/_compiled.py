"""Compile CasADi Functions to native code once, cache the shared library on disk, safely.

The library (about 10x faster than CasADi's virtual machine) is keyed by a hash of the C code,
the CasADi version, the compiler flags and the CPU, in the compiled-code cache of
:mod:`fmu_models.infra.cache`. Without a working C compiler or a writable cache, the functions
run in the virtual machine, with a warning (same numbers, slower).
"""
from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import sys
import warnings
from pathlib import Path

import casadi as ca

from fmu_models.errors import BuildError, CompilerNotFoundError, UnknownNameError
from fmu_models.infra.cache import cache_dir, cached_file, writable_cache
from fmu_models.infra.codegen import inline_min_max
from fmu_models.infra.compiler import find_compiler, run_compiler

__all__ = ["BACKENDS", "cache_dir", "compile_functions"]

BACKENDS = ("compiled", "vm")
# CasADi's code is C89; compiled as such its fmin/fmax are plain comparisons instead of
# libm calls (25 % faster fuzzy inference). C99 if gnu89 is refused. -march=native: the
# libraries are built for the machine that runs them (10 % faster); the CPU's identity is
# part of the cache key, so a cache shared between different CPUs never mixes them.
# A step on an FMU's process model calls that model's library (loaded with its symbols global
# before the step's): macOS links a shared library with undefined symbols only when told.
_FLAGS = ("-O3", "-march=native", "-shared", "-fPIC") + (("-Wl,-undefined,dynamic_lookup",)
                                                         if sys.platform == "darwin" else ())
_STDS = ("-std=gnu89", "-std=gnu99")
_VM = "running filters in CasADi's virtual machine (same numbers, slower)"


def _cpu_identity() -> str:
    """The CPU model and feature flags (Linux), else the platform's machine name."""
    try:
        with open("/proc/cpuinfo") as f:
            return "".join([ln for ln in f if ln.startswith(("model name", "flags"))][:2]) or platform.machine()
    except OSError:
        return platform.machine()


def _check_loads(lib: Path, names: list[str]) -> None:
    try:
        handle = ctypes.CDLL(str(lib))
    except OSError as e:
        raise BuildError(f"the compiled library {lib.name} does not load: {e}") from None
    missing = [n for n in names if not hasattr(handle, n)]
    if missing:
        raise BuildError(f"the compiled library {lib.name} lacks {missing}")


def _compile(code: str, cc: str):
    def build(lib: Path) -> None:
        src = lib.with_suffix(".c")
        src.write_text(code)
        command = [cc, *_FLAGS, str(src), "-o", str(lib), "-lm"]
        try:
            run_compiler([*command, _STDS[0]], "filter functions")
        except BuildError:            # gnu89 refused: C99
            run_compiler([*command, _STDS[1]], "filter functions")
    return build


def compile_functions(fns: list[ca.Function], backend: str = "compiled", extra_code: str = "",
                      return_library: bool = False) -> tuple:
    """Return ``fns`` compiled into one shared library, and the backend actually used.

    Parameters
    ----------
    fns : list of casadi.Function
        Functions to generate and compile together.
    backend : {"compiled", "vm"}
        ``"vm"`` returns ``fns`` unchanged; ``"compiled"`` falls back to it (with a warning)
        without a compiler, with a failing compiler found on the PATH, or an unwritable cache.
    extra_code : str
        C code appended to the generated file (e.g. a driver calling the functions).
    return_library : bool
        Also return the library's path (None with the VM backend) as a third element.

    Raises
    ------
    UnknownNameError
        An unknown backend.
    BuildError
        The compiler named by ``$CC`` failed (the user's own is not replaced).
    """
    if backend not in BACKENDS:
        raise UnknownNameError(f"backend must be one of {BACKENDS}, got {backend!r}")
    lib = None
    if backend == "compiled":
        try:
            cc = find_compiler()
        except CompilerNotFoundError as e:
            warnings.warn(f"{_VM}: {e}", stacklevel=2)
            cc = None
        directory = None if cc is None else writable_cache(_VM)
        lib = None if directory is None else _library(fns, extra_code, cc, directory)
    out = fns if lib is None else [ca.external(f.name(), str(lib)) for f in fns]
    used = "vm" if lib is None else "compiled"
    return (out, used, lib) if return_library else (out, used)


def _library(fns: list[ca.Function], extra_code: str, cc: str, directory: Path) -> Path | None:
    """The shared library of ``fns`` and ``extra_code`` in the cache ``directory``, built by
    ``cc`` if it is not there yet; None (with a warning) if the cache cannot be written or a
    compiler found on the PATH fails (the user's own ``$CC`` failing raises BuildError)."""
    cg = ca.CodeGenerator("fns.c")
    for f in fns:
        cg.add(f)
    code = inline_min_max(cg.dump()) + extra_code        # in memory: CasADi ignores failed file writes
    key = "\n".join([code, ca.__version__, " ".join(_FLAGS + _STDS), _cpu_identity()])
    lib = directory / f"fns_{hashlib.sha256(key.encode()).hexdigest()[:24]}.so"
    try:
        return cached_file(lib, _compile(code, cc), lambda p: _check_loads(p, [f.name() for f in fns]))
    except OSError as e:             # the disk filled up, the folder vanished, ...
        warnings.warn(f"the compiled-code cache {directory} cannot be written ({e.strerror or e}); {_VM}",
                      stacklevel=3)
    except BuildError as e:          # a broken compiler ($CC=/bin/false, a missing libm, ...)
        if os.environ.get("CC"):     # the user's own choice is not replaced behind their back
            raise BuildError(f"the C compiler named by $CC ({os.environ['CC']}) failed to compile the filter "
                             f"functions: {' '.join(str(e).split())}; fix CC or unset it, or choose "
                             "backend='vm' (CasADi's virtual machine: same numbers, slower)") from None
        warnings.warn(f"{_VM}: the C compiler {cc} failed: {' '.join(str(e).split())}", stacklevel=3)
    return None

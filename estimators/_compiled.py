"""Compile CasADi Functions to native code once, cache the shared library on disk, safely.

A filter's fused step compiled by the C compiler runs about 10x faster than in CasADi's
virtual machine. The library is keyed by a hash of the generated C code, the CasADi
version and the compiler flags, and kept in the cache folder: ``$PENDULUM_COSIM_CACHE``,
else ``$XDG_CACHE_HOME/pendulum-cosim``, else ``~/.cache/pendulum-cosim``.

Safe under concurrency and damage:

* every build happens in a private temporary folder inside the cache; the finished
  library is checked (it loads and exports every function) and then renamed into place
  atomically, so processes filling an empty cache at once never read a half-written file;
* each library has a ``.sha256`` sidecar written after it; an entry whose hash does not
  match (truncated, zero-length, overwritten) is reported with a warning and rebuilt
  before anything loads it;
* a cache that cannot be written (read-only, not a folder) falls back to CasADi's virtual
  machine with a warning (same numbers, slower); so does a machine without a C compiler.
"""
from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
import warnings
from pathlib import Path

import casadi as ca

from fmu_models.errors import BuildError, CompilerNotFoundError, UnknownNameError

__all__ = ["BACKENDS", "cache_dir", "compile_functions"]

BACKENDS = ("compiled", "vm")
# CasADi's code is C89; compiled as such its fmin/fmax are plain comparisons instead of
# libm calls (25 % faster fuzzy inference). C99 if gnu89 is refused. -march=native: the
# libraries are built for the machine that runs them (10 % faster); the CPU's identity is
# part of the cache key, so a cache shared between different CPUs never mixes them.
_FLAGS = ("-O3", "-march=native", "-shared", "-fPIC")
_STDS = ("-std=gnu89", "-std=gnu99")


def _cpu_identity() -> str:
    """The CPU model and feature flags (Linux), else the platform's machine name."""
    import platform

    try:
        with open("/proc/cpuinfo") as f:
            lines = [ln for ln in f if ln.startswith(("model name", "flags"))][:2]
        return "".join(lines) or platform.machine()
    except OSError:
        return platform.machine()


def cache_dir() -> Path:
    """The cache folder (see the module documentation); not created here."""
    env = os.environ.get("PENDULUM_COSIM_CACHE")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "pendulum-cosim"


def _writable_cache() -> Path | None:
    d = cache_dir()
    try:
        d.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=d, prefix=".probe-")
        os.close(fd)
        os.unlink(probe)
        return d
    except OSError as e:
        warnings.warn(f"the compiled-code cache {d} cannot be written ({e.strerror or e}); running "
                      "filters in CasADi's virtual machine (same numbers, slower). Set "
                      "PENDULUM_COSIM_CACHE to a writable folder to compile them.", stacklevel=3)
        return None


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(1 << 20):
            h.update(chunk)
    return h.hexdigest()


def _valid(lib: Path) -> bool | None:
    """True: a complete entry; False: a damaged one (its hash does not match); None: no
    complete entry (absent, or being written by another process)."""
    sig = lib.with_name(lib.name + ".sha256")
    try:
        want = sig.read_text().strip()
    except OSError:
        return None
    try:
        return want == _sha256(lib)
    except OSError:
        return False


def _check_loads(lib: Path, names: list[str]) -> None:
    try:
        handle = ctypes.CDLL(str(lib))
    except OSError as e:
        raise BuildError(f"the compiled library {lib.name} does not load: {e}") from None
    missing = [n for n in names if not hasattr(handle, n)]
    if missing:
        raise BuildError(f"the compiled library {lib.name} lacks {missing}")


def _build(code: str, lib: Path, names: list[str], cc: str) -> None:
    work = Path(tempfile.mkdtemp(dir=lib.parent, prefix=".build-"))
    try:
        src, tmp_lib = work / "fns.c", work / "fns.so"
        src.write_text(code)
        for std in _STDS:
            proc = subprocess.run([cc, *_FLAGS, std, str(src), "-o", str(tmp_lib), "-lm"],
                                  capture_output=True, text=True, check=False)
            if proc.returncode == 0:
                break
        else:
            raise BuildError(f"compiling filter functions failed:\n{proc.stderr}")
        _check_loads(tmp_lib, names)
        sig = work / "fns.sha256"
        sig.write_text(_sha256(tmp_lib))
        os.replace(tmp_lib, lib)                               # atomic: whole library or none
        os.replace(sig, lib.with_name(lib.name + ".sha256"))   # written last: marks it complete
    finally:
        shutil.rmtree(work, ignore_errors=True)


def compile_functions(fns: list[ca.Function], backend: str = "compiled", extra_code: str = "",
                      return_library: bool = False) -> tuple:
    """Return ``fns`` compiled into one shared library, and the backend actually used.

    Parameters
    ----------
    fns : list of casadi.Function
        Functions to generate and compile together.
    backend : {"compiled", "vm"}
        ``"vm"`` returns ``fns`` unchanged; ``"compiled"`` falls back to it (with a
        warning) when no compiler is found or the cache cannot be written.
    extra_code : str
        C code appended to the generated file (e.g. a driver calling the functions).
    return_library : bool
        Also return the library's path (None with the VM backend).

    Returns
    -------
    (functions, backend) or (functions, backend, library path)

    Raises
    ------
    UnknownNameError
        An unknown backend.
    BuildError
        The compiler failed on the generated code (its output is in the message).
    """
    if backend not in BACKENDS:
        raise UnknownNameError(f"backend must be one of {BACKENDS}, got {backend!r}")
    vm = (fns, "vm", None) if return_library else (fns, "vm")
    if backend == "vm":
        return vm
    from fmu_models.export.pack import find_compiler

    try:
        cc = find_compiler()
    except CompilerNotFoundError as e:
        warnings.warn(f"running filters in CasADi's virtual machine (slower): {e}", stacklevel=2)
        return vm
    directory = _writable_cache()
    if directory is None:
        return vm
    cg = ca.CodeGenerator("fns.c")
    for f in fns:
        cg.add(f)
    code = cg.dump() + extra_code        # in memory: CasADi ignores failed file writes
    key = "\n".join([code, ca.__version__, " ".join(_FLAGS + _STDS), _cpu_identity()])
    lib = directory / f"fns_{hashlib.sha256(key.encode()).hexdigest()[:24]}.so"
    names = [f.name() for f in fns]
    state = _valid(lib)
    if state is False:
        warnings.warn(f"damaged entry {lib.name} in the compiled-code cache {directory} (truncated or "
                      "altered); rebuilding it", stacklevel=2)
    if state is not True:
        # never delete an entry: another process may be loading it; replace it atomically
        try:
            _build(code, lib, names, cc)
        except OSError as e:         # the disk filled up, the folder vanished, ...
            warnings.warn(f"the compiled-code cache {directory} cannot be written ({e.strerror or e}); running "
                          "filters in CasADi's virtual machine (same numbers, slower)", stacklevel=2)
            return vm
    out = [ca.external(n, str(lib)) for n in names]
    return (out, "compiled", lib) if return_library else (out, "compiled")

"""The crash guard: an FMU's code that kills the master's process says so before it dies.

A fatal-signal handler (``crash_guard.c``, compiled once and cached) names the component whose
FMU library holds the crash, the FMI function and the base step's time, starts the salvage program
(:mod:`cosim.core.salvage`), then hands the signal on (the third-party FMUs page of the documentation).
"""
from __future__ import annotations

import contextlib
import ctypes
import sys
from collections.abc import Iterator
from pathlib import Path

from fmu_models.infra.files import private_tempdir
from fmu_models.infra.native_library import compiled_library

__all__ = ["active", "forget_library", "guard", "register_library", "set_step_counter", "stream_ended",
           "stream_started", "temp_folder_made", "temp_folder_removed", "temporary_folder"]

_SOURCE = Path(__file__).with_name("crash_guard.c")
_FLAGS = ("-O2", "-shared", "-fPIC", "-std=c99")
_state: dict = {}
_streams: dict[int, tuple[str, str, str]] = {}
_folders: list[str] = []


def guard() -> ctypes.CDLL | None:
    """The installed guard library, or None where it cannot be built (no C compiler, no
    writable cache) or installed."""
    if "lib" in _state:
        return _state["lib"]
    lib, _ = compiled_library(_SOURCE.read_text(), "crash_guard", _FLAGS, "guard_install",
                              "the crash guard", "an FMU's crash is not explained")
    if lib is not None:
        lib.guard_register.argtypes = [ctypes.c_void_p, ctypes.c_char_p]  # int results: the default restype
        lib.guard_unregister.argtypes = [ctypes.c_int]
        lib.guard_time.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double]
        lib.guard_salvage.argtypes = [ctypes.POINTER(ctypes.c_char_p), ctypes.c_int]
        if lib.guard_install() != 0:
            lib = None
    _state["lib"] = lib
    _update()                      # the streams and folders noted before the guard was loaded
    return lib


def disable() -> None:
    """No guard in this process (an isolated FMU's own process: its parent names the crash)."""
    _state["lib"] = None


def active() -> bool:
    """Whether the guard is installed in this process (an FMU was loaded with it)."""
    return _state.get("lib") is not None


def register_library(function_address: int | None, component: str) -> int:
    """The FMU library holding the function at ``function_address`` (e.g. its
    ``fmi2GetVersion``) belongs to ``component``; returns its entry for
    :func:`forget_library` (-1: no guard, or not registered)."""
    lib = guard()
    if lib is None or not function_address:
        return -1
    return int(lib.guard_register(function_address, component.encode(errors="replace")[:150]))


def forget_library(entry: int) -> None:
    """The FMU library of ``entry`` (from :func:`register_library`) was unloaded."""
    lib = _state.get("lib")
    if lib is not None and entry >= 0:
        lib.guard_unregister(entry)


def set_step_counter(address: int | None, t0: float = 0.0, h: float = 0.0) -> None:
    """A crash happens at ``t0 + k h`` s, ``k`` the int64 at ``address`` (the master's
    base step); None: no run in progress."""
    lib = _state.get("lib")
    if lib is not None:
        lib.guard_time(address, t0, h)


def stream_started(key: int, ipc: str, tmp: str, partial: str) -> None:
    """The streamed recording ``key`` (for :func:`stream_ended`) begins: its rows so far in the Arrow
    stream ``ipc``, its Parquet file being written ``tmp``, its partial result to go to ``partial``."""
    _streams[key] = (ipc, tmp, partial)
    _update()


def stream_ended(key: int) -> None:
    """The streamed recording ``key`` ended (finished, or its partial file written)."""
    if _streams.pop(key, None) is not None:
        _update()


def temp_folder_made(folder: str) -> None:
    """A temporary folder the salvage removes if the process dies."""
    _folders.append(folder)
    _update()


def temp_folder_removed(folder: str) -> None:
    """The temporary folder was removed."""
    if folder in _folders:
        _folders.remove(folder)
        _update()


@contextlib.contextmanager
def temporary_folder(prefix: str) -> Iterator[str]:
    """A private temporary folder (``prefix``), removed at the end of the block and, if an
    FMU crashes the process inside it, by the salvage."""
    with private_tempdir(prefix) as folder:
        temp_folder_made(folder)
        try:
            yield folder
        finally:
            temp_folder_removed(folder)


def _update() -> None:
    """Hand the guard the salvage program's command line for the streams and folders now."""
    lib = _state.get("lib")
    if lib is None:
        return
    if not _streams and not _folders:
        lib.guard_salvage(None, 0)
        return
    argv = [sys.executable, "-m", "cosim.core.salvage"]
    argv += [a for stream in _streams.values() for a in ("--stream", *stream)]
    argv += [a for f in _folders for a in ("--remove", f)]
    encoded = [a.encode(errors="surrogateescape") for a in argv]
    array = (ctypes.c_char_p * len(encoded))(*encoded)
    if lib.guard_salvage(array, len(encoded)) != 0:          # too many: at least the streams
        lib.guard_salvage(array, min(len(encoded), 3 + 4 * len(_streams)))

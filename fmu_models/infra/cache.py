"""The on-disk cache of compiled code (filters' native steps, FMU binaries), safe under concurrency and
damage: entries named by a hash of all that went into them, renamed into place and marked complete by a
``.sha256`` sidecar written last; a damaged entry is rebuilt, never deleted (another process may load it)."""
from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import tempfile
import warnings
from collections.abc import Callable
from pathlib import Path

__all__ = ["build_cached", "cache_dir", "cached_file", "file_digest", "writable_cache"]


def cache_dir() -> Path:
    """The cache folder, not created here: ``$PENDULUM_COSIM_CACHE``, else
    ``$XDG_CACHE_HOME/pendulum-cosim``, else ``~/.cache/pendulum-cosim``; where there is no home
    folder (a container with an arbitrary user id and no ``HOME``), ``<temp>/pendulum-cosim-<uid>``."""
    if env := os.environ.get("PENDULUM_COSIM_CACHE"):
        return Path(env)
    if xdg := os.environ.get("XDG_CACHE_HOME"):
        return Path(xdg) / "pendulum-cosim"
    try:
        home = str(Path.home())
    except (RuntimeError, KeyError, OSError):       # no HOME and no passwd entry for this uid
        home = ""
    if home in ("", "/"):
        uid = os.getuid() if hasattr(os, "getuid") else "user"
        return Path(tempfile.gettempdir()) / f"pendulum-cosim-{uid}"
    return Path(home) / ".cache" / "pendulum-cosim"


def writable_cache(purpose: str) -> Path | None:
    """The cache folder, created, if it can be written; else None, with a warning naming
    ``purpose`` (what falls back)."""
    d = cache_dir()
    try:
        d.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=d, prefix=".probe-")
        os.close(fd)
        os.unlink(probe)
        return d
    except OSError as e:
        warnings.warn(f"the compiled-code cache {d} cannot be written ({e.strerror or e}); {purpose}. Set "
                      "PENDULUM_COSIM_CACHE to a writable folder.", stacklevel=3)
        return None


def file_digest(path: Path) -> str:
    """The SHA-256 of the file at ``path`` (hex)."""
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def _state(entry: Path) -> bool | None:
    """True: a complete entry; False: a damaged one (its hash does not match); None: no
    complete entry (absent, or being written by another process)."""
    try:
        want = entry.with_name(entry.name + ".sha256").read_text().strip()
    except OSError:
        return None
    with contextlib.suppress(OSError):
        return want == file_digest(entry)
    return False


def cached_file(entry: Path, build: Callable[[Path], None], check: Callable[[Path], None] | None = None) -> Path:
    """The cache entry ``entry`` (a file in the cache folder), built by ``build(path)`` into a private
    temporary path if it is absent or damaged, checked by ``check(path)`` (which raises if the file is
    unusable), then renamed into place with its sidecar.

    Raises
    ------
    OSError
        The cache cannot be written (full disk, the folder vanished): the caller falls back.
    """
    if (state := _state(entry)) is True:
        return entry
    if state is False:
        warnings.warn(f"damaged entry {entry.name} in the compiled-code cache {entry.parent} (truncated or "
                      "altered); rebuilding it", stacklevel=3)
    work = Path(tempfile.mkdtemp(dir=entry.parent, prefix=".build-"))
    try:
        tmp = work / entry.name
        build(tmp)
        if check is not None:
            check(tmp)
        sig = work / "entry.sha256"
        sig.write_text(file_digest(tmp))
        os.replace(tmp, entry)                                   # atomic: whole file or none
        os.replace(sig, entry.with_name(entry.name + ".sha256"))  # written last: marks it complete
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return entry


def build_cached(name: str, key: str, sources: Path, build: Callable[[Path], None], out: Path,
                 purpose: str) -> None:
    """Write ``out`` (a compiled library) by ``build(path)`` through the cache entry
    ``<name>_<hash><suffix of out>``, the hash taken over ``key`` (compiler, flags, target)
    and every file of the folder ``sources`` (names and contents): built once, then copied.
    Without a writable cache (``purpose`` says what falls back) or when the cache fails
    (full disk, vanished folder), ``build(out)`` directly."""
    h = hashlib.sha256(key.encode())
    for f in sorted(Path(sources).iterdir()):
        h.update(f.name.encode() + b"\0" + f.read_bytes())
    if (directory := writable_cache(purpose)) is not None:
        with contextlib.suppress(OSError):      # a full or vanished cache: build without it
            shutil.copyfile(cached_file(directory / f"{name}_{h.hexdigest()[:24]}{Path(out).suffix}", build), out)
            return
    build(out)

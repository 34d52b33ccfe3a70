"""A small C library of the project's own (the master's crash guard, ...), compiled once and kept in the
compiled-code cache (:func:`~fmu_models.infra.cache.cached_file`)."""
from __future__ import annotations

import ctypes
import hashlib
import warnings
from collections.abc import Sequence
from pathlib import Path

from fmu_models.errors import BuildError, CompilerNotFoundError

from .cache import cached_file, writable_cache
from .compiler import find_compiler, run_compiler

__all__ = ["compiled_library"]


def compiled_library(code: str, stem: str, flags: Sequence[str], symbol: str, what: str,
                     fallback: str, link: Sequence[str] = ()) -> tuple[ctypes.CDLL | None, str]:
    """The library compiled from the C source ``code`` (built on first use, cached on disk).

    Parameters
    ----------
    code, stem, symbol : str
        The C source; the cache entry's name prefix; a function the library must export (checked
        before the entry is kept).
    flags, link : sequence of str
        Compiler flags (``-shared -fPIC`` among them); libraries to link after the source (``-lm``).
    what, fallback : str
        What the library is, and what happens without it, for messages.

    Returns
    -------
    (library or None, reason)
        None, with the reason (and a warning), where there is no C compiler, the cache cannot be
        written or the build fails.
    """
    try:
        cc = find_compiler()
        directory = writable_cache(fallback)
        if directory is None:
            return None, "the compiled-code cache cannot be written"
        key = "|".join([code, cc, *flags, *link])
        entry = directory / f"{stem}_{hashlib.sha256(key.encode()).hexdigest()[:24]}.so"

        def build(out: Path) -> None:
            src = out.with_suffix(".c")
            src.write_text(code)
            run_compiler([cc, *flags, str(src), "-o", str(out), *link], what)

        def check(p: Path) -> None:
            try:
                getattr(ctypes.CDLL(str(p)), symbol)
            except (OSError, AttributeError) as e:
                raise BuildError(f"{what}: the compiled library does not load: {e}") from None

        return ctypes.CDLL(str(cached_file(entry, build, check))), ""
    except (CompilerNotFoundError, BuildError, OSError) as e:
        why = " ".join(str(e).split())
        warnings.warn(f"{what} is not available ({why}); {fallback}", stacklevel=3)
        return None, why

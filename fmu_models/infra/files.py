"""Files written whole or not at all (at every instant the target is absent, the old file or the new one),
and private temporary folders removed whatever happens."""
from __future__ import annotations

import contextlib
import os
import secrets
import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

from .interrupts import Deferred

__all__ = ["atomic_copy", "atomic_write", "private_tempdir", "remove_empty_folders", "temp_beside"]


def temp_beside(dst: Path) -> tuple[int, str]:
    """A new temporary file in ``dst``'s folder, opened for writing: ``(fd, path)``. Unlike
    ``tempfile.mkstemp`` (always 0600) its permissions follow the umask, as the final file's
    would, since it is renamed into place."""
    for _ in range(100):
        tmp = str(dst.parent / f".{dst.name}.{secrets.token_hex(6)}.tmp")
        with contextlib.suppress(FileExistsError):
            return os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666), tmp
    raise FileExistsError(f"no free temporary name beside {dst}")


def atomic_write(path, write: Callable[[Path], object]) -> Path:
    """Call ``write(tmp)`` to write a temporary file beside ``path``, then rename it to
    ``path`` (atomic); the temporary file is removed if ``write`` fails. Returns ``path``."""
    path = Path(path)
    fd, tmp = temp_beside(path)
    os.close(fd)
    try:
        write(Path(tmp))
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    return path


def atomic_copy(src: Path, dst: Path) -> Path:
    """Copy the file ``src`` to ``dst`` through :func:`atomic_write`; returns ``dst``."""
    return atomic_write(dst, lambda tmp: shutil.copyfile(src, tmp))


@contextlib.contextmanager
def private_tempdir(prefix: str, dir=None) -> Iterator[str]:
    """A new temporary folder (``prefix``, in ``dir`` or the default place) removed at the
    end of the block, also when Ctrl-C or SIGTERM arrives while it is being created (with
    ``tempfile.TemporaryDirectory`` an interrupt inside its creation leaves the folder
    behind)."""
    deferred = Deferred()
    path = None
    try:
        path = tempfile.mkdtemp(prefix=prefix, dir=dir)
        deferred.release()
        yield path
    finally:
        deferred.release()
        if path is not None:
            shutil.rmtree(path, ignore_errors=True)


def remove_empty_folders(folders: list[Path]) -> None:
    """Remove ``folders`` in the order given (the deepest first: a folder a failed run created
    and its created parents), each only if it is empty; any other is left as it is.

    Parameters
    ----------
    folders : list of Path
        The folders, each listed before its parent.
    """
    for d in folders:
        with contextlib.suppress(OSError):
            d.rmdir()

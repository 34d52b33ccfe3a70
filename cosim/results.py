"""Writing and plotting co-simulation results, and guarding an output folder.

Every file is written under a temporary name in its folder and renamed when complete
(:func:`atomic_write`), so a reader, a crash or Ctrl-C never leaves a file that looks
finished but is not. :class:`OutputFolder` refuses a non-empty folder unless asked to
overwrite it (then clears it first) and locks it, so that two runs cannot write into
one folder at once.
"""
from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
from collections.abc import Callable, Sequence
from pathlib import Path

import pandas as pd

from fmu_models.errors import ConfigurationError

__all__ = ["OutputFolder", "atomic_write", "plot_estimates", "save_results"]


def atomic_write(path, write: Callable[[Path], object]) -> Path:
    """Call ``write(tmp)`` to write a temporary file beside ``path``, then rename it to
    ``path`` (atomic); the temporary file is removed if ``write`` fails. Returns ``path``."""
    from fmu_models.export.pack import temp_beside

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


def save_results(df: pd.DataFrame, out_dir, name: str = "results") -> list[Path]:
    """Write ``df`` as ``<name>.csv`` and ``<name>.parquet`` (each atomically).

    Parameters
    ----------
    df : DataFrame
        Results indexed by time [s].
    out_dir : path
        Directory (created if missing).
    name : str
        File stem.

    Returns the paths written.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return [atomic_write(out / f"{name}.csv", df.to_csv),
            atomic_write(out / f"{name}.parquet", df.to_parquet)]


class OutputFolder:
    """An output folder held for one run: created, checked, optionally cleared, locked.

    Parameters
    ----------
    path : path
        The folder.
    overwrite : bool
        Clear a non-empty folder first (default False: refuse it).

    Use as a context manager; the lock (``flock`` on the folder) is released at exit, and
    a folder this object created is removed again if nothing was written into it.

    Raises
    ------
    ConfigurationError
        ``path`` is a file, the folder is not empty and ``overwrite`` is False, another
        run holds the folder, or it cannot be created or written.
    """

    def __init__(self, path, overwrite: bool = False):
        self.path, self.overwrite = Path(path), bool(overwrite)
        self._fd: int | None = None

    def __enter__(self) -> Path:
        p = self.path
        if p.exists() and not p.is_dir():
            raise ConfigurationError(f"--out {p} is a file, not a folder")
        self._created = not p.exists()
        try:
            p.mkdir(parents=True, exist_ok=True)
            self._fd = os.open(p, os.O_RDONLY)
        except OSError as e:
            raise ConfigurationError(f"cannot create the output folder {p}: {e.strerror or e}") from None
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(self._fd)
            self._fd = None
            raise ConfigurationError(f"another pendulum-cosim run is writing to {p}; wait for it or "
                                     "choose another --out") from None
        content = list(p.iterdir())
        if content and not self.overwrite:
            self.__exit__(None, None, None)
            raise ConfigurationError(f"the output folder {p} is not empty ({len(content)} entries, e.g. "
                                     f"{content[0].name}); use --overwrite to replace its contents, or "
                                     "another --out")
        for entry in content:
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()
        if not os.access(p, os.W_OK):
            self.__exit__(None, None, None)
            raise ConfigurationError(f"the output folder {p} is not writable")
        return p

    def __exit__(self, *exc) -> None:
        if self._fd is not None:
            if self._created:
                with contextlib.suppress(OSError):
                    self.path.rmdir()          # only succeeds if nothing was written
            with contextlib.suppress(OSError):
                fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None


def plot_estimates(df: pd.DataFrame, truth: Sequence[str], estimate: Sequence[str],
                   measured: Sequence[str | None] | None = None, path=None, title: str = ""):
    """One panel per state: truth, estimate (and the measurement if given).

    Parameters
    ----------
    df : DataFrame
        Results indexed by time [s].
    truth, estimate : sequence of str
        Columns of the true and estimated signals, pairwise.
    measured : sequence of str or None, optional
        Measurement column per pair (None where a state is not measured).
    path : path, optional
        Write the figure to this PNG file.
    title : str
        Figure title.

    Returns the matplotlib Figure.
    """
    from matplotlib.figure import Figure

    from fmu_models.errors import UnknownNameError

    if len(truth) != len(estimate):
        raise ConfigurationError("truth and estimate must list the same number of columns")
    for col in [*truth, *estimate, *[m for m in (measured or []) if m]]:
        if col not in df.columns:
            raise UnknownNameError(f"no column {col!r}; columns: {', '.join(df.columns)}")
    fig = Figure(figsize=(8, 2.2 * len(truth)))
    axes = fig.subplots(len(truth), 1, sharex=True, squeeze=False)
    for i, (tc, ec) in enumerate(zip(truth, estimate)):
        ax = axes[i, 0]
        if measured and measured[i]:
            ax.plot(df.index, df[measured[i]], ".", ms=2, color="0.7", label="measured")
        ax.plot(df.index, df[tc], "k-", lw=1.2, label="truth")
        ax.plot(df.index, df[ec], "r--", lw=1.0, label="estimate")
        ax.set_ylabel(tc.split(".")[-1])
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="best", fontsize=8)
    axes[-1, 0].set_xlabel("time [s]")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    if path is not None:
        atomic_write(Path(path), lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    return fig

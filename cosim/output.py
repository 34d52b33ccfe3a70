"""Writing and plotting co-simulation results, and guarding an output folder
(:class:`~cosim.output.OutputFolder`); every file is written whole or not at all
(:func:`~fmu_models.infra.files.atomic_write`).
"""
from __future__ import annotations

import contextlib
import fcntl
import json
import os
from collections.abc import Iterator, Sequence
from pathlib import Path

import pandas as pd

from fmu_models.errors import ConfigurationError, TypeMismatchError, UnknownNameError
from fmu_models.infra.files import atomic_write, remove_empty_folders

__all__ = ["MARKER", "MAX_PANELS", "OutputFolder", "plot_estimates", "plot_signals", "save_results"]


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
    if not isinstance(df, pd.DataFrame):
        raise TypeMismatchError(f"save_results takes a pandas DataFrame, got {type(df).__name__}")
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ConfigurationError(f"cannot create the folder {out}: {e.strerror or e}") from None
    return [atomic_write(out / f"{name}.csv", df.to_csv),
            atomic_write(out / f"{name}.parquet", df.to_parquet)]


#: The file that marks a folder as a result of this project and lists what it wrote there.
MARKER = ".pendulum-cosim-output"


def _files_below(folder: Path) -> list[str]:
    """Every entry below ``folder`` (links not followed) as a relative POSIX path, but the marker."""
    paths = [(Path(root).relative_to(folder) / name).as_posix()
             for root, dirs, files in os.walk(folder, followlinks=False) for name in dirs + files]
    return sorted(p for p in paths if p != MARKER)


def _manifest(folder: Path) -> set[str] | None:
    """What a previous run of this project wrote in ``folder``, or None (no or unreadable marker)."""
    try:
        data = json.loads((folder / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    files = data.get("files") if isinstance(data, dict) and data.get("tool") == "pendulum-cosim" else None
    return set(files) if isinstance(files, list) and all(isinstance(x, str) for x in files) else None


def _write_marker(folder: Path, files: list[str], state: str) -> None:
    atomic_write(folder / MARKER, lambda tmp: tmp.write_text(json.dumps(
        {"tool": "pendulum-cosim", "state": state, "files": files}, indent=1), encoding="utf-8"))


def _take(p: Path, overwrite: bool) -> None:
    """Check the locked output folder ``p``, clear a previous result of this project from it
    (``overwrite``) and mark it as ours; a ConfigurationError says why not."""
    content = _files_below(p)
    if content:
        if not overwrite:
            raise ConfigurationError(f"the output folder {p} is not empty ({len(content)} entries, e.g. "
                                     f"{content[0]}); use --overwrite to replace a previous result of "
                                     "pendulum-cosim, or another --out")
        ours = _manifest(p)
        foreign = content if ours is None else [f for f in content if f not in ours]
        if foreign:
            shown = ", ".join(foreign[:5]) + (f" and {len(foreign) - 5} more" if len(foreign) > 5 else "")
            raise ConfigurationError(f"the output folder {p} holds files pendulum-cosim did not write ({shown}); "
                                     "--overwrite only replaces a previous result of pendulum-cosim; move them or "
                                     "choose another --out (nothing was removed)")
        for rel in sorted(content, key=lambda f: -f.count("/")):      # files, then their folders
            entry = p / rel
            with contextlib.suppress(FileNotFoundError):
                if entry.is_dir() and not entry.is_symlink():
                    entry.rmdir()
                else:
                    entry.unlink()
    if not os.access(p, os.W_OK):
        raise ConfigurationError(f"the output folder {p} is not writable")
    try:
        _write_marker(p, [], "running")
    except OSError as e:
        raise ConfigurationError(f"cannot write into the output folder {p}: {e.strerror or e}") from None


@contextlib.contextmanager
def OutputFolder(path, overwrite: bool = False) -> Iterator[Path]:
    """An output folder held for one run (a context manager giving its path): created (and
    removed again, parents included, if the run wrote nothing), checked, optionally cleared,
    locked (``flock``); only the files a previous run listed in its marker file
    (``.pendulum-cosim-output``) are ever cleared.

    Parameters
    ----------
    path : path
        The folder.
    overwrite : bool
        Replace a previous result of this project in the folder (default False: refuse
        any non-empty folder).

    Raises
    ------
    ConfigurationError
        ``path`` is a file, the folder is not empty and ``overwrite`` is False, it holds
        files this project did not write, another run holds the folder, or it cannot be
        created or written.
    """
    p, created = Path(path), []
    if p.exists() and not p.is_dir():
        raise ConfigurationError(f"--out {p} is a file, not a folder")
    try:
        for d in reversed([q for q in (p.absolute(), *p.absolute().parents) if not q.exists()]):
            d.mkdir()
            created.append(d)
        fd = os.open(p, os.O_RDONLY)
    except OSError as e:
        remove_empty_folders(created[::-1])
        raise ConfigurationError(f"cannot create the output folder {p}: {e.strerror or e}") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise ConfigurationError(f"another pendulum-cosim run is writing to {p}; wait for it or "
                                 "choose another --out") from None
    owned, state = False, "failed"
    try:
        _take(p, overwrite)
        owned = True                    # the checks passed: what is written now is ours
        yield p
        state = "complete"
    finally:
        try:
            files = _files_below(p) if owned else []
            if files:
                _write_marker(p, files, state)
            elif owned:
                with contextlib.suppress(OSError):
                    (p / MARKER).unlink()
            if not files:
                remove_empty_folders(created[::-1])
        except OSError:
            pass
        finally:
            with contextlib.suppress(OSError):
                fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)


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
    return _finish(fig, axes, title, path)


def _finish(fig, axes, title: str, path):
    """The figure's time axis and title laid out, written to the PNG file ``path`` if given."""
    axes[-1, 0].set_xlabel("time [s]")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    if path is not None:
        atomic_write(Path(path), lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    return fig


#: The most signals :func:`plot_signals` draws (one panel each).
MAX_PANELS = 16


def plot_signals(df: pd.DataFrame, path=None, title: str = ""):
    """One panel per recorded signal (the first :data:`MAX_PANELS`; the title says how many
    there are).

    Parameters
    ----------
    df, path, title
        As :func:`plot_estimates`.

    Returns the matplotlib Figure.
    """
    from matplotlib.figure import Figure

    if not isinstance(df, pd.DataFrame) or not len(df.columns):
        raise ConfigurationError("plot_signals takes a DataFrame with at least one column")
    columns = list(df.columns[:MAX_PANELS])
    fig = Figure(figsize=(8, 1.6 + 1.4 * len(columns)))
    axes = fig.subplots(len(columns), 1, sharex=True, squeeze=False)
    for ax, col in zip(axes[:, 0], columns):
        ax.plot(df.index, df[col].astype(float), lw=1.0)
        ax.set_ylabel(col, rotation=0, ha="right", fontsize=8)
        ax.grid(alpha=0.3)
    more = f" (the first {len(columns)} of {len(df.columns)} signals)" if len(df.columns) > len(columns) else ""
    return _finish(fig, axes, title + more, path)


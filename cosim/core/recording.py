"""Recording of co-simulation signals: which signals, how often, in memory or streamed to disk.

A recording keeps the signals matching ``signals`` (shell-style globs such as
``"plant.*"`` or ``"ekf.P_*"``; default every signal) at every ``output_interval``
seconds (a multiple of the master's base step; default every base step). Rows either
stay in memory (:class:`MemorySink`, a DataFrame at the end) or go to a Parquet file in
chunks of ``chunk_rows`` rows (:class:`ParquetSink`): memory stays constant however long
the run. The Parquet file is written under a temporary name and renamed when the run
ends; an interrupted or failed run leaves ``<name>.partial.parquet`` with the rows
recorded so far, never a file that looks complete.
"""
from __future__ import annotations

import contextlib
import fnmatch
import os
import shutil
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from fmu_models.errors import ConfigurationError, ResourceError, UnknownNameError
from fmu_models.memory import MEMORY_FRACTION, available_memory

__all__ = ["MemorySink", "ParquetSink", "partial_path", "select_signals"]



def select_signals(names: Sequence[str], patterns: Sequence[str] | str | None) -> list[int]:
    """Indices of the ``names`` matching any of the glob ``patterns`` (None: all), in the
    order of ``names``. A pattern that matches nothing is refused (a typo would otherwise
    record nothing)."""
    if patterns is None:
        return list(range(len(names)))
    if isinstance(patterns, str):
        patterns = [patterns]
    chosen = set()
    for pat in patterns:
        hits = [i for i, n in enumerate(names) if fnmatch.fnmatchcase(n, pat)]
        if not hits:
            raise UnknownNameError(f"signal pattern {pat!r} matches no signal; signals: {', '.join(names)}")
        chosen.update(hits)
    return sorted(chosen)


def partial_path(path: Path) -> Path:
    """Where the rows of an interrupted or failed run writing ``path`` go:
    ``<stem>.partial<suffix>``."""
    return path.with_name(f"{path.stem}.partial{path.suffix}")


class MemorySink:
    """Rows kept in memory: a preallocated array, a DataFrame at the end.

    The writer fills :attr:`buffer` row by row and calls :meth:`flush` with the number of
    rows written whenever the buffer is full and at the end (the protocol of both sinks).

    Parameters
    ----------
    columns : sequence of str
        Signal names of the recorded columns.
    n_rows : int
        Rows the run will record.
    t0, step : float
        Time [s] of the first row, and the base step [s].
    every : int
        Base steps between rows (row ``i`` is at ``t0 + step * (every * i)``, the master's
        own arithmetic).
    """

    def __init__(self, columns: Sequence[str], n_rows: int, t0: float = 0.0, step: float = 1.0,
                 every: int = 1):
        need = n_rows * (len(columns) + 1) * 8
        avail = available_memory()
        if need > MEMORY_FRACTION * avail:
            raise ResourceError(
                f"recording {n_rows} rows x {len(columns)} signals in memory needs {need / 2**30:.2f} GiB, "
                f"more than half of the {avail / 2**30:.2f} GiB available; record fewer signals, "
                "a longer output_interval, or stream to a Parquet file (run_to_parquet / --stream)")
        self.columns = list(columns)
        self.buffer = np.empty((n_rows, len(columns)))
        self.t0, self.step, self.every, self.n = t0, step, every, 0

    def flush(self, rows: int) -> None:
        """``rows`` more rows of :attr:`buffer` are complete (the buffer holds the whole run,
        so it fills only once)."""
        self.n += rows

    def frame(self) -> pd.DataFrame:
        """The rows recorded so far, indexed by ``time``."""
        times = self.t0 + self.step * (self.every * np.arange(self.n))
        return pd.DataFrame(self.buffer[: self.n], index=pd.Index(times, name="time"), columns=self.columns)

    def finish(self) -> pd.DataFrame:
        """End of a successful run: the whole recording."""
        return self.frame()

    def abort(self) -> pd.DataFrame:
        """End of a failed run: the rows recorded so far."""
        return self.frame()


class ParquetSink:
    """Rows streamed to a Parquet file in chunks (constant memory).

    Parameters
    ----------
    path : path
        Target file; written as ``.<name>.<pid>.tmp`` and renamed at the end.
    columns : sequence of str
        Signal names of the recorded columns.
    n_rows : int
        Rows the run will record (for the disk-space check).
    t0, step, every
        As :class:`MemorySink`.
    chunk_rows : int
        Rows per Parquet row group (default 8192).
    """

    def __init__(self, path, columns: Sequence[str], n_rows: int, t0: float = 0.0, step: float = 1.0,
                 every: int = 1, chunk_rows: int = 8192):
        import pyarrow as pa
        import pyarrow.parquet as pq

        self.path = Path(path)
        if self.path.is_dir():
            raise ConfigurationError(f"{self.path} is a folder; give a .parquet file name")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        need = n_rows * (len(columns) + 1) * 8
        free = shutil.disk_usage(self.path.parent).free
        if need > free:
            raise ResourceError(f"streaming {n_rows} rows x {len(columns)} signals needs up to "
                                f"{need / 2**30:.2f} GiB, but {self.path.parent} has {free / 2**30:.2f} GiB free")
        self.columns = list(columns)
        self.chunk = int(chunk_rows)
        self.buffer = np.empty((self.chunk, len(columns)))
        self.t0, self.step, self.every, self.total = t0, step, every, 0
        self.tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        fields = [pa.field("time", pa.float64())] + [pa.field(c, pa.float64()) for c in self.columns]
        meta = {b"pandas": _pandas_metadata(self.columns)}
        self.schema = pa.schema(fields, metadata=meta)
        self._pa = pa
        self.writer = pq.ParquetWriter(self.tmp, self.schema)

    def flush(self, rows: int) -> None:
        """Write the first ``rows`` rows of :attr:`buffer` as one row group."""
        if not rows:
            return
        pa = self._pa
        times = self.t0 + self.step * (self.every * np.arange(self.total, self.total + rows))
        arrays = [pa.array(times)] + [pa.array(self.buffer[:rows, j]) for j in range(len(self.columns))]
        self.writer.write_table(pa.Table.from_arrays(arrays, schema=self.schema))
        self.total += rows

    def finish(self) -> Path:
        """End of a successful run: close and rename to the target; returns it."""
        self.writer.close()
        os.replace(self.tmp, self.path)
        return self.path

    def abort(self) -> Path | None:
        """End of a failed or interrupted run (after the last :meth:`flush`): keep the rows so far as
        ``<name>.partial.parquet`` (returned), or nothing if no row was recorded."""
        self.writer.close()
        if self.total == 0:
            with contextlib.suppress(OSError):
                os.unlink(self.tmp)
            return None
        target = partial_path(self.path)
        os.replace(self.tmp, target)
        return target


def _pandas_metadata(columns: Sequence[str]) -> bytes:
    """pandas' Parquet metadata for a float frame indexed by ``time``, so that
    ``pandas.read_parquet`` restores the index."""
    import json

    cols = [{"name": c, "field_name": c, "pandas_type": "float64", "numpy_type": "float64",
             "metadata": None} for c in columns]
    cols.append({"name": "time", "field_name": "time", "pandas_type": "float64",
                 "numpy_type": "float64", "metadata": None})
    return json.dumps({"index_columns": ["time"], "column_indexes": [], "columns": cols,
                       "creator": {"library": "pendulum-cosim"}, "pandas_version": pd.__version__}).encode()

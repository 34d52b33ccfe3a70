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

__all__ = ["MemorySink", "ParquetSink", "available_memory", "select_signals", "partial_path"]

#: Fraction of the available memory an in-memory recording may take before it is refused.
MEMORY_FRACTION = 0.5


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


def available_memory() -> int:
    """Bytes of memory available to this process (Linux: MemAvailable; elsewhere a
    conservative 2 GiB)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 2 * 1024**3


def partial_path(path: Path) -> Path:
    """Where the rows of an interrupted or failed run go: ``<stem>.partial<suffix>``."""
    return path.with_name(f"{path.stem}.partial{path.suffix}")


class MemorySink:
    """Rows kept in memory: a preallocated array, a DataFrame at the end.

    Parameters
    ----------
    columns : sequence of str
        Signal names of the recorded columns.
    n_rows : int
        Rows the run will record.
    """

    def __init__(self, columns: Sequence[str], n_rows: int):
        need = n_rows * (len(columns) + 1) * 8
        avail = available_memory()
        if need > MEMORY_FRACTION * avail:
            raise ResourceError(
                f"recording {n_rows} rows x {len(columns)} signals in memory needs {need / 2**30:.2f} GiB, "
                f"more than half of the {avail / 2**30:.2f} GiB available; record fewer signals, "
                "a longer output_interval, or stream to a Parquet file (run_to_parquet / --stream)")
        self.columns = list(columns)
        self.times = np.empty(n_rows)
        self.rows = np.empty((n_rows, len(columns)))
        self.n = 0

    def append(self, t: float, row: np.ndarray) -> None:
        """Record the signals ``row`` at time ``t`` [s]."""
        self.times[self.n] = t
        self.rows[self.n] = row
        self.n += 1

    def frame(self) -> pd.DataFrame:
        """The rows recorded so far, indexed by ``time``."""
        return pd.DataFrame(self.rows[: self.n], index=pd.Index(self.times[: self.n], name="time"),
                            columns=self.columns)

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
    chunk_rows : int
        Rows per Parquet row group (default 8192).
    """

    def __init__(self, path, columns: Sequence[str], n_rows: int, chunk_rows: int = 8192):
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
        self.times = np.empty(self.chunk)
        self.rows = np.empty((self.chunk, len(columns)))
        self.n, self.total = 0, 0
        self.tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        fields = [pa.field("time", pa.float64())] + [pa.field(c, pa.float64()) for c in self.columns]
        meta = {b"pandas": _pandas_metadata(self.columns)}
        self.schema = pa.schema(fields, metadata=meta)
        self._pa = pa
        self.writer = pq.ParquetWriter(self.tmp, self.schema)

    def append(self, t: float, row: np.ndarray) -> None:
        """Record the signals ``row`` at time ``t`` [s]."""
        self.times[self.n] = t
        self.rows[self.n] = row
        self.n += 1
        if self.n == self.chunk:
            self._flush()

    def _flush(self) -> None:
        if not self.n:
            return
        pa = self._pa
        arrays = [pa.array(self.times[: self.n])] + [pa.array(self.rows[: self.n, j])
                                                     for j in range(len(self.columns))]
        self.writer.write_table(pa.Table.from_arrays(arrays, schema=self.schema))
        self.total += self.n
        self.n = 0

    def finish(self) -> Path:
        """End of a successful run: flush, close and rename to the target; returns it."""
        self._flush()
        self.writer.close()
        os.replace(self.tmp, self.path)
        return self.path

    def abort(self) -> Path | None:
        """End of a failed or interrupted run: keep the rows so far as
        ``<name>.partial.parquet`` (returned), or nothing if no row was recorded."""
        try:
            self._flush()
        finally:
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

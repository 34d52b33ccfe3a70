"""Recording of co-simulation signals: the signals matching glob patterns, every ``output_interval``,
in memory (:class:`~cosim.core.recording.MemorySink`) or streamed to a Parquet file in chunks
(:class:`~cosim.core.recording.ParquetSink`); integer signals exactly (``int64``, ``uint64`` for UInt64).
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
from fmu_models.infra.memory import check_fits

from . import crash_guard

__all__ = ["RECORD_LESS", "MemorySink", "ParquetSink", "RowWriter", "partial_path", "select_signals"]

#: What to do when a recording does not fit in memory.
RECORD_LESS = ("record fewer signals (signals=...), a longer output_interval, or stream the rows to a Parquet file "
               "(run_to_parquet; --stream on the command line)")


def select_signals(names: Sequence[str], patterns: Sequence[str] | str | None) -> list[int]:
    """Indices of the ``names`` matching any of the glob ``patterns`` (None: all), in the
    order of ``names``. A pattern that matches nothing is refused (a typo would otherwise
    record nothing)."""
    if patterns is None:
        return list(range(len(names)))
    chosen = set()
    for pat in [patterns] if isinstance(patterns, str) else patterns:
        hits = [i for i, n in enumerate(names) if fnmatch.fnmatchcase(n, pat)]
        if not hits:
            raise UnknownNameError(f"signal pattern {pat!r} matches no signal; signals: {', '.join(names)}")
        chosen.update(hits)
    return sorted(chosen)


def partial_path(path: Path) -> Path:
    """Where the rows of an interrupted or failed run writing ``path`` go:
    ``<stem>.partial<suffix>``."""
    return path.with_name(f"{path.stem}.partial{path.suffix}")


class _Rows:
    """What both sinks keep: the columns, the row buffers (``buffer``; ``ibuffer``, the exact
    integer columns at ``int_positions``) and the rows' times."""

    def __init__(self, columns: Sequence[str], rows: int, t0: float, step: float, every: int,
                 int_columns: dict | None) -> None:
        self.columns = list(columns)
        self.buffer = np.empty((rows, len(columns)))
        self.int_positions = np.array(sorted(int_columns or {}), dtype=np.intp)
        self._int_types = [int_columns[p] for p in self.int_positions]
        self.ibuffer = np.empty((rows, len(self.int_positions)), dtype=np.int64)
        self.t0, self.step, self.every = t0, step, every
        #: the time of the last row, if it is not on the recording grid (a stopped run)
        self.last_time = None

    def _times(self, first: int, rows: int) -> np.ndarray:
        """The times [s] of the rows ``first`` to ``first + rows`` (the master's own arithmetic)."""
        times = self.t0 + self.step * (self.every * np.arange(first, first + rows))
        if self.last_time is not None and rows:
            times[-1] = self.last_time
        return times

    def _exact(self, k: int, rows: int) -> np.ndarray:
        """The first ``rows`` values of the ``k``-th exact integer column (a UInt64 one as uint64)."""
        col = self.ibuffer[:rows, k]
        return col.view(np.uint64) if self._int_types[k] == "UInt64" else col


class MemorySink(_Rows):
    """Rows kept in memory: a preallocated array, a DataFrame at the end.

    The writer fills ``buffer`` (and ``ibuffer``, the exact integer columns at
    ``int_positions``) row by row and calls :meth:`flush` with the number of rows
    written whenever the buffer is full and at the end (the protocol of both sinks).

    Parameters
    ----------
    columns : sequence of str
        Signal names of the recorded columns.
    n_rows : int
        Rows the run will record.
    t0, step : float
        Time [s] of the first row, and the base step [s].
    every : int
        Base steps between rows (row ``i`` is at ``t0 + step * (every * i)``).
    int_columns : dict of int to str, optional
        Columns (positions) of integer signals and their FMI types, kept exactly.
    """

    def __init__(self, columns: Sequence[str], n_rows: int, t0: float = 0.0, step: float = 1.0,
                 every: int = 1, int_columns: dict | None = None):
        check_fits(n_rows * (len(columns) + 1) * 8, f"recording {n_rows} rows x {len(columns)} signals in memory",
                   RECORD_LESS)
        super().__init__(columns, n_rows, t0, step, every, int_columns)
        self.n = 0

    def flush(self, rows: int) -> None:
        """``rows`` more rows of ``buffer`` are complete (it holds the whole run: it fills once)."""
        self.n += rows

    def finish(self) -> pd.DataFrame:
        """The rows recorded so far (after a successful run: the whole recording), indexed by ``time``."""
        df = pd.DataFrame(self.buffer[: self.n], index=pd.Index(self._times(0, self.n), name="time"),
                          columns=self.columns, copy=False)     # the run is over, nothing writes the buffer
        for k, pos in enumerate(self.int_positions):
            df[self.columns[pos]] = self._exact(k, self.n).copy()
        return df

    abort = finish          # a failed run: the rows recorded so far


class ParquetSink(_Rows):
    """Rows streamed to a Parquet file in chunks (constant memory).

    Parameters
    ----------
    path : path
        Target file; written as ``.<name>.<pid>.tmp`` and renamed at the end.
    columns, n_rows, t0, step, every, int_columns
        As :class:`MemorySink` (``n_rows`` for the disk-space check).
    chunk_rows : int
        Rows per Parquet row group (default 8192).
    """

    def __init__(self, path, columns: Sequence[str], n_rows: int, t0: float = 0.0, step: float = 1.0,
                 every: int = 1, chunk_rows: int = 8192, int_columns: dict | None = None):
        import pyarrow as pa
        import pyarrow.parquet as pq

        self.path = Path(path)
        if self.path.is_dir():
            raise ConfigurationError(f"{self.path} is a folder; give a .parquet file name")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        need = 2 * n_rows * (len(columns) + 1) * 8        # the Parquet file and its crash-safe stream
        free = shutil.disk_usage(self.path.parent).free
        if need > free:
            raise ResourceError(f"streaming {n_rows} rows x {len(columns)} signals needs up to "
                                f"{need / 2**30:.2f} GiB, but {self.path.parent} has {free / 2**30:.2f} GiB free")
        super().__init__(columns, int(chunk_rows), t0, step, every, int_columns)
        self.total, self._pa = 0, pa
        self._exact_at = {int(p): k for k, p in enumerate(self.int_positions)}     # column -> exact column
        # pandas' own metadata, so that pandas.read_parquet restores the time index; time the first column
        empty = pd.DataFrame(dict(zip(self.columns, self._arrays(0))), index=pd.Index([], dtype=float, name="time"))
        schema = pa.Schema.from_pandas(empty)
        self.schema = pa.schema([schema.field("time"), *list(schema)[:-1]], metadata=schema.metadata)
        self.tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        self.writer = pq.ParquetWriter(self.tmp, self.schema)
        # every chunk also goes to an Arrow stream, complete on disk once written: if an FMU's
        # code kills the process, the crash guard's salvage turns it into the partial file
        self.ipc_path = self.path.with_name(f".{self.path.name}.{os.getpid()}.arrows")
        self._ipc_file = pa.OSFile(str(self.ipc_path), "wb")
        self._ipc = pa.ipc.new_stream(self._ipc_file, self.schema)
        crash_guard.stream_started(id(self), os.path.abspath(self.ipc_path), os.path.abspath(self.tmp),
                                   os.path.abspath(partial_path(self.path)))     # whatever the cwd then

    def flush(self, rows: int) -> None:
        """Write the first ``rows`` rows of ``buffer`` as one row group."""
        if not rows:
            return
        arrays = (self._times(self.total, rows), *self._arrays(rows))
        table = self._pa.Table.from_arrays([self._pa.array(a) for a in arrays], schema=self.schema)
        self.writer.write_table(table)
        self._ipc.write_table(table)
        self.total += rows

    def _arrays(self, rows: int) -> list[np.ndarray]:
        """The first ``rows`` values of every column, the exact integer ones as :meth:`_exact` gives them."""
        return [self.buffer[:rows, j] if j not in self._exact_at else self._exact(self._exact_at[j], rows)
                for j in range(len(self.columns))]

    def _close(self) -> None:
        """Close the Parquet writer and end the crash-safe stream."""
        self.writer.close()
        crash_guard.stream_ended(id(self))
        with contextlib.suppress(OSError, self._pa.ArrowException):
            self._ipc.close()
            self._ipc_file.close()
        with contextlib.suppress(OSError):
            os.unlink(self.ipc_path)

    def finish(self) -> Path:
        """End of a successful run: close and rename to the target; returns it."""
        self._close()
        os.replace(self.tmp, self.path)
        return self.path

    def abort(self) -> Path | None:
        """End of a failed or interrupted run (after the last :meth:`flush`): keep the rows so far as
        ``<name>.partial.parquet`` (returned), or nothing if no row was recorded."""
        self._close()
        if self.total:
            os.replace(self.tmp, partial_path(self.path))
            return partial_path(self.path)
        with contextlib.suppress(OSError):
            os.unlink(self.tmp)
        return None


class RowWriter:
    """Writes the recorded signals' current values as the next row of a sink's buffer, flushing it
    when full: the Python loop's rows and a stopped run's last row (the native kernel writes its own).

    Parameters
    ----------
    sink : MemorySink or ParquetSink
        Where the rows go (its ``buffer``, and ``ibuffer`` for its exact integer columns).
    values : ndarray, shape (n_signals,)
        Every signal's value.
    integers : ndarray of int64, shape (n_signals,)
        The exact values of the integer and Boolean signals.
    sel : sequence of int
        The recorded signals, one per column of the sink (positions in ``values``).
    """

    __slots__ = ("buffer", "cap", "every_signal", "ibuffer", "int_sel", "integers", "sel", "sink", "values")

    def __init__(self, sink: MemorySink | ParquetSink, values: np.ndarray, integers: np.ndarray,
                 sel: Sequence[int]) -> None:
        self.sink, self.values, self.integers = sink, values, integers
        self.sel = np.asarray(sel, dtype=np.intp)
        self.every_signal = len(self.sel) == len(values)
        self.int_sel = self.sel[sink.int_positions] if len(sink.int_positions) else None
        self.buffer, self.ibuffer, self.cap = sink.buffer, sink.ibuffer, len(sink.buffer)

    def write(self, row: int) -> int:
        """Write the values as row ``row`` of the buffer; returns the next row (0 after
        the full buffer is flushed)."""
        if self.every_signal:
            self.buffer[row] = self.values
        else:
            np.take(self.values, self.sel, out=self.buffer[row])
        if self.int_sel is not None:
            np.take(self.integers, self.int_sel, out=self.ibuffer[row])
        row += 1
        if row == self.cap:
            self.sink.flush(row)
            row = 0
        return row

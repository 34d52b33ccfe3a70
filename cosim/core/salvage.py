"""The salvage program: what a run leaves when an FMU's code killed its process.

Started by the crash guard (:mod:`cosim.core.crash_guard`) from the dying process::

    python -m cosim.core.salvage [--stream IPC TMP PARTIAL]... [--remove FOLDER]...

Each streamed recording's rows so far (the Arrow stream ``IPC`` beside its Parquet file, every
chunk complete once written) become the Parquet file ``PARTIAL``; ``TMP`` and the stream are
removed, and each ``FOLDER``. One line per file kept; what it cannot do is said on stderr, never
a traceback.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import sys
from collections.abc import Sequence

__all__ = ["main", "salvage_stream"]


def salvage_stream(ipc: str, tmp: str, partial: str) -> int:
    """Rows of the Arrow stream ``ipc`` (up to its last complete chunk) written to the
    Parquet file ``partial``; ``ipc`` and ``tmp`` removed, and the temporary Parquet file
    whatever happens. Returns the rows kept."""
    import pyarrow as pa

    rows, part = 0, f"{partial}.{os.getpid()}.tmp"
    try:
        with pa.OSFile(ipc, "rb") as f:
            try:
                reader = pa.ipc.open_stream(f)
            except (pa.ArrowInvalid, OSError):                # not even its schema: no chunk written
                return 0
            rows = _copy_batches(reader, part)
        if rows:
            os.replace(part, partial)
    finally:
        for path in (ipc, tmp, part):                         # part: left only if writing failed
            with contextlib.suppress(OSError):
                os.unlink(path)
    return rows


def _copy_batches(reader, part: str) -> int:
    """The complete batches of ``reader`` into the Parquet file ``part`` (created with the
    first batch); the rows written."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    rows, writer = 0, None
    try:
        while True:
            try:
                batch = reader.read_next_batch()
            except (StopIteration, pa.ArrowInvalid, OSError):   # the end, or the chunk being written
                return rows
            if writer is None:
                writer = pq.ParquetWriter(part, reader.schema)
            writer.write_batch(batch)
            rows += batch.num_rows
    finally:
        if writer is not None:
            writer.close()


def main(argv: Sequence[str] | None = None) -> int:
    """The program (see the module documentation); returns its exit status.

    Parameters
    ----------
    argv : sequence of str, optional
        The arguments (default ``sys.argv[1:]``).
    """
    args = list(sys.argv[1:] if argv is None else argv)
    status = 0
    while args:
        flag = args.pop(0)
        try:
            if flag == "--stream" and len(args) >= 3:
                ipc, tmp, partial = args[:3]
                del args[:3]
                rows = salvage_stream(ipc, tmp, partial)
                print(f"rows so far ({rows}) kept in {partial}" if rows else "no row had been recorded",
                      file=sys.stderr)
            elif flag == "--remove" and args:
                shutil.rmtree(args.pop(0), ignore_errors=True)
            else:
                print(f"salvage: unknown argument {flag!r}", file=sys.stderr)
                status = 2
        except Exception as e:  # noqa: BLE001 - a dying run's last words: said, never a traceback
            print(f"salvage: {type(e).__name__}: {e}", file=sys.stderr)
            status = 1
    return status


if __name__ == "__main__":
    sys.exit(main())

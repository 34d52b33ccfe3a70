"""SIGTERM handled as Ctrl-C by the command lines, so that a killed build or run cleans up
(temporary folders, compiler processes, partial outputs) through the same ``finally``
blocks as an interrupted one."""
from __future__ import annotations

import contextlib
import signal
from collections.abc import Iterator

__all__ = ["terminate_as_interrupt"]


def _raise_interrupt(signum, frame):
    raise KeyboardInterrupt


@contextlib.contextmanager
def terminate_as_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM raises KeyboardInterrupt (in the main thread; elsewhere
    SIGTERM is left alone); the previous handler is restored after it."""
    try:
        previous = signal.signal(signal.SIGTERM, _raise_interrupt)
    except ValueError:                     # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)

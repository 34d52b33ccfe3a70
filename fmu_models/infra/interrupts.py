"""Signals: SIGTERM handled as Ctrl-C by the command lines, so that a killed build or run cleans up as an
interrupted one; and Ctrl-C/SIGTERM deferred over statements that must not be cut in two."""
from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

__all__ = ["Deferred", "terminate_as_interrupt"]


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


class Deferred:
    """Ctrl-C and SIGTERM noted instead of raised until :meth:`~.Deferred.release` (main thread only:
    elsewhere Python raises no signal exceptions)."""

    def __init__(self):
        self.noted, self.old = [], {}
        if threading.current_thread() is threading.main_thread():
            for s in (signal.SIGINT, signal.SIGTERM):
                self.old[s] = signal.signal(s, lambda signum, frame: self.noted.append(signum))

    def release(self) -> None:
        """Restore the handlers; a signal noted meanwhile is raised now as the old handler
        would have (KeyboardInterrupt for Ctrl-C, or for SIGTERM under
        :func:`terminate_as_interrupt`)."""
        old, self.old = self.old, {}
        for s, handler in old.items():
            signal.signal(s, handler)
        if self.noted:
            signum = self.noted[0]
            self.noted = []
            handler = old.get(signum)
            if callable(handler):
                handler(signum, None)
            elif handler != signal.SIG_IGN:
                signal.raise_signal(signum)

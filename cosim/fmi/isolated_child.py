"""The child process of an isolated FMU (:mod:`cosim.fmi.isolated`): builds the component on the
parent's unpacked folder and answers its requests until told to close."""
from __future__ import annotations

import contextlib
import ctypes
import os
import pickle
import signal
import struct
import sys

import numpy as np

from ..core import crash_guard
from ..core.component import StopRequest
from .fmu_component import FMUComponent
from .isolated import HEAD, REPLY, read_exactly, write_all

__all__ = ["main"]


def _serve(fd_in: int, fd_out: int) -> None:
    head = read_exactly(fd_in, HEAD.size + 4)
    if not head:
        return
    length = struct.unpack_from("<I", head, HEAD.size)[0]
    setup = pickle.loads(read_exactly(fd_in, length))
    n_out = 0

    def reply(status: bytes = b"K", payload: bytes = b"") -> None:
        out = values[n_in:].tobytes() + ints[n_in:].tobytes() if status == b"K" else bytes(16 * n_out)
        write_all(fd_out, REPLY.pack(status, len(payload)) + payload + out)

    def fail(e: BaseException) -> None:
        if isinstance(e, StopRequest):
            reply(b"S", pickle.dumps((e.component, e.time, e.reason)))
        else:
            reply(b"E", pickle.dumps((type(e).__name__, str(e))))

    try:
        comp = FMUComponent(**setup["arguments"])
        comp.use_unpacked(setup["directory"])
        comp.use_inputs(setup["inputs"], setup["sources"])
        n_in, n_out = len(comp.connected_inputs), len(comp.output_names)
        comp.reset(setup["t0"])
        values = np.zeros(n_in + n_out)
        ints = np.zeros(n_in + n_out, dtype=np.int64)
        out_fn, upd_fn = comp.bind(values, slice(0, n_in), slice(n_in, n_in + n_out), ints)
        out_fn(setup["t0"])
    except BaseException as e:  # noqa: BLE001 - every failure goes back to the parent
        fail(e)
        return
    reply()
    try:
        while head := read_exactly(fd_in, HEAD.size + 16 * n_in):
            op, t = HEAD.unpack_from(head)
            if op == b"C":
                break
            values[:n_in] = np.frombuffer(head, np.float64, n_in, HEAD.size)
            ints[:n_in] = np.frombuffer(head, np.int64, n_in, HEAD.size + 8 * n_in)
            try:
                if op == b"O":
                    out_fn(t)
                else:
                    upd_fn(t)
                    if not comp.feedthrough:         # the outputs at t + period, sent back now
                        out_fn(t + comp.period)
            except BaseException as e:  # noqa: BLE001
                fail(e)
            else:
                reply()
    finally:
        comp.close()


def main() -> None:
    """The child process: serve one FMU on stdin/stdout until told to close."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    crash_guard.disable()          # the parent names a crash here as a named error, with its results
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None).prctl(1, signal.SIGKILL)          # PR_SET_PDEATHSIG: die with the parent
    fd_in, fd_out = sys.stdin.buffer.fileno(), os.dup(sys.stdout.buffer.fileno())
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())        # FMU prints go to stderr, not the pipe
    try:
        _serve(fd_in, fd_out)
    except (OSError, EOFError, pickle.UnpicklingError, struct.error) as e:   # the parent went away
        print(f"cosim.fmi.isolated_child: {type(e).__name__}: {e}", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()

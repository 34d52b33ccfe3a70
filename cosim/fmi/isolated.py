"""An FMU in a process of its own (``isolate=True``): a crash of its code ends the run with
an :class:`~fmu_models.errors.FMUError` naming the FMU, the call, the time and the signal.
The parent (:class:`RemoteFMU`) and the child (:mod:`cosim.fmi.isolated_child`) talk over a
pipe as the third-party FMUs page of the documentation says (crash isolation)."""
from __future__ import annotations

import contextlib
import os
import pickle
import select
import signal
import struct
import subprocess
import sys

import numpy as np

from fmu_models import errors as _errors
from fmu_models.errors import FMUError

from ..core.component import StopRequest

__all__ = ["HEAD", "REPLY", "RemoteFMU", "read_exactly", "write_all"]

#: A request's head, the op byte and the time ``t`` [s].
HEAD = struct.Struct("<cd")
#: A reply's head, the status byte and the length of its pickled payload.
REPLY = struct.Struct("<cI")
#: Seconds a child may take to end its instance and exit before it is killed.
CLOSE_TIMEOUT = 2.0
#: Seconds the parent waits on the child's pipe between checks for Ctrl-C (a signal that
#: the kernel hands to another thread of the parent does not interrupt a blocking read).
POLL = 0.25 if os.name == "posix" else None


def read_exactly(fd: int, n: int, poll: float | None = None) -> bytes:
    """Exactly ``n`` bytes from ``fd`` (b"" if the other end closed first); with ``poll`` [s]
    the wait returns to the interpreter that often, so that Ctrl-C is raised even while the
    other end never answers."""
    chunks, got = [], 0
    while got < n:
        if poll is not None:
            while not select.select([fd], [], [], poll)[0]:
                pass                       # pending signal handlers run between the waits
        b = os.read(fd, n - got)
        if not b:
            return b""
        chunks.append(b)
        got += len(b)
    return b"".join(chunks)


def write_all(fd: int, data: bytes) -> None:
    """Write all of ``data`` to ``fd`` (a pipe may take it in pieces)."""
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def _reap(proc: subprocess.Popen) -> int:
    """The exit code of ``proc``, killed if it does not exit in :data:`CLOSE_TIMEOUT` s."""
    try:
        return proc.wait(timeout=CLOSE_TIMEOUT)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.wait()


class RemoteFMU:
    """The parent's side of an isolated FMU.

    Parameters
    ----------
    component : FMUComponent
        The component (its arguments, connected inputs, sources and unpacked folder).
    t0 : float
        The start time [s]; the child instantiates and initialises the FMU at once.

    Raises
    ------
    FMUError
        The child could not start, or the FMU failed or crashed while initialising.
    """

    def __init__(self, component, t0: float):
        self.name = component.name
        self.fmu_name = component.path.name
        self.feedthrough = bool(component.feedthrough)
        self._stale = False                  # the outputs the last update returned are not current
        self.n_in, self.n_out = len(component.connected_inputs), len(component.output_names)
        p = component.description.prefix
        self._step_calls = (f"setting the inputs or {p}DoStep" if component.interface == "cs" else
                            f"setting the inputs or integrating ({p}GetDerivatives, events, ...)")
        self._output_calls = f"setting the feed-through inputs or getting the outputs ({p}Set*/Get*)"
        init = "fmiInitialize" if component.version == 1 else "ExitInitializationMode"
        setup = {"arguments": component.arguments, "directory": component.unpacked,
                 "inputs": list(component.connected_inputs), "sources": component.input_sources, "t0": float(t0)}
        self.proc = subprocess.Popen([sys.executable, "-m", "cosim.fmi.isolated_child"], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, bufsize=0, close_fds=True)
        self._to, self._from = self.proc.stdin.fileno(), self.proc.stdout.fileno()
        self.outputs = np.zeros(self.n_out)
        self.int_outputs = np.zeros(self.n_out, dtype=np.int64)
        payload = pickle.dumps(setup)
        self._call(f"instantiation or initialisation ({p}Instantiate .. {init})", t0,
                   HEAD.pack(b"R", t0) + struct.pack("<I", len(payload)) + payload)

    # ------------------------------------------------------------------ the pipe
    def _died(self, what: str, t: float) -> FMUError:
        code = _reap(self.proc)
        how = (f"signal {signal.Signals(-code).name}" if code < 0 and -code in signal.Signals._value2member_map_
               else f"exit status {code}")
        return FMUError(f"{self.name}: the process running {self.fmu_name} died ({how}) during {what} at "
                        f"t = {t:g} s")

    def _call(self, what: str, t: float, data: bytes) -> None:
        try:
            write_all(self._to, data)
            head = read_exactly(self._from, REPLY.size, POLL)
        except (BrokenPipeError, ConnectionResetError):
            head = b""
        if not head:
            raise self._died(what, t) from None
        status, length = REPLY.unpack(head)
        body = read_exactly(self._from, length + 16 * self.n_out, POLL)
        if len(body) < length:
            raise self._died(what, t)
        if status == b"K":
            self.outputs[:] = np.frombuffer(body, dtype=np.float64, count=self.n_out)
            self.int_outputs[:] = np.frombuffer(body, dtype=np.int64, count=self.n_out, offset=8 * self.n_out)
            return
        info = pickle.loads(body[:length])
        if status == b"S":
            self._stale = True               # the outputs at the stop time are asked for afresh
            raise StopRequest(*info)
        kind, message = info
        cls = getattr(_errors, kind, None)
        if not (isinstance(cls, type) and issubclass(cls, _errors.PendulumCosimError)):
            cls = FMUError
        raise cls(message)

    @staticmethod
    def _request(op: bytes, t: float, values, integers, index) -> bytes:
        return (HEAD.pack(op, t) + np.ascontiguousarray(values[index], dtype=np.float64).tobytes()
                + np.ascontiguousarray(integers[index], dtype=np.int64).tobytes())

    # ------------------------------------------------------------------ the binding
    def bind(self, values: np.ndarray, inputs, outputs, integers: np.ndarray | None = None):
        """Output and update closures (:class:`~cosim.core.component.FastBinding`), each one round trip to the child."""
        if integers is None:
            integers = np.zeros(len(values), dtype=np.int64)
        out_idx = np.arange(len(values))[outputs]
        feedthrough = self.feedthrough

        def output_fn(t: float) -> None:
            if feedthrough or self._stale:
                self._call(self._output_calls, t, self._request(b"O", t, values, integers, inputs))
                self._stale = False
            values[out_idx] = self.outputs
            integers[out_idx] = self.int_outputs

        def update_fn(t: float) -> None:
            self._call(self._step_calls, t, self._request(b"U", t, values, integers, inputs))
        return output_fn, update_fn

    def close(self) -> None:
        """Ask the child to end its instance; kill it if it does not exit in :data:`CLOSE_TIMEOUT` s. Safe twice."""
        proc = self.proc
        if proc.poll() is None:
            with contextlib.suppress(OSError):
                write_all(self._to, HEAD.pack(b"C", 0.0) + bytes(16 * self.n_in))
            _reap(proc)
        for f in (proc.stdin, proc.stdout):
            with contextlib.suppress(OSError):
                f.close()

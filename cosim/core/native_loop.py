"""A run's loop in the native kernel, and the driver that answers the kernel's events.

The kernel (:mod:`cosim.core.native`) runs the base steps of a :class:`~cosim.core.run.Run`
and records its rows itself; it returns to Python with an event when it needs Python:

* ``EV_PY``: a call that runs in Python (a Python component, Model Exchange, an isolated
  FMU, integer ports, an algebraic loop), made as the Python loop makes it; the kernel
  resumes after it;
* ``EV_HOOK``: a filter's Python hook after its step, then its operation pointed at the
  arrays the hook replaced; the kernel resumes after it;
* ``EV_REFILL``: a noise stream drawn to its end: its next block is drawn, and the kernel
  resumes at the same operation;
* ``EV_CHUNK``: a chunk of base steps is done (about :data:`CHUNK_SECONDS` of wall time, at
  most :data:`CHUNK` steps): the progress bar moves, Ctrl-C is seen;
* ``EV_FLUSH``: the record buffer is full: the sink writes it.

The loop ends with ``EV_DONE`` (every base step ran), ``EV_NONFINITE`` (a signal became NaN
or inf in the block that ended), ``EV_FAIL`` (a native operation failed: its own handler
raises the error the Python path raises) or a component's stop request. Whichever way it
ends, also by an exception, the run's position and the state the kernel keeps for Python
objects (a filter's current state copy and step count) are first handed back to them.
"""
from __future__ import annotations

import ctypes
import time

import numpy as np

from fmu_models.errors import CosimError

from . import crash_guard
from .component import StopRequest
from .native import EV_CHUNK, EV_DONE, EV_FAIL, EV_FLUSH, EV_HOOK, EV_NONFINITE, EV_PY, EV_REFILL, KState

__all__ = ["BLOCK", "CHUNK", "CHUNK_SECONDS", "NativeLoop"]

#: Base steps between checks that every signal is finite (and progress updates), in both loops.
BLOCK = 64
#: Most base steps the native kernel runs before it returns to Python (Ctrl-C, progress);
#: fewer when they take longer than :data:`CHUNK_SECONDS`.
CHUNK = 64 * BLOCK
#: Wall time [s] the native kernel aims at between two returns to Python.
CHUNK_SECONDS = 0.02


class NativeLoop:
    """A run's base steps in the native kernel (see the module documentation).

    Parameters
    ----------
    run : cosim.core.run.Run
        The run, set up, with its native program and kernel.
    """

    def __init__(self, run) -> None:
        self.run, self.program = run, run.program
        rec, program = run.writer, self.program
        self.sel = np.ascontiguousarray(rec.sel, dtype=np.int64)          # kept alive with the state
        self.isel = np.ascontiguousarray(rec.int_sel if rec.int_sel is not None else np.zeros(0), dtype=np.int64)
        arrays = dict(values=run.values, integers=run.integers, buf=rec.buffer, ibuf=rec.ibuffer, sel=self.sel,
                      isel=self.isel, pattern=program.pattern, out_start=program.out_start, out_len=program.out_len,
                      upd_start=program.upd_start, upd_len=program.upd_len)
        self.kst = KState(t0=run.t0, h=run.h, n=run.n, m=run.m, L=len(run.schedule), cap=rec.cap, block=BLOCK,
                          ncols=rec.buffer.shape[1], nint=rec.ibuffer.shape[1], nsig=len(run.values), kstop=BLOCK,
                          ops=ctypes.addressof(program.ops), **{k: a.ctypes.data for k, a in arrays.items()})
        self.done, self.chunk, self.since = 0, BLOCK, 0.0      # steps shown by the bar; the chunk's length, start

    def loop(self) -> None:
        """Run the kernel to the end of the run, answering its events."""
        run, kst, program = self.run, self.kst, self.program
        calls, updates, t0, h = program.calls, program.updates, run.t0, run.h
        step, state = run.kernel.kernel_run, ctypes.byref(kst)
        crash_guard.set_step_counter(ctypes.addressof(kst) + KState.k.offset, t0, h)
        self.since = time.perf_counter()
        run.phase = "output"
        try:
            for sync in program.syncs_in:
                sync()
            while True:
                event = step(state)
                if event == EV_PY:
                    at = kst.at
                    run.failing = f = calls[at]
                    try:
                        f(t0 + kst.k * h)
                    except StopRequest as request:
                        if not updates[at]:
                            raise
                        run.stop = request
                        break
                    kst.pc += 1
                elif event in (EV_HOOK, EV_REFILL):
                    self._hook(event == EV_HOOK)
                elif event == EV_CHUNK:
                    self._chunk()
                elif event == EV_FLUSH:
                    run.sink.flush(kst.cap)
                    kst.j = 0
                else:
                    break
        finally:
            run.k, run.j, run.jb, run.k0 = kst.k, kst.j, kst.jb, kst.k0
            for sync in program.syncs_out:
                sync()
        self._end(event)

    def _hook(self, after_step: bool) -> None:
        """The Python hook of the operation the kernel stopped at: a filter's after its step
        (``after_step``: the operation is then rebound, the kernel resumes after it), or a
        noise stream's refill (the kernel resumes at the operation)."""
        at, program = self.kst.at, self.program
        self.run.failing, meta = program.calls[at], program.meta[at]
        meta.hook()
        if after_step:
            if meta.rebind is not None:
                meta.rebind(program.ops[at])
            self.kst.pc += 1

    def _chunk(self) -> None:
        """A chunk done: the bar moves, and the next chunk's length aims at :data:`CHUNK_SECONDS`."""
        kst = self.kst
        self.run.bar.update(kst.k - self.done)
        now = time.perf_counter()
        ratio = CHUNK_SECONDS / max(now - self.since, 1e-6)
        self.chunk = max(BLOCK, min(CHUNK, int(self.chunk * min(ratio, 4.0)) // BLOCK * BLOCK))
        self.done, self.since, kst.kstop = kst.k, now, kst.k + self.chunk

    def _end(self, event: int) -> None:
        """The end of the loop, by ``event`` (the position handed back): the bar's last steps,
        the non-finite signal raised, or the failed call's error raised or the stop request
        finished."""
        run, kst, program = self.run, self.kst, self.program
        if event == EV_DONE:
            run.bar.update(run.n + 1 - self.done)
            return
        if event == EV_NONFINITE:                   # checked before base step k, or after the last one
            run.k = run.n if kst.phase == 3 else run.k - 1
            raise run.nonfinite_error()
        at = kst.at
        run.failing, run.phase = program.calls[at], "update" if program.updates[at] else "output"
        if event == EV_FAIL:
            op = program.ops[at]
            try:
                program.meta[at].fail(op, run.t0 + run.k * run.h)
                raise CosimError(f"native call of {run.owner.get(run.failing, '?')} failed with status {op.status}")
            except StopRequest as request:
                if run.phase != "update":
                    raise
                run.stop = request
        run.finish_stop()
        run.check_finite()
        run.bar.update(run.k + 1 - self.done)

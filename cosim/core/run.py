"""One run of a co-simulation (:class:`~cosim.core.run.Run`): its state, its setup, the Python loop
(the native one is :class:`~cosim.core.native_loop.NativeLoop`, the same results bit for bit) and
the run's end, whatever happened.
"""
from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from fmu_models.errors import ConfigurationError, CosimError, Interrupted, ResourceError

from . import crash_guard
from .algebraic import LoopSolver
from .component import StopRequest, bind_protocol
from .native import build_program, load_kernel
from .native_loop import BLOCK, NativeLoop
from .recording import RECORD_LESS, MemorySink, ParquetSink, RowWriter

__all__ = ["Run"]


class Run:
    """One run of a co-simulation, made by :meth:`Cosimulation.run <cosim.core.master.Cosimulation.run>`
    and ``run_to_parquet``; :meth:`execute` runs it.

    Parameters
    ----------
    cosim : cosim.core.master.Cosimulation
        What runs: its components, signal layout and schedule.
    sink : MemorySink or ParquetSink
        Where the rows go.
    sel : sequence of int
        The recorded signals (positions in ``cosim.signal_names``).
    n, m : int
        Base steps of the run, and between two rows.
    t0 : float
        Start time [s].
    progress : bool or None
        Show a progress bar (None: when the run takes more than 2 s).

    Attributes
    ----------
    k, j, k0, jb : int
        The position: base step, next row, the block's first base step and its first row.
    phase : str
        ``reset``, ``bind``, ``output`` or ``update``; ``failing`` is the call being made.
    """

    def __init__(self, cosim, sink: MemorySink | ParquetSink, sel: Sequence[int], n: int, m: int, t0: float,
                 progress: bool | None) -> None:
        if cosim.engine == "native" and load_kernel()[0] is None:     # refused before anything starts
            sink.abort()
            raise ConfigurationError(f"engine='native': the native kernel is not available ({load_kernel()[1]})")
        self.cosim, self.sink, self.n, self.m, self.t0, self.h = cosim, sink, n, m, t0, cosim.step_size
        self.progress, self.jacobi = progress, cosim.order == "jacobi"
        self.values = np.zeros(len(cosim.signal_names))
        self.integers = np.zeros(len(self.values), dtype=np.int64)
        self.source = np.zeros_like(self.values) if self.jacobi else self.values
        self.writer = RowWriter(sink, self.values, self.integers, sel)
        self.k = self.j = self.jb = self.k0 = 0
        self.phase, self.failing, self.stop = "reset", None, None
        self.bound, self.owner, self.schedule = {}, {}, []
        self.program = self.kernel = self.bar = self.board = None
        self.ran_ahead: dict = {}           # update calls another thread made past a failed one (native_loop)
        self.timings: dict[str, float] = {}
        cosim.timings, cosim.stopped, cosim.clock_ticks = self.timings, None, None
        cosim.stepping = "serial (the Python loop)"

    def execute(self):
        """The run, from its setup to its end; returns the sink's result (the DataFrame, or
        the Parquet file's path) and raises as :meth:`~cosim.core.master.Cosimulation.run` says."""
        from tqdm.auto import tqdm

        clock = time.perf_counter()
        try:
            self.setup()
            self.timings["setup"] = time.perf_counter() - clock
            clock = time.perf_counter()
            self.bar = tqdm(total=self.n + 1, unit="step", delay=0 if self.progress else 2.0, leave=False,
                            disable=self.progress is False, desc="co-simulation", mininterval=0.5)
            if self.program is None:
                self.python_loop()
            else:
                NativeLoop(self).loop()
            self.sink.flush(self.j)
            self.timings["loop"] = time.perf_counter() - clock
            return self.finish()
        except KeyboardInterrupt:
            partial = self.abort()
            raise Interrupted(f"interrupted at t = {self.t0 + self.k * self.h:g} s"
                              + (f"; rows so far in {partial}" if isinstance(partial, Path) else ""),
                              partial) from None
        except CosimError as e:
            if e.results is None:
                e.results = self.abort()
            raise
        except MemoryError as e:
            error = ResourceError(f"the run ran out of memory at t = {self.t0 + self.k * self.h:g} s ({e}); "
                                  f"{RECORD_LESS}")
            error.results = self.abort()          # the rows so far, as a failed run keeps them
            raise error from None
        except Exception as e:
            raise self.failure(e) from e
        finally:
            self.teardown()

    # ---------------------------------------------------------------- setup
    def setup(self) -> None:
        """Reset and bind every component (the clocked ones attached to the clock board), list
        the schedule and build the native program (or None)."""
        cs = self.cosim
        for c in cs.components:
            self.failing = c
            c.reset(self.t0)
        self.phase = "bind"
        if cs.clock_plan is not None:
            self.board = cs.clock_plan.board(self.values, self.integers, cs._slots)
            for c in cs.clock_plan.members:
                self.failing = c
                c.attach_clocks(self.board)
        self.bound = {c.name: self._bind(c) for c in cs.components}
        self.owner = {fn: name for name, calls in self.bound.items() for fn in calls}
        dues = [frozenset(c.name for c in cs.components if i % cs._ratio[c.name] == 0) for i in range(cs._hyper)]
        entries = {due: self._entry(due) for due in dict.fromkeys(dues)}      # one per set of due components
        self.schedule = [entries[due] for due in dues]
        self.program = self._program()

    def _bind(self, c) -> tuple:
        """``(output call, update call)`` of ``c`` on the signal arrays (its fast path, or the protocol's)."""
        cs = self.cosim
        inputs, outputs = cs._inputs[c.name], cs._out_slices[c.name]
        try:                # hasattr(c, "bind") = isinstance(c, FastBinding), faster
            if self.source is self.values and hasattr(c, "bind"):
                return c.bind(self.values, inputs, outputs, self.integers)
            return bind_protocol(c, self.values, self.source, inputs, outputs, self.integers)
        except CosimError:
            raise
        except Exception as e:
            raise CosimError(f"component {c.name!r} failed before the run (bind): {e}", c.name) from e

    def _entry(self, due: frozenset) -> tuple[tuple, tuple]:
        """The output calls (in evaluation order) and the update calls of the components ``due``."""
        cs = self.cosim
        outs = []
        for g in cs.schedule:
            units = [u for u in g.units if u.comp.name in due]
            if units and g.loop:
                signals = np.r_[tuple(cs._out_slices[u.comp.name] for u in units)]
                outs.append(LoopSolver(units, [self.bound[u.comp.name][0] for u in units], signals, self.values,
                                       cs.loop_tolerance, cs.loop_max_iter, cs.loop_solver))
            else:
                outs.extend(self.bound[u.comp.name][0] for u in units)
        return tuple(outs), tuple(self.bound[c.name][1] for c in cs._update_order if c.name in due)

    def _program(self):
        """The native kernel's program of the run, or None for the Python loop."""
        if self.cosim._whole_run_python() is None:
            self.kernel = load_kernel()[0]
        if self.kernel is None:
            return None
        program = build_program(self.schedule)
        nothing_native = program.n_native == 0 and self.cosim.engine == "auto"      # the Python loop costs less
        return None if nothing_native else program

    # ---------------------------------------------------------------- the Python loop
    def python_loop(self) -> None:
        """The base steps in Python, by blocks of :data:`~cosim.core.native_loop.BLOCK`: the due
        components' outputs, the row (every ``m`` base steps), their updates."""
        n, m, t0, h, L = self.n, self.m, self.t0, self.h, len(self.schedule)
        schedule, values, source, jacobi = self.schedule, self.values, self.source, self.jacobi
        record, bar = self.writer.write, self.bar
        guarded = crash_guard.active()               # an FMU's crash names the time
        step_now = np.zeros(1, dtype=np.int64)
        if guarded:
            crash_guard.set_step_counter(step_now.ctypes.data, t0, h)
        k = j = 0
        phase, f = self.phase, self.failing
        for k0 in range(0, n + 1, BLOCK):
            k1 = min(k0 + BLOCK, n + 1)
            jb = j                                  # the block's first row in the buffer
            try:
                for k in range(k0, k1):
                    if guarded:
                        step_now[0] = k
                    t = t0 + k * h
                    outs, upds = schedule[k % L]
                    if jacobi:
                        source[:] = values
                    phase = "output"
                    for f in outs:
                        f(t)
                    if k % m == 0:
                        j = record(j)
                    if k == n:
                        break
                    phase = "update"
                    try:
                        for f in upds:
                            f(t)
                    except StopRequest as request:
                        self.stop = request
                        break
            finally:
                self.k, self.j, self.jb, self.k0, self.phase, self.failing = k, j, jb, k0, phase, f
            if self.stop is not None:
                self.finish_stop()
            self.check_finite()
            bar.update(k1 - k0)
            if self.stop is not None:
                return

    # ---------------------------------------------------------------- the end
    def finish(self):
        """The end of a run that did not fail: the sink's result, with the stop request (if a
        component asked) in ``attrs["stopped"]`` of a DataFrame."""
        result, stop = self.sink.finish(), self.stop
        if stop is not None:
            self.cosim.stopped = stop
            if isinstance(result, pd.DataFrame):
                result.attrs["stopped"] = {"component": stop.component, "time": stop.time, "reason": stop.reason}
        return result

    def finish_stop(self) -> None:
        """A component (``failing``) asked to stop while stepping from ``t_k``: the others finish
        the instant, then the last row is the instant ``t_{k+1}`` if it stops there (within
        rounding), else the stopping component's outputs at its stop time (the others held)."""
        request, k, L = self.stop, self.k, len(self.schedule)
        t = self.t0 + k * self.h
        t_next = t + self.h
        upds = self.schedule[k % L][1]
        for g in upds[upds.index(self.failing) + 1:]:
            with contextlib.suppress(StopRequest):
                self.ran_ahead.get(g, g)(t)         # an update a thread already made: not again
        ts = request.time
        if not np.isfinite(ts) or abs(ts - t_next) <= 1e-9 * max(1.0, abs(t_next)) or ts > t_next:
            ts = t_next
            if self.jacobi:
                self.source[:] = self.values
            for g in self.schedule[(k + 1) % L][0]:
                g(t_next)
            self.sink.last_time = None
        else:
            if request.component in self.bound:
                self.bound[request.component][0](ts)
            self.sink.last_time = ts
        request.time = ts
        logging.getLogger("cosim").warning("%s asked to stop the run at t = %g s%s; the run ends there",
                                           request.component, ts, f" ({request.reason})" if request.reason else "")
        self.j = self.writer.write(self.j)

    def abort(self):
        """The rows recorded so far, flushed: the sink's partial result (see its ``abort``)."""
        self.sink.flush(self.j)
        return self.sink.abort()

    def failure(self, error: Exception) -> CosimError:
        """The CosimError ending the run for ``error`` of the call being made (component, time, the
        rows so far), or naming a NaN or inf signal that came before it (the root cause)."""
        if self.phase != "reset" and not self.finite():
            return self.nonfinite_error()
        results = self.abort()
        t = self.t0 + self.k * self.h
        name = getattr(self.failing, "name", None) or self.owner.get(self.failing, "?")
        where = f"component {name!r} failed at t = {t:g} s" + ("" if self.phase != "reset" else " (reset)")
        return CosimError(f"{where}: {error}", name, t, results)

    def _block_rows(self) -> list[tuple[int, int]]:
        """The buffer's rows since the block began, ``(first, end)`` pairs (two if it was flushed meanwhile)."""
        return [(self.jb, self.j)] if self.j >= self.jb else [(self.jb, len(self.sink.buffer)), (0, self.j)]

    def finite(self) -> bool:
        """Whether every signal, and every row recorded since the block began, is finite."""
        buf = self.sink.buffer
        return bool(np.isfinite(self.values).all()) and all(np.isfinite(buf[a:b]).all() for a, b in self._block_rows())

    def check_finite(self) -> None:
        """Raise the CosimError of :meth:`nonfinite_error` if a signal is NaN or inf."""
        if not self.finite():
            raise self.nonfinite_error()

    def nonfinite_error(self) -> CosimError:
        """The CosimError for the first NaN or inf of the base steps ``k0..k``: in a row recorded
        since the block began, named with its time (the results end just before its row), else
        among the current values, named with the window ``t_k0..t_k``."""
        buf, h, m, t0 = self.sink.buffer, self.h, self.m, self.t0
        kr = -(-self.k0 // m) * m                            # the base step of row jb
        for lo, hi in self._block_rows():
            bad = ~np.isfinite(buf[lo:hi])
            if bad.any():
                row, col = (int(v[0]) for v in np.nonzero(bad))
                t_bad, sig, value = t0 + (kr + row * m) * h, self.sink.columns[col], buf[lo + row, col]
                self.j = lo + row if hi == self.j else 0           # the rows before it are kept
                return CosimError(f"signal {sig} is {value} at t = {t_bad:g} s (component {sig.split('.')[0]!r})",
                                  sig.split(".")[0], t_bad, self.abort())
            kr += (hi - lo) * m
        col = int(np.flatnonzero(~np.isfinite(self.values))[0])
        sig, t_bad = self.cosim.signal_names[col], t0 + self.k * h
        return CosimError(f"signal {sig} is {self.values[col]} between t = {t0 + self.k0 * h:g} s and t = "
                          f"{t_bad:g} s (component {sig.split('.')[0]!r})", sig.split(".")[0], t_bad, self.abort())

    def teardown(self) -> None:
        """Whatever happened: the bar closed, the clock activations kept, every component's
        instants counted (``n_samples``) and every component closed."""
        cs = self.cosim
        crash_guard.set_step_counter(None)
        if self.bar is not None:
            self.bar.close()
        if self.board is not None:
            cs.clock_ticks = self.board.ticks()
        reached = self.k if self.phase in ("output", "update") else -1
        for c in cs.components:              # the instants each component computed
            c.n_samples = reached // cs._ratio[c.name] + 1 if reached >= 0 else 0
        clock = time.perf_counter()
        for c in cs.components:
            c.close()
        self.timings["teardown"] = time.perf_counter() - clock

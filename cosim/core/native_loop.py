"""A run's loop in the native kernel (:class:`~cosim.core.native_loop.NativeLoop`, answering the kernel's
events) and which thread steps each FMU (:class:`~cosim.core.native_loop.Stepping`), both described in the
co-simulation page of the documentation (the native kernel, parallel stepping).
"""
from __future__ import annotations

import ctypes
import os
import time

import numpy as np

from fmu_models.errors import CosimError

from . import crash_guard
from .component import StopRequest
from .native import EV_CHUNK, EV_DONE, EV_FAIL, EV_FLUSH, EV_HOOK, EV_NONFINITE, EV_PY, EV_REFILL, STEP_KINDS, KState

__all__ = ["BLOCK", "CHUNK", "CHUNK_SECONDS", "CLEAR_RATIO", "HOPELESS_RATIO", "KEEP_RATIO", "MEASURE_BLOCKS",
           "MEASURE_SECONDS", "MIN_GAIN", "RECHECK", "RECHECK_SECONDS", "NativeLoop", "Stepping"]

#: Base steps between checks that every signal is finite (and progress updates), in both loops.
BLOCK = 64
#: Most base steps the native kernel runs before it returns to Python (Ctrl-C, progress);
#: fewer when they take longer than :data:`CHUNK_SECONDS`.
CHUNK = 64 * BLOCK
#: Wall time [s] the native kernel aims at between two returns to Python.
CHUNK_SECONDS = 0.02
#: ``threads="auto"``: the least gain [s per base step] parallel stepping must have measured
#: to be kept (below it, the gain is within the timing's own noise).
MIN_GAIN = 0.2e-6
#: ``threads="auto"``: the threads are kept if they took at most this fraction of the serial time.
KEEP_RATIO = 0.9
#: Wall time [s] the threads are measured for (at least one block), so that a preemption or a page
#: fault does not decide it; less when they took longer than the serial time or under :data:`CLEAR_RATIO` of it.
MEASURE_SECONDS = 0.002
#: The measured fraction of the serial time below which the threads are kept at once.
CLEAR_RATIO = 0.6
#: ``threads="auto"``: the threads are left after the warming block if they took more than
#: this many times the serial time in it.
HOPELESS_RATIO = 2.0
#: Blocks in a measured chunk (after a measurement's first block, which warms the threads, not counted).
MEASURE_BLOCKS = 4
#: ``threads="auto"``: base steps after a measurement until the next (twice as many after each)...
RECHECK = 16 * BLOCK
#: ... and at least this wall time [s], so that measuring stays a small share of a run.
RECHECK_SECONDS = 0.5


class _DlInfo(ctypes.Structure):
    _fields_ = [("fname", ctypes.c_char_p), ("base", ctypes.c_void_p), ("sname", ctypes.c_char_p),
                ("saddr", ctypes.c_void_p)]


def _library_base(address: int) -> int:
    """The load address of the library holding the function at ``address`` (itself if unknown)."""
    info = _DlInfo()
    try:
        found = ctypes.CDLL(None).dladdr(ctypes.c_void_p(address), ctypes.byref(info))
    except (OSError, AttributeError):
        found = 0
    return info.base if found and info.base else address


def _seconds(value: float) -> str:
    """A duration [s] in words (µs or ms)."""
    return f"{value * 1e3:.3g} ms" if value >= 1e-3 else f"{value * 1e6:.3g} µs"


class Stepping:
    """Which thread steps each FMU update of a run (the co-simulation page: parallel stepping); ``text`` says
    it in words (the master's ``stepping``).

    Parameters
    ----------
    run : cosim.core.run.Run
        The run, with its native program and kernel.
    kst : KState
        The kernel's state (its ``lane``, ``seg``, ``fail_at``, ``cost``, ``timing`` and ``pool`` set here).
    """

    def __init__(self, run, kst: KState) -> None:
        self.run, self.kst, self.program = run, kst, run.program
        self.threads = run.cosim.threads
        self.runs = self.program.parallel_runs() if self.threads != 1 else []
        self.groups = self._groups()
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
        wanted = cores if self.threads == "auto" else self.threads
        self.n = min(wanted, len(self.groups))
        self.fail_at = np.full(max(self.n, 1), -1, dtype=np.int64)
        self.cost = np.zeros(len(self.program.ops))
        self.pool, self.on_threads, self.next_check, self.wait = None, False, 0, RECHECK
        self.next_time = 0.0                       # perf_counter() of the next measurement, at the earliest
        self.measured = (0, 0.0)                   # base steps measured, their wall time [s]
        self.warm = False                          # True: the measurement's first block, not counted
        kst.fail_at, kst.cost = self.fail_at.ctypes.data, self.cost.ctypes.data
        if self.n < 2:
            self.state, self.runs = "serial", []
            self.text = "serial: " + ("threads=1" if self.threads == 1 else
                                      "fewer than two FMUs that may step at once" if len(self.groups) < 2 else
                                      "one core")
            self._lanes({})
        else:
            self._measure(warm=True)                # the groups in turn, until their costs are measured
            self.members = [[c for g, (_, calls) in enumerate(self.groups) if g % self.n == me for c in calls]
                            for me in range(self.n)]
            self.thread_of = {c: me for me, calls in enumerate(self.members) for c in calls}
            self._parallel()

    def _groups(self) -> list[tuple[set, list]]:
        """The FMU update calls of the parallel runs, in groups that never step at once (a
        library they share, or ``canBeInstantiatedOnlyOncePerProcess``): ``(keys, calls)``."""
        program, owner, by_name = self.program, self.run.owner, self.run.cosim.by_name
        groups: list[tuple[set, list]] = []
        for run in self.runs:
            for call, first, end, fmu in run:
                if not fmu or any(call in calls for _, calls in groups):
                    continue
                step = next(program.ops[q] for q in range(first, end) if program.ops[q].kind in STEP_KINDS)
                keys = {("library", _library_base(step.fn))}
                cs = getattr(getattr(by_name.get(owner.get(call)), "md", None), "coSimulation", None)
                if getattr(cs, "canBeInstantiatedOnlyOncePerProcess", False):
                    keys.add(("once",))
                merged = [g for g in groups if g[0] & keys]
                joined = (keys.union(*(k for k, _ in merged)), [c for _, cs in merged for c in cs] + [call])
                at = groups.index(merged[0]) if merged else len(groups)
                groups = [g for g in groups if g not in merged]
                groups.insert(at, joined)
        return groups

    def _lanes(self, thread_of: dict) -> None:
        """Point the kernel at the segments for ``thread_of`` (the thread of each FMU update)."""
        self.lane, self.seg = self.program.lanes(self.runs, thread_of)
        self.kst.lane, self.kst.seg = self.lane.ctypes.data, self.seg.ctypes.data

    def _assign(self) -> tuple[dict, list[list]]:
        """The thread of each call and each thread's calls: the costliest group first, each to the
        least loaded thread (the calling thread also makes the filters' held inputs)."""
        cost = self.cost
        span = {call: (first, end) for run in self.runs for call, first, end, _ in run}
        costs = [sum(cost[slice(*span[c])].sum() for c in calls) for _, calls in self.groups]
        loads = [sum(cost[first:end].sum() for run in self.runs for _, first, end, fmu in run if not fmu)]
        loads += [0.0] * (self.n - 1)
        members: list[list] = [[] for _ in range(self.n)]
        thread_of = {}
        for g in sorted(range(len(self.groups)), key=lambda g: -costs[g]):
            me = loads.index(min(loads))
            loads[me] += costs[g]
            members[me] += self.groups[g][1]
            thread_of.update(dict.fromkeys(self.groups[g][1], me))
        return thread_of, members

    def _parallel(self) -> bool:
        """Step on the pool's threads by ``thread_of`` (each thread's calls: ``members``); False
        (and serially) if the threads could not be started."""
        if self.pool is None:
            self.pool = self.run.kernel.kernel_pool_start(self.n) or None
            if self.pool is None:
                self._serial(f"serial: {self.n} threads could not be started")
                return False
        self.kst.pool, self.on_threads = self.pool, True
        self._lanes(self.thread_of)
        names = [", ".join(self.run.owner.get(c, "?") for c in calls) for calls in self.members]
        self.text = f"{self.n} threads: " + "; ".join(f"[{n}]" for n in names)
        return True

    def chunk(self, steps: int, seconds: float) -> None:
        """A chunk of ``steps`` base steps done in ``seconds`` [s]: a measurement goes on, or is
        decided, or (``threads="auto"``) a new one starts when it is time."""
        kst = self.kst
        if self.state == "measure":
            serial, parallel = self.cost.sum(), kst.seg_time
            hopeless = self.threads == "auto" and parallel > HOPELESS_RATIO * serial
            if self.warm and kst.k < self.run.n and not hopeless:
                self._measure(warm=False)           # the threads started and woken: not counted
                return
            steps, seconds = self.measured[0] + steps, self.measured[1] + seconds
            self.measured = (steps, seconds)
            # a plain result decides at once (a wrong call is corrected at the next measurement)
            plain = parallel > serial or parallel < CLEAR_RATIO * serial
            if not self.warm and seconds < MEASURE_SECONDS and kst.k < self.run.n and not plain:
                return
            self._decide(steps)
            self.next_check, self.wait = kst.k + self.wait, 2 * self.wait
            self.next_time = time.perf_counter() + RECHECK_SECONDS
        elif (self.threads == "auto" and self.n >= 2 and kst.k >= self.next_check
              and time.perf_counter() >= self.next_time):
            decided = self.text
            if self._parallel():
                self.text = f"{decided}; measuring {self.n} threads again from base step {kst.k}"
                self._measure(warm=True)

    def _measure(self, warm: bool) -> None:
        """Start a measurement afresh (the kernel times the updates), not counting its first block if ``warm``."""
        self.state, self.warm, self.measured = "measure", warm, (0, 0.0)
        self.kst.timing, self.kst.seg_time = 1, 0.0
        self.cost[:] = 0.0

    def _decide(self, steps: int) -> None:
        """After ``steps`` measured base steps: the threads balanced by the updates' times, and kept
        or (``threads="auto"``) left for the serial loop."""
        serial, parallel = self.cost.sum() / max(steps, 1), self.kst.seg_time / max(steps, 1)
        self.thread_of, self.members = self._assign()
        measured = f"on {self.n} threads {_seconds(parallel)} per base step, serially {_seconds(serial)}"
        if self.threads == "auto" and (serial - parallel < MIN_GAIN or parallel > KEEP_RATIO * serial):
            self._serial(f"serial: the FMU updates that may step at once took {measured}")
        elif self._parallel():
            self.state, self.kst.timing = "parallel", 0
            self.text += f" (measured: {measured})"

    def _serial(self, why: str) -> None:
        """Go on serially (the threads kept, asleep, for a later measurement), for the reason ``why``."""
        self.kst.pool, self.on_threads = None, False
        self.state, self.text, self.kst.timing = "serial", why, 0

    def finish(self, steps: int) -> None:
        """The loop ended ``steps`` base steps after the last chunk: a measurement under way is
        decided on what it measured, and the pool's threads end."""
        if self.state == "measure" and self.measured[0] + steps > 0:
            self._decide(self.measured[0] + steps)
        pool, self.pool = self.pool, None
        self.kst.pool = None
        if pool:
            self.run.kernel.kernel_pool_stop(pool)

    def ran_ahead(self, at: int) -> dict:
        """After the operation ``at`` failed in a parallel segment: the update calls the other
        threads made in it, each with ``f(t)`` replaying its outcome (nothing, or its ``fail``)."""
        starts = [q for q in np.flatnonzero(self.seg).tolist() if q <= at < q + self.seg[q]]
        if not self.on_threads or not starts:          # the segment ran serially
            return {}
        program, made, failed = self.program, {}, {}
        for q in range(starts[0], starts[0] + int(self.seg[starts[0]])):
            call, last = program.calls[q], int(self.fail_at[self.lane[q]])
            made[call] = made.get(call, True) and (last < 0 or q <= last)
            if q == last:
                failed[call] = q
        replay = {call: (lambda t: None) for call, done in made.items() if done}
        return replay | {call: (lambda t, q=q: program.meta[q].fail(program.ops[q], t)) for call, q in failed.items()}


class NativeLoop:
    """A run's base steps in the native kernel; ``run`` (a :class:`~cosim.core.run.Run`) is set up,
    with its native program and kernel."""

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
        self.stepping = Stepping(run, self.kst)
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
            self.stepping.finish(kst.k - self.done)
            run.cosim.stepping = self.stepping.text
            run.k, run.j, run.jb, run.k0 = kst.k, kst.j, kst.jb, kst.k0
            for sync in program.syncs_out:
                sync()
        self._end(event)

    def _hook(self, after_step: bool) -> None:
        """The hook of the operation the kernel stopped at: a filter's ``after_step`` (the operation
        rebound, resumed after it), or a noise stream's refill (resumed at the operation)."""
        at, program = self.kst.at, self.program
        self.run.failing, meta = program.calls[at], program.meta[at]
        meta.hook()
        if after_step:
            if meta.rebind is not None:
                meta.rebind(program.ops[at])
            self.kst.pc += 1

    def _chunk(self) -> None:
        """A chunk done: the bar moves, and the next chunk's length aims at :data:`CHUNK_SECONDS`."""
        kst, stepping = self.kst, self.stepping
        self.run.bar.update(kst.k - self.done)
        now = time.perf_counter()
        stepping.chunk(kst.k - self.done, now - self.since)
        ratio = CHUNK_SECONDS / max(now - self.since, 1e-6)
        self.chunk = max(BLOCK, min(CHUNK, int(self.chunk * min(ratio, 4.0)) // BLOCK * BLOCK))
        # while measuring: one warming block, then MEASURE_BLOCKS blocks (the threads may sleep between chunks)
        if stepping.state != "measure":
            length = self.chunk
        else:
            length = BLOCK if stepping.warm else MEASURE_BLOCKS * BLOCK
        self.done, self.since, kst.kstop = kst.k, now, kst.k + length

    def _end(self, event: int) -> None:
        """The end of the loop by ``event``: the bar's last steps, the non-finite signal or the
        failed call's error raised, or the stop request finished."""
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
            run.ran_ahead = self.stepping.ran_ahead(at)
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

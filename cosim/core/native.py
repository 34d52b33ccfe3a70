"""The native kernel: the master's base-step loop in compiled C (``kernel.c``; the co-simulation page
of the documentation), interpreting a :class:`~cosim.core.native.Program` of the bound calls'
operations (:class:`~cosim.core.native.Op`; a call without them returns to Python). It computes as
the Python path does, without fused multiply-adds: the same results bit for bit.
"""
from __future__ import annotations

import ctypes
import itertools
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fmu_models.infra.native_library import compiled_library

__all__ = ["ENGINES", "KState", "Op", "OpStruct", "load_kernel", "native_ops"]

ENGINES = ("auto", "native", "python")

(OP_PY, OP_GET, OP_SET, OP_STEP2, OP_STEP3, OP_CONST, OP_SWITCH, OP_FILTER, OP_HOLD, OP_HOOK, OP_SUMMARY, OP_NOISE,
 OP_PRBS, OP_RECORD, OP_STEP1) = range(15)
EV_DONE, EV_PY, EV_FAIL, EV_FLUSH, EV_NONFINITE, EV_CHUNK, EV_HOOK, EV_REFILL = range(8)

_P = ctypes.c_void_p
_I = ctypes.c_int64
_D = ctypes.c_double


class OpStruct(ctypes.Structure):
    """One operation of the kernel (``op_t`` in ``kernel.c``)."""

    _fields_ = [("kind", _I), ("owner", _I), ("n", _I), ("nvr", _I), ("nbuf", _I), ("status", _I), ("flag", _I),
                ("slot", _I), ("fn", _P), ("inst", _P), ("vr", _P), ("buf", _P), ("idx", _P), ("off", _P),
                ("a", _D), ("b", _D), ("c", _D), ("d", _D), ("arg", _P * 2), ("res", _P * 2), ("iw", _P),
                ("w", _P), ("ub", _P), ("yb", _P), ("uprev", _P), ("yidx", _P), ("ny", _I), ("nu", _I),
                ("nx", _I), ("nup", _I), ("cur", _P), ("status_out", _P), ("x", _P * 2), ("P", _P * 2),
                ("nis", _P), ("out", _P), ("uidx", _P), ("upi", _P), ("upj", _P)]


class KState(ctypes.Structure):
    """The kernel's run description and resumable state (``kstate_t`` in ``kernel.c``)."""

    _fields_ = [("t0", _D), ("h", _D), ("n", _I), ("m", _I), ("L", _I), ("cap", _I), ("ncols", _I), ("nint", _I),
                ("nsig", _I), ("block", _I), ("values", _P), ("integers", _P), ("buf", _P), ("ibuf", _P),
                ("sel", _P), ("isel", _P), ("pattern", _P), ("out_start", _P), ("out_len", _P), ("upd_start", _P),
                ("upd_len", _P), ("ops", _P), ("k", _I), ("phase", _I), ("pc", _I), ("j", _I), ("jb", _I),
                ("k0", _I), ("kstop", _I), ("at", _I), ("pool", _P), ("lane", _P), ("seg", _P), ("fail_at", _P),
                ("cost", _P), ("seg_time", _D), ("timing", _I)]


@dataclass
class Op:
    """One native operation of a bound call: its ``kind`` (``OP_GET``, ``OP_SET``, ... of this module),
    its :class:`OpStruct` ``fields`` (pointers as integers) and what they point into (``keep``, kept
    alive with it). ``fail(op, t)`` raises the failed operation's error as the Python path does
    (``op``: its OpStruct, ``status``, ``flag``, ``d`` set; ``t`` [s]); ``sync_in`` and ``sync_out``
    move the state Python objects keep (a filter's state, step count) into and out of the kernel's
    arrays; ``hook`` is what an ``OP_HOOK`` runs in Python (a filter's ``after_step``; a full
    ``OP_RECORD``) or an ``OP_NOISE`` stream's refill, after which ``rebind(op)`` points the OpStruct
    at the arrays the hook replaced."""

    kind: int
    fields: dict = field(default_factory=dict)
    keep: tuple = ()
    fail: Callable | None = None
    sync_in: Callable[[], None] | None = None
    sync_out: Callable[[], None] | None = None
    hook: Callable[[], None] | None = None
    rebind: Callable[[OpStruct], None] | None = None


def native_ops(fn) -> list[Op] | None:
    """The native operations of ``fn``, a bound output or update call, or None if it runs in Python."""
    return getattr(fn, "native", None)


#: The doStep operations (FMI 1.0, 2.0, 3.0).
STEP_KINDS = (OP_STEP1, OP_STEP2, OP_STEP3)
# an FMU's update on a worker thread: its inputs set, its doStep; beside them, a filter's held input
_WORKER_KINDS, _BESIDE = {OP_SET, *STEP_KINDS}, {OP_HOLD}
_SOURCE = Path(__file__).with_name("kernel.c")
#: No fused multiply-add: the kernel's arithmetic must be Python's, operation for operation.
_FLAGS = ("-O2", "-shared", "-fPIC", "-std=c99", "-pthread", "-ffp-contract=off", "-fno-fast-math")
_kernel: list = []          # [library or None, reason]


def load_kernel() -> tuple[ctypes.CDLL | None, str]:
    """The compiled kernel (built on first use, cached on disk), or None and why not."""
    if _kernel:
        return _kernel[0], _kernel[1]
    lib, why = compiled_library(_SOURCE.read_text(), "kernel", _FLAGS, "kernel_run", "the native co-simulation kernel",
                                "runs take the Python path (same results, slower)", link=("-lm", "-pthread"))
    signatures = {"kernel_run": (ctypes.c_int, [ctypes.POINTER(KState)]), "kernel_pool_start": (_P, [_I]),
                  "kernel_pool_stop": (None, [_P])}
    for name, (restype, argtypes) in signatures.items() if lib is not None else ():
        fn = getattr(lib, name)
        fn.restype, fn.argtypes = restype, argtypes
    _kernel[:] = [lib, why]
    return lib, why


@dataclass
class Program:
    """The kernel's program for one run: every operation (``ops``, a ctypes array of OpStruct), each
    one's :class:`Op` (``meta``; None: a call back into Python), the Python call it belongs to
    (``calls``) and whether that is an update (``updates``); base step ``k``'s pattern ``p =
    pattern[k % L]`` (int64, shape (L,)) has the operations ``ops[out_start[p] : out_start[p] +
    out_len[p]]`` for its outputs, likewise ``upd_start``, ``upd_len`` for its updates.
    ``syncs_in`` and ``syncs_out`` are the operations' ``sync_in`` / ``sync_out``, ``n_native``
    how many operations run natively."""

    ops: ctypes.Array
    meta: list
    pattern: np.ndarray
    out_start: np.ndarray
    out_len: np.ndarray
    upd_start: np.ndarray
    upd_len: np.ndarray
    syncs_in: list
    syncs_out: list
    n_native: int
    calls: list
    updates: list

    def parallel_runs(self) -> list[list[tuple]]:
        """The runs of update calls that may run at once, with two FMU updates at least: each a list
        of ``(call, first, end, fmu)`` (operations ``ops[first:end]``; ``fmu``: an FMU's set inputs
        and ``doStep``, for a worker thread; else a filter's held input, for the calling thread).
        Any other call (into Python, or a native one that writes signals) ends a run."""
        runs: list[list[tuple]] = []
        for start, length in zip(self.upd_start.tolist(), self.upd_len.tolist()):
            run: list[tuple] = []
            for _, group in itertools.groupby(range(start, start + length), key=lambda q: id(self.calls[q])):
                span = list(group)          # the operations of one call
                kinds = {self.ops[q].kind for q in span}
                fmu = bool(kinds & set(STEP_KINDS)) and kinds <= _WORKER_KINDS
                if fmu or kinds <= _BESIDE:
                    run.append((self.calls[span[0]], span[0], span[-1] + 1, fmu))
                else:
                    runs.append(run)
                    run = []
            runs.append(run)
        return [run for run in runs if sum(fmu for *_, fmu in run) >= 2]

    def lanes(self, runs: list[list[tuple]], thread_of: dict) -> tuple[np.ndarray, np.ndarray]:
        """The kernel's ``lane`` and ``seg`` arrays (see ``kernel.c``): each of the ``runs`` (of
        :meth:`parallel_runs`) whose FMU updates fall on two threads or more by ``thread_of`` (the
        thread of each, 0: the calling one) becomes a parallel segment."""
        lane = np.full(len(self.ops), -1, dtype=np.int64)
        seg = np.zeros(len(self.ops), dtype=np.int64)
        for run in runs:
            if len({thread_of[call] for call, _, _, fmu in run if fmu}) < 2:
                continue
            seg[run[0][1]] = run[-1][2] - run[0][1]
            for call, first, end, fmu in run:
                lane[first:end] = thread_of[call] if fmu else 0
        return lane, seg


def build_program(schedule: list) -> Program:
    """The kernel's program of a run from its ``schedule``: per base step of the hyperperiod, the
    output calls and the update calls (a tuple each) the Python loop makes, equal entries shared."""
    index: dict[int, int] = {}
    pattern = np.empty(len(schedule), dtype=np.int64)
    structs: list[OpStruct] = []
    meta: list = []
    calls: list = []            # per op: the Python call it belongs to
    updates: list = []          # per op: whether it is an update
    starts: list[tuple[int, int, int, int]] = []
    for i, entry in enumerate(schedule):
        if id(entry) not in index:
            index[id(entry)] = len(starts)
            spans = []
            for phase, fns in enumerate(entry):
                first = len(structs)
                for owner, fn in enumerate(fns):
                    ops = native_ops(fn)
                    for op in ops if ops is not None else (None,):
                        structs.append(OpStruct(kind=OP_PY, owner=owner) if op is None else
                                       OpStruct(kind=op.kind, owner=owner, **op.fields))
                        meta.append(op)
                        calls.append(fn)
                        updates.append(phase == 1)
                spans += [first, len(structs) - first]
            starts.append(tuple(spans))
        pattern[i] = index[id(entry)]
    arr = (OpStruct * max(len(structs), 1))(*structs)
    columns = np.array(starts, dtype=np.int64).reshape(-1, 4).T
    out_start, out_len, upd_start, upd_len = (np.ascontiguousarray(c) for c in columns)
    unique = list({id(op): op for op in meta if op is not None}.values())          # each native Op once
    return Program(arr, meta, pattern, out_start, out_len, upd_start, upd_len,
                   [op.sync_in for op in unique if op.sync_in is not None],
                   [op.sync_out for op in unique if op.sync_out is not None], sum(m is not None for m in meta),
                   calls, updates)

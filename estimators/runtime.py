"""The filters' runtime: a compiled step bound to numpy buffers, fast input conversion, and the errors of a failed step.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping

import casadi as ca
import numpy as np

from fmu_models.errors import InputError, NumericalError
from fmu_models.infra.checks import float_array

from .linalg import BAD_INPUT, BAD_RESULT

__all__ = ["BoundStep", "BufferedFunction", "StepArrays", "VectorInput", "broadcast_inputs", "explain_status",
           "lean_step", "matrix"]


class BufferedFunction:
    """Evaluate ``fn`` on preset arrays: ``trigger()`` costs about a microsecond.

    Every input and output is a flat float array in CasADi's column-major layout
    (:func:`matrix` gives a 2-D view). Arrays passed in ``bind_args``/``bind_res`` (by
    index) are shared, not copied: several functions can read and write the same arrays.
    """

    def __init__(self, fn: ca.Function, bind_args: dict[int, np.ndarray] | None = None,
                 bind_res: dict[int, np.ndarray] | None = None):
        self.fn = fn
        self.buffer, self.trigger = fn.buffer()
        self.args = self._bind("input", fn.n_in(), fn.sparsity_in, fn.name_in, bind_args, self.buffer.set_arg)
        self.res = self._bind("output", fn.n_out(), fn.sparsity_out, fn.name_out, bind_res, self.buffer.set_res)

    def _bind(self, kind: str, count: int, sparsity, name, bound, setter) -> list[np.ndarray]:
        """The arrays of the inputs (or outputs), the ``bound`` ones shared, set in the buffer."""
        arrays = []
        for i in range(count):
            if not sparsity(i).is_dense():
                raise ValueError(f"{self.fn.name()}: {kind} {name(i)} must be dense")
            nnz = sparsity(i).nnz()
            a = (bound or {}).get(i, np.zeros(nnz))
            if a.shape != (nnz,) or a.dtype != np.float64 or not a.flags.c_contiguous:
                raise ValueError(f"{self.fn.name()}: bad array bound to {kind} {name(i)}")
            setter(i, memoryview(a))
            arrays.append(a)
        return arrays


def matrix(flat: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """2-D view (column-major, shared memory) of the flat CasADi matrix array ``flat``, shape (``rows``, ``cols``)."""
    return flat.reshape((rows, cols), order="F")


class StepArrays:
    """The flat arrays a step reads and writes: the state in two copies (``pairs``; the step
    reads the current one, ``pairs[name][cell[0]]``, and writes the other, made current after a
    successful step: a failed step leaves the state as it was), the other ``inputs`` and the ``outputs``.

    Parameters
    ----------
    fn : casadi.Function
        The step: an input ``s`` with an output ``s_new`` is state.
    state : mapping of str to ndarray
        Initial values of the state inputs (flat, column-major), copied.
    shared : mapping of str to ndarray
        Arrays bound as they are to inputs of these names (the owner changes them in place).
    runs : int
        Realisations side by side (run-major) in every array.
    """

    def __init__(self, fn: ca.Function, state: Mapping[str, np.ndarray], shared: Mapping[str, np.ndarray],
                 runs: int = 1):
        self.pairs = {k: (np.array(state[k], float), np.array(state[k], float)) for k in fn.name_in() if k in state}
        self.inputs = {k: (shared[k] if k in shared else np.zeros(runs * fn.nnz_in(k))) for k in fn.name_in()
                       if k not in self.pairs}
        self.outputs = {n: np.zeros(runs * fn.nnz_out(n)) for n in fn.name_out() if not n.endswith("_new")}
        self.status = self.outputs["status"]
        #: which copy of the state is current (0 or 1), in a cell the lean step shares
        self.cell = [0]

    def now(self, name: str) -> np.ndarray:
        """The current copy of state array ``name`` (a view: writing it changes the state)."""
        return self.pairs[name][self.cell[0]]


class BoundStep(StepArrays):
    """A step Function ``fn`` bound to the arrays of :class:`StepArrays` (parameters ``fn``, ``state``,
    ``shared`` as there)."""

    def __init__(self, fn: ca.Function, state: Mapping[str, np.ndarray], shared: Mapping[str, np.ndarray]):
        super().__init__(fn, state, shared)
        self._steps = tuple(self._bind(fn, i) for i in (0, 1))
        #: the two evaluations (from copy 0, from copy 1), for callers that inline trigger()
        self.triggers = tuple(s.trigger for s in self._steps)

    def _bind(self, fn: ca.Function, i: int) -> BufferedFunction:
        args = {j: self.pairs[n][i] if n in self.pairs else self.inputs[n] for j, n in enumerate(fn.name_in())}
        res = {j: self.pairs[n[:-4]][1 - i] if n.endswith("_new") else self.outputs[n]
               for j, n in enumerate(fn.name_out())}
        return BufferedFunction(fn, args, res)

    def trigger(self) -> float:
        """Evaluate the step into the other state copy; the status."""
        self._steps[self.cell[0]].trigger()
        return self.status[0]


class VectorInput:
    """Writes a vector of ``n`` numbers (a bare number if ``n == 1``) into a buffer: a length
    check and one assignment per entry, else :meth:`checked` names the problem (NaN and inf are
    left to the compiled step's status).

    Parameters
    ----------
    buffer : ndarray
        The float buffer (length ``n``).
    owner, what : str
        For messages: the filter's name and the input's (``"u"``, ``"y"``, ``"mask"``).
    """

    def __init__(self, buffer: np.ndarray, owner: str, what: str):
        self.buffer, self.owner, self.what, self.n = buffer, owner, what, len(buffer)
        self._entries = range(self.n)

    def __call__(self, value) -> None:
        """Copy ``value`` into the buffer, or raise InputError / TypeMismatchError naming the problem."""
        buf = self.buffer
        try:
            if value.__class__ is str or len(value) != self.n:
                raise ValueError
            for i in self._entries:
                buf[i] = value[i]
        except _SLOW:
            self.checked(value)

    def checked(self, value) -> None:
        """The full check of ``value`` (the slow path): a named error, or the copy."""
        n, what, owner = self.n, self.what, self.owner
        a = float_array(value, f"{owner}: {what}")
        if a.ndim == 0:
            if n != 1:
                raise InputError(f"{owner}: {what} must have shape ({n},), got the scalar {value!r}")
            a = a.reshape(1)
        if a.shape != (n,):
            raise InputError(f"{owner}: {what} must have shape ({n},), got shape {a.shape}")
        self.buffer[:] = a


_SLOW = (TypeError, ValueError, IndexError, KeyError)
#: Types taken as the one entry of a one-element vector on the lean path (a numpy float64
#: is a float; a 0-d array becomes a float through ``tolist()``).
_SCALARS = frozenset({float, np.float64})


def _unpack(name: str, entries: list[str]) -> list[str]:
    """Lines of the lean step unpacking ``name`` into ``entries``; a one-element input also
    takes a bare float (``ekf.step(U[k], Y[k])`` with a 1-D ``U``)."""
    if not entries:
        return [f"        if len({name}):", "            raise ValueError"]
    if len(entries) == 1:
        return [f"        if {name}.__class__ in SCALARS:",
                f"            {entries[0]} = {name}",
                "        else:",
                f"            {entries[0]}, = {name}"]
    return [f"        {', '.join(entries)}, = {name}"]


def lean_step(rt: BoundStep, fill_u: VectorInput, fill_y: VectorInput, count: list, general: Callable,
              explain: Callable[[str], None], after: Callable[[], None] | None) -> Callable:
    """A filter's ``step(u, y, mask=None)`` specialised for its sizes.

    For the common call (a measurement, no mask) ``u`` and ``y`` (lists, tuples or float
    arrays) are unpacked and copied entry by entry (source written out for ``nu`` and ``ny``, as
    dataclasses writes its methods) and the step is one native call; nothing else is checked
    unless the conversion fails or the status is not 0.

    Parameters
    ----------
    rt : BoundStep
        The filter's bound step.
    fill_u, fill_y : VectorInput
        The checked conversions.
    count : list
        One element: the step count.
    general, explain, after : callable
        ``general(u, y, mask)`` steps the other calls (``y=None``, a mask); ``explain(what)``
        raises the error of a failed step; ``after()`` is the runtime hook (or None).
    """
    scope = dict(general=general, ndarray=np.ndarray, SCALARS=_SCALARS, ub=memoryview(fill_u.buffer),
                 yb=memoryview(fill_y.buffer), SLOW=_SLOW, slow_u=fill_u.checked, slow_y=fill_y.checked,
                 cell=rt.cell, triggers=rt.triggers, status=memoryview(rt.status), explain=explain, count=count,
                 after=after, copies=tuple(x.copy for x in rt.pairs["x"]))
    exec(_lean_source(fill_u.n, fill_y.n, after is not None), scope)   # from integers only, as dataclasses does
    return scope["step"]


def _lean_source(nu: int, ny: int, after: bool) -> str:
    """The source of the lean ``step`` for ``nu`` inputs, ``ny`` measurements, ``after`` a hook."""
    us, ys = [f"u{i}" for i in range(nu)], [f"y{j}" for j in range(ny)]
    # memoryviews: an entry that is not a number (a string, None, a sequence) is a TypeError,
    # and reading the status gives a float, both cheaper than through numpy; an array is
    # unpacked through tolist() (unpacking it directly makes numpy scalars)
    return "\n".join(["def step(u, y, mask=None):",
                      "    if mask is not None or y is None:",
                      "        return general(u, y, mask)",
                      "    try:",
                      "        if u.__class__ is ndarray:",
                      "            u = u.tolist()",
                      "        if y.__class__ is ndarray:",
                      "            y = y.tolist()",
                      *_unpack("u", us), *_unpack("y", ys),
                      *[f"        ub[{i}] = {v}" for i, v in enumerate(us)],
                      *[f"        yb[{j}] = {v}" for j, v in enumerate(ys)],
                      "    except SLOW:",
                      "        slow_u(u)",
                      "        slow_y(y)",
                      "    c = cell[0]",
                      "    triggers[c]()",
                      "    if status[0]:",
                      "        explain('step')",
                      "    c ^= 1",
                      "    cell[0] = c",
                      "    count[0] += 1",
                      *(["    after()"] if after else []),
                      "    return copies[c]()"])


def broadcast_inputs(us, runs: int, N: int, nu: int) -> np.ndarray:
    """The inputs ``us`` of ``runs`` records of ``N`` steps, (N, ``nu``) shared or (runs, N, nu),
    as a (runs, N, nu) float array (a broadcast view), or InputError naming the problem."""
    us = float_array(us, "inputs us")
    try:
        us = np.broadcast_to(us.reshape(1, N, nu) if us.ndim <= 2 else us, (runs, N, nu))
    except ValueError:
        raise InputError(f"inputs us must have shape ({N}, {nu}) or ({runs}, {N}, {nu}), got {us.shape}") from None
    if not np.isfinite(us).all():
        raise InputError("inputs us contain NaN or inf")
    return us


def explain_status(status: float, owner: str, k: int, u: np.ndarray, y: np.ndarray, mask: np.ndarray,
                   nan_is_missing: bool, what: str) -> None:
    """Raise the error of a step whose ``status`` is :data:`~estimators.linalg.BAD_INPUT`
    (InputError: ``u`` or a used ``y`` entry was NaN or inf) or ``BAD_RESULT`` (NumericalError).

    Parameters
    ----------
    status : float
    owner, what : str
        The filter's name; what was running (``"step"``, ``"run index 12"``).
    k : int
        The step's index.
    u, y, mask : ndarray
        The step's inputs.
    nan_is_missing : bool
        Whether a NaN measurement is a missing channel.
    """
    if status == BAD_INPUT:
        bad_u = np.flatnonzero(~np.isfinite(u))
        if len(bad_u):
            raise InputError(f"{owner}: u contains NaN or inf at index {bad_u.tolist()} at step {k} "
                             f"(u = {u}); filter state unchanged")
        used = mask != 0
        bad_y = np.flatnonzero(used & np.isinf(y) | (used & np.isnan(y) & (not nan_is_missing)))
        kind = "inf" if np.isinf(y[bad_y]).any() else "NaN"
        raise InputError(f"{owner}: y contains {kind} at index {bad_y.tolist()} at step {k} (y = {y}); filter "
                         "state unchanged" + ("" if nan_is_missing else " (nan_is_missing=False)"))
    if status == BAD_RESULT:
        raise NumericalError(f"{owner}: the estimate became non-finite at step {k} ({what}); filter state "
                             "unchanged (diverged, or covariances too large)")

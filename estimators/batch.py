"""Run many realisations of one filter in lockstep: one native call per step for all.

The filter's fused step Function is mapped over ``n_runs`` realisations
(``casadi.Function.map``) and compiled, so a Monte Carlo campaign pays the Python
overhead once per step, not once per realisation.
"""
from __future__ import annotations

import numpy as np

from ._buffered import BufferedFunction
from ._compiled import compile_functions
from .base import BAD_INPUT, KalmanBase


class BatchFilter:
    """``n_runs`` copies of ``template`` stepped together.

    Parameters
    ----------
    template : KalmanBase
        A filter whose current state (x, P, Q, R, ...) starts every realisation.
    n_runs : int
        Number of realisations.
    x0 : array_like, shape (n_runs, nx), optional
        Per-realisation initial estimates (default: the template's x for all).
    on_failure : {"raise", "mark"}
        What a realisation whose input or result is not finite does: raise (default),
        or keep its previous state, mark it in :attr:`failed` and go on with the others
        (Monte Carlo campaigns count such runs as diverged).

    Attributes
    ----------
    x : ndarray, shape (n_runs, nx)
        Current estimates.
    P : ndarray, shape (n_runs, nx, nx)
    nis : ndarray, shape (n_runs,)
    failed : ndarray of bool, shape (n_runs,)
        Realisations that failed at least once (``on_failure="mark"``).
    """

    def __init__(self, template: KalmanBase, n_runs: int, x0=None, on_failure: str = "raise"):
        if on_failure not in ("raise", "mark"):
            raise ValueError(f"on_failure must be 'raise' or 'mark', got {on_failure!r}")
        self.on_failure = on_failure
        if not template.supports_batch:
            raise TypeError(f"{template.name} cannot run batched (its adaptation is not in the fused step)")
        if int(n_runs) != n_runs or n_runs < 1:
            raise ValueError(f"n_runs must be a positive integer, got {n_runs!r}")
        self.template, self.n = template, int(n_runs)
        s = template.system
        self.nx, self.nu, self.ny = s.nx, s.nu, s.ny
        key = ("batch", template._cache_key(), self.n, template.backend)
        if key not in s.cache:
            raw_step = template._raw_functions[2]
            s.cache[key] = compile_functions([raw_step.map(self.n, "serial")], template.backend)
        (step,), _ = s.cache[key]
        template._sync()
        self._pairs = {k: (np.tile(v[0], self.n), np.tile(v[0], self.n))
                       for k, v in template._pairs.items()}
        if x0 is not None:
            x0 = np.asarray(x0, float)
            if x0.shape != (self.n, self.nx) or not np.all(np.isfinite(x0)):
                raise ValueError(f"x0 must be finite with shape ({self.n}, {self.nx}), got {x0.shape}")
            self._pairs["x"][0][:] = x0.ravel()
        self._cur = 0
        self._inputs = {step.name_in(i): np.zeros(step.nnz_in(i)) for i in range(step.n_in())
                        if step.name_in(i) not in self._pairs}
        self._out = {step.name_out(i): np.zeros(step.nnz_out(i)) for i in range(step.n_out())
                     if not step.name_out(i).endswith("_new")}
        self._steps = []
        for i in (0, 1):
            args = {j: (self._pairs[step.name_in(j)][i] if step.name_in(j) in self._pairs
                        else self._inputs[step.name_in(j)]) for j in range(step.n_in())}
            res = {j: (self._pairs[step.name_out(j)[:-4]][1 - i] if step.name_out(j).endswith("_new")
                       else self._out[step.name_out(j)]) for j in range(step.n_out())}
            self._steps.append(BufferedFunction(step, args, res))
        self.k = 0
        self.failed = np.zeros(self.n, dtype=bool)
        template._batch_init(self)

    def now(self, key: str) -> np.ndarray:
        """Current flat state array ``key`` (all realisations, run-major)."""
        return self._pairs[key][self._cur]

    x = property(lambda self: self.now("x").reshape(self.n, self.nx).copy())
    P = property(lambda self: self.now("P").reshape(self.n, self.nx, self.nx).transpose(0, 2, 1).copy())
    Q = property(lambda self: self.now("Q").reshape(self.n, self.nx, self.nx).transpose(0, 2, 1).copy())
    R = property(lambda self: self.now("R").reshape(self.n, self.ny, self.ny).transpose(0, 2, 1).copy())
    nis = property(lambda self: self._out["nis"].copy())
    innovation = property(lambda self: self._out["innov"].reshape(self.n, self.ny).copy())

    def step(self, u, y) -> np.ndarray:
        """One step of every realisation: ``u`` (n_runs, nu) or (nu,), ``y`` (n_runs, ny).

        Returns the estimates, shape (n_runs, nx). NaN or inf anywhere raises ValueError
        naming the realisation; the state is then unchanged.
        """
        u_in, y_in = self._inputs["u"], self._inputs["y"]
        try:
            u_in.reshape(self.n, self.nu)[:] = u
            y = np.asarray(y, float)
            if y.shape != (self.n, self.ny):
                raise ValueError
            y_in[:] = y.ravel()
        except ValueError:
            raise ValueError(f"u must broadcast to ({self.n}, {self.nu}) and y have shape "
                             f"({self.n}, {self.ny}); got {np.shape(u)} and {np.shape(y)}") from None
        self.template._batch_prepare(self)
        self._steps[self._cur].trigger()
        status = self._out["status"]
        if status.any() and self.on_failure == "mark":
            bad = status != 0
            for pair in self._pairs.values():     # failed runs keep their previous state
                old, new = pair[self._cur], pair[1 - self._cur]
                new.reshape(self.n, -1)[bad] = old.reshape(self.n, -1)[bad]
            self.failed |= bad
        elif status.any():
            run = int(np.flatnonzero(status)[0])
            what = "u or y contains NaN or inf" if status[run] == BAD_INPUT else "the estimate became non-finite"
            raise (ValueError if status[run] == BAD_INPUT else FloatingPointError)(
                f"batched {self.template.name}: {what} in realisation {run} at step {self.k}; "
                "state unchanged")
        self._cur ^= 1
        self.k += 1
        self.template._batch_after(self)
        return self.x


def _noop(self, batch):
    """Default batch hooks of a filter with nothing outside the fused step."""


KalmanBase._batch_init = _noop
KalmanBase._batch_prepare = _noop
KalmanBase._batch_after = _noop

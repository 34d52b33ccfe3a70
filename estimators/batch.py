"""Run many realisations of one filter in lockstep: one native call per step for all, or one
native call per block of steps for whole trajectories.

The filter's fused step Function is mapped over ``n_runs`` realisations
(``casadi.Function.map``) and compiled, so a Monte Carlo campaign pays the Python
overhead once per step (:meth:`BatchFilter.step`) or once per block of
:data:`~estimators.base.RUN_BLOCK` steps (:meth:`BatchFilter.run`), not once per
realisation.
"""
from __future__ import annotations

import numpy as np

from fmu_models import checks
from fmu_models.errors import ConfigurationError, InputError, NumericalError, TypeMismatchError

from ._buffered import BufferedFunction
from ._compiled import compile_functions
from .base import BAD_INPUT, RUN_BLOCK, KalmanBase

__all__ = ["BatchFilter", "BatchRun"]

ON_FAILURE = ("raise", "mark")


class BatchRun:
    """The result of :meth:`BatchFilter.run` (``R`` realisations, ``N`` steps).

    Attributes
    ----------
    x : ndarray, shape (R, N + 1, nx)
        Estimates, with the initial one at index 0.
    P : ndarray, shape (R, N + 1, nx, nx)
        Their covariances.
    nis : ndarray, shape (R, N)
    accepted : ndarray of bool, shape (R, N)
    Q, R : ndarray, shapes (R, N + 1, nx), (R, N + 1, ny)
        Diagonals of Q and R after each step (row 0: initial).
    failed : ndarray of bool, shape (R,)
        Realisations whose input or estimate became non-finite (their values from that
        step on are not meaningful).
    """

    def __init__(self, **arrays):
        self.__dict__.update(arrays)


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
        or keep its previous state (in :meth:`step`), mark it in :attr:`failed` and go on
        with the others (Monte Carlo campaigns count such runs as diverged).

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
        if not isinstance(template, KalmanBase):
            raise TypeMismatchError(f"template must be a filter, got {type(template).__name__}")
        if on_failure not in ON_FAILURE:
            raise ConfigurationError(f"on_failure must be 'raise' or 'mark', got {on_failure!r}")
        if not template.supports_batch:
            raise TypeMismatchError(f"{template.name} cannot run batched (its adaptation is not in the fused step)")
        self.on_failure = on_failure
        self.template, self.n = template, checks.positive_int(n_runs, "n_runs")
        s = template.system
        self.nx, self.nu, self.ny = s.nx, s.nu, s.ny
        key = ("batch", template.cache_key, self.n, template.backend)
        if key not in s.cache:
            s.cache[key] = compile_functions([template.step_function().map(self.n, "serial")], template.backend)
        (step,), _ = s.cache[key]
        state = template.state_arrays()
        self._pairs = {k: (np.tile(v, self.n), np.tile(v, self.n)) for k, v in state.items()}
        if x0 is not None:
            x0 = checks.float_array(x0, "x0")
            if x0.shape != (self.n, self.nx) or not np.all(np.isfinite(x0)):
                raise ConfigurationError(f"x0 must be finite with shape ({self.n}, {self.nx}), got {x0.shape}")
            self._pairs["x"][0][:] = x0.ravel()
        self._cur = 0
        consts = {"gate": template.gate, "nan_missing": float(template.nan_is_missing)}
        self._params = {k: np.tile(v, self.n) for k, v in template.parameter_arrays().items()}
        self._inputs = {step.name_in(i): (self._params[step.name_in(i)] if step.name_in(i) in self._params
                                          else np.full(step.nnz_in(i), consts.get(step.name_in(i), 0.0)))
                        for i in range(step.n_in()) if step.name_in(i) not in self._pairs}
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

    def now(self, key: str) -> np.ndarray:
        """Current flat state array ``key`` (all realisations, run-major)."""
        return self._pairs[key][self._cur]

    x = property(lambda self: self.now("x").reshape(self.n, self.nx).copy())
    P = property(lambda self: self.now("P").reshape(self.n, self.nx, self.nx).transpose(0, 2, 1).copy())
    Q = property(lambda self: self._cov("Q", self.nx), doc="Process noise covariances, (n_runs, nx, nx).")
    R = property(lambda self: self._cov("R", self.ny), doc="Measurement noise covariances, (n_runs, ny, ny).")

    def _cov(self, key: str, n: int) -> np.ndarray:
        flat = self._pairs[key][self._cur] if key in self._pairs else self._params[key]
        return flat.reshape(self.n, n, n).transpose(0, 2, 1).copy()
    nis = property(lambda self: self._out["nis"].copy())
    innovation = property(lambda self: self._out["innov"].reshape(self.n, self.ny).copy())

    def _inputs_for(self, u, y, mask):
        try:
            self._inputs["u"].reshape(self.n, self.nu)[:] = u
            y = checks.float_array(y, "y")
            if y.shape != (self.n, self.ny):
                raise ValueError
            self._inputs["y"][:] = y.ravel()
            self._inputs["mask"][:] = 1.0 if mask is None else np.broadcast_to(
                checks.float_array(mask, "mask"), (self.n, self.ny)).ravel()
        except ValueError:
            raise InputError(f"u must broadcast to ({self.n}, {self.nu}) and y have shape "
                             f"({self.n}, {self.ny}); got {np.shape(u)} and {np.shape(y)}") from None

    def step(self, u, y, mask=None) -> np.ndarray:
        """One step of every realisation: ``u`` (n_runs, nu) or (nu,), ``y`` (n_runs, ny)
        (NaN entries missing), optional ``mask`` (n_runs, ny).

        Returns the estimates, shape (n_runs, nx). Raises InputError / NumericalError
        naming the realisation (with ``on_failure="raise"``); the state is then unchanged.
        """
        self._inputs_for(u, y, mask)
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
            raise (InputError if status[run] == BAD_INPUT else NumericalError)(
                f"batched {self.template.name}: {what} in realisation {run} at step {self.k}; state unchanged")
        self._cur ^= 1
        self.k += 1
        return self.x

    def run(self, us, ys, masks=None) -> BatchRun:
        """Whole trajectories of every realisation, one native call per block of steps.

        Parameters
        ----------
        us : array_like, shape (N, nu) or (n_runs, N, nu)
            Inputs (shared by all realisations, or one sequence each).
        ys : array_like, shape (n_runs, N, ny)
            Measurements (NaN entries missing).
        masks : array_like of bool, shape (n_runs, N, ny), optional

        Returns
        -------
        BatchRun
            Each realisation as :meth:`step` would give it (equal to 1e-12); the batch is
            left at the last step. A realisation that fails is marked in ``failed`` (with
            ``on_failure="mark"``) or raises, naming it and the step.
        """
        R, nx, ny, nu = self.n, self.nx, self.ny, self.nu
        ys = checks.float_array(ys, "ys")
        if ys.ndim != 3 or ys.shape[0] != R or ys.shape[2] != ny:
            raise InputError(f"ys must have shape ({R}, N, {ny}), got {ys.shape}")
        N = ys.shape[1]
        us = checks.float_array(us, "us")
        us = np.broadcast_to(us.reshape(-1, N, nu) if us.ndim == 3 else us.reshape(1, N, nu), (R, N, nu))
        if not np.isfinite(us).all():
            raise InputError("us contains NaN or inf")
        masks = np.ones((R, N, ny)) if masks is None else np.broadcast_to(checks.float_array(masks, "masks"),
                                                                          (R, N, ny))
        t = self.template
        fn = t.folded_step(RUN_BLOCK, R)
        sizes = {name: t.step_function().size_out(name) for name in
                 [t.step_function().name_out(i) for i in range(t.step_function().n_out())]}
        state = {k: v[self._cur].copy() for k, v in self._pairs.items()}
        size_in = {k: t.step_function().size_in(k) for k in state}
        keep = (*(f"{k}_new" for k in state), "nis", "accepted", "status")
        parts: dict = {k: [] for k in keep}
        for b0 in range(0, N, RUN_BLOCK):
            n = min(RUN_BLOCK, N - b0)

            def seq(a):  # (R, n, w) -> (w, R * RUN_BLOCK) with each run's block contiguous
                pad = np.concatenate([a[:, b0:b0 + n], np.zeros((R, RUN_BLOCK - n, a.shape[2]))], axis=1)
                return pad.transpose(2, 0, 1).reshape(a.shape[2], R * RUN_BLOCK)

            args = {k: _runs_flat(v, R, size_in[k]) for k, v in state.items()}
            args.update({k: _repeated(v, R, t.step_function().size_in(k), RUN_BLOCK)
                         for k, v in self._params.items()})
            args.update(u=seq(us), y=seq(ys), mask=seq(masks),
                        gate=np.full((1, R * RUN_BLOCK), t.gate),
                        nan_missing=np.full((1, R * RUN_BLOCK), float(t.nan_is_missing)))
            res = fn.call(args)
            for name in keep:
                r, c = sizes[name]
                a = np.asarray(res[name]).reshape(r, R, RUN_BLOCK, c)[:, :, :n, :]   # (r, R, n, c)
                parts[name].append(a.transpose(1, 2, 0, 3))                          # (R, n, r, c)
            for name in state:
                last = parts[f"{name}_new"][-1][:, n - 1]                              # (R, r, c)
                state[name] = last.transpose(0, 2, 1).reshape(R, -1).ravel()
        cat = {k: np.concatenate(v, axis=1) for k, v in parts.items()}
        status = cat["status"][:, :, 0, 0]
        bad = status != 0
        if bad.any() and self.on_failure == "raise":
            run, k = map(int, np.argwhere(bad)[0])
            what = "u or y contains NaN or inf" if status[run, k] == BAD_INPUT else "the estimate became non-finite"
            raise (InputError if status[run, k] == BAD_INPUT else NumericalError)(
                f"batched {t.name}: {what} in realisation {run} at index {k}; state unchanged")
        self.failed |= bad.any(axis=1)
        x0 = self.now("x").reshape(R, nx)
        P0 = self.now("P").reshape(R, nx, nx).transpose(0, 2, 1)
        Q0 = self.Q.diagonal(axis1=1, axis2=2)
        R0 = self.R.diagonal(axis1=1, axis2=2)
        out = BatchRun(
            x=np.concatenate([x0[:, None], cat["x_new"][..., 0]], axis=1),
            P=np.concatenate([P0[:, None], cat["P_new"]], axis=1),
            nis=cat["nis"][:, :, 0, 0], accepted=cat["accepted"][:, :, 0, 0] != 0,
            Q=(np.concatenate([Q0[:, None], cat["Q_new"].diagonal(axis1=2, axis2=3)], axis=1) if "Q_new" in cat
               else np.repeat(Q0[:, None], N + 1, axis=1)),
            R=(np.concatenate([R0[:, None], cat["R_new"].diagonal(axis1=2, axis2=3)], axis=1) if "R_new" in cat
               else np.repeat(R0[:, None], N + 1, axis=1)),
            failed=bad.any(axis=1))
        for name, value in state.items():
            self._pairs[name][self._cur][:] = value
        self.k += N
        return out


def _runs_flat(flat: np.ndarray, runs: int, size) -> np.ndarray:
    """Run-major flat state (each run's array column-major) as the mapped input matrix."""
    r, c = size
    return flat.reshape(runs, c, r).transpose(2, 0, 1).reshape(r, runs * c)


def _repeated(flat: np.ndarray, runs: int, size, block: int) -> np.ndarray:
    """A per-run fixed input (run-major flat, column-major each) repeated for every step
    of a folded block, as the mapped folded Function's input matrix."""
    r, c = size
    per_run = flat.reshape(runs, c, r).transpose(0, 2, 1)             # (runs, r, c)
    return np.tile(per_run, (1, 1, block)).transpose(1, 0, 2).reshape(r, runs * c * block)

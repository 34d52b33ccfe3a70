"""Run many realisations of one filter in lockstep: one native call per step for all, or one for whole records.

A Monte Carlo campaign pays the Python overhead once per step, or once, not once per realisation.
"""
from __future__ import annotations

import numpy as np

from fmu_models.errors import ConfigurationError, InputError, NumericalError, TypeMismatchError
from fmu_models.infra import checks
from fmu_models.infra.memory import check_fits

from ._compiled import compile_functions
from .base import KalmanBase
from .linalg import BAD_INPUT
from .runs import BatchRun
from .runtime import BoundStep, StepArrays, broadcast_inputs

__all__ = ["BatchFilter", "BatchRun"]

ON_FAILURE = ("raise", "mark")


class FoldedStep(StepArrays):
    """One step of ``runs`` realisations through a filter's native ``fold`` (compiled: no code per
    number of runs) with the interface of :class:`~estimators.runtime.BoundStep`; ``state`` and
    ``shared`` as :class:`~estimators.runtime.StepArrays`, flat run-major."""

    def __init__(self, fold, runs: int, state, shared):
        super().__init__(fold.step, state, shared, runs)
        args = {k: v.reshape(runs, -1) for k, v in self.inputs.items()}

        def bound(c: int):
            init = {k: pair[c].reshape(runs, -1) for k, pair in self.pairs.items()}
            outs = {n: (self.pairs[n[:-4]][1 - c] if n.endswith("_new") else self.outputs[n]).reshape(runs, 1, -1)
                    for n in fold.names_out}
            return fold.bind(runs, 1, args, init, outs)
        self._calls = (bound(0), bound(1))

    def trigger(self) -> float:
        """Step every realisation into the other state copy; returns the first run's status."""
        if self._calls[self.cell[0]]():
            raise NumericalError("batched step: the compiled step failed to evaluate")
        return self.status[0]


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
        What a realisation whose input or result is not finite does: raise (default), or
        keep its previous state (in :meth:`step`), be marked in ``failed`` and let the others
        go on (Monte Carlo campaigns count such runs as diverged).

    Attributes
    ----------
    x, P, Q, R, nis, innovation : ndarray
        The current estimates (n_runs, nx), covariances (n_runs, nx, nx), noise covariances
        and last diagnostics of every realisation.
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
        step_fn = template.step_function()
        per_run = 8 * (step_fn.nnz_in() + step_fn.nnz_out() + step_fn.nnz_out("x_new"))
        check_fits(self.n * per_run, f"n_runs = {self.n} realisations of {template.name} ({per_run} bytes each)",
                   "use fewer realisations per batch")
        state = {k: np.tile(v, self.n) for k, v in template.state_arrays().items()}
        if x0 is not None:
            x0 = checks.float_array(x0, "x0")
            if x0.shape != (self.n, self.nx) or not np.all(np.isfinite(x0)):
                raise ConfigurationError(f"x0 must be finite with shape ({self.n}, {self.nx}), got {x0.shape}")
            state["x"] = x0.ravel()
        self._params = {k: np.tile(v, self.n) for k, v in template.parameter_arrays().items()}
        if template.backend == "compiled":      # the filter's own fold, one step for all runs: no code per n_runs
            self._rt = FoldedStep(template.native_fold(), self.n, state, self._params)
        else:
            (step,), _ = s.compiled("batch", (*template.cache_key, self.n), template.backend,
                                    lambda: compile_functions([step_fn.map(self.n, "serial")], template.backend))
            self._rt = BoundStep(step, state, self._params)
        self.k = 0
        self.failed = np.zeros(self.n, dtype=bool)

    def now(self, key: str) -> np.ndarray:
        """Current flat state array ``key`` (all realisations, run-major)."""
        return self._rt.now(key)

    def _cov(self, key: str, n: int) -> np.ndarray:
        flat = self._rt.now(key) if key in self._rt.pairs else self._params[key]
        return flat.reshape(self.n, n, n).transpose(0, 2, 1).copy()

    x = property(lambda self: self.now("x").reshape(self.n, self.nx).copy())
    P = property(lambda self: self._cov("P", self.nx))
    Q = property(lambda self: self._cov("Q", self.nx), doc="Process noise covariances, (n_runs, nx, nx).")
    R = property(lambda self: self._cov("R", self.ny), doc="Measurement noise covariances, (n_runs, ny, ny).")
    nis = property(lambda self: self._rt.outputs["nis"].copy())
    innovation = property(lambda self: self._rt.outputs["innov"].reshape(self.n, self.ny).copy())

    def _inputs_for(self, u, y, mask):
        ins = self._rt.inputs
        try:
            ins["u"].reshape(self.n, self.nu)[:] = u
            y = checks.float_array(y, "y")
            if y.shape != (self.n, self.ny):
                raise ValueError
            ins["y"][:] = y.ravel()
            ins["mask"][:] = 1.0 if mask is None else np.broadcast_to(
                checks.float_array(mask, "mask"), (self.n, self.ny)).ravel()
        except ValueError:
            raise InputError(f"u must broadcast to ({self.n}, {self.nu}) and y have shape "
                             f"({self.n}, {self.ny}); got {np.shape(u)} and {np.shape(y)}") from None

    def step(self, u, y, mask=None) -> np.ndarray:
        """One step of every realisation: ``u`` (n_runs, nu) or (nu,), ``y`` (n_runs, ny) (NaN
        entries missing), optional ``mask`` (n_runs, ny). Returns the estimates (n_runs, nx).
        Raises InputError / NumericalError naming the realisation (``on_failure="raise"``);
        the state is then unchanged."""
        self._inputs_for(u, y, mask)
        rt = self._rt
        rt.trigger()
        bad = self._failures(rt.status, lambda: f"step {self.k}")
        if bad.any():
            for name, pair in rt.pairs.items():     # failed runs keep their previous state
                pair[1 - rt.cell[0]].reshape(self.n, -1)[bad] = rt.now(name).reshape(self.n, -1)[bad]
            self.failed |= bad
        rt.cell[0] ^= 1
        self.k += 1
        return self.x

    def run(self, us, ys, masks=None) -> BatchRun:
        """Whole trajectories of every realisation in one native call.

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
            left at the last step. A failing realisation is marked in ``failed`` or raises
            (``on_failure``), naming it and the step.
        """
        R, nx, ny = self.n, self.nx, self.ny
        us, ys, masks = self._record(us, ys, masks)
        N = ys.shape[1]
        t = self.template
        state = {k: self._rt.now(k).reshape(R, -1) for k in self._rt.pairs}
        outs, _, last = t.fold_record(state, us, ys, masks, {k: v.reshape(R, -1) for k, v in self._params.items()})
        bad = self._failures(outs["status"][:, :, 0], lambda k: f"index {k}").any(axis=1)
        self.failed |= bad

        def diag(name, n, fixed):
            if name in outs:
                return outs[name].reshape(R, N + 1, n, n).diagonal(axis1=2, axis2=3)
            return np.repeat(fixed.reshape(R, n, n).diagonal(axis1=1, axis2=2)[:, None], N + 1, axis=1)

        out = BatchRun(
            x=outs["x_new"], P=outs["P_new"].reshape(R, N + 1, nx, nx).transpose(0, 1, 3, 2),
            nis=outs["nis"][:, :, 0], accepted=outs["accepted"][:, :, 0] != 0,
            Q=diag("Q_new", nx, self._params.get("Q")), R=diag("R_new", ny, self._params.get("R")),
            failed=bad, state_names=list(t.system.state_names), output_names=list(t.system.output_names),
            innovation=outs["innov"].reshape(R, N, ny), S=outs["S"].reshape(R, N, ny, ny), jacobians=t.system.jacobians)
        for name, value in last.items():
            self._rt.now(name)[:] = value.ravel()
        self.k += N
        return out

    def _record(self, us, ys, masks) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The records of :meth:`run` as contiguous float arrays, or InputError naming the problem."""
        R, ny, nu = self.n, self.ny, self.nu
        ys = np.ascontiguousarray(checks.float_array(ys, "ys"))
        if ys.ndim != 3 or ys.shape[0] != R or ys.shape[2] != ny:
            raise InputError(f"ys must have shape ({R}, N, {ny}), got {ys.shape}")
        N = ys.shape[1]
        us = np.ascontiguousarray(broadcast_inputs(us, R, N, nu))
        masks = (np.ones((R, N, ny)) if masks is None else
                 np.ascontiguousarray(np.broadcast_to(checks.float_array(masks, "masks"), (R, N, ny))))
        return us, ys, masks

    def _failures(self, status: np.ndarray, where) -> np.ndarray:
        """Where ``status`` (n_runs, ...) is not 0; with ``on_failure="raise"``, the error of the
        first failure (at step ``where(k)``; the model's error if it made a result non-finite)."""
        bad = status != 0
        if not bad.any():
            return bad
        failure = self.template.system.take_failure()
        if self.on_failure == "mark":
            return bad
        run, *k = map(int, np.argwhere(bad)[0])
        status, where = status[(run, *k)], where(*k)
        bad_input = status == BAD_INPUT
        if failure is not None and not bad_input:
            raise type(failure)(f"batched {self.template.name}: realisation {run} at {where}: {failure}; state "
                                "unchanged")
        what = "u or y contains NaN or inf" if bad_input else "the estimate became non-finite"
        raise (InputError if bad_input else NumericalError)(
            f"batched {self.template.name}: {what} in realisation {run} at {where}; state unchanged")

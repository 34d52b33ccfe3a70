"""The base class of every filter, :class:`~estimators.base.KalmanBase`: its interface and the protocol's defaults.

The hooks (:mod:`estimators.protocol`) make one fused ``step`` Function, compiled and bound to the
filter's arrays, folded over records, mapped over realisations and exported as an FMU; the
manual's estimators page describes missing channels, the gate and refused inputs.
"""
from __future__ import annotations

from collections.abc import Mapping

import casadi as ca
import numpy as np

from fmu_models.errors import ConfigurationError, InputError, UnknownNameError
from fmu_models.infra import checks
from fmu_models.infra.memory import check_fits
from fmu_models.infra.registry import Registry

from ._compiled import compile_functions
from ._fold import NativeFold, compile_with_fold
from .discrete import DiscreteModel, checked_model
from .linalg import BAD_RESULT, CSE, log_det, log_likelihood, status_flag, upper_entries, used_measurement
from .protocol import DIAGNOSTICS, Parameter, StepContext, StepResult, Update, build_step, per_name
from .runs import FilterRun, NoiseHistory
from .runtime import BoundStep, BufferedFunction, VectorInput, explain_status, lean_step, matrix

__all__ = ["DIAGNOSTICS", "FILTERS", "KEEP", "FilterRun", "KalmanBase", "Parameter", "StepContext", "StepResult",
           "Update"]

#: The filters usable by name in scenario files and the command line (``class F(KalmanBase, register="F")``).
FILTERS: Registry = Registry("filter")
#: Outputs that are symmetric matrices (exactly, their lower triangle mirrors the upper).
SYMMETRIC = ("P_new", "P_prior", "S", "Q_new", "R_new")
#: What run(keep="estimates") does not store.
DROPPABLE = ("x_prior", "P_prior", "innov", "S", "K")
KEEP = ("all", "estimates")


def _matrix(key: str, rows: str, cols: str, doc: str) -> property:
    """A property: a copy of ``KalmanBase._now(key)`` as a matrix of the model's sizes ``rows``, ``cols``."""
    return property(lambda self: matrix(self._now(key), getattr(self.system, rows), getattr(self.system, cols)).copy(),
                    doc=doc)


class KalmanBase:
    """Common interface: ``predict(u)``, ``update(y)``, ``step(u, y)``, ``run(us, ys)``; a new filter
    implements the hooks of :mod:`estimators.protocol` and registers with ``register="Name"``.

    Parameters
    ----------
    system : DiscreteModel
        The discrete model the filter runs on (see :func:`estimators.discretize`).
    x0 : array_like, shape (nx,)
        Initial state estimate.
    P0, Q, R : array_like
        Initial state, process and measurement noise covariances (nx, nx), (nx, nx), (ny, ny),
        symmetric positive definite, or a diagonal vector, or a scalar (times identity).
    gate : float, optional
        Chi-square gate on the NIS: a measurement vector with ``nis > gate`` is refused (the
        step predicts only), e.g. ``scipy.stats.chi2.ppf(0.999, ny)``. Default None (no gate).
    nan_is_missing : bool
        A NaN measurement channel is missing (default True); with False it is an error.
    backend : {"compiled", "vm"}
        Run the step as compiled native code (cached on disk, about 10x faster; needs a C
        compiler, else falls back to "vm") or in CasADi's VM; the attribute is the one in use.

    Attributes
    ----------
    history : NoiseHistory
        The diagonals of Q and R: the initial values, each :meth:`set_noise` and every adaptation.
    """

    name = "base"
    #: Whether the fused step holds the whole filter (BatchFilter, native run, FMU use it).
    supports_batch = True
    #: Whether Q and R are part of the state (adaptive filters), else fixed inputs of the step.
    adapts_noise = False

    def __init_subclass__(cls, register: str | None = None, aliases: tuple[str, ...] = (), **kwargs):
        super().__init_subclass__(**kwargs)
        if register is not None:
            FILTERS.register(register, cls, aliases=aliases)

    def __init__(self, system: DiscreteModel, x0, P0, Q, R, gate: float | None = None,
                 nan_is_missing: bool = True, backend: str = "compiled"):
        self.system = checked_model(system)
        n, p = system.nx, system.ny
        self.gate = np.inf if gate is None else checks.positive(gate, "gate")
        self.nan_is_missing = bool(nan_is_missing)
        noise = {"Q": checks.covariance(Q, n, "Q").ravel(order="F"),
                 "R": checks.covariance(R, p, "R").ravel(order="F")}
        self._start = (checks.vector(x0, n, "x0", ConfigurationError), checks.covariance(P0, n, "P0"))
        extra = self._extra_arrays()
        self._extra_names, self._params = list(extra), list(self.step_parameters())
        state = {"x": self._start[0], "P": self._start[1].ravel(order="F"), **(noise if self.adapts_noise else {}),
                 **extra}
        # fixed inputs of the step, shared with the bound step: changed in place (set_noise)
        self._fixed = {"gate": np.array([self.gate]), "nan_missing": np.array([float(self.nan_is_missing)]),
                       **({} if self.adapts_noise else noise), **{q.name: q.value.copy() for q in self._params}}

        def build():
            raw = self.wrap_step(build_step(self, extra, self._params))
            fn, used, lib = compile_with_fold(raw, backend)     # one library: the step and its fold
            return fn, used, raw, lib

        step, self.backend, self._raw_step, self._step_library = system.compiled("step", self.cache_key, backend,
                                                                                 build)
        self._rt = BoundStep(step, state, self._fixed)
        ins = self._rt.inputs
        self._u, self._y, self._mask = ins["u"], ins["y"], ins["mask"]
        self._fill_u, self._fill_y, self._fill_mask = (VectorInput(ins[k], self.name, k) for k in ("u", "y", "mask"))
        self._mask[:] = 1.0                    # between calls the mask buffer is all ones
        self._count = [0]                      # the step count k
        self._after = type(self).after_step is not KalmanBase.after_step
        if type(self).step is KalmanBase.step:      # the lean path, specialised for nu and ny
            self.step = lean_step(self._rt, self._fill_u, self._fill_y, self._count, self._step, self._explain,
                                  self.after_step if self._after else None)
        self.history = NoiseHistory(n, p)
        self._record()

    @property
    def k(self) -> int:
        """Number of steps done."""
        return self._count[0]

    @k.setter
    def k(self, value: int) -> None:
        self._count[0] = int(value)

    def config_key(self) -> tuple:
        """What identifies the compiled step beyond the class (a window length, not step inputs)."""
        return ()

    @property
    def cache_key(self) -> tuple:
        """The class (module and name) and :meth:`config_key`: what identifies the compiled step."""
        cls = type(self)
        return (cls.__module__, cls.__qualname__, *self.config_key())

    def extra_state(self) -> dict:
        """Initial values of the extra state arrays, by name (default none); the filter starts
        from ``self._start = (x0, P0)``."""
        return {}

    def _extra_arrays(self) -> dict[str, np.ndarray]:
        """:meth:`extra_state` flat (column-major)."""
        return {k: np.array(v, float).ravel(order="F") for k, v in self.extra_state().items()}

    def wrap_step(self, step: ca.Function) -> ca.Function:
        """The Function every form of the filter runs, from the fused ``step`` (default: itself)."""
        return step

    def step_parameters(self) -> list[Parameter]:
        """The step's fixed inputs beyond Q and R, each also an FMU parameter (default none)."""
        return []

    def predict_expr(self, ctx: StepContext) -> tuple[ca.SX, ca.SX]:
        """The time update ``(x_prior, P_prior)`` from the symbols of ``ctx`` (required)."""
        raise NotImplementedError(f"{type(self).__name__} must implement predict_expr (see estimators.protocol)")

    def update_expr(self, ctx: StepContext, x_prior: ca.SX, P_prior: ca.SX) -> Update:
        """The measurement update of the valid channels from the prior (required)."""
        raise NotImplementedError(f"{type(self).__name__} must implement update_expr (see estimators.protocol)")

    def adapt_expr(self, ctx: StepContext, result: StepResult) -> dict:
        """New Q, R (if the filter adapts them) and extra state from the step's ``result`` (default none)."""
        return {}

    def after_step(self) -> None:
        """Runtime hook after every :meth:`step` from Python, the new state current (default: nothing)."""

    def after_run(self, outputs: dict) -> None:
        """Runtime hook after a native :meth:`run`, with every step's flat ``outputs`` by name
        (``x_new`` ... rows ``k = 1..N``); default: nothing."""

    def smoother_cross_covariance(self, x: ca.SX, P: ca.SX, u: ca.SX) -> ca.SX:
        """The RTS smoother's ``D_k = Cov(x_k, x_{k+1} | y_1..k)`` at the filtered ``(x, P)``
        and input ``u`` (SX): ``P F^T`` with the model's exact Jacobian (EKF-type filters)."""
        _, F = self.system.transition(x, u)
        return ca.mtimes(P, F.T)

    def fmu_noise_parameters(self) -> list[Parameter]:
        """The FMU parameters giving Q and R (default their diagonals ``Q0_<state>``, ``R0_<output>``)."""
        s, extra = self.system, " (initial)" if self.adapts_noise else ""
        return [per_name("Q0", _diagonal(self.Q, "Q", self.name), "positive", "process noise variance" + extra,
                         s.state_names),
                per_name("R0", _diagonal(self.R, "R", self.name), "positive", "measurement noise variance" + extra,
                         s.output_names)]

    def fmu_noise(self, p: Mapping[str, ca.SX]) -> tuple[ca.SX, ca.SX]:
        """``(Q, R)`` from the FMU parameters ``p`` (SX by name) of :meth:`fmu_noise_parameters`."""
        return ca.diag(p["Q0"]), ca.diag(p["R0"])

    def fmu_parameters(self) -> list[Parameter]:
        """The parameters of this filter's FMU at its current values: ``x0``, ``P0`` (diagonal),
        ``gate`` (0: none), :meth:`fmu_noise_parameters` and :meth:`step_parameters`."""
        names = self.system.state_names
        return [per_name("x0", self.x, "real", "initial estimate", names),
                per_name("P0", _diagonal(self.P, "P0", self.name), "positive", "initial variance", names),
                Parameter("gate", self.gate if np.isfinite(self.gate) else 0.0, "nonnegative",
                          "chi-square gate on the NIS: a measurement with a larger NIS is refused (0: no gate)"),
                *self.fmu_noise_parameters(), *self._params]

    def fmu_initial(self, p: Mapping[str, ca.SX]) -> dict[str, ca.SX]:
        """The initial state arrays and the fixed step inputs from the FMU parameters ``p`` (SX by name)."""
        Q, R = self.fmu_noise(p)
        return {"x": p["x0"], "P": ca.diag(p["P0"]), "Q": Q, "R": R,
                "gate": ca.if_else(p["gate"] > 0, p["gate"], ca.inf), "nan_missing": ca.SX(float(self.nan_is_missing)),
                **{k: ca.SX(ca.DM(v)) for k, v in self.extra_state().items()},
                **{q.name: p[q.name] for q in self._params}}

    def state_arrays(self) -> dict[str, np.ndarray]:
        """Copies of the flat (column-major) state arrays by name: ``x, P`` and any adaptive
        state (``Q, R``, ...); what :class:`~estimators.BatchFilter` starts from."""
        return {k: self._rt.now(k).copy() for k in self._rt.pairs}

    def parameter_arrays(self) -> dict[str, np.ndarray]:
        """Copies of the step's flat fixed inputs (gate, nan_missing, a fixed Q and R, step parameters)."""
        return {k: v.copy() for k, v in self._fixed.items()}

    def bind_summary(self, out: np.ndarray, covariance: str = "diagonal"):
        """A call writing, in one native call, the current ``x`` (nx), ``diag P`` (nx), with
        ``covariance="full"`` the upper off-diagonal entries of P (row by row, ``i < j``), and the last
        NIS into the contiguous float array ``out`` (bound once: a component's slice of the signals).

        Raises
        ------
        UnknownNameError
            ``covariance`` is not ``"diagonal"`` or ``"full"``.
        ConfigurationError
            ``out`` has the wrong size or is not a contiguous float array.
        """
        if covariance not in ("diagonal", "full"):
            raise UnknownNameError(f"{self.name}: covariance must be 'diagonal' or 'full', got {covariance!r}")
        n = self.system.nx
        upper = [(i, j) for i in range(n) for j in range(i + 1, n)] if covariance == "full" else []
        size = 2 * n + len(upper) + 1
        if not (isinstance(out, np.ndarray) and out.dtype == np.float64 and out.shape == (size,)
                and out.flags.c_contiguous):
            raise ConfigurationError(f"{self.name}: the summary needs a contiguous float array of {size} entries")

        def build():
            x, P, nis = ca.SX.sym("x", n), ca.SX.sym("P", n, n), ca.SX.sym("nis")
            fn = ca.Function("summary", [x, P, nis],
                             [ca.vertcat(x, ca.diag(P), *[P[i, j] for i, j in upper], nis)])
            return compile_functions([fn], self.backend)[0][0]

        fn = self.system.compiled("summary", (covariance, n), self.backend, build)
        rt = self._rt
        bound = [BufferedFunction(fn, {0: rt.pairs["x"][i], 1: rt.pairs["P"][i], 2: rt.outputs["nis"]}, {0: out})
                 for i in (0, 1)]
        triggers = tuple(b.trigger for b in bound)
        cell = rt.cell

        def write(_keep=bound) -> None:      # _keep: the buffers must live as long as their triggers
            triggers[cell[0]]()
        return write

    def step_function(self) -> ca.Function:
        """The uncompiled fused step (a CasADi Function; see :func:`~estimators.protocol.build_step`)."""
        return self._raw_step

    def _now(self, key: str) -> np.ndarray:
        """The current state array ``key``, else the fixed input (Q, R), else the output ``key`` (shared)."""
        rt = self._rt
        if key in rt.pairs:
            return rt.now(key)
        return self._fixed[key] if key in self._fixed else rt.outputs[key]

    def _out(self, name: str) -> np.ndarray:
        return self._rt.outputs[name]

    x = property(lambda self: self._rt.now("x").copy(), doc="State estimate, shape (nx,).")
    P = _matrix("P", "nx", "nx", "State covariance, shape (nx, nx).")
    Q = _matrix("Q", "nx", "nx", "Process noise covariance, shape (nx, nx).")
    R = _matrix("R", "ny", "ny", "Measurement noise covariance, shape (ny, ny).")
    x_prior = property(lambda self: self._out("x_prior").copy(), doc="Prediction of the last step, (nx,).")
    P_prior = _matrix("P_prior", "nx", "nx", "Covariance of the prediction, (nx, nx).")
    innovation = property(lambda self: self._out("innov").copy(),
                          doc="Last innovation ``y - h(x_prior)`` (seed 000 eq 26), (ny,).")
    S = _matrix("S", "ny", "ny", "Last innovation covariance, (ny, ny).")
    K = _matrix("K", "nx", "ny", "Last gain, (nx, ny).")
    nis = property(lambda self: float(self._out("nis")[0]), doc="Last normalised innovation squared.")
    accepted = property(lambda self: bool(self._out("accepted")[0]), doc="The gate passed the last measurement.")

    def reset(self, x0=None, P0=None) -> None:
        """Start again from ``x0`` (nx,) and ``P0`` (default: the current ones) with the current
        Q and R; the step count and the extra state restart too."""
        n = self.system.nx
        x = self.x if x0 is None else checks.vector(x0, n, "x0", ConfigurationError)
        P = self.P if P0 is None else checks.covariance(P0, n, "P0")
        self._start = (x, P)
        rt = self._rt
        values = {"x": x, "P": P.ravel(order="F"), **self._extra_arrays()}
        for name, pair in rt.pairs.items():
            value = values.get(name, rt.now(name).copy())
            for a in pair:
                a[:] = value
        rt.cell[0], self.k = 0, 0
        self._record()

    def snapshot(self) -> dict:
        """The filter's whole state, for :meth:`restore`: copies of every array its step reads or
        writes, the current state copy, the step count, the noise history's length, the attributes."""
        rt = self._rt
        unique = {id(a): a for a in [*(a for pair in rt.pairs.values() for a in pair), *rt.outputs.values(),
                                     *rt.inputs.values(), *self._fixed.values(), rt.status]}
        return {"arrays": [(a, a.copy()) for a in unique.values()], "cur": rt.cell[0], "k": self.k,
                "history": len(self.history), "attributes": dict(self.__dict__)}

    def restore(self, snapshot: dict) -> None:
        """Return to the state :meth:`snapshot` took of this filter (the numbers of a new one)."""
        for a, saved in snapshot["arrays"]:
            a[:] = saved
        self.__dict__.clear()
        self.__dict__.update(snapshot["attributes"])
        self._rt.cell[0], self.k = snapshot["cur"], snapshot["k"]
        self.history.count[0] = snapshot["history"]

    def set_noise(self, Q=None, R=None) -> None:
        """Replace Q and/or R (both validated first: on a refusal nothing changes)."""
        new = {k: checks.covariance(M, n, k).ravel(order="F")
               for k, M, n in (("Q", Q, self.system.nx), ("R", R, self.system.ny)) if M is not None}
        for k, flat in new.items():
            self._now(k)[:] = flat
        self._record()

    def _record(self) -> None:
        self.history.append_flat(self.k, self._now("Q"), self._now("R"))

    def noise_history(self):
        """How Q and R changed: DataFrame indexed by step with their diagonals."""
        return self.history.to_frame(self.system.state_names, self.system.output_names)

    def _explain(self, what: str) -> None:
        """Raise the error of a failed step (an FMU model's own, if it made a result non-finite)."""
        failure = self.system.take_failure()
        if failure is not None and self._rt.status[0] == BAD_RESULT:
            raise type(failure)(f"{self.name}: {failure}, at step {self.k} ({what}); filter state unchanged")
        explain_status(self._rt.status[0], self.name, self.k, self._u, self._y, self._mask, self.nan_is_missing,
                       what)

    def _used_channels(self, ys: np.ndarray, masks: np.ndarray) -> np.ndarray:
        """Which channels of ``ys`` (..., ny) an update uses: masked in and (unless NaN is an error) not NaN."""
        return (masks != 0) & (~np.isnan(ys) if self.nan_is_missing else True)

    def step(self, u, y, mask=None) -> np.ndarray:
        """Predict with ``u`` (nu,), then update with ``y`` (ny,); ``y=None`` predicts only.
        NaN entries of ``y`` are missing channels (unless ``nan_is_missing=False``), and so are
        those where ``mask`` (ny,) of bool is False. Returns a copy of the new estimate (nx,).

        Raises
        ------
        InputError
            ``u`` or a used ``y`` entry is NaN or inf, or a shape is wrong.
        TypeMismatchError
            ``u`` or ``y`` is not numbers.
        NumericalError
            The estimate became non-finite. After any error the state is unchanged.
        """
        return self._step(u, y, mask)

    def _step(self, u, y, mask=None) -> np.ndarray:
        """:meth:`step` for every call (``runtime.lean_step`` takes the common one faster)."""
        self._fill_u(u)
        try:
            if y is None:
                self._mask[:] = 0.0
            else:
                self._fill_y(y)
                if mask is not None:
                    self._fill_mask(mask)
            rt = self._rt
            cur = rt.cell[0]
            rt.triggers[cur]()
            if rt.status[0]:
                self._explain("step")
        finally:
            self._mask[:] = 1.0
        rt.cell[0] = cur ^ 1
        self._count[0] += 1
        if self._after:
            self.after_step()
        return rt.pairs["x"][cur ^ 1].copy()

    def predict(self, u) -> np.ndarray:
        """Time update with input ``u`` (nu,), a step without measurement; returns the prior estimate."""
        return self.step(u, None)

    def _update_function(self) -> ca.Function:
        """The compiled measurement update of :meth:`update`."""
        s = self.system
        x, P, R = ca.SX.sym("x", s.nx), ca.SX.sym("P", s.nx, s.nx), ca.SX.sym("R", s.ny, s.ny)
        y, mask, gate, nan_missing = (ca.SX.sym("y", s.ny), ca.SX.sym("mask", s.ny), ca.SX.sym("gate"),
                                      ca.SX.sym("nan_missing"))
        valid, y_used = used_measurement(y, mask, nan_missing)
        ctx = StepContext(s, x, P, ca.SX.zeros(s.nx, s.nx), R, ca.SX.zeros(s.nu), y_used, valid, gate)
        upd = Update(*self.update_expr(ctx, x, P))
        d = ca.densify
        fn = ca.Function("update", [x, P, R, y, mask, gate, nan_missing],
                         [d(upd.x), d(upd.P), d(upd.innovation), d(upd.S), d(upd.K), upd.nis, upd.accepted,
                          log_det(upd.S), status_flag([y_used], [upd.x, upper_entries(upd.P)])], CSE)
        return compile_functions([fn], self.backend)[0][0]

    def update(self, y, mask=None) -> np.ndarray:
        """Measurement update alone with ``y`` (ny,) (and ``mask``) from the current estimate:
        x, P and the diagnostics describe it (Q and R do not adapt). Returns the posterior estimate."""
        s = self.system
        fn = s.compiled("update", self.cache_key, self.backend, self._update_function)
        self._fill_y.checked(y)
        try:
            if mask is not None:
                self._fill_mask.checked(mask)
            res = fn(self._now("x"), matrix(self._now("P"), s.nx, s.nx), matrix(self._now("R"), s.ny, s.ny),
                     self._y, self._mask, self.gate, float(self.nan_is_missing))
            self._rt.status[0] = float(res[-1])
            if self._rt.status[0]:
                self._explain("update")
        finally:
            self._mask[:] = 1.0
        self._out("x_prior")[:], self._out("P_prior")[:] = self._now("x"), self._now("P")
        for key, value in zip(("x", "P", *DIAGNOSTICS[2:]), res):
            self._now(key)[:] = np.asarray(value).ravel(order="F")
        return self.x

    def native_fold(self):
        """The fused step folded over records in native code (a ``NativeFold``), cached on the model."""
        return self.system.compiled("fold", self.cache_key, self.backend,
                                    lambda: NativeFold(self._raw_step, len(self._rt.pairs), self.backend,
                                                       library=self._step_library))

    def fold_record(self, state: dict, us, ys, masks, params: dict, drop=()) -> tuple[dict, dict, dict]:
        """Fold the fused step over the records of ``runs`` realisations in one native call.

        Parameters
        ----------
        state, params : dict of str to ndarray
            The initial state arrays and the step's fixed inputs, shape (runs, nnz) each.
        us, ys, masks : ndarray
            The contiguous records, shapes (runs, N, nu), (runs, N, ny), (runs, N, ny).
        drop : collection of str
            Outputs not kept (their views are scratch rows).

        Returns
        -------
        (stored, views, last)
            ``NativeFold.outputs`` (without the extra state's history) and the state after the
            last step, (runs, nnz) by name.
        """
        runs, N = ys.shape[:2]
        fold = self.native_fold()
        cycled = [f"{k}_new" for k in self._extra_names]     # no one reads their history
        outs, views = fold.outputs(runs, N, state, drop, cycled)
        fold(runs, N, {"u": us, "y": ys, "mask": masks, **params}, state, views, cycled)
        last = {name: outs[f"{name}_new"][:, (N - 1) % 2 if f"{name}_new" in cycled else -1] for name in state}
        return {n: a for n, a in outs.items() if n not in cycled}, views, last

    def check_record(self, us, ys, masks=None):
        """A record ``(us, ys, masks)`` as contiguous float arrays (N, nu), (N, ny), (N, ny), or
        :class:`InputError` / :class:`~fmu_models.errors.TypeMismatchError` naming the problem."""
        nu, ny = self.system.nu, self.system.ny
        us = checks.float_array(us, "us")
        ys = checks.float_array(ys, "ys")
        N = ys.shape[0] if ys.ndim else 0
        if us.ndim == 1 and nu == 1:
            us = us[:, None]
        if ys.ndim == 1 and ny == 1:
            ys = ys[:, None]
        if ys.shape != (N, ny) or us.shape != (N, nu):
            raise InputError(f"{self.name}: run needs us of shape (N, {nu}) and ys of shape "
                             f"(N, {ny}); got {us.shape} and {ys.shape}")
        if N == 0:
            raise InputError(f"{self.name}: the record is empty (N = 0 steps)")
        if not np.isfinite(us).all():
            k = int(np.flatnonzero(~np.isfinite(us).all(axis=1))[0])
            raise InputError(f"{self.name}: us contains NaN or inf at index {k}")
        m = np.ones((N, ny)) if masks is None else checks.float_array(masks, "masks")
        if m.shape != (N, ny):
            raise InputError(f"{self.name}: masks must have shape ({N}, {ny}), got {m.shape}")
        return tuple(np.ascontiguousarray(a, dtype=float) for a in (us, ys, m))

    def _check_run_fits(self, ys, keep: str) -> None:
        """Refuse (ResourceError) a run whose record and outputs would not fit in memory."""
        try:
            n = len(ys)
        except TypeError:
            return                   # not a sequence: check_record names the problem
        s, fn = self.system, self._raw_step
        out = sum(fn.nnz_out(i) for i in range(fn.n_out()) if keep == "all" or fn.name_out(i) not in DROPPABLE)
        per_step = 8 * (2 * (s.nu + 2 * s.ny) + 2 * out)   # the record and its mask as arrays; outputs, results
        check_fits(n * per_step, f"{self.name}: run over N = {n} steps ({per_step} bytes a step)",
                   "filter the record in pieces (each run continues where the last ended), or keep='estimates'")

    def run(self, us, ys, masks=None, y0=None, keep: str = "all") -> FilterRun:
        """Filter whole sequences in one native call: ``step(us[k], ys[k], masks[k])``, ``k = 0..N-1``.

        Parameters
        ----------
        us : array_like, shape (N, nu)
            Inputs; ``us[k]`` is held over the step that ends at measurement ``ys[k]``.
        ys : array_like, shape (N, ny)
            Measurements; NaN entries are missing (all NaN: a prediction only).
        masks : array_like of bool, shape (N, ny), optional
            False marks further missing channels.
        y0 : array_like, shape (ny,), optional
            A measurement of the initial state: ``update(y0)`` before the first step (the
            model of pykalman and of EM); ``x[0]``, ``P[0]`` are then the updated ones and
            the log-likelihood includes it.
        keep : {"all", "estimates"}
            Keep every diagnostic (default; what :func:`~estimators.rts_smooth` needs), or only
            ``x``, ``P``, the NIS, the acceptance and the log-likelihood (the other attributes
            of the result are then None).

        Returns
        -------
        FilterRun
            Every step's results; the filter is left at the last step, as after N calls of
            :meth:`step` (equal to 1e-12).

        Raises
        ------
        InputError, NumericalError
            As :meth:`step`, naming the step; the filter's state is then unchanged.
        ResourceError
            The record and the run's outputs would not fit in memory (said before allocating).
        """
        if keep not in KEEP:
            raise UnknownNameError(f"{self.name}: keep must be one of {KEEP}, got {keep!r}")
        self._check_run_fits(ys, keep)
        us, ys, masks = self.check_record(us, ys, masks)
        y0_ll = 0.0
        if y0 is not None:
            self.update(y0)
            out = self._rt.outputs
            y0_ll = log_likelihood(out["nis"], out["logdet_S"], [self._used_channels(self._y, self._mask).sum()],
                                   out["accepted"] != 0)
        result = self._run_native(us, ys, masks, keep) if self.supports_batch else self._run_by_steps(us, ys, masks)
        result.log_likelihood += y0_ll
        return result

    def _run_native(self, us, ys, masks, keep: str) -> FilterRun:
        """:meth:`run` of checked arrays in one native call; the filter is left at the last step."""
        state = {k: v[None] for k, v in self.state_arrays().items()}
        params = {k: v[None] for k, v in self.parameter_arrays().items()}
        outs, views, last = self.fold_record(state, us[None], ys[None], masks[None], params,
                                             DROPPABLE if keep == "estimates" else ())
        status = outs["status"][0, :, 0]
        if status.any():
            self._explain_run(int(np.flatnonzero(status)[0]), status, us, ys, masks)
        cat = {name: a[0] for name, a in outs.items()}
        result = self._make_run(cat, us, ys, masks)
        rt = self._rt
        for name in rt.pairs:                      # the filter now stands at the last step
            rt.now(name)[:] = last[name][0]
        for name in rt.outputs:
            if name != "status":
                rt.outputs[name][:] = cat[name][-1] if name in cat else views[name][0, -1]
        self.k += len(ys)
        self.after_run({name: (v[1:] if name.endswith("_new") else v) for name, v in cat.items()})
        return result

    def _explain_run(self, k: int, status: np.ndarray, us, ys, masks) -> None:
        """Raise the error of a native run whose step ``k`` failed with ``status[k]``, as :meth:`step` would."""
        self._rt.status[0] = status[k]
        self._u[:], self._y[:], self._mask[:] = us[k], ys[k], masks[k]
        k_saved, self.k = self.k, self.k + k
        try:
            self._explain(f"run index {k}")
        finally:
            self.k = k_saved
            self._mask[:] = 1.0

    def _make_run(self, cat: dict, us, ys, masks) -> FilterRun:
        """A FilterRun from the flat per-step outputs ``cat`` (the state's from the initial row)."""
        s = self.system
        nx, ny = s.nx, s.ny

        def mats(name, r, c):
            if name in SYMMETRIC:      # mirrored by construction: the column-major rows are row-major
                return cat[name].reshape(-1, r, c)
            return cat[name].reshape(-1, c, r).transpose(0, 2, 1)

        acc = cat["accepted"].ravel() != 0
        nis = cat["nis"].ravel()
        used = self._used_channels(ys, masks)
        if "Q_new" in cat:
            Qd = mats("Q_new", nx, nx).diagonal(axis1=1, axis2=2)
            Rd = mats("R_new", ny, ny).diagonal(axis1=1, axis2=2)
        else:
            Qd = np.broadcast_to(np.diag(self.Q), (len(nis) + 1, nx))
            Rd = np.broadcast_to(np.diag(self.R), (len(nis) + 1, ny))
        kept = "x_prior" in cat
        return FilterRun(
            x=cat["x_new"].reshape(-1, nx), P=mats("P_new", nx, nx),
            x_prior=cat["x_prior"].reshape(-1, nx) if kept else None,
            P_prior=mats("P_prior", nx, nx) if kept else None,
            innovation=cat["innov"].reshape(-1, ny) if kept else None, S=mats("S", ny, ny) if kept else None,
            K=mats("K", nx, ny) if kept else None, nis=nis, accepted=acc, mask=used & acc[:, None], us=us,
            Q=Qd, R=Rd, log_likelihood=log_likelihood(nis, cat["logdet_S"].ravel(), used.sum(axis=1), acc),
            state_names=list(s.state_names), output_names=list(s.output_names), filter_name=self.name,
            model=s.identity, jacobians=s.jacobians)

    def _run_by_steps(self, us, ys, masks) -> FilterRun:
        """``run`` as a loop of :meth:`step` (a filter whose adaptation is not all in the fused step)."""
        arrays = {"x_new": "x", "P_new": "P", "Q_new": "Q", "R_new": "R", **{name: name for name in DIAGNOSTICS}}
        rec: dict = {key: [self._now(name).copy()] if key.endswith("_new") else [] for key, name in arrays.items()}
        for k in range(len(ys)):
            self.step(us[k], ys[k], masks[k] != 0)
            for key, name in arrays.items():
                rec[key].append(self._now(name).copy())
        return self._make_run({k: np.array(v) for k, v in rec.items()}, us, ys, masks)


def _diagonal(M: np.ndarray, what: str, owner: str) -> np.ndarray:
    """The diagonal of ``M``, refused (ConfigurationError) if ``M`` has off-diagonal entries
    (the FMU's parameters are diagonals)."""
    if np.abs(M - np.diag(np.diag(M))).max() > 0:
        raise ConfigurationError(f"{owner}: the FMU takes a diagonal {what}; this filter's current {what} has "
                                 "off-diagonal entries (export a filter before it steps, or reset it first)")
    return np.diag(M).copy()

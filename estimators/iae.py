"""Innovation-based adaptive EKF, maximum-likelihood window estimate (seed 000 eqs 26-37)."""
from __future__ import annotations

import casadi as ca
import numpy as np

from fmu_models.errors import ConfigurationError, UnknownNameError
from fmu_models.infra import checks

from .adaptive import AdaptationRecord, WindowedAdaptiveEKF, bound_parameters, bounds_around
from .discrete import DiscreteModel

__all__ = ["ADAPT", "FORMS", "IAE", "project_pd"]

FORMS = ("diagonal", "scalar", "full")
ADAPT = {"both": ("Q", "R"), "Q": ("Q",), "R": ("R",)}


def project_pd(M: np.ndarray, low: float, high: float, form: str) -> np.ndarray:
    """Nearest covariance of the ``form`` to the square ``M`` with eigenvalues in ``[low, high]``:
    ``"diagonal"`` clips the diagonal; ``"scalar"`` is ``sigma^2 I``, ``sigma^2 = trace/n``
    clipped (seed 000 eqs 24-25); ``"full"`` symmetrises and clips the eigenvalues."""
    n = M.shape[0]
    if form == "diagonal":
        return np.diag(np.clip(np.diag(M), low, high))
    if form == "scalar":
        return float(np.clip(np.trace(M) / n, low, high)) * np.eye(n)
    w, V = np.linalg.eigh(0.5 * (M + M.T))
    return (V * np.clip(w, low, high)) @ V.T


def _project_sym(M, low, high, form):
    """:func:`project_pd` for the "diagonal" and "scalar" forms, as a CasADi expression."""
    n = M.shape[0]
    if form == "diagonal":
        return ca.diag(ca.fmin(ca.fmax(ca.diag(M), low), high))
    return ca.fmin(ca.fmax(ca.trace(M) / n, low), high) * ca.SX.eye(n)


class IAE(WindowedAdaptiveEKF, register="IAE"):
    """EKF whose Q and R follow the innovation sequence (Mohamed and Schwarz, 1999).

    After each update, from the last ``window`` innovations ``I_j``: ``C_I = (1/N) sum I_j I_j^T``
    (eq 37), ``R = C_I - H P^- H^T`` (eq 35; ``H P^- H^T = S - R``) and ``Q = K C_I K^T``
    (eq 36), each projected onto the ``form`` within ``q_bounds`` / ``r_bounds``, applied from
    the next step. ``K C_I K^T`` has rank at most ny: unbounded, it collapses Q where the gain
    does not reach, so ``adapt="R"`` is the stable choice when Q is known to an order of magnitude.

    Parameters
    ----------
    system, x0, P0, Q, R, gate, nan_is_missing, backend
        As :class:`~estimators.base.KalmanBase`; Q and R are the initial values.
    window : int
        N, the number of innovations in the estimate (eq 37); default 20.
    adapt : {"both", "Q", "R"} or tuple of "Q", "R"
        Which covariances to adapt (default both).
    form : {"diagonal", "scalar", "full"}
        Structure kept for the estimates (default "diagonal"; "scalar" is eqs 24-25); "full"
        projects the eigenvalues in numpy after each step (no batched or native run).
    q_bounds, r_bounds : (float, float), optional
        Smallest and largest variance in Q and R (default a factor 1e4 beyond the initial ones).
    """

    name = "IAE"

    def __init__(self, system: DiscreteModel, x0, P0, Q, R, window: int = 20, adapt="both",
                 form: str = "diagonal", q_bounds=None, r_bounds=None, gate: float | None = None,
                 nan_is_missing: bool = True, backend: str = "compiled"):
        if isinstance(adapt, str):
            if adapt not in ADAPT:
                raise UnknownNameError(f"adapt must be one of {', '.join(ADAPT)}, got {adapt!r}")
            adapt = ADAPT[adapt]
        if not adapt or not set(adapt) <= {"Q", "R"}:
            raise ConfigurationError(f"adapt must name Q, R or both, got {adapt!r}")
        if form not in FORMS:
            raise UnknownNameError(f"form must be one of {FORMS}, got {form!r}")

        q0 = np.diag(checks.covariance(Q, system.nx, "Q"))
        r0 = np.diag(checks.covariance(R, system.ny, "R"))
        self.adapt, self.form = tuple(sorted(adapt)), form
        self.supports_batch = form != "full"          # the full form's projection runs in numpy
        self.q_bounds = bounds_around(q0, q_bounds, "q_bounds")
        self.r_bounds = bounds_around(r0, r_bounds, "r_bounds")
        super().__init__(system, x0, P0, Q, R, window, gate, nan_is_missing, backend)

    def records_only(self) -> bool:
        """Whether :meth:`on_adapted` only records Q and R (not with ``form="full"``)."""
        return (self.form != "full" and type(self).on_adapted is IAE.on_adapted
                and type(self).after_step is AdaptationRecord.after_step)

    def config_key(self) -> tuple:
        """Window, adapted covariances and form (the bounds are step inputs)."""
        return (self.window, self.adapt, self.form)

    def step_parameters(self):
        return bound_parameters(self.q_bounds, self.r_bounds)

    def adapt_noise(self, ctx, result, C_I):
        """Eqs 35-36, projected on the form and the bounds."""
        Q, R = ctx.Q, ctx.R
        if self.form == "full":          # adapted in numpy after the step
            return Q, R
        qb, rb = ctx.params["q_bounds"], ctx.params["r_bounds"]
        if "R" in self.adapt:
            R = _project_sym(C_I - (result.S - ctx.R), rb[0], rb[1], self.form)   # eq 35
        if "Q" in self.adapt:
            Q = _project_sym(ca.mtimes([result.K, C_I, result.K.T]), qb[0], qb[1], self.form)   # eq 36
        return Q, R

    def on_adapted(self):
        """The ``full`` form's projection (in numpy), then the record."""
        if self.form == "full":
            C_I = self.innovation_covariance()
            HPH = self.S - self.R             # the step left R unchanged in this form
            if "R" in self.adapt:
                self._now("R")[:] = project_pd(C_I - HPH, *self.r_bounds, "full").ravel(order="F")
            if "Q" in self.adapt:
                K = self.K
                self._now("Q")[:] = project_pd(K @ C_I @ K.T, *self.q_bounds, "full").ravel(order="F")
        self._record()

"""Innovation-based adaptive EKF, maximum-likelihood window estimate (seed 000 eqs 26-37)."""
from __future__ import annotations

import casadi as ca
import numpy as np

from .adaptive import WindowedAdaptiveEKF
from .system import DiscreteModel

FORMS = ("diagonal", "scalar", "full")


def project_pd(M: np.ndarray, floor: float, form: str) -> np.ndarray:
    """Nearest admissible covariance of the given form, eigenvalues at least ``floor``.

    ``"diagonal"``: keep the diagonal, clip it at ``floor``; ``"scalar"``: ``sigma^2 I``
    with ``sigma^2 = max(trace/n, floor)`` (the form of seed 000 eqs 24-25); ``"full"``:
    symmetrise and clip the eigenvalues at ``floor``.
    """
    n = M.shape[0]
    if form == "diagonal":
        return np.diag(np.maximum(np.diag(M), floor))
    if form == "scalar":
        return max(np.trace(M) / n, floor) * np.eye(n)
    w, V = np.linalg.eigh(0.5 * (M + M.T))
    return (V * np.maximum(w, floor)) @ V.T


def _project_sym(M, floor, form):
    """:func:`project_pd` for the "diagonal" and "scalar" forms, as a CasADi expression."""
    n = M.shape[0]
    if form == "diagonal":
        return ca.diag(ca.fmax(ca.diag(M), floor))
    return ca.fmax(ca.trace(M) / n, floor) * ca.SX.eye(n)


class IAE(WindowedAdaptiveEKF):
    """EKF whose Q and R follow the innovation sequence (Mohamed and Schwarz, 1999).

    After each update, with ``I_j`` the innovations of the last ``window`` steps:
    ``C_I = (1/N) sum I_j I_j^T`` (eq 37), ``R = C_I - H P^- H^T`` (eq 35) and
    ``Q = K C_I K^T`` (eq 36), each projected onto the chosen ``form`` with eigenvalues
    at least ``floor`` so that they stay positive definite. ``H P^- H^T`` is taken as
    ``S - R`` of the step. The new values apply from the next step. Until the window is
    full, the initial Q and R are kept. The "diagonal" and "scalar" forms are computed in
    the compiled step (and run batched); "full" projects the eigenvalues in numpy after
    each step. Adaptation happens in :meth:`step` (a separate predict/update does not
    adapt).

    Parameters
    ----------
    system, x0, P0, Q, R, backend
        As :class:`~estimators.base.KalmanBase`; Q and R are the initial values.
    window : int
        N, the number of innovations in the estimate (eq 37); default 20.
    adapt : tuple of str
        Which covariances to adapt: any of ``"Q"``, ``"R"`` (default both).
    form : {"diagonal", "scalar", "full"}
        Structure kept for the estimates (default "diagonal"; "scalar" is eqs 24-25).
    q_floor, r_floor : float
        Smallest eigenvalue allowed in Q and R (default 1e-9). ``K C_I K^T`` has rank
        at most ny, so Q needs a floor to stay positive definite.
    """

    name = "IAE"

    def __init__(self, system: DiscreteModel, x0, P0, Q, R, window: int = 20,
                 adapt=("Q", "R"), form: str = "diagonal", q_floor: float = 1e-9,
                 r_floor: float = 1e-9, backend: str = "compiled"):
        if not set(adapt) <= {"Q", "R"}:
            raise ValueError(f"adapt must contain only 'Q' and 'R', got {adapt!r}")
        if form not in FORMS:
            raise ValueError(f"form must be one of {FORMS}, got {form!r}")
        if not (q_floor > 0 and r_floor > 0):
            raise ValueError("q_floor and r_floor must be > 0")
        self.adapt, self.form = tuple(adapt), form
        self.q_floor, self.r_floor = float(q_floor), float(r_floor)
        super().__init__(system, x0, P0, Q, R, window, backend)

    @property
    def supports_batch(self):
        return self.form != "full"

    def _cache_key(self):
        return (type(self).__name__, self.window, self.adapt, self.form, self.q_floor, self.r_floor)

    def _adapt(self, st, diag, C_I):
        if self.form == "full":          # adapted in numpy after the step
            return st["Q"], st["R"]
        Q, R = st["Q"], st["R"]
        if "R" in self.adapt:
            R = _project_sym(C_I - (diag["S"] - st["R"]), self.r_floor, self.form)   # eq 35
        if "Q" in self.adapt:
            K = diag["K"]
            Q = _project_sym(ca.mtimes([K, C_I, K.T]), self.q_floor, self.form)      # eq 36
        return Q, R

    def _adapted(self):
        if self.form != "full":
            return super()._adapted()
        C_I = self.innovation_covariance()
        if "R" in self.adapt:
            self._now("R")[:] = project_pd(C_I - (self.S - self.R), self.r_floor, "full").ravel(order="F")
        if "Q" in self.adapt:
            K = self.K
            self._now("Q")[:] = project_pd(K @ C_I @ K.T, self.q_floor, "full").ravel(order="F")
        self._record()

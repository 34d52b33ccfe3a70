"""Expectation-maximisation of the noise covariances Q and R (and x0, P0) from a record (Shumway
and Stoffer 1982; Ghahramani and Hinton 1996): the filter's pass, its RTS smoothing, the M-step's
closed forms (docs/guide/offline.md); a scalar structure is seed 000 eqs 24-25's ``sigma^2 I``."""
from __future__ import annotations

import casadi as ca
import numpy as np

from fmu_models.errors import ConfigurationError, TypeMismatchError, UnknownNameError
from fmu_models.infra import checks

from ._fold import NativeFold
from .base import KalmanBase
from .iae import project_pd
from .runs import EMResult
from .smoother import rts_smooth

__all__ = ["STRUCTURES", "EMResult", "em_noise"]

STRUCTURES = ("full", "diagonal", "scalar")
LEARNABLE = ("Q", "R", "x0", "P0")


def _terms(filt: KalmanBase):
    """The compiled per-step M-step terms (cached on the model): ``(xs_k, xs_k1, Ps_k, Ps_k1,
    Plag, u) -> Q term`` and ``(xs, Ps, y, mask) -> (R term, counts)``."""
    s = filt.system

    def build():
        n, p = s.nx, s.ny
        x0, x1, u = ca.SX.sym("xs", n), ca.SX.sym("xs1", n), ca.SX.sym("u", s.nu)
        P0, P1, L = ca.SX.sym("Ps", n, n), ca.SX.sym("Ps1", n, n), ca.SX.sym("Plag", n, n)
        f, F = s.transition(x0, u)
        e = x1 - f
        FL = ca.mtimes(F, L.T)
        q_term = ca.mtimes(e, e.T) + ca.mtimes([F, P0, F.T]) + P1 - FL.T - FL
        trans = ca.Function("emq", [x0, x1, P0, P1, L, u], [ca.densify(q_term)],
                            ["xs", "xs1", "Ps", "Ps1", "Plag", "u"], ["q"])
        y, m = ca.SX.sym("y", p), ca.SX.sym("mask", p)
        hx, H = s.measurement(x0)
        r = m * (y - hx)
        M = ca.mtimes(m, m.T)
        r_term = M * (ca.mtimes(r, r.T) + ca.mtimes([H, P0, H.T]))
        meas = ca.Function("emr", [x0, P0, y, m], [ca.densify(r_term), ca.densify(M)],
                           ["xs", "Ps", "y", "mask"], ["r", "count"])
        return NativeFold(trans, 0, filt.backend), NativeFold(meas, 0, filt.backend)

    return s.compiled("em", filt.cache_key, filt.backend, build)


def em_noise(filt: KalmanBase, us, ys, masks=None, y0=None, n_iter: int = 50, tol: float = 1e-6,
             learn=("Q", "R"), structure: str = "full", floor: float = 1e-12) -> EMResult:
    """Learn Q and R (and optionally x0, P0) of ``filt`` from one record by EM.

    Parameters
    ----------
    filt : KF, EKF or UKF
        The filter; its current x, P, Q, R are the starting values, and at the end it holds
        the learned values, reset to the start of the record.
    us, ys, masks, y0
        The record, as :meth:`~estimators.base.KalmanBase.run` takes it.
    n_iter, tol : int, float
        At most ``n_iter`` iterations (default 50), stopping when ``|LL_i - LL_{i-1}| <= tol |LL_i|``
        (default 1e-6).
    learn : sequence of {"Q", "R", "x0", "P0"}
        What to learn (default Q and R).
    structure : {"full", "diagonal", "scalar"}
        The form kept for Q and R (and P0).
    floor : float
        Smallest eigenvalue of a learned covariance (default 1e-12).

    Returns
    -------
    EMResult

    Raises
    ------
    TypeMismatchError
        An adaptive filter (its Q and R are not fixed parameters).
    """
    learn, n_iter, tol, floor = _settings(filt, n_iter, tol, learn, structure, floor)
    us, ys, masks = filt.check_record(us, ys, masks)
    em = _EM(filt, us, ys, masks, y0, learn, structure, floor)
    ll = [em.expectation()]
    for _ in range(n_iter):
        em.maximisation()
        ll.append(em.expectation())
        converged = abs(ll[-1] - ll[-2]) <= tol * abs(ll[-1])
        if converged:
            break
    em.install()
    return EMResult(Q=em.Q, R=em.R, x0=em.x0, P0=em.P0, log_likelihood=ll, iterations=len(ll) - 1, converged=converged)


def _settings(filt, n_iter, tol, learn, structure, floor) -> tuple:
    """The settings of :func:`em_noise` checked: ``(learn, n_iter, tol, floor)``."""
    if not isinstance(filt, KalmanBase):
        raise TypeMismatchError(f"em_noise needs a filter, got {type(filt).__name__}")
    if filt.adapts_noise or not filt.supports_batch:
        raise TypeMismatchError(f"{filt.name} adapts Q and R itself; EM learns them for a KF, EKF or UKF")
    if structure not in STRUCTURES:
        raise UnknownNameError(f"structure must be one of {STRUCTURES}, got {structure!r}")
    learn = tuple(learn)
    if not learn or not set(learn) <= set(LEARNABLE):
        raise ConfigurationError(f"learn must name some of {LEARNABLE}, got {learn!r}")
    return (learn, checks.positive_int(n_iter, "n_iter"), checks.positive(tol, "tol"),
            checks.positive(floor, "floor"))


class _EM:
    """An EM run of :func:`em_noise`: the record, the current ``x0, P0, Q, R`` and the last pass."""

    def __init__(self, filt: KalmanBase, us, ys, masks, y0, learn: tuple, structure: str, floor: float):
        self.filt, self.us, self.ys, self.masks, self.y0 = filt, us, ys, masks, y0
        self.learn, self.structure, self.floor = learn, structure, floor
        self.x0, self.P0, self.Q, self.R = filt.x, filt.P, filt.Q, filt.R
        self.trans, self.meas = _terms(filt)
        ny = filt.system.ny
        y_all = ys if y0 is None else np.vstack([checks.vector(y0, ny, "y0"), ys])
        m_all = masks if y0 is None else np.vstack([np.ones(ny), masks])
        self.m_all = np.ascontiguousarray(m_all * ~np.isnan(y_all))
        self.y_all = np.ascontiguousarray(np.nan_to_num(y_all))

    def install(self) -> None:
        """Give the filter the current parameters, at the start of the record."""
        self.filt.set_noise(self.Q, self.R)
        self.filt.reset(self.x0, self.P0)

    def expectation(self) -> float:
        """The E-step: the filter's pass with the current parameters; its log-likelihood."""
        self.install()
        self.run = self.filt.run(self.us, self.ys, self.masks, self.y0)
        return self.run.log_likelihood

    def maximisation(self) -> None:
        """The M-step from the smoothed pass."""
        sm = rts_smooth(self.filt, self.run)
        N = len(self.ys)
        xs = np.ascontiguousarray(sm.x)
        Ps = np.ascontiguousarray(sm.P.transpose(0, 2, 1)).reshape(N + 1, -1)     # column-major rows
        lag = np.ascontiguousarray(sm.P_lag.transpose(0, 2, 1)).reshape(N, -1)
        if "Q" in self.learn:
            self.Q = self._process_noise(xs, Ps, lag)
        if "R" in self.learn:
            self.R = self._measurement_noise(xs, Ps)
        if "x0" in self.learn:
            self.x0 = sm.x[0].copy()
        if "P0" in self.learn:
            self.P0 = project_pd(sm.P[0], self.floor, np.inf, self.structure)

    def _process_noise(self, xs, Ps, lag) -> np.ndarray:
        """The M-step's Q from the smoothed ``xs`` (N + 1, nx), ``Ps`` and ``lag`` (column-major rows)."""
        N, nx = len(self.ys), self.filt.system.nx
        qt = np.empty((1, N, nx * nx))
        self.trans(1, N, {"xs": xs[:-1][None], "xs1": xs[1:][None], "Ps": Ps[:-1][None], "Ps1": Ps[1:][None],
                          "Plag": lag[None], "u": self.us[None]}, {}, {"q": qt})
        return project_pd(qt[0].sum(axis=0).reshape(nx, nx, order="F") / N, self.floor, np.inf, self.structure)

    def _measurement_noise(self, xs, Ps) -> np.ndarray:
        """The M-step's R (entries over the valid channels; the others keep their value)."""
        ny, K = self.filt.system.ny, len(self.y_all)
        first = 0 if self.y0 is not None else 1
        rt, ct = np.empty((1, K, ny * ny)), np.empty((1, K, ny * ny))
        self.meas(1, K, {"xs": xs[first:][None], "Ps": Ps[first:][None], "y": self.y_all[None],
                         "mask": self.m_all[None]}, {}, {"r": rt, "count": ct})
        counts = ct[0].sum(axis=0).reshape(ny, ny, order="F")
        total = rt[0].sum(axis=0).reshape(ny, ny, order="F")
        return project_pd(np.where(counts > 0, total / np.maximum(counts, 1), self.R), self.floor, np.inf,
                          self.structure)

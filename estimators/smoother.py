"""Rauch-Tung-Striebel smoothing of a stored filter pass (Rauch, Tung and Striebel 1965; for the UKF,
Särkkä 2008), one compiled step per time step folded in native code with the filter's own
predictions; the equations are in the guide's page on offline estimation (docs/guide/offline.md)."""
from __future__ import annotations

import casadi as ca
import numpy as np

from fmu_models.errors import ConfigurationError, NumericalError, TypeMismatchError

from ._fold import NativeFold
from .base import KalmanBase
from .linalg import CSE, spd_solve, symmetric
from .runs import FilterRun, Smoothed

__all__ = ["Smoothed", "rts_smooth", "smoother_step"]


def smoother_step(filt: KalmanBase) -> ca.Function:
    """The backward step ``(xs, Ps, x, P, xp, Pp, u) -> (xs_new, Ps_new, C, Plag)`` on the
    filter's :meth:`~estimators.base.KalmanBase.smoother_cross_covariance`.

    Parameters
    ----------
    filt : KalmanBase
        The filter (its model and cross-covariance).
    """
    s = filt.system
    n = s.nx
    xs, Ps = ca.SX.sym("xs", n), ca.SX.sym("Ps", n, n)
    x, P, xp, Pp = ca.SX.sym("x", n), ca.SX.sym("P", n, n), ca.SX.sym("xp", n), ca.SX.sym("Pp", n, n)
    u = ca.SX.sym("u", s.nu)
    P_, Pp_, Ps_ = symmetric(P), symmetric(Pp), symmetric(Ps)
    D = filt.smoother_cross_covariance(x, P_, u)
    C = spd_solve(Pp_, D.T).T                       # C Pp = D, Pp symmetric positive definite
    xs_new = x + ca.mtimes(C, xs - xp)
    Ps_new = symmetric(P_ + ca.mtimes([C, Ps_ - Pp_, C.T]))
    lag = ca.mtimes(Ps_, C.T)
    d = ca.densify
    return ca.Function("rts", [xs, Ps, x, P, xp, Pp, u], [d(xs_new), d(Ps_new), d(C), d(lag)],
                       ["xs", "Ps", "x", "P", "xp", "Pp", "u"], ["xs_new", "Ps_new", "C", "Plag"], CSE)


def _fold(filt: KalmanBase):
    """The compiled backward step of ``filt``, folded over time (cached on the model)."""
    return filt.system.compiled("rts", filt.cache_key, filt.backend,
                                lambda: NativeFold(smoother_step(filt), 2, filt.backend))


def rts_smooth(filt: KalmanBase, run: FilterRun) -> Smoothed:
    """Smooth the filter pass ``run`` that ``filt`` produced.

    Parameters
    ----------
    filt : KalmanBase
        The filter (its model and, for the UKF, its sigma-point parameters are used).
    run : FilterRun
        What ``filt.run(us, ys)`` returned.

    Raises
    ------
    NumericalError
        The smoothed estimate became non-finite (a singular predicted covariance).
    """
    if not isinstance(filt, KalmanBase) or not isinstance(run, FilterRun):
        raise TypeMismatchError("rts_smooth needs a filter and the FilterRun of its run()")
    if run.x_prior is None:
        raise ConfigurationError("this run kept the estimates only; smoothing needs run(..., keep='all')")
    if run.filter_name != filt.name or run.state_names != filt.system.state_names or \
            run.us.shape[1] != filt.system.nu:
        raise ConfigurationError(f"this run was made by {run.filter_name or 'another filter'} on states "
                                 f"{run.state_names}, not by {filt.name} on {filt.system.state_names}")
    if run.model and run.model != filt.system.identity:
        raise ConfigurationError(f"this run was made on another model than {filt.name}'s ({filt.system!r}): "
                                 "its period, parameters or equations differ; smooth it with the filter "
                                 "that made it")
    N, nx = len(run.x) - 1, filt.system.nx
    X, xp = np.ascontiguousarray(run.x), np.ascontiguousarray(run.x_prior)
    P, Pp = (np.ascontiguousarray(a).reshape(len(a), -1) for a in (run.P, run.P_prior))    # symmetric: rows
    xs, Ps = np.empty((N + 1, nx)), np.empty((N + 1, nx * nx))
    C, lag = np.empty((N, nx * nx)), np.empty((N, nx * nx))
    xs[N], Ps[N] = X[N], P[N]
    if N:
        # backward: step j handles k = N-1-j; reversed views have negative strides
        args = {"x": X[N - 1::-1][None], "P": P[N - 1::-1][None], "xp": xp[::-1][None], "Pp": Pp[::-1][None],
                "u": np.ascontiguousarray(run.us)[::-1][None]}
        outs = {"xs_new": xs[N - 1::-1][None], "Ps_new": Ps[N - 1::-1][None], "C": C[::-1][None],
                "Plag": lag[::-1][None]}
        _fold(filt)(1, N, args, {"xs": xs[N][None], "Ps": Ps[N][None]}, outs)
    if not (np.isfinite(xs).all() and np.isfinite(Ps).all()):
        failure = filt.system.take_failure()
        if failure is not None:
            raise type(failure)(f"{filt.name}: the smoothed estimate became non-finite: {failure}")
        raise NumericalError(f"{filt.name}: the smoothed estimate became non-finite (singular predicted "
                             "covariance?)")
    lag, C = (a.reshape(N, nx, nx).transpose(0, 2, 1) for a in (lag, C))         # column-major rows
    return Smoothed(xs, Ps.reshape(N + 1, nx, nx), lag, C, list(filt.system.state_names))   # Ps is symmetric

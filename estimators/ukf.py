"""Unscented Kalman filter with the scaled unscented transform (seed 001 section 1)."""
from __future__ import annotations

import casadi as ca

from fmu_models.errors import ConfigurationError
from fmu_models.infra.checks import finite

from .base import KalmanBase
from .discrete import DiscreteModel
from .linalg import cholesky_lower, gated_gain, mask_measurement, symmetric
from .protocol import StepContext, Update

__all__ = ["UKF"]


class UKF(KalmanBase, register="UKF"):
    """Unscented Kalman filter (Julier; scaled sigma points of van der Merwe).

    ``2n+1`` sigma points ``x``, ``x +/- sqrt(n + lambda) L_i`` with ``P = L L^T``
    (Cholesky), ``lambda = alpha^2 (n + kappa) - n``; mean weights
    ``Wm0 = lambda/(n + lambda)``, covariance weight ``Wc0 = Wm0 + 1 - alpha^2 + beta``,
    others ``1/(2(n + lambda))``. The measurement sigma points are drawn anew from the
    prior ``(x^-, P^-)``; update ``K = Pxy S^{-1}`` (by a solve), ``P = P^- - K S K^T``.
    A covariance that is not positive definite makes the Cholesky factor NaN: the step
    then raises FloatingPointError and keeps the previous state.

    Parameters
    ----------
    system, x0, P0, Q, R, gate, nan_is_missing, backend
        As :class:`~estimators.base.KalmanBase`.
    alpha : float
        Spread of the sigma points, 0 < alpha <= 1 (default 0.5, see Notes).
    beta : float
        Prior knowledge of the distribution; 2 is optimal for a Gaussian (default 2).
    kappa : float
        Secondary scaling, commonly ``3 - n`` or 0 (default 0).

    Notes
    -----
    ``alpha = 0.5`` is the default: the often quoted 1e-3 makes ``Wc0`` about -1e6 and
    the covariance update numerically fragile for nonlinear models.
    """

    name = "UKF"

    def __init__(self, system: DiscreteModel, x0, P0, Q, R, alpha: float = 0.5,
                 beta: float = 2.0, kappa: float = 0.0, gate: float | None = None,
                 nan_is_missing: bool = True, backend: str = "compiled"):
        n = system.nx
        alpha, beta, kappa = (finite(v, w) for v, w in ((alpha, "alpha"), (beta, "beta"), (kappa, "kappa")))
        if not (0 < alpha <= 1):
            raise ConfigurationError(f"alpha must be in (0, 1], got {alpha}")
        if not (n + kappa > 0):
            raise ConfigurationError(f"kappa must satisfy n + kappa > 0 (n = {n}), got {kappa}")
        self.alpha, self.beta, self.kappa = float(alpha), float(beta), float(kappa)
        lam = alpha**2 * (n + kappa) - n
        self.lam = lam
        self.Wm = [lam / (n + lam)] + [0.5 / (n + lam)] * (2 * n)
        self.Wc = [lam / (n + lam) + 1 - alpha**2 + beta] + [0.5 / (n + lam)] * (2 * n)
        super().__init__(system, x0, P0, Q, R, gate, nan_is_missing, backend)

    def config_key(self) -> tuple:
        """The sigma-point parameters."""
        return (self.alpha, self.beta, self.kappa)

    def sigma_points(self, x, P):
        """The 2n+1 scaled sigma points of (x, P), as CasADi columns (used by the filter and
        by the unscented RTS smoother)."""
        n = self.system.nx
        L = cholesky_lower((n + self.lam) * P)
        return [x] + [x + L[:, i] for i in range(n)] + [x - L[:, i] for i in range(n)]

    @staticmethod
    def _mean_cov(points, Wm, Wc):
        mean = sum((w * p for w, p in zip(Wm, points)), ca.SX.zeros(points[0].shape))
        cov = sum((w * ca.mtimes(p - mean, (p - mean).T) for w, p in zip(Wc, points)),
                  ca.SX.zeros(points[0].numel(), points[0].numel()))
        return mean, cov

    def predict_expr(self, ctx: StepContext):
        """The unscented transform of ``(x, P)`` through ``f``, plus Q."""
        s = self.system
        f = ca.Function("f", [s.x, s.u], [s.fx])
        xp, Pp = self._mean_cov([f(p, ctx.u) for p in self.sigma_points(ctx.x, ctx.P)], self.Wm, self.Wc)
        return xp, symmetric(Pp + ctx.Q)

    def update_expr(self, ctx: StepContext, xp, Pp) -> Update:
        """Sigma points redrawn from the prior; ``K = Pxy S^{-1}``, ``P = P^- - K S K^T``."""
        s = self.system
        y, R, valid, gate = ctx.y, ctx.R, ctx.valid, ctx.gate
        h = ca.Function("h", [s.x], [s.hx])
        # sigma points redrawn from the prior (x^-, P^-), so that Q is in S and Pxy
        sig = self.sigma_points(xp, Pp)
        sig_y = [h(p) for p in sig]
        yp, S = self._mean_cov(sig_y, self.Wm, self.Wc)
        S, innov, M = mask_measurement(valid, symmetric(S + R), y - yp)
        Pxy = sum((w * ca.mtimes(p - xp, (q - yp).T) for w, p, q in zip(self.Wc, sig, sig_y)),
                  ca.SX.zeros(s.nx, s.ny))
        K, nis, acc = gated_gain(S, ca.mtimes(Pxy, M).T, innov, gate)
        Ka = acc * K
        return Update(xp + ca.mtimes(Ka, innov), symmetric(Pp - ca.mtimes([Ka, S, Ka.T])), innov, S, K, nis, acc)

    def smoother_cross_covariance(self, x, P, u):
        """The unscented RTS smoother's ``D_k`` (Särkkä, 2008): the cross-covariance of the
        sigma points of ``(x, P)`` and their images under ``f``."""
        s = self.system
        f = ca.Function("f", [s.x, s.u], [s.fx])
        sig = self.sigma_points(x, P)
        img = [f(p, u) for p in sig]
        m = sum((w * p for w, p in zip(self.Wm, img)), ca.SX.zeros(s.nx))
        return sum((w * ca.mtimes(p - x, (q - m).T) for w, p, q in zip(self.Wc, sig, img)), ca.SX.zeros(s.nx, s.nx))

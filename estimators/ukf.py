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

    ``2n+1`` sigma points ``x``, ``x +/- sqrt(n + lambda) L_i`` with ``P = L L^T`` (Cholesky),
    ``lambda = alpha^2 (n + kappa) - n``; weights ``Wm0 = lambda/(n + lambda)``, ``Wc0 = Wm0 + 1
    - alpha^2 + beta``, others ``1/(2(n + lambda))``. A covariance that is not positive definite
    makes the step raise (NumericalError) and keep the previous state.

    Parameters
    ----------
    system, x0, P0, Q, R, gate, nan_is_missing, backend
        As :class:`~estimators.base.KalmanBase`.
    alpha : float
        Spread of the sigma points, 0 < alpha <= 1 (default 0.5: the often quoted 1e-3 makes
        ``Wc0`` about -1e6 and the covariance update fragile for nonlinear models).
    beta : float
        Prior knowledge of the distribution; 2 is optimal for a Gaussian (default 2).
    kappa : float
        Secondary scaling, commonly ``3 - n`` or 0 (default 0).
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
        self.lam = lam = alpha**2 * (n + kappa) - n
        self.Wm = [lam / (n + lam)] + [0.5 / (n + lam)] * (2 * n)
        self.Wc = [lam / (n + lam) + 1 - alpha**2 + beta] + [0.5 / (n + lam)] * (2 * n)
        super().__init__(system, x0, P0, Q, R, gate, nan_is_missing, backend)

    def config_key(self) -> tuple:
        return (self.alpha, self.beta, self.kappa)

    def sigma_points(self, x, P):
        """The 2n+1 scaled sigma points of (x, P), as CasADi columns (used by the filter and
        by the unscented RTS smoother)."""
        n = self.system.nx
        L = cholesky_lower((n + self.lam) * P)
        return [x] + [x + L[:, i] for i in range(n)] + [x - L[:, i] for i in range(n)]

    def predict_expr(self, ctx: StepContext):
        """The unscented transform of ``(x, P)`` through ``f``, plus Q."""
        img = [self.system._f(p, ctx.u) for p in self.sigma_points(ctx.x, ctx.P)]
        xp = _mean(self.Wm, img)
        return xp, symmetric(_cross(self.Wc, img, xp, img, xp) + ctx.Q)

    def update_expr(self, ctx: StepContext, xp, Pp) -> Update:
        """Sigma points redrawn from the prior ``(x^-, P^-)``, so that Q is in S and Pxy;
        ``K = Pxy S^{-1}``, ``P = P^- - K S K^T``."""
        sig = self.sigma_points(xp, Pp)
        sig_y = [self.system._h(p) for p in sig]
        yp = _mean(self.Wm, sig_y)
        S, innov, M = mask_measurement(ctx.valid, symmetric(_cross(self.Wc, sig_y, yp, sig_y, yp) + ctx.R), ctx.y - yp)
        K, nis, acc = gated_gain(S, ca.mtimes(_cross(self.Wc, sig, xp, sig_y, yp), M).T, innov, ctx.gate)
        Ka = acc * K
        return Update(xp + ca.mtimes(Ka, innov), symmetric(Pp - ca.mtimes([Ka, S, Ka.T])), innov, S, K, nis, acc)

    def smoother_cross_covariance(self, x, P, u):
        """The unscented RTS smoother's ``D_k`` (Särkkä, 2008): the cross-covariance of the
        sigma points of ``(x, P)`` and their images under ``f``."""
        sig = self.sigma_points(x, P)
        img = [self.system._f(p, u) for p in sig]
        return _cross(self.Wc, sig, x, img, _mean(self.Wm, img))


def _mean(W, points):
    """``sum_i W_i p_i``."""
    return sum((w * p for w, p in zip(W, points)), ca.SX.zeros(points[0].shape))


def _cross(W, ps, p_mean, qs, q_mean):
    """``sum_i W_i (p_i - p_mean) (q_i - q_mean)^T``."""
    return sum((w * ca.mtimes(p - p_mean, (q - q_mean).T) for w, p, q in zip(W, ps, qs)),
               ca.SX.zeros(ps[0].numel(), qs[0].numel()))

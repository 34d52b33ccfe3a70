"""Extended Kalman filter with the model's exact CasADi Jacobians (seed 002 eqs 10-16)."""
from __future__ import annotations

import casadi as ca

from .base import KalmanBase
from .linalg import joseph_update, mask_measurement, symmetric
from .protocol import StepContext, Update

__all__ = ["EKF"]


class EKF(KalmanBase, register="EKF"):
    """Extended Kalman filter with the model's exact Jacobians (:meth:`~estimators.DiscreteModel.transition`).

    Parameters ``system, x0, P0, Q, R, gate, nan_is_missing, backend`` and the attributes are those
    of :class:`~estimators.base.KalmanBase`.
    """

    name = "EKF"

    def predict_expr(self, ctx: StepContext):
        """``x^- = f(x, u)``, ``P^- = F P F^T + Q`` (seed 002 eqs 10-11)."""
        xp, F = self.system.transition(ctx.x, ctx.u)
        return xp, symmetric(ca.mtimes([F, ctx.P, F.T]) + ctx.Q)

    def update_expr(self, ctx: StepContext, x_prior, P_prior) -> Update:
        """``H = dh/dx`` at ``x^-``; gain by a linear solve, Joseph-form update of the valid channels
        (seed 002 eqs 12-16)."""
        yp, H = self.system.measurement(x_prior)
        S, innov, M = mask_measurement(ctx.valid, ca.mtimes([H, P_prior, H.T]) + ctx.R, ctx.y - yp)
        Hm, Rm = ca.mtimes(M, H), ca.mtimes([M, ctx.R, M])
        xu, Pu, K, nis, acc = joseph_update(x_prior, P_prior, innov, Hm, S, Rm, ctx.gate)
        return Update(xu, Pu, innov, S, K, nis, acc)

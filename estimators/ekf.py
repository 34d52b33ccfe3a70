"""Extended Kalman filter with the model's exact CasADi Jacobians (seed 002 eqs 10-16)."""
from __future__ import annotations

import casadi as ca

from .base import KalmanBase, joseph_update, mask_measurement, symmetric


class EKF(KalmanBase):
    """Extended Kalman filter.

    Prediction ``x^- = f(x, u)``, ``P^- = F P F^T + Q`` with ``F = df/dx`` exact (CasADi
    AD); update with ``H = dh/dx`` at ``x^-`` over the valid measurement channels, gain by
    a linear solve and the Joseph form. Parameters ``system, x0, P0, Q, R, gate,
    nan_is_missing, backend`` and the attributes are those of
    :class:`~estimators.base.KalmanBase`.
    """

    name = "EKF"

    def _predict_expr(self, x, P, u, Q):
        s = self.system
        xp = ca.substitute(s.fx, ca.vertcat(s.x, s.u), ca.vertcat(x, u))
        F = ca.substitute(ca.jacobian(s.fx, s.x), ca.vertcat(s.x, s.u), ca.vertcat(x, u))
        return xp, symmetric(ca.mtimes([F, P, F.T]) + Q)

    def _update_expr(self, xp, Pp, y, R, valid, gate):
        s = self.system
        yp = ca.substitute(s.hx, s.x, xp)
        H = ca.substitute(ca.jacobian(s.hx, s.x), s.x, xp)
        S, innov, M = mask_measurement(valid, ca.mtimes([H, Pp, H.T]) + R, y - yp)
        Hm, Rm = ca.mtimes(M, H), ca.mtimes([M, R, M])
        xu, Pu, K, nis, acc = joseph_update(xp, Pp, innov, Hm, S, Rm, gate)
        return xu, Pu, innov, S, K, nis, acc

"""Linear Kalman filter on the model linearised about an operating point (seed 001's KF)."""
from __future__ import annotations

from .ekf import EKF
from .system import DiscreteModel


class KF(EKF):
    """Kalman filter on the affine model tangent to ``system`` at ``(x_op, u_op)``.

    The model is :meth:`DiscreteModel.linearized`; with constant Jacobians the EKF
    equations are exactly the Kalman filter's.

    Parameters
    ----------
    system : DiscreteModel
        Nonlinear model; it is linearised here.
    x0, P0, Q, R
        As :class:`~estimators.base.KalmanBase`.
    x_op : array_like, shape (nx,)
        Operating point (default: zero, the cart-pole's upright equilibrium).
    u_op : array_like, shape (nu,)
        Operating input (default zero).
    backend : {"compiled", "vm"}
        As :class:`~estimators.base.KalmanBase`.
    """

    name = "KF"

    def __init__(self, system: DiscreteModel, x0, P0, Q, R, x_op=None, u_op=None,
                 backend: str = "compiled"):
        import numpy as np

        x_op = np.zeros(system.nx) if x_op is None else x_op
        u_op = np.zeros(system.nu) if u_op is None else u_op
        self.nonlinear_system = system
        self.x_op, self.u_op = np.asarray(x_op, float), np.asarray(u_op, float)
        super().__init__(system.linearized(x_op, u_op), x0, P0, Q, R, backend)

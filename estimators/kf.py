"""Linear Kalman filter on the model linearised about an operating point (seed 001's KF)."""
from __future__ import annotations

import numpy as np

from fmu_models.errors import ConfigurationError
from fmu_models.infra.checks import vector

from .discrete import DiscreteModel, checked_model
from .ekf import EKF

__all__ = ["KF"]


class KF(EKF, register="KF"):
    """Kalman filter on the affine model tangent to ``system`` at ``(x_op, u_op)``
    (:meth:`DiscreteModel.linearized`: with constant Jacobians the EKF is the Kalman filter).

    Parameters
    ----------
    system : DiscreteModel
        Nonlinear model; it is linearised here.
    x0, P0, Q, R, gate, nan_is_missing, backend
        As :class:`~estimators.base.KalmanBase`.
    x_op, u_op : array_like, shapes (nx,), (nu,)
        Operating point and input (default zero: the cart-pole's upright equilibrium).
    """

    name = "KF"

    def __init__(self, system: DiscreteModel, x0, P0, Q, R, x_op=None, u_op=None,
                 gate: float | None = None, nan_is_missing: bool = True, backend: str = "compiled"):
        system = checked_model(system)
        x_op = np.zeros(system.nx) if x_op is None else vector(x_op, system.nx, "x_op", ConfigurationError)
        u_op = np.zeros(system.nu) if u_op is None else vector(u_op, system.nu, "u_op", ConfigurationError)
        self.x_op, self.u_op = x_op, u_op
        super().__init__(system.linearized(x_op, u_op), x0, P0, Q, R, gate, nan_is_missing, backend)

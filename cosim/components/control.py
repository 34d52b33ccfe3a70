"""State feedback by LQR on the model linearised at an operating point (seed 002's balancing controller)."""
from __future__ import annotations

import numpy as np

from fmu_models.errors import ConfigurationError
from fmu_models.infra.checks import float_array, vector
from fmu_models.plant import PlantModel

from ..core.component import Component

__all__ = ["LQRController", "lqr_gain"]


def lqr_gain(model: PlantModel, x_op, u_op, period: float, Q, R) -> np.ndarray:
    """Discrete LQR gain K (nu, nx) of ``model`` linearised at (x_op, u_op) and discretised
    with exact ZOH over ``period`` [s]: ``u = u_op - K (x - x_op)`` minimises ``sum x^T Q x +
    u^T R u`` for ``x_{k+1} = Ad x_k + Bd u_k`` (deviations from the operating point).
    """
    Ad, Bd = model.discretize(x_op, u_op, period, method="zoh")
    Q = np.atleast_2d(float_array(Q, "LQR weight Q")) * (np.eye(model.nx) if np.ndim(Q) == 0 else 1)
    Q = np.diag(Q.ravel()) if Q.shape == (1, model.nx) else Q
    R = np.atleast_2d(float_array(R, "LQR weight R"))
    if Q.shape != (model.nx, model.nx) or R.shape != (model.nu, model.nu):
        raise ConfigurationError(f"LQR weights must be Q ({model.nx}, {model.nx}) and R ({model.nu}, {model.nu}); "
                                 f"got {Q.shape} and {R.shape}")
    try:
        import scipy.linalg  # here: 0.2 s of import time most runs never need

        P = scipy.linalg.solve_discrete_are(Ad, Bd, Q, R)
    except (ValueError, np.linalg.LinAlgError) as e:
        raise ConfigurationError(f"no LQR solution for these weights: {e}") from None
    return np.linalg.solve(R + Bd.T @ P @ Bd, Bd.T @ P @ Ad)


class LQRController(Component, kind="lqr"):
    """State feedback ``u = u_op - K (x_hat - x_op)`` with a discrete LQR gain; input ports the
    model's state names (an estimator's outputs, as in seed 002), output ports its inputs.

    Parameters
    ----------
    name : str
    model : PlantModel
        Model linearised at (x_op, u_op) for the design.
    period : float
        Sample period [s] of the controller (the design's discretisation step).
    x_op, u_op : array_like
        Operating point (default: zero, the upright equilibrium).
    Q, R : array_like
        LQR weights: state (scalar, diagonal or (nx, nx)) and input ((nu, nu)).
    u_limits : (float, float), optional
        Saturation of the command.
    """

    reentrant = True

    @classmethod
    def from_scenario(cls, name, table, context):
        """``model`` by name (with ``model_parameters``), the other keys as the constructor's."""
        return context.construct_with_model(cls, name, table)

    def __init__(self, name: str, model: PlantModel, period: float, Q, R, x_op=None,
                 u_op=None, u_limits=None):
        super().__init__(name, period, inputs=model.state_names, outputs=model.input_names)
        self.x_op = np.zeros(model.nx) if x_op is None else vector(x_op, model.nx, f"{name}: x_op", ConfigurationError)
        self.u_op = np.zeros(model.nu) if u_op is None else vector(u_op, model.nu, f"{name}: u_op", ConfigurationError)
        self.K = lqr_gain(model, self.x_op, self.u_op, self.period, Q, R)
        closed = model.discretize(self.x_op, self.u_op, self.period)
        eig = np.abs(np.linalg.eigvals(closed[0] - closed[1] @ self.K))
        if eig.max() >= 1:
            raise ConfigurationError(f"{name}: the LQR design does not stabilise the linearisation "
                                     f"(closed-loop |eig| max {eig.max():.3f})")
        self.u_limits = None
        if u_limits is not None:
            lim = float_array(u_limits, f"{name}: u_limits")
            if lim.shape != (2,) or not lim[0] < lim[1]:
                raise ConfigurationError(f"{name}: u_limits must be (low, high) with low < high, got {u_limits!r}")
            self.u_limits = (float(lim[0]), float(lim[1]))

    def output(self, t, u):
        cmd = self.u_op - self.K @ (u - self.x_op)
        if self.u_limits is not None:
            cmd = np.clip(cmd, *self.u_limits)
        return cmd

"""Estimator and controller components: any filter of :mod:`estimators`, and LQR."""
from __future__ import annotations

from typing import Callable

import numpy as np
import scipy.linalg

from estimators.base import KalmanBase
from fmu_models.plant import PlantModel

from .component import Component


class EstimatorComponent(Component):
    """Runs a filter of :mod:`estimators` at its model's sample period.

    Input ports: the model's inputs (e.g. ``F``; the value held over the last period)
    and outputs (e.g. ``y_x, y_theta``: the measurements). Output ports: the state
    estimate (state names), the covariance diagonal (``P_<state>``) and ``nis``. At the
    first sample the initial estimate is output; from the second on, each sample is one
    ``step(u, y)`` (predict with the held input, update with the measurement).

    Parameters
    ----------
    name : str
    make_filter : callable
        Returns a new filter (called at every reset, so each run starts afresh), e.g.
        ``lambda: EKF(system, x0, P0, Q, R)``.
    period : float, optional
        Must equal the filter's model period ``system.dt`` (default: that period).
    """

    def __init__(self, name: str, make_filter: Callable[[], KalmanBase], period: float | None = None):
        if not callable(make_filter):
            raise TypeError(f"{name}: make_filter must be a callable returning a filter")
        probe = make_filter()
        if not isinstance(probe, KalmanBase):
            raise TypeError(f"{name}: make_filter returned {type(probe).__name__}, not a filter")
        sys_ = probe.system
        period = sys_.dt if period is None else period
        if abs(period - sys_.dt) > 1e-12 * max(1.0, sys_.dt):
            raise ValueError(f"{name}: period {period} s differs from the filter model's dt "
                             f"{sys_.dt} s; discretise the model with dt = period")
        super().__init__(name, period, inputs=sys_.input_names + sys_.output_names,
                         outputs=sys_.state_names + [f"P_{s}" for s in sys_.state_names] + ["nis"])
        self.make_filter, self.filter = make_filter, probe
        self._nu, self._nx = sys_.nu, sys_.nx

    def _outputs(self):
        f = self.filter
        return np.concatenate([f.x, np.diag(f.P), [f.nis]])

    def reset(self, t0):
        super().reset(t0)
        if self.filter.k:
            self.filter = self.make_filter()
        return self._outputs()

    def sample(self, t, u):
        self.n_samples += 1
        if self.n_samples > 1:
            self.filter.step(u[: self._nu], u[self._nu:])
        return self._outputs()


def lqr_gain(model: PlantModel, x_op, u_op, period: float, Q, R) -> np.ndarray:
    """Discrete LQR gain K (nu, nx) of ``model`` linearised at (x_op, u_op) and discretised
    with exact ZOH over ``period`` [s]; weights Q (state) and R (input).

    Minimises ``sum x^T Q x + u^T R u`` for ``x_{k+1} = Ad x_k + Bd u_k`` (deviations from
    the operating point); ``u = u_op - K (x - x_op)``.
    """
    Ad, Bd = model.discretize(x_op, u_op, period, method="zoh")
    Q = np.atleast_2d(np.asarray(Q, float)) * (np.eye(model.nx) if np.ndim(Q) == 0 else 1)
    Q = np.diag(Q.ravel()) if Q.shape == (1, model.nx) else Q
    R = np.atleast_2d(np.asarray(R, float))
    P = scipy.linalg.solve_discrete_are(Ad, Bd, Q, R)
    return np.linalg.solve(R + Bd.T @ P @ Bd, Bd.T @ P @ Ad)


class LQRController(Component):
    """State feedback ``u = u_op - K (x_hat - x_op)`` with a discrete LQR gain.

    Input ports: the model's state names (connect them to an estimator's outputs, as in
    seed 002, or to the plant's states); output ports: the model's input names.

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

    def __init__(self, name: str, model: PlantModel, period: float, Q, R, x_op=None,
                 u_op=None, u_limits=None):
        super().__init__(name, period, inputs=model.state_names, outputs=model.input_names)
        self.x_op = np.zeros(model.nx) if x_op is None else np.asarray(x_op, float)
        self.u_op = np.zeros(model.nu) if u_op is None else np.asarray(u_op, float)
        self.K = lqr_gain(model, self.x_op, self.u_op, self.period, Q, R)
        closed = model.discretize(self.x_op, self.u_op, self.period)
        eig = np.abs(np.linalg.eigvals(closed[0] - closed[1] @ self.K))
        if eig.max() >= 1:
            raise ValueError(f"{name}: the LQR design does not stabilise the linearisation "
                             f"(closed-loop |eig| max {eig.max():.3f})")
        self.u_limits = None if u_limits is None else (float(u_limits[0]), float(u_limits[1]))

    def reset(self, t0):
        super().reset(t0)
        return self.u_op.copy()

    def sample(self, t, u):
        self.n_samples += 1
        cmd = self.u_op - self.K @ (u - self.x_op)
        if self.u_limits is not None:
            cmd = np.clip(cmd, *self.u_limits)
        return cmd

"""Adaptive EKFs driven by a window of innovations (seed 000 eq 37), adapted inside the step.

:class:`WindowedAdaptiveEKF` extends the EKF's fused step with the last ``window``
innovations (a ``ny x window`` ring, part of the filter's state) and their covariance
``C_I = (1/N) sum I_j I_j^T`` (eq 37), recomputed from the ring at every step (no
running sum that could drift), and hands ``C_I`` to the subclass's
:meth:`~WindowedAdaptiveEKF._adapt`, which returns the next Q and R as CasADi
expressions. The whole adaptation is compiled with the filter, so it runs batched and in
the native :meth:`~estimators.base.KalmanBase.run`.

Only complete, accepted measurement vectors enter the window (a step with a missing
channel or a gated measurement leaves it, and Q and R, unchanged); until ``window``
innovations are stored, Q and R keep their initial values.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from fmu_models.checks import float_array, positive_int
from fmu_models.errors import ConfigurationError

from ._buffered import matrix
from .ekf import EKF
from .system import DiscreteModel

__all__ = ["WindowedAdaptiveEKF", "bounds_around"]

#: Default bounds: this factor either side of the initial variances.
BOUND_FACTOR = 1e4


def bounds_around(initial: np.ndarray, given, what: str) -> tuple[float, float]:
    """``(low, high)`` bounds for adapted variances: ``given``, or a factor
    :data:`BOUND_FACTOR` below the smallest and above the largest ``initial`` variance."""
    if given is None:
        return float(np.min(initial)) / BOUND_FACTOR, float(np.max(initial)) * BOUND_FACTOR
    b = float_array(given, what)
    if b.shape != (2,) or not (np.isfinite(b).all() and 0 < b[0] < b[1]):
        raise ConfigurationError(f"{what} must be (low, high) with 0 < low < high, got {given!r}")
    return float(b[0]), float(b[1])


class WindowedAdaptiveEKF(EKF):
    """Base of :class:`~estimators.IAE` and :class:`~estimators.MFIAE` (Q and R are state).

    Parameters
    ----------
    system, x0, P0, Q, R, gate, nan_is_missing, backend
        As :class:`~estimators.base.KalmanBase` (Q and R are the initial values).
    window : int
        N, the number of innovations in ``C_I`` (eq 37). Until N are stored, Q and R
        keep their initial values.
    """

    adapts_noise = True

    def __init__(self, system: DiscreteModel, x0, P0, Q, R, window: int, gate: float | None = None,
                 nan_is_missing: bool = True, backend: str = "compiled"):
        self.window = positive_int(window, "window")
        super().__init__(system, x0, P0, Q, R, gate, nan_is_missing, backend)

    def _adapt(self, st: dict, diag: dict, C_I):
        """Return ``(Q_new, R_new)`` expressions from the state symbols ``st`` (x, P, Q, R),
        the step's diagnostics ``diag`` (innov, S, K, ...) and ``C_I``. Subclasses implement."""
        raise NotImplementedError

    def _extra_state_init(self):
        return {"ring": np.zeros(self.system.ny * self.window), "count": np.zeros(1)}

    def _step_spec(self):
        st, ins, new, diag, extra = super()._step_spec()
        ny, N = self.system.ny, self.window
        ring, count = self._sym("ring", ny, N), self._sym("count")
        st.update(ring=ring, count=count)
        # a complete, accepted measurement vector enters the window
        push = diag["accepted"] * ca.mmin(self._valid_expr)
        shifted = ca.horzcat(ring[:, 1:], diag["innov"]) if N > 1 else diag["innov"]
        ring_new = ca.if_else(push, shifted, ring)
        count_new = count + push
        C_I = ca.mtimes(ring_new, ring_new.T) / N                         # eq 37
        Q_new, R_new = self._adapt(st, diag, C_I)
        adapted = push * (count_new >= N)
        new.update(Q=ca.if_else(adapted, Q_new, st["Q"]), R=ca.if_else(adapted, R_new, st["R"]),
                   ring=ring_new, count=count_new)
        extra["adapted"] = adapted
        return st, ins, new, diag, extra

    def innovation_covariance(self) -> np.ndarray:
        """C_I of eq 37 from the innovations stored so far (at most ``window``), (ny, ny)."""
        ny = self.system.ny
        n = int(min(self._now("count")[0], self.window))
        ring = matrix(self._now("ring"), ny, self.window)[:, self.window - n:]
        return ring @ ring.T / max(n, 1)

    def _after_step(self):
        if self._extra["adapted"][0]:
            self._adapted()

    def _adapted(self):
        """Runs after every step that adapted Q and R: records them."""
        self._record()

    def _after_run(self, cat: dict) -> None:
        nx, ny = self.system.nx, self.system.ny
        adapted = np.flatnonzero(cat["adapted"].ravel())
        N = len(cat["adapted"])
        Q = cat["Q_new"].reshape(-1, nx, nx).diagonal(axis1=1, axis2=2)
        R = cat["R_new"].reshape(-1, ny, ny).diagonal(axis1=1, axis2=2)
        for i in adapted:
            self.history.append(self.k - N + i + 1, np.concatenate([Q[i], R[i]]))

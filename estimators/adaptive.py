"""Adaptive EKFs driven by a window of innovations (seed 000 eq 37), adapted inside the step.

:class:`WindowedAdaptiveEKF` extends the EKF's fused step with the running sum of the
last ``window`` innovation products ``I_j I_j^T`` and hands ``C_I`` (eq 37) to the
subclass's :meth:`~WindowedAdaptiveEKF._adapt`, which returns the next Q and R as
CasADi expressions: the adaptation is compiled with the filter and runs batched. The
innovations themselves live in a ring buffer in Python (one row copy per step); the
running sum is recomputed exactly once per lap of the ring so it cannot drift.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from .ekf import EKF
from .system import DiscreteModel


class WindowedAdaptiveEKF(EKF):
    """Base of :class:`~estimators.IAE` and :class:`~estimators.MFIAE`.

    Parameters
    ----------
    system, x0, P0, Q, R, backend
        As :class:`~estimators.base.KalmanBase` (Q and R are the initial values).
    window : int
        N, the number of innovations in ``C_I`` (eq 37). Until N are stored, Q and R
        keep their initial values.
    """

    def __init__(self, system: DiscreteModel, x0, P0, Q, R, window: int, backend: str = "compiled"):
        if int(window) != window or window < 1:
            raise ValueError(f"window must be a positive integer, got {window!r}")
        self.window = int(window)
        super().__init__(system, x0, P0, Q, R, backend)
        self._ring = np.zeros((self.window, system.ny))
        self._ri = 0
        self._count = 0

    def _adapt(self, st: dict, diag: dict, C_I):
        """Return ``(Q_new, R_new)`` expressions from the state symbols ``st`` (x, P, Q, R),
        the step's diagnostics ``diag`` (innov, S, K, ...) and ``C_I``. Subclasses implement."""
        raise NotImplementedError

    def _extra_state_init(self):
        ny = self.system.ny
        return {"Csum": np.zeros(ny * ny), "count": np.zeros(1)}

    def _step_spec(self):
        st, ins, new, diag, extra = super()._step_spec()
        ny = self.system.ny
        Csum, count, I_old = self._sym("Csum", ny, ny), self._sym("count", 1), self._sym("I_old", ny)
        st.update(Csum=Csum, count=count)
        ins["I_old"] = I_old
        innov = diag["innov"]
        Csum_new = Csum + ca.mtimes(innov, innov.T) - ca.mtimes(I_old, I_old.T)
        count_new = count + 1
        Q_new, R_new = self._adapt(st, diag, Csum_new / self.window)       # eq 37
        full = count_new >= self.window
        new.update(Q=ca.if_else(full, Q_new, st["Q"]), R=ca.if_else(full, R_new, st["R"]),
                   Csum=Csum_new, count=count_new)
        extra["qr"] = ca.vertcat(ca.diag(new["Q"]), ca.diag(new["R"]))     # the history row
        return st, ins, new, diag, extra

    def _bind(self, pred, upd, step):
        super()._bind(pred, upd, step)
        self._iold, self._innov, self._qr = self._inputs["I_old"], self._diag["innov"], self._extra["qr"]

    def innovation_covariance(self) -> np.ndarray:
        """C_I of eq 37 from the innovations stored so far (at most ``window``)."""
        n = min(self._count, self.window)
        return self._ring[:n].T @ self._ring[:n] / max(n, 1)

    def _prepare_step(self):
        self._iold[:] = self._ring[self._ri]

    def _after_step(self):
        ri = self._ri
        self._ring[ri] = self._innov
        ri += 1
        if ri == self.window:
            ri = 0
            # re-sum the window exactly once per lap: no drift of the running sum
            self._now("Csum")[:] = (self._ring.T @ self._ring).ravel(order="F")
        self._ri = ri
        self._count += 1
        if self._count >= self.window:
            self._adapted()

    def _adapted(self):
        """Runs after every step that adapted Q and R: records them."""
        self.history.append(self.k, self._qr)

    # ---------------------------------------------------------------- batched runs
    def _batch_init(self, batch):
        batch.ring = np.zeros((self.window, batch.n, self.system.ny))
        batch.ri = 0

    def _batch_prepare(self, batch):
        batch._inputs["I_old"][:] = batch.ring[batch.ri].ravel()

    def _batch_after(self, batch):
        batch.ring[batch.ri] = batch._out["innov"].reshape(batch.n, self.system.ny)
        batch.ri += 1
        if batch.ri == self.window:
            batch.ri = 0
            C = np.einsum("wri,wrj->rji", batch.ring, batch.ring)   # column-major per run
            batch.now("Csum")[:] = C.ravel()

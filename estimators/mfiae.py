"""Fuzzy innovation-based adaptive EKF, MF-IAE (seed 000 eqs 38-42)."""
from __future__ import annotations

import casadi as ca
import numpy as np

from fmu_models import checks
from .adaptive import WindowedAdaptiveEKF
from .fuzzy import MamdaniFuzzy
from .system import DiscreteModel


class MFIAE(WindowedAdaptiveEKF):
    """EKF whose scalar Q and R are tuned online by a Mamdani fuzzy system (seed 000 sec. 4).

    Each step, after the EKF update: ``C_I`` is the mean of ``I_j I_j^T`` over the last
    ``window`` innovations (eq 37), ``C_T = H P^- H^T + R`` the theoretical innovation
    covariance (eq 39, the step's S). The fuzzy system (:class:`MamdaniFuzzy`, Table 2)
    maps ``(C_T, C_I)`` to a normalised adjustment ``m`` in [-1, 1], and
    ``MAdj = m s`` with ``s = (C_T + C_I)/2`` is the fuzzy image of ``C_T - C_I``
    (eq 38), in measurement units. Then, with ``Q = q I`` and ``R = r I`` (eqs 24-25)::

        r_{k+1} = r_k     - gain_r MAdj                      (eq 42)
        q_k     = q_{k-1} - gain_q trace(K MAdj K^T) / nx    (eq 41)

    Too large innovations (``C_I > C_T``, ``m < 0``) raise Q and R, too small ones lower
    them. Choices the paper leaves open, each a parameter or documented here:

    * how MAdj reaches Q: eq 41 subtracts a measurement-space quantity from a
      state-space matrix; it is mapped through the gain, as eq 36 maps ``C_I`` into
      ``Q = K C_I K^T``. (Adjusting Q and R by the same relative factor would keep Q/R,
      hence the steady-state gain, unchanged: the filter could not improve.)
    * the scalar summary of the matrices: ``trace/ny``, or one adjustment per measurement
      channel with ``per_channel=True`` (R diagonal);
    * the input normalisation and membership functions (:class:`MamdaniFuzzy`);
    * gains and bounds (q and r are clipped to them, so they stay positive).

    Until ``window`` innovations are stored Q and R stay at their initial values. The
    whole step, fuzzy inference included, is one compiled CasADi Function.

    Parameters
    ----------
    system, x0, P0, backend
        As :class:`~estimators.base.KalmanBase`.
    q0 : float
        Initial process noise variance sigma_q^2 (Q = q0 I).
    r0 : float or array_like (ny,)
        Initial measurement noise variance sigma_r^2 (R = r0 I), or one per channel.
    window : int
        N of eq 37 (default 50).
    fuzzy : MamdaniFuzzy, optional
        The fuzzy system (default ``MamdaniFuzzy()``).
    gain_q, gain_r : float
        Step sizes in (0, 1] (defaults 0.02 and 0.2). With window 50 they took the
        cart-pole (q = 1e-4, r = 1e-2, started at 1e-7) to q = 7e-5, r = 1.03e-2 and the
        error of the EKF that knows Q and R (tests/test_estimators.py); Q moves slower
        than R because a wrong Q shows in the innovations only through the dynamics.
    per_channel : bool
        One adjustment per measurement channel for R (default False: scalar R).
    q_bounds, r_bounds : (float, float)
        Bounds kept on q and on each r (default (1e-9, 1e6)).

    Attributes
    ----------
    m : ndarray, shape (ny,)
        The last normalised fuzzy adjustment per channel (all equal unless
        ``per_channel``).
    """

    name = "MF-IAE"

    def __init__(self, system: DiscreteModel, x0, P0, q0: float, r0, window: int = 50,
                 fuzzy: MamdaniFuzzy | None = None, gain_q: float = 0.02, gain_r: float = 0.2,
                 per_channel: bool = False, q_bounds=(1e-9, 1e6), r_bounds=(1e-9, 1e6),
                 backend: str = "compiled"):
        for name, g in (("gain_q", gain_q), ("gain_r", gain_r)):
            if not (0 < g <= 1):
                raise ValueError(f"{name} must be in (0, 1], got {g}")
        for name, (lo, hi) in (("q_bounds", q_bounds), ("r_bounds", r_bounds)):
            if not (0 < lo < hi):
                raise ValueError(f"{name} must satisfy 0 < low < high, got {(lo, hi)}")
        self.fuzzy = fuzzy or MamdaniFuzzy()
        self.gain_q, self.gain_r, self.per_channel = float(gain_q), float(gain_r), bool(per_channel)
        self.q_bounds, self.r_bounds = tuple(map(float, q_bounds)), tuple(map(float, r_bounds))
        q0 = checks.positive(q0, "q0")
        r0 = np.broadcast_to(np.asarray(r0, float), (system.ny,))
        for r in r0:
            checks.positive(r, "r0")
        if not per_channel and np.ptp(r0) > 0:
            raise ValueError("r0 must be one value unless per_channel=True")
        super().__init__(system, x0, P0, q0 * np.eye(system.nx), np.diag(r0), window, backend)

    def _cache_key(self):
        return (type(self).__name__, self.window, self.fuzzy, self.gain_q, self.gain_r,
                self.per_channel, self.q_bounds, self.r_bounds)

    def _adapt(self, st, diag, C_I):
        ny, nx = self.system.ny, self.system.nx
        C_T, K = diag["S"], diag["K"]                            # eq 39: C_T = H P^- H^T + R
        if self.per_channel:
            c_t, c_i = ca.diag(C_T), ca.diag(C_I)
            m = ca.vertcat(*[self.fuzzy.expression(c_t[j], c_i[j]) for j in range(ny)])
        else:
            c_t, c_i = ca.trace(C_T) / ny, ca.trace(C_I) / ny
            m = ca.repmat(self.fuzzy.expression(c_t, c_i), ny, 1)
            c_t, c_i = ca.repmat(c_t, ny, 1), ca.repmat(c_i, ny, 1)
        self._m_expr = m
        madj = m * (c_t + c_i) / 2                              # eq 38, measurement units
        madj_q = ca.trace(ca.mtimes([K, ca.diag(madj), K.T])) / nx
        q_new = ca.fmin(ca.fmax(st["Q"][0, 0] - self.gain_q * madj_q, self.q_bounds[0]), self.q_bounds[1])
        r_new = ca.fmin(ca.fmax(ca.diag(st["R"]) - self.gain_r * madj, self.r_bounds[0]), self.r_bounds[1])
        return q_new * ca.SX.eye(nx), ca.diag(r_new)            # eqs 41, 42

    def _step_spec(self):
        st, ins, new, diag, extra = super()._step_spec()
        full = st["count"] + 1 >= self.window
        extra["m"] = ca.if_else(full, self._m_expr, ca.SX.zeros(self.system.ny))
        return st, ins, new, diag, extra

    m = property(lambda self: self._extra["m"].copy())

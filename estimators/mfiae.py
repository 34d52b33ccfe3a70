"""Fuzzy innovation-based adaptive EKF, MF-IAE (seed 000 eqs 38-42)."""
from __future__ import annotations

import casadi as ca
import numpy as np

from fmu_models.errors import ConfigurationError, TypeMismatchError, UnknownNameError
from fmu_models.infra import checks

from .adaptive import WindowedAdaptiveEKF, bound_parameters, bounds_around
from .discrete import DiscreteModel
from .fuzzy import MamdaniFuzzy
from .protocol import Parameter, per_name

__all__ = ["MFIAE", "Q_MAPPINGS"]

#: How the fuzzy adjustment reaches the process noise (see :class:`MFIAE`).
Q_MAPPINGS = ("literal", "gain")


class MFIAE(WindowedAdaptiveEKF, register="MFIAE", aliases=("MF-IAE",)):
    """EKF whose scalar Q and R are tuned online by a Mamdani fuzzy system (seed 000 sec. 4).

    Each step, after the EKF update, the fuzzy system (:class:`MamdaniFuzzy`, Table 2) maps
    ``C_T = H P^- H^T + R`` (eq 39, the step's S) and ``C_I`` (eq 37) to ``m`` in [-1, 1];
    ``MAdj = m (C_T + C_I)/2`` is the fuzzy image of ``C_T - C_I`` (eq 38). Then, with
    ``Q = sigma_q^2 I`` and ``R = sigma_r^2 I`` (eqs 24-25)::

        sigma_r^2 <- sigma_r^2 - gain_r MAdj                     (eq 42)
        sigma_q^2 <- sigma_q^2 - gain_q MAdj                     (eq 41, q_mapping="literal")
        sigma_q^2 <- sigma_q^2 - gain_q trace(K MAdj K^T) / nx   (q_mapping="gain")

    each clipped to its bounds: too large innovations (``C_I > C_T``, ``m < 0``) raise Q and R.
    ``"gain"`` maps MAdj through the gain as eq 36 maps ``C_I`` (Q moves about ``|K|^2`` times
    less than R). The manual's estimators page lists the choices the paper leaves open.

    Parameters
    ----------
    system, x0, P0, gate, nan_is_missing, backend
        As :class:`~estimators.base.KalmanBase`.
    q0 : float
        Initial process noise variance sigma_q^2 (Q = q0 I).
    r0 : float or array_like (ny,)
        Initial measurement noise variance sigma_r^2 (R = r0 I), or one per channel.
    window : int
        N of eq 37 (default 10: the paper gives none; Table 3 is matched within 10 % for 6 to 15).
    fuzzy : MamdaniFuzzy, optional
        The fuzzy system (default ``MamdaniFuzzy()``).
    gain_q, gain_r : float
        Step sizes in (0, 1] (default 1 both: eqs 41-42 subtract MAdj itself).
    q_mapping : {"literal", "gain"}
        How MAdj reaches sigma_q^2 (default "literal": eqs 41-42 as printed).
    per_channel : bool
        One adjustment per measurement channel (default False: scalar R).
    q_bounds, r_bounds : (float, float), optional
        Bounds on sigma_q^2 and each sigma_r^2 (default a factor 1e4 either side of the start:
        a start wrong by four orders of magnitude is corrected, nothing collapses to a floor).
    """

    name = "MF-IAE"

    def __init__(self, system: DiscreteModel, x0, P0, q0: float, r0, window: int = 10,
                 fuzzy: MamdaniFuzzy | None = None, gain_q: float = 1.0, gain_r: float = 1.0,
                 q_mapping: str = "literal", per_channel: bool = False, q_bounds=None, r_bounds=None,
                 gate: float | None = None, nan_is_missing: bool = True, backend: str = "compiled"):
        for name, g in (("gain_q", gain_q), ("gain_r", gain_r)):
            if not (0 < checks.finite(g, name) <= 1):
                raise ConfigurationError(f"{name} must be in (0, 1], got {g}")
        if q_mapping not in Q_MAPPINGS:
            raise UnknownNameError(f"q_mapping must be one of {Q_MAPPINGS}, got {q_mapping!r}")
        if fuzzy is not None and not isinstance(fuzzy, MamdaniFuzzy):
            raise TypeMismatchError(f"fuzzy must be a MamdaniFuzzy, got {type(fuzzy).__name__}")
        self.fuzzy = fuzzy or MamdaniFuzzy()
        self.gain_q, self.gain_r, self.per_channel = float(gain_q), float(gain_r), bool(per_channel)
        self.q_mapping = q_mapping
        q0 = checks.positive(q0, "q0")
        r0 = checks.float_array(r0, "r0")
        try:
            r0 = np.broadcast_to(r0, (system.ny,)).copy()
        except ValueError:
            raise ConfigurationError(f"r0 must be one value or {system.ny}, got {r0.tolist()}") from None
        for r in r0:
            checks.positive(r, "r0")
        if not per_channel and np.ptp(r0) > 0:
            raise ConfigurationError("r0 must be one value unless per_channel=True")
        self.q_bounds = bounds_around(np.array([q0]), q_bounds, "q_bounds")
        self.r_bounds = bounds_around(r0, r_bounds, "r_bounds")
        super().__init__(system, x0, P0, q0 * np.eye(system.nx), np.diag(r0), window, gate,
                         nan_is_missing, backend)

    def config_key(self) -> tuple:
        """Window, fuzzy system, mapping and channel mode (gains and bounds are step inputs)."""
        return (self.window, self.fuzzy, self.q_mapping, self.per_channel)

    def step_parameters(self):
        return [Parameter("gains", (self.gain_q, self.gain_r), "unit",
                          ("step size of sigma_q^2 (eq 41), in (0, 1]", "step size of sigma_r^2 (eq 42), in (0, 1]"),
                          ("gain_q", "gain_r")),
                *bound_parameters(self.q_bounds, self.r_bounds)]

    def fmu_noise_parameters(self):
        """``q0`` and ``r0`` (one per channel with ``per_channel``): Q = q0 I, R = r0 I."""
        r = np.diag(self.R)
        q = Parameter("q0", self.Q[0, 0], "positive", "initial process noise variance sigma_q^2 (Q = q0 I)")
        if self.per_channel:
            return [q, per_name("r0", r, "positive", "initial measurement noise variance", self.system.output_names)]
        return [q, Parameter("r0", r[0], "positive", "initial measurement noise variance sigma_r^2 (R = r0 I)")]

    def fmu_noise(self, p):
        """``Q = q0 I``, ``R = diag(r0)`` (r0 repeated unless per channel)."""
        s = self.system
        r = p["r0"] if self.per_channel else ca.repmat(p["r0"], s.ny, 1)
        return p["q0"] * ca.SX.eye(s.nx), ca.diag(r)

    def adapt_noise(self, ctx, result, C_I):
        """Eqs 38-42: the fuzzy adjustment of sigma_q^2 and sigma_r^2. Declares the output ``m``."""
        ny, nx = self.system.ny, self.system.nx
        C_T, K = result.S, result.K                              # eq 39: C_T = H P^- H^T + R
        if self.per_channel:
            c_t, c_i = ca.diag(C_T), ca.diag(C_I)
            m = ca.vertcat(*[self.fuzzy.expression(c_t[j], c_i[j]) for j in range(ny)])
        else:
            c_t, c_i = ca.trace(C_T) / ny, ca.trace(C_I) / ny
            m = ca.repmat(self.fuzzy.expression(c_t, c_i), ny, 1)
            c_t, c_i = ca.repmat(c_t, ny, 1), ca.repmat(c_i, ny, 1)
        madj = m * (c_t + c_i) / 2                              # eq 38, measurement units
        if self.q_mapping == "literal":
            madj_q = ca.sum1(madj) / ny                         # eq 41 as printed
        else:
            madj_q = ca.trace(ca.mtimes([K, ca.diag(madj), K.T])) / nx
        qb, rb, gains = ctx.params["q_bounds"], ctx.params["r_bounds"], ctx.params["gains"]
        q_new = ca.fmin(ca.fmax(ctx.Q[0, 0] - gains[0] * madj_q, qb[0]), qb[1])
        r_new = ca.fmin(ca.fmax(ca.diag(ctx.R) - gains[1] * madj, rb[0]), rb[1])
        ctx.output("m", m)
        return q_new * ca.SX.eye(nx), ca.diag(r_new)            # eqs 41, 42

    m = property(lambda self: self._out("m").copy(),
                 doc="The last normalised fuzzy adjustment per channel (0 before the window is full), (ny,).")

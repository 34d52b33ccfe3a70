"""Mamdani type-1 fuzzy system of seed 000's MF-IAE (eqs 38-40, Table 2), in CasADi.

From the theoretical and measured innovation covariances C_T (eq 39) and C_I (eq 37), the
normalised adjustment ``m`` on [-1, 1]; the manual's estimators page describes its sets and inference.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import reduce

import casadi as ca
import numpy as np

INPUT_SETS = ("NP", "ZE", "GA")
OUTPUT_SETS = ("DI", "MA", "AU")
#: Table 2 of seed 000 (rows C_T, columns C_I), ``RULES[C_T set][C_I set] -> output set``.
RULES = {"NP": {"NP": "MA", "ZE": "DI", "GA": "DI"},
         "ZE": {"NP": "AU", "ZE": "MA", "GA": "DI"},
         "GA": {"NP": "AU", "ZE": "AU", "GA": "MA"}}


def _sig(x, center, slope):
    return 1.0 / (1.0 + np.exp(-slope * (x - center)))


@dataclass(frozen=True)
class MamdaniFuzzy:
    """The MF-IAE fuzzy system; every choice the paper leaves open is a field.

    Parameters
    ----------
    in_centers : tuple of 3 floats
        Centres of the Gaussian input sets NP, ZE, GA on the normalised universe [0, 2].
    in_sigma : float
        Their common standard deviation (default 0.35).
    out_center : float
        Sigmoids' crossing points: DI falls through 0.5 at ``-out_center``, AU rises
        through 0.5 at ``+out_center``, MA is the product of the rising one at
        ``-out_center`` and the falling one at ``+out_center`` (default 0.5).
    out_slope : float
        Slope of the output sigmoids (default 10).
    n_out : int
        Points of the output grid on [-1, 1] for the centroid (default 51: the centroid
        of the piecewise-linear membership changes by about 1e-4 from 51 to 201 points,
        and the cost of the inference grows linearly with it).
    """

    in_centers: tuple = (0.0, 1.0, 2.0)
    in_sigma: float = 0.35
    out_center: float = 0.5
    out_slope: float = 10.0
    n_out: int = 51

    def __post_init__(self):
        if len(self.in_centers) != 3 or not (self.in_sigma > 0 and self.out_slope > 0):
            raise ValueError("need 3 input centres, in_sigma > 0 and out_slope > 0")
        if self.n_out < 3:
            raise ValueError("n_out must be at least 3")

    @property
    def grid(self) -> np.ndarray:
        """The output universe, shape (n_out,)."""
        return np.linspace(-1.0, 1.0, self.n_out)

    def output_memberships(self) -> dict[str, np.ndarray]:
        """Membership of each output set on :attr:`grid`."""
        m, c, a = self.grid, self.out_center, self.out_slope
        return {"DI": _sig(m, -c, -a), "MA": _sig(m, -c, a) * _sig(m, c, -a), "AU": _sig(m, c, a)}

    def expression(self, c_t, c_i):
        """Normalised adjustment ``m`` in [-1, 1] for covariances ``c_t``, ``c_i`` (SX or float)."""
        s = ca.fmax(0.5 * (c_t + c_i), 1e-300)
        def memberships(v):
            return {n: ca.exp(-0.5 * ((v - c) / self.in_sigma) ** 2) for n, c in zip(INPUT_SETS, self.in_centers)}

        mt, mi = memberships(c_t / s), memberships(c_i / s)
        strength = {o: reduce(ca.fmax, [ca.fmin(mt[a], mi[b]) for a in INPUT_SETS for b in INPUT_SETS
                                        if RULES[a][b] == o]) for o in OUTPUT_SETS}
        outs = self.output_memberships()
        agg = reduce(ca.fmax, [ca.fmin(strength[o], ca.DM(outs[o])) for o in OUTPUT_SETS])
        # centroid of the piecewise-linear membership: segment areas and first moments
        x = self.grid
        h = x[1] - x[0]
        m1, m2 = agg[:-1], agg[1:]
        area = ca.sum1(h * (m1 + m2) / 2)
        moment = ca.sum1(h / 6 * (ca.DM(x[:-1]) * (2 * m1 + m2) + ca.DM(x[1:]) * (m1 + 2 * m2)))
        return moment / ca.fmax(area, 1e-300)

    def function(self) -> ca.Function:
        ct, ci = ca.SX.sym("c_t"), ca.SX.sym("c_i")
        return ca.Function("mamdani", [ct, ci], [self.expression(ct, ci)])

    def __call__(self, c_t, c_i):
        """Evaluate on numbers or arrays (broadcast); returns m in [-1, 1]."""
        c_t, c_i = np.broadcast_arrays(np.asarray(c_t, float), np.asarray(c_i, float))
        f = self.function().map(c_t.size)
        out = np.asarray(f(c_t.ravel()[None, :], c_i.ravel()[None, :])).reshape(c_t.shape)
        return out if out.ndim else float(out)

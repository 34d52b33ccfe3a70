"""Algebraic loops solved at each instant (``loops="iterate"`` of :class:`~cosim.core.master.Cosimulation`).

A loop's signals ``z`` (every output of its components) are a fixed point of ``g``, one pass of the
components' output calls from ``z``: Newton on ``g(z) = z`` (``g`` a Jacobi pass, a finite-difference
Jacobian) or fixed-point Gauss-Seidel sweeps ``z = g(z)`` (the co-simulation page of the documentation).
"""
from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from fmu_models.errors import CosimError

__all__ = ["LoopSolver"]


class LoopSolver:
    """One algebraic loop, solved at an instant by calling ``solver(t)`` in place of its
    components' output calls.

    Parameters
    ----------
    units : sequence of Unit
        The loop's units (:class:`~cosim.core.schedule.Unit`, of a loop group).
    outputs : sequence of callable
        Each unit's bound output call ``f(t)``, which reads and writes ``values``.
    signals : ndarray of int, shape (n_loop,)
        The positions in ``values`` of the loop's components' outputs.
    values : ndarray, shape (n_signals,)
        The run's signal values.
    tolerance : float
        Relative change [-] below which the iteration stops.
    max_iter : int
        Iterations allowed per instant.
    method : {"newton", "fixed-point"}
        How the loop is iterated (see the module documentation).
    """

    def __init__(self, units: Sequence, outputs: Sequence[Callable[[float], None]], signals: np.ndarray,
                 values: np.ndarray, tolerance: float, max_iter: int, method: str) -> None:
        self.outputs, self.signals, self.values = list(outputs), signals, values
        self.tolerance, self.max_iter, self.newton = tolerance, max_iter, method == "newton"
        self.names = ", ".join(dict.fromkeys(u.comp.name for u in units))
        self.component = units[0].comp.name

    def __call__(self, t: float) -> None:
        """Solve the loop at ``t`` [s]: its signals in ``values``, every output call made last
        with them; raises CosimError if it does not converge."""
        values, idx = self.values, self.signals
        z = values[idx].copy()
        for _ in range(self.max_iter):
            gz = self._jacobi_pass(z, t) if self.newton else self._sweep(z, t)
            r = gz - z
            if np.all(np.abs(r) <= self.tolerance * (1 + np.abs(z))):
                values[idx] = gz
                for f in self.outputs:
                    f(t)
                return
            z = self._newton_step(z, gz, r, t) if self.newton else gz
        raise CosimError(f"algebraic loop through {self.names} did not converge in {self.max_iter} iterations "
                         f"at t = {t:g} s (tolerance {self.tolerance:g})", self.component, t)

    def _jacobi_pass(self, z: np.ndarray, t: float) -> np.ndarray:
        """``g(z)``, every component reading ``z``."""
        values, idx = self.values, self.signals
        res = z.copy()
        for f in self.outputs:
            values[idx] = z
            f(t)
            mine = values[idx]
            res[mine != z] = mine[mine != z]
        values[idx] = res
        return res

    def _sweep(self, z: np.ndarray, t: float) -> np.ndarray:
        """``g(z)``, each component reading the outputs of those before it in the sweep."""
        self.values[self.signals] = z
        for f in self.outputs:
            f(t)
        return self.values[self.signals].copy()

    def _newton_step(self, z: np.ndarray, gz: np.ndarray, r: np.ndarray, t: float) -> np.ndarray:
        """The next Newton iterate from ``z`` (``gz = g(z)``, ``r = gz - z``), with a
        finite-difference Jacobian of ``g``; ``gz`` if the Newton matrix is singular."""
        J = np.empty((len(z), len(z)))
        for j in range(len(z)):
            eps = 1e-7 * (1 + abs(z[j]))
            zp = z.copy()
            zp[j] += eps
            J[:, j] = (self._jacobi_pass(zp, t) - gz) / eps
        try:
            return z - np.linalg.solve(J - np.eye(len(z)), r)
        except np.linalg.LinAlgError:
            return gz

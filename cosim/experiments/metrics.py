"""Estimation metrics of Monte Carlo campaigns (seed 000 eqs 43-45) and divergence.

Every function takes ``err``, the errors ``err[r, k, a] = x_hat - x`` (eq 45) of shape
(runs, steps, states).
"""
from __future__ import annotations

import numpy as np


def rms_over_states(err: np.ndarray) -> np.ndarray:
    """``err`` (runs, steps, states): ``sqrt(1/nx sum_a e[r, k, a]^2)``, shape (runs, steps):
    the inner term of eqs 43-44."""
    return np.sqrt(np.mean(np.square(err), axis=-1))


def eps_k(err: np.ndarray) -> np.ndarray:
    """``err`` (runs, steps, states): eq 43, the mean over realisations of the RMS over the
    states at each step, shape (steps,)."""
    return rms_over_states(err).mean(axis=0)


def eta(err: np.ndarray) -> float:
    """``err`` (runs, steps, states): Eq 44: the time average of eps_k (mean over realisations and steps)."""
    return float(rms_over_states(err).mean())


def eta_per_run(err: np.ndarray) -> np.ndarray:
    """``err`` (runs, steps, states): Eq 44's inner time average for each realisation, shape (runs,)."""
    return rms_over_states(err).mean(axis=1)


def rmse_per_state(err: np.ndarray) -> np.ndarray:
    """``err`` (runs, steps, states): RMSE of each state over realisations and steps, shape (states,)."""
    return np.sqrt(np.mean(np.square(err), axis=(0, 1)))


def diverged(err: np.ndarray, threshold: float) -> np.ndarray:
    """Realisations whose error ``err`` (runs, steps, states) is not finite or exceeds
    ``threshold`` in any state at any step, shape (runs,) of bool."""
    finite = np.isfinite(err).all(axis=(1, 2))
    with np.errstate(invalid="ignore"):
        big = np.nanmax(np.abs(np.where(np.isfinite(err), err, np.inf)), axis=(1, 2)) > threshold
    return ~finite | big


def nees(err: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Normalised estimation error squared ``err^T P^{-1} err``, shape (runs, steps);
    ``err`` has shape (runs, steps, nx) and ``P`` (runs, steps, nx, nx)."""
    return np.einsum("rki,rki->rk", err, np.linalg.solve(P, err[..., None])[..., 0])

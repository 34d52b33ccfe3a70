"""Input validation shared by the filters: shapes, finiteness, positive definiteness."""
from __future__ import annotations

import numpy as np


def vector(value, n: int, what: str) -> np.ndarray:
    """``value`` as a finite float vector of shape ``(n,)`` (scalars allowed when n == 1)."""
    a = np.asarray(value, dtype=float)
    if a.ndim == 0 and n == 1:
        a = a.reshape(1)
    if a.shape != (n,):
        raise ValueError(f"{what} must have shape ({n},), got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{what} contains NaN or inf: {a}")
    return a


def covariance(value, n: int, what: str, allow_scalar: bool = True) -> np.ndarray:
    """A symmetric positive-definite ``(n, n)`` matrix from a matrix, a vector (diagonal) or a scalar.

    Raises ValueError naming ``what`` if the shape is wrong, an entry is not finite, the
    matrix is not symmetric (relative 1e-9) or not positive definite (Cholesky fails).
    """
    a = np.asarray(value, dtype=float)
    if a.ndim == 0 and allow_scalar:
        a = float(a) * np.eye(n)
    elif a.ndim == 1 and a.shape == (n,):
        a = np.diag(a)
    if a.shape != (n, n):
        raise ValueError(f"{what} must be a ({n}, {n}) matrix, a length-{n} diagonal or a scalar; "
                         f"got shape {np.shape(value)}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{what} contains NaN or inf")
    scale = max(np.abs(a).max(), 1e-300)
    if np.abs(a - a.T).max() > 1e-9 * scale:
        raise ValueError(f"{what} is not symmetric")
    a = 0.5 * (a + a.T)
    try:
        np.linalg.cholesky(a)
    except np.linalg.LinAlgError:
        raise ValueError(f"{what} is not positive definite (eigenvalues {np.linalg.eigvalsh(a)})") from None
    return a


def positive(value, what: str) -> float:
    v = float(value)
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"{what} must be a positive finite number, got {value!r}")
    return v

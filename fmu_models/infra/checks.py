"""Validation of numbers, vectors and covariances, shared by models, filters and components. A value that
cannot be a number raises :class:`TypeMismatchError`; a wrong shape or a non-finite entry (1.5e308 passes)
the ``error`` class the caller chose (:class:`InputError` for run-time data, :class:`ConfigurationError`)."""
from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable

import numpy as np

from ..errors import ConfigurationError, InputError, TypeMismatchError

__all__ = ["check_unique", "covariance", "finite", "float_array", "positive", "positive_int", "vector"]


def _describe(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _number(value, what: str, kind: str) -> float:
    """``value`` as a float; :class:`TypeMismatchError` saying ``what`` must be ``kind`` if it
    is a bool or not a number."""
    if isinstance(value, bool):
        raise TypeMismatchError(f"{what} must be {kind}, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise TypeMismatchError(f"{what} must be {kind}, got {_describe(value)}") from None


def float_array(value, what: str) -> np.ndarray:
    """``value`` as a float ndarray; :class:`TypeMismatchError` naming ``what`` if it is
    ``None``, a string, or anything else that is not numbers."""
    if value is None:
        raise TypeMismatchError(f"{what} is None; expected numbers")
    if isinstance(value, (str, bytes)):
        raise TypeMismatchError(f"{what} must be numbers, got the string {_describe(value)}")
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise TypeMismatchError(f"{what} must be numbers, got {_describe(value)}") from None


def vector(value, n: int, what: str, error: type[Exception] = InputError) -> np.ndarray:
    """``value`` as a finite float vector of shape ``(n,)`` (a scalar when ``n == 1``, an ``(n, 1)``
    column flattened); a wrong shape or a NaN/inf entry raises ``error`` naming ``what`` (``"EKF: y"``)."""
    a = float_array(value, what)
    if a.ndim == 0 and n == 1:
        a = a.reshape(1)
    elif a.ndim == 2 and a.shape == (n, 1):
        a = a.reshape(n)
    if a.shape != (n,):
        raise error(f"{what} must have shape ({n},) ({n} number{'' if n == 1 else 's'}), "
                    f"got shape {a.shape}")
    bad = ~np.isfinite(a)
    if bad.any():
        raise error(f"{what} contains NaN or inf at index {np.flatnonzero(bad).tolist()}: {a}")
    return a


def covariance(value, n: int, what: str, allow_scalar: bool = True,
               error: type[Exception] = ConfigurationError) -> np.ndarray:
    """A symmetric positive-definite ``(n, n)`` matrix from ``value``: a matrix, a vector (the
    diagonal) or, with ``allow_scalar``, a scalar (times identity); else ``error`` naming ``what``
    (a wrong shape, a non-finite entry, asymmetry beyond 1e-9 relative, a failed Cholesky)."""
    a = float_array(value, what)
    if a.ndim == 0 and allow_scalar:
        a = np.full(n, float(a))       # the diagonal: no inf * 0 off it
    if a.ndim == 1 and a.shape == (n,):
        a = np.diag(a)
    if a.shape != (n, n):
        raise error(f"{what} must be a ({n}, {n}) matrix, a length-{n} diagonal or a scalar; "
                    f"got shape {a.shape}")
    if not np.isfinite(a).all():
        raise error(f"{what} contains NaN or inf")
    scale = max(float(np.abs(a).max()), 1e-300)
    with np.errstate(over="ignore"):   # a difference past the float range is inf: not symmetric
        asymmetry = np.abs(a - a.T).max()
    if asymmetry > 1e-9 * scale:
        raise error(f"{what} is not symmetric")
    a = 0.5 * a + 0.5 * a.T            # halves first: huge finite entries stay finite
    try:
        np.linalg.cholesky(a)
    except np.linalg.LinAlgError:
        raise error(f"{what} is not positive definite (eigenvalues "
                    f"{np.linalg.eigvalsh(a)})") from None
    return a


def finite(value, what: str, error: type[Exception] = ConfigurationError) -> float:
    """``value`` as a finite float, else ``error`` naming ``what``."""
    v = _number(value, what, "a number")
    if not math.isfinite(v):
        raise error(f"{what} must be finite, got {value!r}")
    return v


def positive(value, what: str, error: type[Exception] = ConfigurationError) -> float:
    """``value`` as a positive finite float, else ``error`` naming ``what``."""
    v = finite(value, what, error)
    if not v > 0:
        raise error(f"{what} must be a positive finite number, got {value!r}")
    return v


def positive_int(value, what: str, error: type[Exception] = ConfigurationError,
                 minimum: int = 1) -> int:
    """``value`` as an int ``>= minimum`` (integral floats such as 3.0 accepted); else ``error`` naming ``what``."""
    v = _number(value, what, "an integer")
    if not (math.isfinite(v) and v == int(v) and v >= minimum):
        raise error(f"{what} must be an integer >= {minimum}, got {value!r}")
    return int(v)


def check_unique(names: Iterable[str], what: str, hint: str = "") -> None:
    """Refuse (ConfigurationError) repeated ``names``: the message is ``what`` then the repeated
    names, sorted, then ``hint`` in parentheses if given (``check_unique(names, "duplicate
    component names:")``)."""
    dup = sorted(n for n, k in Counter(names).items() if k > 1)
    if dup:
        raise ConfigurationError(f"{what} {dup}" + (f" ({hint})" if hint else ""))

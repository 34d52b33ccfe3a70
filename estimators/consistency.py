"""Consistency tests of a filter over Monte Carlo runs: chi-square bands of the NEES and NIS, and
the whiteness of the innovations (Bar-Shalom, Li and Kirubarajan 2001, section 5.4); the rules and
verdicts are in the guide's page on the experiments (docs/guide/experiments.md)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2, norm

from fmu_models.errors import ConfigurationError, InputError
from fmu_models.infra import checks

__all__ = ["BandTest", "WhitenessTest", "chi2_band", "nees_test", "nis_test", "whiteness_test"]


def _confidence(confidence) -> float:
    c = checks.finite(confidence, "confidence")
    if not 0.0 < c < 1.0:
        raise ConfigurationError(f"confidence must lie strictly between 0 and 1 (e.g. 0.95), got {confidence!r}")
    return c


def chi2_band(runs, dof, confidence: float = 0.95) -> tuple[float, float]:
    """Two-sided band of the average of ``runs`` independent chi-square(``dof``) values:
    ``chi2.ppf([alpha/2, 1 - alpha/2], runs dof) / runs``, ``alpha = 1 - confidence``
    (Bar-Shalom et al. 2001, section 5.4).

    Parameters
    ----------
    runs : int
        Number of independent values averaged (the Monte Carlo runs), >= 1.
    dof : float
        Degrees of freedom of each value (n_x for the NEES, n_y for the NIS), > 0.
    confidence : float
        Probability of the band, in (0, 1).
    """
    n = checks.positive_int(runs, "runs")
    d = checks.positive(dof, "degrees of freedom dof")
    a = 1.0 - _confidence(confidence)
    lo, hi = chi2.ppf([a / 2, 1 - a / 2], n * d) / n
    return float(lo), float(hi)


@dataclass(frozen=True)
class BandTest:
    """A chi-square band test of the NEES or the NIS over ``runs`` Monte Carlo runs.

    Attributes
    ----------
    statistic : str
        ``"NEES"`` or ``"NIS"``.
    confidence : float
    runs : int
        Number of runs ``N``.
    dof : float
        Degrees of freedom of one value (mean over runs and steps if channels were missing).
    per_step, lower, upper : ndarray, shape (K,)
        Average over the runs at each step (NaN without degrees of freedom), and its band.
    average : float
        Average over runs and steps.
    band : tuple of float
        The verdict's band: the per-step band of the average's degrees of freedom.
    strict_band : tuple of float
        The band of the average if all ``N K`` values were independent.
    share_inside : float
        Share of the steps whose average lies inside its band (1 - alpha expected).
    consistent : bool
        ``average`` inside ``band``.
    """

    statistic: str
    confidence: float
    runs: int
    dof: float
    per_step: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    average: float
    band: tuple
    strict_band: tuple
    share_inside: float
    consistent: bool


def _values(values, what: str) -> np.ndarray:
    v = checks.float_array(values, what)
    if v.ndim == 1:                     # one run
        v = v[None, :]
    if v.ndim != 2:
        raise InputError(f"{what} must have shape (runs, steps), got {v.shape}")
    if v.shape[0] < 1 or v.shape[1] < 1:
        raise InputError(f"{what} is empty (shape {v.shape}): at least one run and one step are needed")
    if np.isnan(v).any():
        r, k = map(int, np.argwhere(np.isnan(v))[0])
        raise InputError(f"{what} contains NaN (first: run {r}, step {k}); mark a diverged run with inf, "
                         "which fails the test")
    if (v < 0).any():
        raise InputError(f"{what} must be non-negative (a normalised squared error)")
    return v


def _band_test(statistic: str, values, dof, confidence: float) -> BandTest:
    v = _values(values, statistic.lower())
    c = _confidence(confidence)
    a = 1.0 - c
    N, K = v.shape
    if np.ndim(dof) == 0:
        d = np.full((N, K), checks.positive(dof, "degrees of freedom dof"))
    else:
        d = checks.float_array(dof, "degrees of freedom dof")
        if d.shape != (N, K):
            raise InputError(f"degrees of freedom dof must be a number or have the shape of the values {v.shape}, "
                             f"got {d.shape}")
        if not (np.isfinite(d).all() and (d >= 0).all() and d.sum() > 0):
            raise InputError("degrees of freedom dof must be finite, >= 0 and not all 0")
    total = d.sum(axis=0)                                   # chi-square dof of the sum over runs
    has = total > 0
    # the quantiles once per distinct number of degrees of freedom (one without missing data)
    levels, where = np.unique(np.where(has, total, 1), return_inverse=True)
    with np.errstate(invalid="ignore"):
        per_step = np.where(has, v.mean(axis=0), np.nan)
        q_lo, q_hi = chi2.ppf(a / 2, levels) / N, chi2.ppf(1 - a / 2, levels) / N
        lower = np.where(has, q_lo[where.ravel()], np.nan)
        upper = np.where(has, q_hi[where.ravel()], np.nan)
    inside = (per_step >= lower) & (per_step <= upper)
    mean_dof = float(total[has].mean() / N)
    average = float(per_step[has].mean())
    band = chi2_band(N, mean_dof, c)
    return BandTest(statistic, c, N, mean_dof, per_step, lower, upper, average, band,
                    chi2_band(int(has.sum()) * N, mean_dof, c), float(inside[has].mean()),
                    bool(band[0] <= average <= band[1]))


def nees_test(nees, nx: int, confidence: float = 0.95) -> BandTest:
    """The NEES test over Monte Carlo runs (Bar-Shalom et al. 2001, section 5.4).

    Parameters
    ----------
    nees : array_like, shape (runs, steps) or (steps,)
        Normalised estimation errors squared ``e^T P^-1 e`` (a 1-D array is one run); a
        diverged run may be ``inf`` (it fails the test), NaN is refused.
    nx : int
        State dimension (the degrees of freedom).
    confidence : float
        Probability of the bands (default 0.95).

    Returns
    -------
    BandTest
    """
    return _band_test("NEES", nees, checks.positive_int(nx, "state dimension nx"), confidence)


def nis_test(nis, dof, confidence: float = 0.95) -> BandTest:
    """The NIS test over Monte Carlo runs (Bar-Shalom et al. 2001, section 5.4).

    Parameters
    ----------
    nis : array_like, shape (runs, steps) or (steps,)
        Normalised innovations squared ``nu^T S^-1 nu`` (a 1-D array is one run).
    dof : int or array_like, shape (runs, steps)
        Measured channels: ``n_y``, or the number of valid channels of each value (0: missing).
    confidence : float
        Probability of the bands (default 0.95).

    Returns
    -------
    BandTest
    """
    return _band_test("NIS", nis, dof, confidence)


@dataclass(frozen=True)
class WhitenessTest:
    """The whiteness test of the innovations over Monte Carlo runs.

    Attributes
    ----------
    confidence : float
    runs : int
        Number of runs ``N``.
    lags : ndarray of int, shape (L,)
    autocorrelation : ndarray, shape (ny, L)
        Each channel's normalised autocorrelation at each lag, pooled over runs and steps.
    per_step : ndarray, shape (ny, L, K)
        ``rho(k, k + l)`` over the runs at each step (NaN without a valid pair, or beyond the record).
    band : float
        The verdict's half-width ``z_{1-alpha/2} / sqrt(N)`` (``N``: the mean number of runs
        with a valid pair at a step).
    strict_band : ndarray, shape (ny, L)
        Half-width ``z_{1-alpha/2} / sqrt(pairs)`` if all pairs were independent.
    share_inside : ndarray, shape (ny, L)
        Share of the steps whose ``rho(k, k + l)`` lies inside the band.
    white : bool
        Every pooled autocorrelation inside ``+-band`` (channels without a valid pair left out).
    """

    confidence: float
    runs: int
    lags: np.ndarray
    autocorrelation: np.ndarray
    per_step: np.ndarray
    band: float
    strict_band: np.ndarray
    share_inside: np.ndarray
    white: bool


def whiteness_test(innovations, S, lags=(1, 2, 3, 4, 5), confidence: float = 0.95, valid=None) -> WhitenessTest:
    """The whiteness test of the innovations, each divided by ``sqrt(S_jj)`` (Bar-Shalom et al.
    2001, section 5.4).

    Parameters
    ----------
    innovations : array_like, shape (runs, steps, ny)
        Innovations ``y_k - h(x_k^-)`` of each run [measurement units].
    S : array_like, shape (runs, steps, ny, ny) or (runs, steps, ny)
        Their predicted covariances (or only the variances).
    lags : sequence of int
        Lags to test, each >= 1 and shorter than the record.
    confidence : float
        Probability of the bands (default 0.95).
    valid : array_like of bool, shape (runs, steps, ny), optional
        The channels measured (default: all).

    Returns
    -------
    WhitenessTest
    """
    e, ok, lags = _normalised(innovations, S, valid, lags)
    N, K, ny = e.shape
    c = _confidence(confidence)
    z = float(norm.ppf(1 - (1 - c) / 2))
    acf, strict, share = np.empty((ny, len(lags))), np.empty((ny, len(lags))), np.empty((ny, len(lags)))
    per_step = np.full((ny, len(lags), K), np.nan)
    counts = []
    pairs_of = None if ok.all() else ok
    for i, lag in enumerate(lags):
        acf[:, i], rk, share[:, i], strict[:, i], n_k = _at_lag(e, pairs_of, lag, z)
        per_step[:, i, :K - lag] = rk.T
        counts.append(n_k[n_k > 0])
    if not np.isfinite(acf).any():
        raise InputError("no channel has a valid pair of innovations at the lags tested")
    # the per-step band at the average number of runs with a valid pair (N without missing data)
    band = z / np.sqrt(float(np.mean(np.concatenate(counts))))
    white = bool(np.all(np.abs(acf[np.isfinite(acf)]) <= band))
    return WhitenessTest(c, N, lags, acf, per_step, band, strict, share, white)


def _normalised(innovations, S, valid, lags) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The arguments of :func:`whiteness_test` checked: the normalised innovations (0 in missing
    channels), the valid channels (runs, steps, ny) and the lags."""
    nu = checks.float_array(innovations, "innovations")
    if nu.ndim != 3 or min(nu.shape) < 1:
        raise InputError(f"innovations must have shape (runs, steps, ny) with none empty, got {nu.shape}")
    N, K, ny = nu.shape
    var = checks.float_array(S, "innovation covariances S")
    if var.shape == (N, K, ny, ny):
        var = np.diagonal(var, axis1=2, axis2=3)
    if var.shape != (N, K, ny):
        raise InputError(f"innovation covariances S must have shape ({N}, {K}, {ny}, {ny}) or ({N}, {K}, {ny}), "
                         f"got {var.shape}")
    if valid is None:
        ok = np.ones((N, K, ny), dtype=bool)
    else:
        m = checks.float_array(valid, "valid")
        if m.shape != (N, K, ny) or not np.isin(m, (0.0, 1.0)).all():
            raise InputError(f"valid must hold 0/1 (or bools) with shape ({N}, {K}, {ny}), got {m.shape}")
        ok = m != 0
    if not np.isfinite(nu[ok]).all():
        raise InputError("innovations contain NaN or inf in a valid channel (mark missing channels with valid)")
    if not (np.isfinite(var[ok]).all() and (var[ok] > 0).all()):
        raise InputError("innovation variances must be positive and finite in every valid channel")
    lags = np.array([checks.positive_int(v, "a lag") for v in np.atleast_1d(lags)], dtype=int)
    if not len(lags) or lags.max() >= K:
        raise ConfigurationError(f"lags must be a non-empty list of integers in 1..{K - 1} (the record has {K} "
                                 f"steps), got {lags.tolist()}")
    return np.where(ok, nu / np.sqrt(np.where(ok, var, 1.0)), 0.0), ok, lags


def _at_lag(e: np.ndarray, ok: np.ndarray | None, lag: int, z: float) -> tuple:
    """At ``lag``, of ``e`` (runs, K, ny) with valid channels ``ok`` (None: all): the pooled
    autocorrelation (ny,), ``rho(k, k + lag)`` (K - lag, ny), the share of steps inside
    ``+-z / sqrt(n_k)`` (ny,), the strict half-width (ny,) and the valid pairs ``n_k`` (K - lag, ny)."""
    if ok is None:
        a, b = e[:, :-lag], e[:, lag:]
        n_k = np.full((e.shape[1] - lag, e.shape[2]), e.shape[0])
    else:
        pairs = ok[:, :-lag] & ok[:, lag:]              # (N, K - lag, ny)
        a, b = e[:, :-lag] * pairs, e[:, lag:] * pairs
        n_k = pairs.sum(axis=0)                          # valid pairs at each step
    num, da, db = (np.einsum("rkj,rkj->kj", x, y) for x, y in ((a, b), (a, a), (b, b)))   # (K - lag, ny)
    with np.errstate(invalid="ignore", divide="ignore"):
        rk = np.where(n_k > 0, num / np.sqrt(da * db), np.nan)
        acf = num.sum(axis=0) / np.sqrt(da.sum(axis=0) * db.sum(axis=0))
        inside = np.abs(rk) <= z / np.sqrt(n_k)
    defined = np.isfinite(rk)
    share = np.where(defined.any(axis=0), (inside & defined).sum(axis=0) / np.maximum(defined.sum(axis=0), 1), np.nan)
    return acf, rk, share, z / np.sqrt(np.maximum(n_k.sum(axis=0), 1)), n_k

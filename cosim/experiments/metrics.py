"""Estimation metrics of Monte Carlo campaigns (seed 000 eqs 43-45; ``err[r, k, a] = x_hat - x``
of shape (runs, steps, states)), divergence, the errors over the posterior Cramér-Rao bound
and the consistency verdicts."""
from __future__ import annotations

import numpy as np

from estimators import nees_test, nis_test, whiteness_test


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
    return ~(np.abs(err) <= threshold).all(axis=(1, 2))


def nees(err: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Normalised estimation error squared ``err^T P^{-1} err``, shape (runs, steps);
    ``err`` has shape (runs, steps, nx) and ``P`` (runs, steps, nx, nx)."""
    return np.einsum("rki,rki->rk", err, np.linalg.solve(P, err[..., None])[..., 0])


# ---------------------------------------------------------------------------- the limit and consistency
def consistency_rule(confidence: float, lags: int) -> str:
    """The consistency rule of the campaigns' reports, in words, at ``confidence`` (e.g. 0.95)
    with whiteness tested at lags 1..``lags``."""
    a = 1 - confidence
    return (f"consistent at {confidence:.0%} = all three textbook tests of Bar-Shalom, Li and Kirubarajan (2001, "
            f"section 5.4) pass on the average over the N runs and the K steps: (1) the average NEES lies inside "
            f"the two-sided band [chi2({a / 2:g}, N nx) / N, chi2({1 - a / 2:g}, N nx) / N] of one step; (2) the "
            f"average NIS inside the same band with ny; (3) the normalised autocorrelation of each measured "
            f"channel's innovations (divided by sqrt(S_jj), pooled over runs and steps) lies inside "
            f"+-z({1 - a / 2:g}) / sqrt(N) at every lag 1..{lags}. A diverged run has an infinite NEES, so it "
            f"fails (1). The share of the K steps whose own N-run statistic lies inside its band is reported "
            f"beside each verdict ({confidence:.0%} expected of a consistent filter)")


def band_row(nees: np.ndarray, nis: np.ndarray, nx: int, ny: int, confidence: float = 0.95) -> tuple[dict, dict]:
    """Tests (1) and (2) of :func:`consistency_rule` for one filter of ``nees`` and ``nis``
    (runs, K; NaN, a diverged run, counts as infinite) in ``nx`` and ``ny`` dimensions, bands
    of probability ``confidence``: ``(row, per_step)``, ``row`` with ``runs``, ``anees``, its
    band ``anees_lo``, ``anees_hi``, ``anees_inside`` (share of the steps inside their band),
    ``nees_ok`` and the same for ``anis`` / ``nis_ok``; ``per_step`` the arrays (K,) ``anees``,
    ``anis`` and their bands ``nees_lo``, ``nees_hi``, ``nis_lo``, ``nis_hi``."""
    ne = nees_test(np.where(np.isnan(nees), np.inf, nees), nx, confidence)
    ni = nis_test(np.where(np.isnan(nis), np.inf, nis), ny, confidence)
    row = {"runs": ne.runs, "anees": ne.average, "anees_lo": ne.band[0], "anees_hi": ne.band[1],
           "anees_inside": ne.share_inside, "nees_ok": ne.consistent,
           "anis": ni.average, "anis_lo": ni.band[0], "anis_hi": ni.band[1], "anis_inside": ni.share_inside,
           "nis_ok": ni.consistent}
    per_step = {"anees": ne.per_step, "anis": ni.per_step, "nees_lo": ne.lower, "nees_hi": ne.upper,
                "nis_lo": ni.lower, "nis_hi": ni.upper}
    return row, per_step


def whiteness_row(innovation: np.ndarray, S: np.ndarray, confidence: float = 0.95, lags: int = 5) -> dict:
    """Test (3) of :func:`consistency_rule` for one filter: ``acf_max`` and ``acf_lag1``
    (largest absolute pooled autocorrelation over the channels, at any lag and at lag 1),
    ``acf_band``, ``acf_inside`` (smallest share of steps inside, over channels and lags) and
    ``white_ok``, at ``confidence`` and lags 1..``lags``, of the ``innovation`` (runs, K, ny)
    with covariances ``S`` (runs, K, ny, ny). Innovations not finite (a diverged run) are not white."""
    if not (np.isfinite(innovation).all() and np.isfinite(S).all()):
        return {"acf_max": np.inf, "acf_lag1": np.inf, "acf_band": np.nan, "acf_inside": np.nan, "white_ok": False}
    w = whiteness_test(innovation, S, lags=range(1, lags + 1), confidence=confidence)
    return {"acf_max": float(np.nanmax(np.abs(w.autocorrelation))),
            "acf_lag1": float(np.nanmax(np.abs(w.autocorrelation[:, 0]))), "acf_band": w.band,
            "acf_inside": float(np.nanmin(w.share_inside)), "white_ok": w.white}


def no_whiteness() -> dict:
    """The whiteness columns of a run without innovations (the master path): not tested."""
    return {"acf_max": np.nan, "acf_lag1": np.nan, "acf_band": np.nan, "acf_inside": np.nan, "white_ok": None}


def consistency_row(nees: np.ndarray, nis: np.ndarray, nx: int, ny: int, confidence: float,
                    whiteness: dict | None) -> tuple[dict, dict]:
    """All three tests of :func:`consistency_rule`: ``(row, per_step)`` of :func:`band_row`
    (``nees``, ``nis``, ``nx``, ``ny``, ``confidence``), the row with the ``whiteness`` columns
    (:func:`whiteness_row`; None: not tested, which does not count) and ``consistent``."""
    row, per_step = band_row(nees, nis, nx, ny, confidence)
    row.update(no_whiteness() if whiteness is None else whiteness)
    row["consistent"] = bool(row["nees_ok"] and row["nis_ok"] and row["white_ok"] in (True, None))
    return row, per_step


def consistency(nees: np.ndarray, nis: np.ndarray, nx: int, ny: int, confidence: float = 0.95,
                innovation: np.ndarray | None = None, S: np.ndarray | None = None, lags: int = 5) -> tuple[dict, dict]:
    """:func:`consistency_row` (``nees``, ``nis``, ``nx``, ``ny``, ``confidence`` as
    :func:`band_row`) with the whiteness of ``innovation``, ``S`` at ``lags`` tested here
    (:func:`whiteness_row`; not tested if ``innovation`` is None)."""
    return consistency_row(nees, nis, nx, ny, confidence,
                           None if innovation is None else whiteness_row(innovation, S, confidence, lags))


def pcrb_ratio_se(rmse_runs: np.ndarray, bound_mse: np.ndarray) -> np.ndarray:
    """The Monte Carlo standard error of :func:`pcrb_ratio` of ``rmse_runs`` and ``bound_mse``,
    shape (nx,): half the relative standard error ``std_r(m_r) / sqrt(N) / mean_r(m_r)`` of
    the mean-square error over the independent realisations (``m_r`` a realisation's over the
    steps; the bound's own Monte Carlo error, from the Jacobians' spread only, is far smaller)."""
    m = np.square(rmse_runs)
    N = len(m)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        rel = m.std(axis=0, ddof=1) / np.sqrt(N) / m.mean(axis=0) if N > 1 else np.full(m.shape[1], np.nan)
        return 0.5 * rel * pcrb_ratio(rmse_runs, bound_mse)


def pcrb_ratio(rmse_runs: np.ndarray, bound_mse: np.ndarray) -> np.ndarray:
    """Each state's RMSE as a multiple of the posterior Cramér-Rao bound, shape (nx,):
    ``sqrt(mean_r rmse_r^2 / mean_k PCRB_k)`` of each realisation's RMSE over steps 1..K
    ``rmse_runs`` (runs, nx) and the bound on the MSE at steps 1..K ``bound_mse`` (K, nx)."""
    with np.errstate(invalid="ignore", over="ignore"):
        return np.sqrt(np.mean(np.square(rmse_runs), axis=0) / np.mean(bound_mse, axis=0))


def after_transient(nees: np.ndarray, nis: np.ndarray, mse: np.ndarray, bound_mse: np.ndarray, ny: int, start: int,
                    whiteness: dict | None, confidence: float = 0.95) -> dict:
    """A diagnostic beside the verdict (not part of :func:`consistency_rule`): the numbers over
    the steps after the first ``start``, where an adaptive filter's start-up no longer counts:
    ``pcrb_ratio_max_late`` (worst state's RMSE / PCRB), ``anees_late``, ``anis_late`` and
    ``consistent_late``. ``nees``, ``nis``, ``ny``, ``confidence`` as :func:`band_row`; ``mse``
    and ``bound_mse``: each state's mean-square error over the runs and its PCRB at steps
    1..K (K, nx); ``whiteness``: :func:`whiteness_row` after ``start`` (None: not tested)."""
    with np.errstate(invalid="ignore", over="ignore"):
        ratio = np.sqrt(mse[start:].mean(axis=0) / bound_mse[start:].mean(axis=0))
    row, _ = consistency_row(nees[:, start:], nis[:, start:], mse.shape[1], ny, confidence, whiteness)
    return {"pcrb_ratio_max_late": float(np.max(ratio)), "anees_late": row["anees"], "anis_late": row["anis"],
            "consistent_late": row["consistent"]}


def consistency_markdown(table, keys: list[str]) -> list[str]:
    """Markdown lines of the consistency tests, a row per row of ``table`` (a DataFrame with the
    columns of :func:`consistency`, ``filter`` and the identifying columns ``keys``, shown first)."""
    def yes(v):
        return "n/a" if v is None or (isinstance(v, float) and np.isnan(v)) else ("yes" if v else "no")

    out = ["| " + " | ".join(keys) + " | filter | runs | avg NEES [band] | steps inside | NEES | avg NIS [band] | "
           "steps inside | NIS | max abs autocorr. (lag 1) [band] | white | consistent |",
           "|" + "---|" * (len(keys) + 11)]
    for _, r in table.iterrows():
        white = (f"{r['acf_max']:.3f} ({r['acf_lag1']:.3f}) [{r['acf_band']:.3f}]" if yes(r["white_ok"]) != "n/a"
                 else "not tested")
        out.append("| " + " | ".join(str(r[k]) for k in keys) + f" | {r['filter']} | {r['runs']} | {r['anees']:.3g} "
                   f"[{r['anees_lo']:.2f}, {r['anees_hi']:.2f}] | {r['anees_inside']:.0%} | {yes(r['nees_ok'])} | "
                   f"{r['anis']:.3g} [{r['anis_lo']:.2f}, {r['anis_hi']:.2f}] | {r['anis_inside']:.0%} | "
                   f"{yes(r['nis_ok'])} | {white} | {yes(r['white_ok'])} | **{yes(r['consistent'])}** |")
    return out

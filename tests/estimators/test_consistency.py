"""Consistency tests: chi-square bands against scipy.stats.chi2, the verdicts on consistent
and inconsistent chi-square samples and on a Kalman filter with the true and a wrong noise,
missing channels, whiteness on white and coloured sequences, and hostile inputs."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from estimators import KF, BatchFilter, chi2_band, linear_model, nees_test, nis_test, whiteness_test
from fmu_models.errors import ConfigurationError, InputError, TypeMismatchError


@pytest.mark.parametrize(("runs", "dof", "confidence"), [(100, 4, 0.95), (100, 2, 0.95), (1, 1, 0.9), (37, 3, 0.99)])
def test_band_is_the_chi2_quantiles_over_runs(runs, dof, confidence):
    lo, hi = chi2_band(runs, dof, confidence)
    a = 1 - confidence
    assert lo == pytest.approx(stats.chi2(runs * dof).ppf(a / 2) / runs, rel=1e-14)
    assert hi == pytest.approx(stats.chi2(runs * dof).isf(a / 2) / runs, rel=1e-12)


def test_textbook_band_for_100_runs_and_four_states():
    lo, hi = chi2_band(100, 4)
    assert (round(lo, 2), round(hi, 2)) == (3.46, 4.57)


def test_consistent_and_inconsistent_chi2_samples():
    rng = np.random.default_rng(0)
    N, K = 100, 500
    values = rng.chisquare(4, (N, K))
    ok = nees_test(values, 4)
    assert ok.consistent and ok.statistic == "NEES" and ok.runs == N and ok.dof == 4
    assert ok.per_step.shape == ok.lower.shape == (K,)
    assert abs(ok.share_inside - 0.95) < 0.03 and ok.band == chi2_band(N, 4)
    np.testing.assert_allclose(ok.per_step, values.mean(axis=0))
    assert ok.average == pytest.approx(values.mean(), rel=1e-12)
    assert ok.strict_band[0] < ok.average < ok.strict_band[1]           # independent steps here
    assert ok.band[0] < ok.strict_band[0] and ok.strict_band[1] < ok.band[1]
    for scale in (0.8, 1.25):                  # optimistic and pessimistic covariances: two-sided
        bad = nees_test(scale * rng.chisquare(4, (N, K)), 4)
        assert not bad.consistent and bad.share_inside < 0.5
    diverged = rng.chisquare(4, (N, K))
    diverged[3, 100:] = np.inf
    assert not nees_test(diverged, 4).consistent
    one = nees_test(rng.chisquare(4, K), 4)                     # one run: shape (steps,)
    assert one.runs == 1 and one.per_step.shape == (K,)


def test_nis_with_missing_channels_counts_only_the_measured_degrees_of_freedom():
    rng = np.random.default_rng(1)
    N, K = 60, 300
    dof = rng.integers(0, 3, (N, K))                           # 0, 1 or 2 channels measured
    dof[:, 7] = 0                                              # a step with no measurement
    nis = np.where(dof > 0, rng.chisquare(np.maximum(dof, 1)), 0.0)
    t = nis_test(nis, dof)
    assert t.consistent and np.isnan(t.per_step[7]) and np.isnan(t.lower[7])
    assert t.dof == pytest.approx(dof.mean() * K / (K - 1), rel=1e-12)
    k = 11
    assert t.lower[k] == pytest.approx(stats.chi2(dof[:, k].sum()).ppf(0.025) / N, rel=1e-12)
    assert abs(t.share_inside - 0.95) < 0.04
    assert not nis_test(np.where(dof > 0, 2.0 * nis, 0.0), dof).consistent


def _ar1(rng, phi, shape):
    e = rng.standard_normal(shape)
    out = np.empty(shape)
    out[:, 0] = e[:, 0]
    for k in range(1, shape[1]):
        out[:, k] = phi * out[:, k - 1] + np.sqrt(1 - phi**2) * e[:, k]
    return out


def test_whiteness_on_white_and_on_coloured_sequences():
    rng = np.random.default_rng(2)
    N, K = 100, 400
    var = np.stack([np.full((N, K), 4.0), np.full((N, K), 0.25)], axis=-1)
    white = rng.standard_normal((N, K, 2)) * np.sqrt(var)
    w = whiteness_test(white, var, lags=[1, 2, 3])
    assert w.white and w.runs == N and w.band == pytest.approx(1.96 / 10, rel=1e-3)
    assert w.autocorrelation.shape == (2, 3) and w.per_step.shape == (2, 3, K)
    assert np.all(np.abs(w.autocorrelation) < 3 * w.strict_band)
    assert np.all(np.abs(w.share_inside - 0.95) < 0.04)
    # full S gives the same as its diagonal
    S = np.zeros((N, K, 2, 2))
    S[..., 0, 0], S[..., 1, 1], S[..., 0, 1], S[..., 1, 0] = var[..., 0], var[..., 1], 0.3, 0.3
    np.testing.assert_allclose(whiteness_test(white, S, lags=[1, 2, 3]).autocorrelation, w.autocorrelation)
    # AR(1) with phi = 0.5: rho(l) = 0.5^l
    col = np.stack([_ar1(rng, 0.5, (N, K)), rng.standard_normal((N, K))], axis=-1)
    c = whiteness_test(col, np.ones((N, K, 2)), lags=[1, 2, 3])
    assert not c.white
    np.testing.assert_allclose(c.autocorrelation[0], [0.5, 0.25, 0.125], atol=0.02)
    assert np.all(np.abs(c.autocorrelation[1]) < 0.05) and c.share_inside[0, 0] < 0.05
    # a moving average of two steps: correlated at lag 1 only (rho = 1/2)
    e = rng.standard_normal((N, K + 1))
    ma = ((e[:, 1:] + e[:, :-1]) / np.sqrt(2))[..., None]
    m = whiteness_test(ma, np.ones((N, K, 1)), lags=[1, 2])
    assert not m.white and abs(m.autocorrelation[0, 0] - 0.5) < 0.02 and abs(m.autocorrelation[0, 1]) < 0.02


def test_whiteness_leaves_missing_channels_out():
    rng = np.random.default_rng(3)
    N, K = 80, 300
    col = _ar1(rng, 0.6, (N, K))[..., None]
    valid = rng.random((N, K, 1)) > 0.3
    seen = np.where(valid, col, 0.0)
    t = whiteness_test(seen, np.ones((N, K, 1)), lags=[1], valid=valid)
    assert t.autocorrelation[0, 0] == pytest.approx(0.6, abs=0.03)
    full = whiteness_test(col, np.ones((N, K, 1)), lags=[1])
    assert t.band > full.band                      # fewer valid pairs, wider band
    # garbage in a missing channel does not matter
    junk = np.where(valid, col, np.nan)
    np.testing.assert_allclose(whiteness_test(junk, np.ones((N, K, 1)), lags=[1], valid=valid).autocorrelation,
                               t.autocorrelation)


def test_a_kalman_filter_with_the_true_noise_passes_and_with_a_wrong_one_fails():
    A, B, C = np.array([[1.0, 0.1], [0.0, 0.95]]), np.array([[0.0], [0.1]]), np.array([[1.0, 0.0]])
    lin = linear_model(A, B, C, 0.1)
    rng = np.random.default_rng(4)
    N, K, q, r = 100, 300, 0.01, 0.1
    X = np.zeros((N, K + 1, 2))
    for k in range(K):
        X[:, k + 1] = X[:, k] @ A.T + rng.normal(0, np.sqrt(q), (N, 2))
    Y = X[:, 1:] @ C.T + rng.normal(0, np.sqrt(r), (N, K, 1))
    X[:, 0] = 0.0

    def tests(R):
        f = KF(lin, np.zeros(2), 1e-9, q, R, x_op=np.zeros(2))
        out = BatchFilter(f, N).run(np.zeros((K, 1)), Y)
        e = out.x[:, 1:] - X[:, 1:]
        nees = np.einsum("rki,rki->rk", e, np.linalg.solve(out.P[:, 1:], e[..., None])[..., 0])
        return nees_test(nees, 2), nis_test(out.nis, 1), whiteness_test(out.innovation, out.S)

    ne, ni, wh = tests(r)
    assert ne.consistent and ni.consistent and wh.white
    assert ne.share_inside > 0.9 and ni.share_inside > 0.9
    ne, ni, wh = tests(30 * r)
    assert not ni.consistent and not wh.white


def test_hostile_inputs_are_refused_by_name():
    ok = np.ones((3, 5))
    for bad in (0, 1, 1.5, -0.1, np.nan, np.inf):
        with pytest.raises(ConfigurationError, match="confidence must"):
            nees_test(ok, 2, confidence=bad)
    with pytest.raises(ConfigurationError, match="runs must be an integer >= 1"):
        chi2_band(0, 4)
    with pytest.raises(ConfigurationError, match="degrees of freedom"):
        chi2_band(10, -1)
    with pytest.raises(ConfigurationError, match="state dimension nx"):
        nees_test(ok, 0)
    with pytest.raises(TypeMismatchError, match="nees"):
        nees_test("abc", 2)
    with pytest.raises(InputError, match="empty"):
        nees_test(np.ones((0, 5)), 2)
    with pytest.raises(InputError, match="shape"):
        nees_test(np.ones((2, 3, 4)), 2)
    nan = ok.copy()
    nan[2, 3] = np.nan
    with pytest.raises(InputError, match="NaN.*run 2, step 3"):
        nees_test(nan, 2)
    with pytest.raises(InputError, match="non-negative"):
        nis_test(-ok, 1)
    with pytest.raises(InputError, match="dof must be a number or have the shape"):
        nis_test(ok, np.ones((3, 4)))
    with pytest.raises(InputError, match="not all 0"):
        nis_test(ok, np.zeros((3, 5)))
    nu, S = np.zeros((3, 5, 2)), np.ones((3, 5, 2))
    with pytest.raises(InputError, match="innovations must have shape"):
        whiteness_test(np.zeros((3, 5)), S)
    with pytest.raises(InputError, match="covariances S must have shape"):
        whiteness_test(nu, np.ones((3, 5, 3)))
    with pytest.raises(InputError, match="positive and finite"):
        whiteness_test(nu, 0 * S)
    with pytest.raises(InputError, match="NaN or inf in a valid channel"):
        whiteness_test(np.full((3, 5, 2), np.nan), S)
    with pytest.raises(InputError, match="valid must hold 0/1"):
        whiteness_test(nu, S, valid=np.full((3, 5, 2), 3.0))
    for lags in ([], [0], [5], [1.5]):
        with pytest.raises(ConfigurationError, match="lag"):
            whiteness_test(nu, S, lags=lags)
    with pytest.raises(InputError, match="no channel has a valid pair"):
        whiteness_test(nu, S, lags=[1], valid=np.zeros((3, 5, 2)))

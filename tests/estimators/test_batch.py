"""Batched filters equal single filters run one by one."""
import numpy as np
import pytest

from estimators import EKF, IAE, KF, MFIAE, UKF, BatchFilter


@pytest.mark.parametrize("cls,args", [(EKF, (0.2, 0.1)), (KF, (0.2, 0.1)), (UKF, (0.2, 0.1)),
                                      (MFIAE, (1e-3, 1e-3)), (IAE, (1e-3, 1e-3))])
def test_batch_equals_single_filters(cp, cls, args):
    rng = np.random.default_rng(1)
    n = 7
    x0 = rng.normal([0.5, 0, 1.8, 0.5], 0.1, (n, 4))
    kw = {"window": 5} if cls in (MFIAE, IAE) else {}
    batch = BatchFilter(cls(cp, x0[0], 1.0, *args, **kw), n, x0=x0)
    singles = [cls(cp, x0[r], 1.0, *args, **kw) for r in range(n)]
    ys = rng.normal([0.5, 1.8], 0.3, (40, n, 2))
    us = rng.normal(0, 0.5, (40, n, 1))
    for k in range(40):
        X = batch.step(us[k], ys[k])
        for r, f in enumerate(singles):
            f.step(us[k, r], ys[k, r])
            np.testing.assert_allclose(X[r], f.x, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(batch.P[3], singles[3].P, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(batch.R[2], singles[2].R, rtol=1e-12, atol=1e-14)


def test_batch_refusals(cp):
    with pytest.raises(TypeError, match="IAE cannot run batched"):
        BatchFilter(IAE(cp, [0.5, 0, 1.8, 0.5], 1.0, 0.1, 0.1, form="full"), 3)
    b = BatchFilter(EKF(cp, [0.5, 0, 1.8, 0.5], 1.0, 0.1, 0.1), 3)
    ys = np.ones((3, 2))
    ys[2, 1] = np.inf                     # (NaN would be a missing measurement)
    with pytest.raises(ValueError, match="realisation 2"):
        b.step(0.0, ys)
    with pytest.raises(ValueError, match=r"y have shape \(3, 2\)"):
        b.step(0.0, np.ones((2, 2)))
    assert b.k == 0 and np.all(np.isfinite(b.x))


def test_batch_marks_failed_realisations_and_goes_on(cp):
    b = BatchFilter(EKF(cp, [0.5, 0, 1.8, 0.5], 1.0, 0.1, 0.1), 3, on_failure="mark")
    b.step(0.0, np.ones((3, 2)))
    x_before = b.x
    ys = np.ones((3, 2))
    ys[1, 0] = np.inf
    X = b.step(0.0, ys)
    assert b.failed.tolist() == [False, True, False]
    np.testing.assert_array_equal(X[1], x_before[1])          # kept its previous state
    assert not np.array_equal(X[0], x_before[0])               # the others went on
    b.step(0.0, np.ones((3, 2)))
    assert b.failed.tolist() == [False, True, False] and np.all(np.isfinite(b.x))

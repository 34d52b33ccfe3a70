"""Behaviour of the estimators: adaptation, consistency, bias removal, bad input."""
import numpy as np
import pytest
from scipy import stats

from estimators import EKF, IAE, KF, MFIAE, UKF, augment_rate_bias, discretize, linear_model
from fmu_models import get_model


def simulate_linear(A, C, Q, R, n, rng, x0=None):
    x = np.zeros(A.shape[0]) if x0 is None else x0
    xs, ys = [], []
    for _ in range(n):
        x = A @ x + rng.multivariate_normal(np.zeros(len(x)), Q)
        xs.append(x)
        ys.append(C @ x + rng.multivariate_normal(np.zeros(C.shape[0]), R))
    return np.array(xs), np.array(ys)


A2 = np.array([[1.0, 0.1], [0.0, 0.95]])
C2 = np.array([[1.0, 0.0]])


def test_nees_and_nis_are_consistent_on_a_linear_gaussian_model():
    Q, R, P0 = np.diag([1e-3, 1e-2]), np.array([[0.05]]), np.diag([0.5, 0.5])
    sys_ = linear_model(A2, np.zeros((2, 1)), C2)
    rng = np.random.default_rng(42)
    M, N = 100, 100
    nees, nis = np.zeros((M, N)), np.zeros((M, N))
    for r in range(M):
        x0 = rng.multivariate_normal(np.zeros(2), P0)
        xs, ys = simulate_linear(A2, C2, Q, R, N, rng, x0)
        f = EKF(sys_, np.zeros(2), P0, Q, R)
        for k in range(N):
            f.step([0.0], ys[k])
            e = xs[k] - f.x
            nees[r, k] = e @ np.linalg.solve(f.P, e)
            nis[r, k] = f.nis
    for values, dof in ((nees, 2), (nis, 1)):
        lo, hi = stats.chi2.ppf([0.025, 0.975], M * dof) / M
        per_step = values.mean(axis=0)
        inside = np.mean((per_step > lo) & (per_step < hi))
        assert inside > 0.9, (dof, inside)                # 95 % expected
        assert abs(values.mean() / dof - 1) < 0.1


@pytest.mark.slow
def test_iae_recovers_true_r_from_a_wrong_start():
    Qt, Rt = np.diag([1e-4, 1e-3]), np.array([[0.5]])
    sys_ = linear_model(A2, np.zeros((2, 1)), C2)
    rng = np.random.default_rng(0)
    _, ys = simulate_linear(A2, C2, Qt, Rt, 8000, rng)
    f = IAE(sys_, [0, 0], 1.0, Qt, 5.0, window=400, adapt=("R",))
    f.run(np.zeros((8000, 1)), ys)
    r_est = f.noise_history()["R_y1"].iloc[-4000:].mean()
    assert abs(r_est / 0.5 - 1) < 0.10
    assert f.noise_history()["Q_x1"].iloc[-1] == pytest.approx(1e-4)   # Q not adapted


@pytest.mark.parametrize("form", ["diagonal", "scalar", "full"])
def test_iae_keeps_covariances_positive_definite(form):
    sys_ = linear_model(A2, np.zeros((2, 1)), C2)
    _, ys = simulate_linear(A2, C2, np.diag([1e-4, 1e-3]), np.array([[0.5]]), 300,
                            np.random.default_rng(1))
    f = IAE(sys_, [0, 0], 1.0, 1e-3, 0.1, window=10, form=form)
    for y in ys:
        f.step([0.0], y)
        assert np.all(np.linalg.eigvalsh(f.Q) > 0) and np.all(np.linalg.eigvalsh(f.R) > 0)
        assert np.allclose(f.Q, f.Q.T)


def cartpole_truth(q, r, n=500, seed=0):
    """Seed 000 truth: Euler map + N(0, q I) per step, y = [x, theta] + N(0, r I); PRBS F."""
    cp = discretize(get_model("cartpole"), 0.01)
    rng = np.random.default_rng(seed)
    us = np.where(np.arange(n) * 0.01 < 2.0, -0.5, 0.5)[:, None]
    x, xs, ys = np.array([0.5, 0, 1.8, 0.5]), [], []
    for k in range(n):
        x = cp.f(x, us[k]) + rng.normal(0, np.sqrt(q), 4)
        xs.append(x)
        ys.append(cp.h(x) + rng.normal(0, np.sqrt(r), 2))
    return cp, us, np.array(xs), np.array(ys)


def test_ekf_tracks_seed000_scenario1_better_than_raw_measurements():
    """Scenario 1 read as eqs 24-25: Q = 0.2 I (sigma_q^2), R = 0.1 I (sigma_r^2)."""
    err_f, err_y = [], []
    for seed in range(10):
        cp, us, xs, ys = cartpole_truth(0.2, 0.1, seed=seed)
        f = EKF(cp, [0.5, 0, 1.8, 0.5], np.eye(4), 0.2, 0.1)
        est = f.run(us, ys).x[1:]
        err_f.append(est[:, [0, 2]] - xs[:, [0, 2]])
        err_y.append(ys - xs[:, [0, 2]])
    rmse = lambda e: np.sqrt(np.mean(np.square(e)))   # noqa: E731
    assert rmse(err_f) < 0.9 * rmse(err_y)


def test_mfiae_moves_q_and_r_from_wrong_values_and_lowers_the_error():
    q_true, r_true, wrong = 1e-4, 1e-2, 1e-7
    rmse_m, rmse_e, qs, rs = [], [], [], []
    for seed in range(5):
        cp, us, xs, ys = cartpole_truth(q_true, r_true, n=1000, seed=seed)
        m = MFIAE(cp, [0.5, 0, 1.8, 0.5], np.eye(4) * 0.1, wrong, wrong, window=50, gain_q=0.02, gain_r=0.2,
                  q_mapping="gain", q_bounds=(1e-9, 1e6), r_bounds=(1e-9, 1e6))
        e = EKF(cp, [0.5, 0, 1.8, 0.5], np.eye(4) * 0.1, wrong, wrong)
        rmse_m.append(np.sqrt(np.mean((m.run(us, ys).x[1:] - xs)[200:] ** 2)))
        rmse_e.append(np.sqrt(np.mean((e.run(us, ys).x[1:] - xs)[200:] ** 2)))
        qs.append(m.Q[0, 0])
        rs.append(m.R[0, 0])
    assert np.mean(rmse_m) < 0.9 * np.mean(rmse_e)
    # both moved up from 1e-7 to within a factor 3 of the truth
    assert all(abs(np.log(q / q_true)) < np.log(3) for q in qs), qs
    assert all(abs(np.log(r / r_true)) < np.log(3) for r in rs), rs
    hist = m.noise_history()
    assert len(hist) == 1 + 1000 - m.window + 1         # initial row, then every adapted step
    assert hist["R_y_x"].iloc[0] == wrong and hist["R_y_x"].iloc[-1] == m.R[0, 0]


def test_bias_augmented_ekf_removes_the_gyro_offset():
    """Seed 002: the gyro reads alpha' + b; the augmented EKF estimates b and removes it."""
    iwp = discretize(get_model("iwp"), 0.01)
    aug = augment_rate_bias(iwp, "y_alpha_dot")
    rng = np.random.default_rng(5)
    b, n = 0.05, 2000
    x = np.array([np.pi + 0.3, 0.0, 0.0])                  # swinging about the hanging position
    xs, ys, us = [], [], []
    for k in range(n):
        u = [0.2 * np.sin(0.5 * k * 0.01)]
        x = iwp.f(x, u) + rng.normal(0, 1e-4, 3)
        xs.append(x)
        us.append(u)
        ys.append(iwp.h(x) + [0, b, 0] + rng.normal(0, [0.01, 0.02, 0.5]))
    xs, ys, us = map(np.array, (xs, ys, us))
    R = np.diag([1e-4, 4e-4, 0.25])
    plain = EKF(iwp, [np.pi + 0.3, 0, 0], np.eye(3) * 0.01, 1e-8, R).run(us, ys).x[1:]
    full = EKF(aug, [np.pi + 0.3, 0, 0, 0], np.diag([0.01, 0.01, 0.01, 0.01]),
               np.diag([1e-8, 1e-8, 1e-8, 1e-9]), R)
    est = full.run(us, ys).x[1:]
    assert est[-1, 3] == pytest.approx(b, rel=0.1)
    late = slice(n // 2, None)
    err_plain = np.sqrt(np.mean((plain[late, 1] - xs[late, 1]) ** 2))
    err_full = np.sqrt(np.mean((est[late, 1] - xs[late, 1]) ** 2))
    assert err_full < 0.5 * err_plain


@pytest.mark.parametrize("cls", [EKF, KF, UKF, IAE])
def test_bad_input_is_refused_and_state_kept(cp, cls):
    f = cls(cp, [0.5, 0, 1.8, 0.5], 1.0, 0.01, 0.1)
    f.step([0.1], [0.5, 1.8])
    x, P = f.x, f.P
    for u, y, msg in [([np.nan], [0.5, 1.8], "u contains NaN or inf"), ([0.1], [np.inf, 1.8], "y contains inf"),
                      ([0.1, 0.2], [0.5, 1.8], r"u must have shape \(1,\)"),
                      ([0.1], [0.5], r"y must have shape \(2,\)"),
                      ([0.1], 0.5, r"y must have shape \(2,\)")]:
        with pytest.raises(ValueError, match=msg):
            f.step(u, y)
        np.testing.assert_array_equal(f.x, x)
        np.testing.assert_array_equal(f.P, P)
    k = f.k
    f.step([0.1], None)                      # missing measurement: predict only
    assert f.k == k + 1 and np.trace(f.P) > np.trace(P)


def test_bad_covariances_are_refused(cp):
    x0 = [0.5, 0, 1.8, 0.5]
    with pytest.raises(ValueError, match="P0 is not positive definite"):
        EKF(cp, x0, np.diag([1, 1, 1, -1.0]), 0.1, 0.1)
    with pytest.raises(ValueError, match="Q is not symmetric"):
        EKF(cp, x0, 1.0, np.triu(np.ones((4, 4))), 0.1)
    with pytest.raises(ValueError, match=r"R must be a \(2, 2\) matrix"):
        EKF(cp, x0, 1.0, 0.1, np.eye(3))
    with pytest.raises(ValueError, match="R contains NaN"):
        EKF(cp, x0, 1.0, 0.1, [np.nan, 1])
    with pytest.raises(ValueError, match="x0 must have shape"):
        EKF(cp, [0, 0], 1.0, 0.1, 0.1)
    with pytest.raises(TypeError, match="DiscreteModel"):
        EKF(get_model("cartpole"), x0, 1.0, 0.1, 0.1)
    f = EKF(cp, x0, 1.0, 0.1, 0.1)
    with pytest.raises(ValueError, match="Q is not positive definite"):
        f.set_noise(Q=-np.eye(4))
    with pytest.raises(ValueError, match="alpha"):
        UKF(cp, x0, 1.0, 0.1, 0.1, alpha=0)
    with pytest.raises(ValueError, match="window"):
        IAE(cp, x0, 1.0, 0.1, 0.1, window=0)
    with pytest.raises(ValueError, match="gain_q"):
        MFIAE(cp, x0, 1.0, 0.1, 0.1, gain_q=2)
    with pytest.raises(ValueError, match="q0"):
        MFIAE(cp, x0, 1.0, -0.1, 0.1)


def test_divergence_raises_instead_of_returning_nan(cp):
    f = EKF(cp, [0.5, 0, 1.8, 0.5], 1e308, 1e308, 0.1)     # F P F^T + Q overflows
    with pytest.raises(FloatingPointError, match="non-finite"):
        for _ in range(5):
            f.step([0.0], [0.5, 1.8])
    assert np.all(np.isfinite(f.x))


def test_vm_backend_gives_the_same_numbers(cp):
    ys = np.random.default_rng(0).normal([0.5, 1.8], 0.1, (50, 2))
    a = MFIAE(cp, [0.5, 0, 1.8, 0.5], 1.0, 1e-3, 1e-2, window=5)
    b = MFIAE(cp, [0.5, 0, 1.8, 0.5], 1.0, 1e-3, 1e-2, window=5, backend="vm")
    np.testing.assert_allclose(a.run(np.zeros((50, 1)), ys).x, b.run(np.zeros((50, 1)), ys).x,
                               rtol=1e-12, atol=1e-12)
    assert a.backend == "compiled" and b.backend == "vm"

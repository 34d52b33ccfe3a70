"""Offline estimation (issue 15): native whole-record runs equal repeated steps; RTS
smoothers against pykalman, filterpy and a numpy reference; EM against pykalman and on
the cart-pole."""
import numpy as np
import pytest

from estimators import EKF, IAE, KF, MFIAE, UKF, em_noise, linear_model, rts_smooth

X0 = np.array([0.5, 0.0, 1.8, 0.5])


@pytest.fixture(scope="module")
def record(cp):
    rng = np.random.default_rng(11)
    N = 600
    us = np.where(np.arange(N) * 0.01 < 2.0, -0.5, 0.5)[:, None]
    x, xs, ys = X0.copy(), [], []
    for k in range(N):
        x = cp.f(x, us[k]) + rng.normal(0, np.sqrt(0.01), 4)
        xs.append(x)
        ys.append(cp.h(x) + rng.normal(0, np.sqrt(0.05), 2))
    return us, np.array(xs), np.array(ys)


FILTERS = {"KF": lambda cp: KF(cp, X0, 1.0, 0.01, 0.05, x_op=X0, u_op=[0.0]),
           "EKF": lambda cp: EKF(cp, X0, 1.0, 0.01, 0.05),
           "UKF": lambda cp: UKF(cp, X0, 1.0, 0.01, 0.05),
           "IAE": lambda cp: IAE(cp, X0, 1.0, 0.01, 0.05, window=15),
           "IAE full": lambda cp: IAE(cp, X0, 1.0, 0.01, 0.05, window=15, form="full"),
           "MF-IAE": lambda cp: MFIAE(cp, X0, 1.0, 0.01, 0.05),
           "EKF gated": lambda cp: EKF(cp, X0, 1.0, 0.01, 0.05, gate=6.0)}


@pytest.mark.parametrize("name", list(FILTERS))
@pytest.mark.parametrize("missing", [False, True])
def test_run_equals_repeated_step(cp, record, name, missing):
    us, _, ys = record
    ys = ys.copy()
    masks = None
    if missing:
        ys[[5, 40, 41, 300], 0] = np.nan                   # single channels
        ys[[100, 101, 102]] = np.nan                        # whole vectors: predictions only
        masks = np.ones_like(ys, dtype=bool)
        masks[200:210, 1] = False
    a, b = FILTERS[name](cp), FILTERS[name](cp)
    steps = np.array([a.step(us[k], ys[k], None if masks is None else masks[k]) for k in range(len(ys))])
    out = b.run(us, ys, masks)
    np.testing.assert_allclose(out.x[1:], steps, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out.P[-1], a.P, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.x, a.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.Q, a.Q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.R, a.R, rtol=0, atol=1e-12)
    assert b.k == a.k and len(b.noise_history()) == len(a.noise_history())
    assert np.isfinite(out.log_likelihood)
    df = out.to_frame()
    assert len(df) == len(ys) + 1 and "innovation_y_x" in df.columns
    if missing:
        assert not out.mask[5, 0] and out.mask[5, 1] and not out.mask[100].any()


def test_run_refuses_bad_records_and_keeps_the_state(cp, record):
    us, _, ys = record
    f = EKF(cp, X0, 1.0, 0.01, 0.05)
    x = f.x
    bad = ys.copy()
    bad[7, 1] = np.inf
    with pytest.raises(ValueError, match=r"y contains inf at index \[1\] at step 7"):
        f.run(us, bad)
    with pytest.raises(ValueError, match="us contains NaN or inf at index 3"):
        f.run(np.where(np.arange(len(us))[:, None] == 3, np.nan, us), ys)
    with pytest.raises(ValueError, match=r"ys of shape \(N, 2\)"):
        f.run(us, ys[:, :1])
    with pytest.raises(TypeError, match="must be numbers"):
        f.run(us, "abc")
    assert np.array_equal(f.x, x) and f.k == 0


def linear_problem(T=150, seed=0):
    rng = np.random.default_rng(seed)
    A = np.array([[1.0, 0.1], [-0.05, 0.95]])
    C = np.array([[1.0, 0.0], [0.5, 1.0]])
    Qt, Rt = np.array([[2e-3, 5e-4], [5e-4, 1e-2]]), np.diag([0.05, 0.02])
    x = rng.multivariate_normal(np.zeros(2), np.eye(2) * 0.5)
    Y = []
    for t in range(T):
        if t:
            x = A @ x + rng.multivariate_normal(np.zeros(2), Qt)
        Y.append(C @ x + rng.multivariate_normal(np.zeros(2), Rt))
    return A, C, Qt, Rt, np.array(Y)


def test_kf_rts_and_em_equal_pykalman():
    from pykalman import KalmanFilter

    A, C, Qt, Rt, Y = linear_problem()
    Y[[20, 21]] = np.nan                 # missing vectors (pykalman skips any partly masked one)
    Q0, R0, mu0, S0 = 3 * Qt, 0.3 * Rt, np.zeros(2), np.eye(2)
    ref = KalmanFilter(transition_matrices=A, observation_matrices=C, transition_covariance=Q0,
                       observation_covariance=R0, initial_state_mean=mu0, initial_state_covariance=S0)
    masked = np.ma.masked_invalid(Y)
    fm, fc = ref.filter(masked)
    sm, sc = ref.smooth(masked)
    sys_ = linear_model(A, np.zeros((2, 1)), C)
    us = np.zeros((len(Y) - 1, 1))
    f = KF(sys_, mu0, S0, Q0, R0)
    run = f.run(us, Y[1:], y0=Y[0])
    np.testing.assert_allclose(run.x, fm, rtol=0, atol=1e-8)
    np.testing.assert_allclose(run.P, fc, rtol=0, atol=1e-8)
    assert run.log_likelihood == pytest.approx(ref.loglikelihood(masked), rel=1e-10)
    smoothed = rts_smooth(f, run)
    np.testing.assert_allclose(smoothed.x, sm, rtol=0, atol=1e-8)
    np.testing.assert_allclose(smoothed.P, sc, rtol=0, atol=1e-8)
    # EM, 8 iterations, learning Q, R, x0 and P0, on the fully observed record
    A, C, Qt, Rt, Y = linear_problem(seed=1)
    ref = KalmanFilter(transition_matrices=A, observation_matrices=C, transition_covariance=Q0,
                       observation_covariance=R0, initial_state_mean=mu0, initial_state_covariance=S0,
                       em_vars=["transition_covariance", "observation_covariance", "initial_state_mean",
                                "initial_state_covariance"]).em(Y, n_iter=8)
    f = KF(linear_model(A, np.zeros((2, 1)), C), mu0, S0, Q0, R0)
    res = em_noise(f, us, Y[1:], y0=Y[0], n_iter=8, tol=1e-300, learn=("Q", "R", "x0", "P0"))
    assert res.iterations == 8 and not res.converged
    np.testing.assert_allclose(res.Q, ref.transition_covariance, rtol=0, atol=1e-8)
    np.testing.assert_allclose(res.R, ref.observation_covariance, rtol=0, atol=1e-8)
    np.testing.assert_allclose(res.x0, ref.initial_state_mean, rtol=0, atol=1e-8)
    np.testing.assert_allclose(res.P0, ref.initial_state_covariance, rtol=0, atol=1e-8)
    assert np.all(np.diff(res.log_likelihood) >= -1e-9)          # EM never decreases it (linear)
    np.testing.assert_allclose(f.Q, res.Q)                         # the filter holds the result


def test_extended_rts_equals_a_numpy_reference(cp, record):
    us, xs, ys = record
    f = EKF(cp, X0, 1.0, 0.01, 0.05)
    run = f.run(us, ys)
    sm = rts_smooth(f, run)
    x_s, P_s = run.x[-1].copy(), run.P[-1].copy()
    for k in range(len(ys) - 1, -1, -1):                 # the textbook recursion, in numpy
        F = cp.F(run.x[k], us[k])
        C = run.P[k] @ F.T @ np.linalg.inv(run.P_prior[k])
        x_s = run.x[k] + C @ (x_s - run.x_prior[k])
        P_s = run.P[k] + C @ (P_s - run.P_prior[k]) @ C.T
        np.testing.assert_allclose(sm.x[k], x_s, rtol=0, atol=1e-9)
        np.testing.assert_allclose(sm.P[k], P_s, rtol=0, atol=1e-9)
    err_f = np.sqrt(np.mean((run.x[1:] - xs) ** 2))
    err_s = np.sqrt(np.mean((sm.x[1:] - xs) ** 2))
    assert err_s < err_f                                  # smoothing helps
    assert sm.to_frame().shape == (len(ys) + 1, 8)


def test_unscented_rts_equals_a_reference_on_filterpy_sigma_points(cp, record):
    """The filter pass equals filterpy's UKF; the backward pass equals the unscented RTS
    recursion (Särkkä 2008) written here in numpy on filterpy's sigma points and weights
    (filterpy's own rts_smoother cannot pass the per-step input to fx)."""
    from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

    us, _, ys = record
    ys, us = ys[:200], us[:200]
    f = UKF(cp, X0, 1.0, 0.01, 0.05, alpha=0.5, beta=2.0, kappa=0.0)
    run = f.run(us, ys)
    sm = rts_smooth(f, run)
    pts = MerweScaledSigmaPoints(4, alpha=0.5, beta=2.0, kappa=0.0)
    ref = UnscentedKalmanFilter(4, 2, 0.01, hx=cp.h, fx=lambda x, dt, u: cp.f(x, [u]), points=pts)
    ref.x, ref.P, ref.Q, ref.R = X0.copy(), np.eye(4), 0.01 * np.eye(4), 0.05 * np.eye(2)
    Xs, Ps = [X0.copy()], [np.eye(4)]
    for y, u in zip(ys, us):
        ref.predict(u=u[0])
        ref.update(y)
        Xs.append(ref.x.copy())
        Ps.append(ref.P.copy())
    Xs, Ps = np.array(Xs), np.array(Ps)
    np.testing.assert_allclose(run.x, Xs, rtol=0, atol=1e-9)
    xs, P_s = Xs[-1].copy(), Ps[-1].copy()
    Wm, Wc = pts.Wm, pts.Wc
    for k in range(len(ys) - 1, -1, -1):
        sig = pts.sigma_points(Xs[k], Ps[k])
        fs = np.array([cp.f(s_, us[k]) for s_ in sig])
        m = Wm @ fs
        Pp = (fs - m).T @ np.diag(Wc) @ (fs - m) + 0.01 * np.eye(4)
        D = (sig - Xs[k]).T @ np.diag(Wc) @ (fs - m)
        G = D @ np.linalg.inv(Pp)
        xs = Xs[k] + G @ (xs - m)
        P_s = Ps[k] + G @ (P_s - Pp) @ G.T
        np.testing.assert_allclose(sm.x[k], xs, rtol=0, atol=1e-8)
        np.testing.assert_allclose(sm.P[k], P_s, rtol=0, atol=1e-8)


@pytest.mark.parametrize("kind", ["nonlinear", "linearised"])
@pytest.mark.parametrize("factor", [100.0, 0.01])
def test_em_recovers_q_and_r_of_a_cartpole_record(cp, kind, factor):
    """Hanging cart-pole, 10 000 steps, q = r = 1e-3 (scalar forms): EM from 100x wrong
    values lands within 10 % of both."""
    q, r, N = 1e-3, 1e-3, 10_000
    x0 = np.array([0.0, 0.0, np.pi, 0.0])
    model = cp if kind == "nonlinear" else cp.linearized(x0, [0.0])
    t = np.arange(N) * 0.01
    us = (0.5 * np.sin(0.7 * t) + 0.3 * np.sign(np.sin(2.3 * t)))[:, None]
    rng = np.random.default_rng(5)
    x, ys = x0.copy(), []
    for k in range(N):
        x = model.f(x, us[k]) + rng.normal(0, np.sqrt(q), 4)
        ys.append(model.h(x) + rng.normal(0, np.sqrt(r), 2))
    f = (EKF(cp, x0, 1e-2, q * factor, r * factor) if kind == "nonlinear"
         else KF(cp, x0, 1e-2, q * factor, r * factor, x_op=x0, u_op=[0.0]))
    res = em_noise(f, us, np.array(ys), n_iter=300, tol=1e-9, structure="scalar")
    assert res.Q[0, 0] == pytest.approx(q, rel=0.10) and res.R[0, 0] == pytest.approx(r, rel=0.10)
    np.testing.assert_allclose(res.Q, res.Q[0, 0] * np.eye(4))
    assert res.converged and np.all(np.diff(res.log_likelihood)[-20:] > -1e-6 * abs(res.log_likelihood[-1]))


def test_em_refusals(cp, record):
    us, _, ys = record
    with pytest.raises(TypeError, match="adapts Q and R itself"):
        em_noise(MFIAE(cp, X0, 1.0, 0.01, 0.05), us, ys)
    with pytest.raises(ValueError, match="structure must be one of"):
        em_noise(EKF(cp, X0, 1.0, 0.01, 0.05), us, ys, structure="banded")
    with pytest.raises(ValueError, match="learn must name"):
        em_noise(EKF(cp, X0, 1.0, 0.01, 0.05), us, ys, learn=("S",))


def test_run_keeping_the_estimates_only(cp, record):
    us, _, ys = record
    full = EKF(cp, X0, 1.0, 0.2, 0.1).run(us, ys)
    f = EKF(cp, X0, 1.0, 0.2, 0.1)
    lean = f.run(us, ys, keep="estimates")
    np.testing.assert_array_equal(lean.x, full.x)
    np.testing.assert_array_equal(lean.P, full.P)
    assert lean.log_likelihood == full.log_likelihood and np.array_equal(lean.nis, full.nis)
    assert lean.x_prior is None and lean.K is None
    np.testing.assert_array_equal(f.innovation, full.innovation[-1])      # the filter stands at the last step
    with pytest.raises(ValueError, match="keep='all'"):
        rts_smooth(f, lean)
    with pytest.raises(ValueError, match="keep must be one of"):
        f.run(us, ys, keep="some")

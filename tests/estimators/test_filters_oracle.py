"""KF, EKF and UKF give filterpy's estimates and covariances on the same model and data."""
import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter, KalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter

from estimators import EKF, KF, UKF, discretize
from fmu_models import get_model

N = 300
Q, R = np.diag([1e-4, 1e-3, 1e-4, 1e-3]), np.diag([0.01, 0.02])
P0 = np.diag([0.1, 0.2, 0.1, 0.3])


def cartpole_data(seed=0, x0=(0.5, 0, 1.8, 0.5)):
    """Euler truth with process and measurement noise; PRBS-like input."""
    sys_ = discretize(get_model("cartpole"), 0.01)
    rng = np.random.default_rng(seed)
    us = np.where(rng.random(N) < 0.5, -0.5, 0.5)[:, None]
    x = np.array(x0, float)
    ys = []
    for k in range(N):
        x = sys_.f(x, us[k]) + rng.multivariate_normal(np.zeros(4), Q)
        ys.append(sys_.h(x) + rng.multivariate_normal(np.zeros(2), R))
    return sys_, us, np.array(ys)


@pytest.fixture(scope="module")
def data():
    return cartpole_data()


def test_ekf_equals_filterpy(data):
    sys_, us, ys = data
    x0 = np.array([0.4, 0.0, 1.7, 0.4])
    ours = EKF(sys_, x0, P0, Q, R)

    class Oracle(ExtendedKalmanFilter):
        def predict_x(self, u=0):
            self.x = sys_.f(self.x.ravel(), u).reshape(-1, 1)

    ref = Oracle(dim_x=4, dim_z=2)
    ref.x, ref.P, ref.Q, ref.R = x0.reshape(-1, 1).copy(), P0.copy(), Q.copy(), R.copy()
    for k in range(N):
        ref.F = sys_.F(ref.x.ravel(), us[k])
        ref.predict(u=us[k])
        ref.update(ys[k].reshape(-1, 1), lambda x: sys_.H(x.ravel()),
                   lambda x: sys_.h(x.ravel()).reshape(-1, 1))
        ours.step(us[k], ys[k])
        np.testing.assert_allclose(ours.x, ref.x.ravel(), rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(ours.P, ref.P, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(ours.innovation, np.ravel(ref.y), rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(ours.S, ref.S, rtol=1e-10, atol=1e-12)


def test_kf_equals_filterpy(data):
    sys_, us, _ = data
    lin = sys_.linearized(np.zeros(4), np.zeros(1))
    F, G, H = lin.F(np.zeros(4), [0]), lin.G(np.zeros(4), [0]), lin.H(np.zeros(4))
    # data near the upright equilibrium, where the KF is meant to be used
    _, _, ys = cartpole_data(seed=1, x0=(0.0, 0.0, 0.05, 0.0))
    ours = KF(sys_, np.zeros(4), P0, Q, R)
    ref = KalmanFilter(dim_x=4, dim_z=2, dim_u=1)
    ref.F, ref.B, ref.H, ref.Q, ref.R, ref.P = F, G, H, Q.copy(), R.copy(), P0.copy()
    ref.x = np.zeros((4, 1))
    for k in range(N):
        ref.predict(u=us[k].reshape(1, 1))
        ref.update(ys[k].reshape(-1, 1))
        ours.step(us[k], ys[k])
        np.testing.assert_allclose(ours.x, ref.x.ravel(), rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(ours.P, ref.P, rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("alpha,beta,kappa", [(0.5, 2.0, 0.0), (1.0, 2.0, -1.0), (0.3, 0.0, 1.0)])
def test_ukf_equals_filterpy(data, alpha, beta, kappa):
    sys_, us, ys = data
    x0 = np.array([0.4, 0.0, 1.7, 0.4])
    ours = UKF(sys_, x0, P0, Q, R, alpha=alpha, beta=beta, kappa=kappa)
    points = MerweScaledSigmaPoints(4, alpha=alpha, beta=beta, kappa=kappa)
    ref = UnscentedKalmanFilter(dim_x=4, dim_z=2, dt=0.01, points=points,
                                fx=lambda x, dt, u: sys_.f(x, u), hx=sys_.h)
    ref.x, ref.P, ref.Q, ref.R = x0.copy(), P0.copy(), Q.copy(), R.copy()
    for k in range(N):
        ref.predict(u=us[k])
        ref.update(ys[k])
        ours.step(us[k], ys[k])
        np.testing.assert_allclose(ours.x, ref.x, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(ours.P, ref.P, rtol=1e-9, atol=1e-12)


def test_predict_then_update_equals_fused_step(data):
    sys_, us, ys = data
    for cls in (EKF, KF):
        a = cls(sys_, [0.4, 0, 1.7, 0.4], P0, Q, R)
        b = cls(sys_, [0.4, 0, 1.7, 0.4], P0, Q, R)
        for k in range(50):
            a.step(us[k], ys[k])
            b.predict(us[k])
            b.update(ys[k])
            np.testing.assert_allclose(a.x, b.x, rtol=1e-13, atol=1e-14)
            np.testing.assert_allclose(a.P, b.P, rtol=1e-12, atol=1e-15)

"""The posterior Cramér-Rao bound: the Kalman covariance on linear models (1e-10), an
independent numpy implementation of the printed recursion on the cart-pole (Jacobians by
complex steps of the sympy-derived model), missing measurements, small Q, the EKF given the
true noise against it, and hostile inputs refused by name."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from testkit.oracles import cartpole_lagrange, complex_step_jacobian
from testkit.pcrb_oracle import pcrb_literal

from estimators import EKF, KF, PCRB, DiscreteModel, linear_model, posterior_crb, rmse_ratio
from fmu_models import get_model
from fmu_models.errors import ConfigurationError, InputError, NumericalError, ResourceError, TypeMismatchError
from fmu_models.infra import memory

A = np.array([[1.0, 0.1, 0.0], [0.0, 0.95, 0.1], [0.02, 0.0, 0.9]])
B = np.array([[0.0], [0.1], [0.05]])
C = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
Q_FULL = np.array([[0.04, 0.01, 0.0], [0.01, 0.09, 0.02], [0.0, 0.02, 0.05]])
R_FULL = np.array([[0.25, 0.05], [0.05, 0.1]])
P0_FULL = np.array([[2.0, 0.3, 0.0], [0.3, 1.0, 0.1], [0.0, 0.1, 0.5]])


@pytest.fixture(scope="module")
def lin():
    return linear_model(A, B, C, 0.1)


def _kf_covariances(lin, P0, Q, R, n, masks=None):
    f = KF(lin, np.zeros(3), P0, Q, R, x_op=np.zeros(3))
    return f.run(np.zeros((n, 1)), np.zeros((n, 2)), masks).P


def _relative(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


@pytest.mark.parametrize("scale", [1.0, 1e-6, 1e-12])
def test_equals_the_kalman_covariance_on_a_linear_model(lin, scale):
    """Any trajectories (the Jacobians are constant), full Q, R and P0; Q down to 1e-12 of
    P0 (the regime where the printed recursion subtracts two nearly equal matrices)."""
    X = np.random.default_rng(0).normal(size=(4, 201, 3))
    Q = scale * Q_FULL
    bound = posterior_crb(lin, X, np.zeros((200, 1)), Q, R_FULL, P0_FULL)
    assert isinstance(bound, PCRB) and len(bound) == 200 and bound.runs == 4 and not bound.known_initial_state
    assert _relative(bound.P, _kf_covariances(lin, P0_FULL, Q, R_FULL, 200)) < 1e-10
    np.testing.assert_allclose(bound.rmse ** 2, bound.mse)


def test_known_initial_state_is_the_kalman_filter_from_its_first_update(lin):
    X = np.random.default_rng(1).normal(size=(2, 51, 3))
    bound = posterior_crb(lin, X, np.zeros((50, 1)), Q_FULL, R_FULL)
    assert bound.known_initial_state and not bound.P[0].any()
    # first step: the prediction's covariance is Q
    Qi, Ri = np.linalg.inv(Q_FULL), np.linalg.inv(R_FULL)
    np.testing.assert_allclose(bound.P[1], np.linalg.inv(Qi + C.T @ Ri @ C), rtol=1e-12)
    # then the Kalman filter started there
    f = KF(lin, np.zeros(3), bound.P[1], Q_FULL, R_FULL, x_op=np.zeros(3))
    assert _relative(bound.P[1:], f.run(np.zeros((49, 1)), np.zeros((49, 2))).P) < 1e-10


def test_missing_channels_carry_no_information(lin):
    """The same missing pattern in every run: the Kalman filter with those masks; NaN
    measurements are the same as masks; a pattern that varies over runs averages the
    information (the numpy oracle)."""
    rng = np.random.default_rng(2)
    n, runs = 80, 3
    X = rng.normal(size=(runs, n + 1, 3))
    mask = rng.random((n, 2)) > 0.4
    mask[10] = False                                    # a step with no measurement at all
    bound = posterior_crb(lin, X, np.zeros((n, 1)), Q_FULL, R_FULL, P0_FULL, masks=np.broadcast_to(mask, (runs, n, 2)))
    assert _relative(bound.P, _kf_covariances(lin, P0_FULL, Q_FULL, R_FULL, n, mask)) < 1e-10
    ys = np.where(mask, 0.3, np.nan)[None].repeat(runs, axis=0)
    np.testing.assert_allclose(posterior_crb(lin, X, np.zeros((n, 1)), Q_FULL, R_FULL, P0_FULL, ys=ys).P, bound.P,
                               rtol=1e-13, atol=0)
    varying = rng.random((runs, n, 2)) > 0.3
    got = posterior_crb(lin, X, np.zeros((n, 1)), Q_FULL, R_FULL, P0_FULL, masks=varying)
    ref = pcrb_literal(lambda x, u: A, lambda x: C, X, np.zeros((n, 1)), Q_FULL, R_FULL, P0_FULL, varying)
    assert _relative(got.P, ref) < 1e-10
    # masks and NaN together: a channel is used only if both say so
    both = posterior_crb(lin, X, np.zeros((n, 1)), Q_FULL, R_FULL, P0_FULL, masks=varying, ys=ys)
    ref = pcrb_literal(lambda x, u: A, lambda x: C, X, np.zeros((n, 1)), Q_FULL, R_FULL, P0_FULL,
                       varying & mask[None])
    assert _relative(both.P, ref) < 1e-10


@pytest.fixture(scope="module")
def cartpole_truth(cp):
    """10 realisations of 50 steps of the seed 000 truth (q = 0.2, r = 0.1, PRBS-like input)."""
    rng = np.random.default_rng(3)
    runs, n = 10, 50
    us = np.where((np.arange(n) // 20) % 2, 0.5, -0.5)[:, None]
    X = np.empty((runs, n + 1, 4))
    X[:, 0] = [0.5, 0.0, 1.8, 0.5]
    for k in range(n):
        for r in range(runs):
            X[r, k + 1] = cp.f(X[r, k], us[k]) + rng.normal(0, np.sqrt(0.2), 4)
    return X, us


@pytest.mark.slow
def test_equals_an_independent_numpy_implementation_on_the_cartpole(cp, cartpole_truth):
    """Jacobians of the Euler map from complex steps of the Lagrange derivation, the
    recursion as printed with explicit inverses, plain means; with and without missing
    channels, full noise covariances."""
    f, _ = cartpole_lagrange()
    p = tuple(get_model("cartpole").p)
    T = cp.dt

    seen = {}

    def jac_f(x, u):                      # both oracle runs below visit the same points
        key = (x.tobytes(), u.tobytes())
        if key not in seen:
            seen[key] = np.eye(4) + T * complex_step_jacobian(lambda z: f(z, u, p), x)
        return seen[key]

    def jac_h(x):
        return np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])

    X, us = cartpole_truth
    Q = 0.2 * np.eye(4) + 0.02 * (np.ones((4, 4)) - np.eye(4))
    R = np.array([[0.1, 0.02], [0.02, 0.15]])
    got = posterior_crb(cp, X, us, Q, R, 1.0)
    ref = pcrb_literal(jac_f, jac_h, X, us, Q, R, np.eye(4))
    assert _relative(got.P, ref) < 1e-10
    valid = np.random.default_rng(4).random((len(X), len(us), 2)) > 0.25
    got = posterior_crb(cp, X, us, Q, R, 1.0, masks=valid)
    assert _relative(got.P, pcrb_literal(jac_f, jac_h, X, us, Q, R, np.eye(4), valid)) < 1e-10
    # the nonlinearity matters: the bound is not the Kalman covariance along the mean Jacobian
    assert _relative(got.P, posterior_crb(cp, X[:1], us, Q, R, 1.0, masks=valid[:1]).P) > 1e-4


def test_jacobians_in_chunks_give_the_same_bound(cp, cartpole_truth, monkeypatch):
    import estimators.pcrb as mod

    X, us = cartpole_truth
    whole = posterior_crb(cp, X, us, 0.2, 0.1, 1.0)
    monkeypatch.setattr(mod, "PCRB_CHUNK", 7)
    np.testing.assert_allclose(posterior_crb(cp, X, us, 0.2, 0.1, 1.0).P, whole.P, rtol=1e-13, atol=0)


def test_the_ekf_given_the_true_noise_is_not_below_the_bound(cp):
    """40 realisations of 150 steps of the seed 000 truth: the EKF with the true Q and R
    sits at 1.00-1.10 x the PCRB per state, and per step never far below it."""
    rng = np.random.default_rng(5)
    runs, n, q, r = 40, 150, 0.2, 0.1
    us = np.where((np.arange(n) // 50) % 2, 0.5, -0.5)[:, None]
    X = np.empty((runs, n + 1, 4))
    X[:, 0] = [0.5, 0.0, 1.8, 0.5]
    for k in range(n):
        for j in range(runs):
            X[j, k + 1] = cp.f(X[j, k], us[k]) + rng.normal(0, np.sqrt(q), 4)
    Y = X[:, 1:, [0, 2]] + rng.normal(0, np.sqrt(r), (runs, n, 2))
    bound = posterior_crb(cp, X, us, q, r)                     # the truth starts at a known state
    err = np.stack([EKF(cp, X[0, 0], 1e-6, q, r).run(us, Y[j]).x for j in range(runs)]) - X
    ratio = rmse_ratio(err, bound)
    assert ((ratio > 0.97) & (ratio < 1.10)).all(), ratio
    assert np.allclose(rmse_ratio(err[:, 1:], bound), ratio)
    per_step = np.sqrt(np.mean(err[:, 1:] ** 2, axis=0) / bound.mse[1:])
    assert per_step.min() > 0.6                                # 40 runs: the MSE's own scatter


def test_hostile_inputs_are_refused_by_name(lin, monkeypatch):
    X = np.zeros((2, 11, 3))
    us = np.zeros((10, 1))
    ok = {"Q": 0.1, "R": 0.1, "P0": 1.0}

    def call(X=X, us=us, **kw):
        return posterior_crb(lin, X, us, **{**ok, **kw})

    with pytest.raises(TypeMismatchError, match="DiscreteModel"):
        posterior_crb("cartpole", X, us, 0.1, 0.1)
    for name in ("Q", "R", "P0"):
        for bad in (-1.0, 0.0, np.nan, np.inf, [[1.0, 2.0], [2.0, 1.0]]):
            with pytest.raises(ConfigurationError, match=f"PCRB: {name}"):
                call(**{name: bad})
    with pytest.raises(ConfigurationError, match="not positive definite"):
        call(Q=np.diag([1.0, -1e-9, 1.0]))
    with pytest.raises(ConfigurationError, match="not symmetric"):
        call(R=[[1.0, 0.5], [0.0, 1.0]])
    with pytest.raises(ConfigurationError, match="None for a known initial state"):
        call(P0=0.0)
    with pytest.raises(TypeMismatchError, match="true trajectories X"):
        call(X="x")
    for bad, what in ((np.zeros((0, 11, 3)), "no realisation"), (np.zeros((2, 1, 3)), "at least two steps"),
                      (np.zeros((2, 11, 4)), r"shape \(runs, N \+ 1, 3\)"), (np.zeros((11, 3)), "shape")):
        with pytest.raises(InputError, match=what):
            call(X=bad)
    nan = X.copy()
    nan[1, 4, 2] = np.nan
    with pytest.raises(InputError, match="realisation 1, step 4, state 2"):
        call(X=nan)
    with pytest.raises(InputError, match="inputs us must have shape"):
        call(us=np.zeros((9, 1)))
    with pytest.raises(InputError, match="inputs us contain NaN"):
        call(us=np.full((10, 1), np.inf))
    with pytest.raises(InputError, match="masks must hold 0/1"):
        call(masks=np.full((2, 10, 2), 2.0))
    with pytest.raises(InputError, match="masks must have shape"):
        call(masks=np.ones((2, 9, 2)))
    with pytest.raises(InputError, match="ys must have shape"):
        call(ys=np.ones((2, 10, 3)))
    with pytest.raises(InputError, match="inf"):
        call(ys=np.full((2, 10, 2), np.inf))
    monkeypatch.setattr(memory, "available_memory", lambda: 1000)
    with pytest.raises(ResourceError, match="PCRB over 2 realisations"):
        call()


def test_non_finite_jacobians_and_lost_definiteness_raise_numerical_errors():
    x, u = ca.SX.sym("x", 1), ca.SX.sym("u", 1)
    root = DiscreteModel(x, u, ca.sqrt(x) + u, x, 1.0, ["x"], ["u"], ["y"])
    X = np.ones((2, 4, 1))
    X[1, 2, 0] = 0.0                                      # d sqrt(x)/dx is inf at 0
    with pytest.raises(NumericalError, match="Jacobian.*realisation 1 at step 2"):
        posterior_crb(root, X, np.zeros((3, 1)), 0.1, 0.1, 1.0)
    huge = DiscreteModel(x, u, 1e200 * x, x, 1.0, ["x"], ["u"], ["y"])
    with pytest.raises(NumericalError, match="PCRB: .* at step"):
        posterior_crb(huge, np.ones((1, 4, 1)), np.zeros((3, 1)), 1e-300, 1e-300, 1e-300)


def test_rmse_ratio_refuses_what_it_cannot_compare(lin):
    bound = posterior_crb(lin, np.zeros((2, 11, 3)), np.zeros((10, 1)), 0.1, 0.1)
    with pytest.raises(TypeMismatchError, match="PCRB"):
        rmse_ratio(np.zeros((2, 11, 3)), "bound")
    with pytest.raises(InputError, match="errors err must have shape"):
        rmse_ratio(np.zeros((2, 9, 3)), bound)
    with pytest.raises(InputError, match="bound is zero"):
        rmse_ratio(np.zeros((2, 11, 3)), bound, steps=slice(0, 1))
    np.testing.assert_allclose(rmse_ratio(np.ones((2, 11, 3)), bound), 1 / np.sqrt(bound.mse[1:].mean(axis=0)))

"""The wheel pendulum's sensor chain: analytic outputs, fusion convergence, refusals, and
the seed 002 experiment through it."""
import numpy as np
import pytest

from cosim.components.imu import Accelerometer, Encoder, Gyroscope, TiltFusion


def test_accelerometer_matches_the_analytic_specific_force():
    acc = Accelerometer("acc", 0.01, r=0.08)
    acc.reset(0.0)
    for alpha in (0.0, 0.3, -1.2, np.pi):           # at rest: tilt only
        a_t, a_r, a_z = acc.sample(0.0, [alpha, 0.0, 0.0])
        assert a_t == pytest.approx(-9.81 * np.sin(alpha)) and a_r == pytest.approx(9.81 * np.cos(alpha))
        assert np.arctan2(-a_t, a_r) == pytest.approx(np.arctan2(np.sin(alpha), np.cos(alpha)))
        assert a_z == 0
    # spinning at constant rate: centripetal term; accelerating: tangential term
    a_t, a_r, _ = acc.sample(0.0, [0.0, 3.0, 2.0])
    assert a_r == pytest.approx(9.81 - 0.08 * 9.0) and a_t == pytest.approx(0.08 * 2.0)


def test_gyroscope_rate_offset_and_drift():
    g = Gyroscope("g", 0.01, bias=0.05)
    g.reset(0.0)
    assert g.sample(0.0, [1.5])[0] == pytest.approx(1.55)
    d = Gyroscope("d", 0.01, drift_std=0.1, seed=4)
    d.reset(0.0)
    out = np.array([d.sample(k * 0.01, [0.0])[0] for k in range(10000)])
    # random-walk offset: variance grows as drift_std^2 t (100 s -> std 1 rad/s)
    assert 0.05 < np.abs(out[-1]) < 5 and np.all(np.diff(out) != 0)


def test_encoder_counts_at_constant_spin():
    e = Encoder("e", 0.01, counts_per_rev=1000)
    e.reset(0.0)
    speed = 2 * np.pi * 5.0                 # 5 rev/s: 50 counts per 10 ms exactly
    out = [e.sample(k * 0.01, [speed])[0] for k in range(20)]
    assert out[0] == 0.0
    np.testing.assert_allclose(out[1:], speed, rtol=1e-9)
    q = Encoder("q", 0.01, counts_per_rev=100, offset=0.2)
    q.reset(0.0)
    out = np.array([q.sample(k * 0.01, [1.0])[0] for k in range(500)])
    step = 2 * np.pi / (100 * 0.01)         # resolution: 6.28 rad/s per count
    levels = np.unique(np.round(out - 0.2, 9))
    assert set(np.round(levels / step, 6)) <= {0.0, 1.0}
    assert np.mean(out[1:] - 0.2) == pytest.approx(1.0, rel=0.05)   # counts average the speed


def test_fusion_converges_to_the_tilt_and_the_gyro_offset_at_rest():
    f = TiltFusion("f", 0.01)
    f.reset(0.0)
    acc = Accelerometer("acc", 0.01, r=0.05, noise_std=0.05, seed=1)
    gyro = Gyroscope("g", 0.01, noise_std=0.01, bias=0.05, seed=2)
    acc.reset(0.0)
    gyro.reset(0.0)
    for k in range(3000):
        a = acc.sample(k * 0.01, [0.2, 0.0, 0.0])
        w = gyro.sample(k * 0.01, [0.0])
        alpha, rate, bias = f.sample(k * 0.01, [a[0], a[1], w[0]])
    assert alpha == pytest.approx(0.2, abs=2e-3)
    assert bias == pytest.approx(0.05, abs=5e-3)
    assert rate == pytest.approx(0.05, abs=0.05)            # raw rate goes on with its offset


def test_bad_sensor_parameters_are_refused():
    with pytest.raises(ValueError, match="counts_per_rev must be an integer >= 1"):
        Encoder("e", 0.01, counts_per_rev=-5)
    with pytest.raises(ValueError, match="sample period must be a positive"):
        Encoder("e", 0.0, counts_per_rev=100)
    with pytest.raises(ValueError, match="r must be a distance"):
        Accelerometer("a", 0.01, r=-1)
    with pytest.raises(ValueError, match="noise_std must be >= 0"):
        Gyroscope("g", 0.01, noise_std=-0.1)
    with pytest.raises(ValueError, match="not positive definite"):
        TiltFusion("f", 0.01, r_tilt=-1.0)


def test_seed002_through_the_chain_fast_equals_master_and_ekf_removes_the_offset():
    from cosim.experiments import seed002

    s = seed002.Settings(runs=1, duration=10.0)
    case = "Q = R = 0.01"
    fast = seed002.realisations(case, s, [0], "fast")[0]
    master = seed002.realisations(case, s, [0], "master")[0]
    for key in ("RMSE EKF alpha", "RMSE EKF alpha_dot", "RMSE EKF phi_dot", "bias estimate"):
        assert fast[key] == pytest.approx(master[key], rel=1e-9, abs=1e-12)
    assert fast["balanced"]
    assert fast["RMSE EKF alpha_dot"] < 0.6 * fast["RMSE fed alpha_dot"]     # offset removed
    assert fast["RMSE EKF phi_dot"] < 0.8 * fast["RMSE fed phi_dot"]         # encoder noise removed

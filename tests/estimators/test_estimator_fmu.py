"""Estimators as native FMUs (issue 13): equal to the Python filters through fmpy, valid,
refusing bad parameters, bit-identical state save/restore, and in the master."""
import re

import numpy as np
import pytest
from fmpy.validation import validate_fmu
from testkit.fmu_helpers import Instance

from cosim.components.estimation import EstimatorComponent
from cosim.components.sensors import ProcessNoise, Sensor
from cosim.components.sources import PRBS
from cosim.core.master import Cosimulation
from cosim.fmi.fmu_component import FMUComponent
from estimators import EKF, IAE, KF, MFIAE, UKF, augment_rate_bias, discretize
from estimators.filter_fmu import export_filter_fmu
from fmu_models import get_model

X0 = [0.5, 0.0, 1.8, 0.5]


@pytest.fixture(scope="module")
def seed000_record(cp):
    """500 steps of seed 000 scenario 1 (eqs reading), one realisation."""
    rng = np.random.default_rng(7)
    us = np.where(np.arange(501) * 0.01 < 2.0, -0.5, 0.5)
    x, ys = np.array(X0), [np.full(2, np.nan)]
    for k in range(500):
        x = cp.f(x, [us[k]]) + rng.normal(0, np.sqrt(0.2), 4)
        ys.append(cp.h(x) + rng.normal(0, np.sqrt(0.1), 2))
    ys = np.array(ys)
    ys[[37, 210], 1] = np.nan                      # two missing channels on the way
    return us, ys


FILTERS = {"KF": lambda cp: KF(cp, X0, 1.0, 0.2, 0.1, x_op=X0, u_op=[0.0]),
           "EKF": lambda cp: EKF(cp, X0, 1.0, 0.2, 0.1),
           "UKF": lambda cp: UKF(cp, X0, 1.0, 0.2, 0.1),
           "IAE": lambda cp: IAE(cp, X0, 1.0, 1e-3, 10.0),
           "MF-IAE": lambda cp: MFIAE(cp, X0, 1.0, 1e-3, 10.0),
           "EKF gated": lambda cp: EKF(cp, X0, 1.0, 0.2, 0.1, gate=9.0)}


def run_fmu(path, us, ys, state_names, output_names, input_name, kind="cs"):
    inst = Instance(str(path), kind=kind)
    inst.init()
    est = [inst.get(*state_names)]
    for k in range(1, len(ys)):
        step_filter(inst, (k - 1) * 0.01, us[k - 1], dict(zip(output_names, ys[k])), input_name)
        est.append(inst.get(*state_names))
    inst.free()
    return np.array(est)


def step_filter(inst, t, u, y, input_name="F"):
    """One filter step: the input held over [t, t + h], then the measurement at t + h."""
    inst.set(input_name, u)
    inst.do_step(t, 0.01)
    for n, v in y.items():
        inst.set(n, v)


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("name", list(FILTERS))
def test_estimator_fmu_equals_the_python_filter(cp, seed000_record, tmp_path, name, version):
    us, ys = seed000_record
    ref_filter, exported = FILTERS[name](cp), FILTERS[name](cp)
    ref = [ref_filter.x] + [ref_filter.step([us[k - 1]], ys[k]) for k in range(1, len(ys))]
    path = export_filter_fmu(exported, tmp_path, fmi_version=version)
    assert validate_fmu(str(path)) == []
    got = run_fmu(path, us, ys, cp.state_names, cp.output_names, "F")
    np.testing.assert_allclose(got, np.array(ref), rtol=0, atol=1e-12)


def test_bias_augmented_wheel_pendulum_ekf_as_fmu(tmp_path):
    iwp = augment_rate_bias(discretize(get_model("iwp"), 0.01), "y_alpha_dot")
    f = EKF(iwp, [0.1, 0, 0, 0], 0.01, [1e-6, 1e-4, 1e-2, 1e-8], [2.5e-5, 4e-4, 0.25])
    path = export_filter_fmu(f, tmp_path, fmi_version=3)
    rng = np.random.default_rng(3)
    ys = np.vstack([np.full(3, np.nan), np.array([0.1, 0.05, 0.0]) + rng.normal(0, 0.01, (300, 3))])
    us = np.zeros(301)
    ref_f = EKF(iwp, [0.1, 0, 0, 0], 0.01, [1e-6, 1e-4, 1e-2, 1e-8], [2.5e-5, 4e-4, 0.25])
    ref = [ref_f.x] + [ref_f.step([us[k - 1]], ys[k]) for k in range(1, len(ys))]
    got = run_fmu(path, us, ys, iwp.state_names, iwp.output_names, "i")
    np.testing.assert_allclose(got, np.array(ref), rtol=0, atol=1e-12)


def test_bad_parameters_steps_and_inputs_are_refused_with_a_message(cp, tmp_path):
    path = export_filter_fmu(MFIAE(cp, X0, 1.0, 1e-3, 10.0), tmp_path, fmi_version=2)
    for params, msg in (({"P0_x": -1.0}, "P0_x = -1 must be > 0"), ({"gain_q": 2.0}, r"gain_q = 2 must be in \(0, 1\]"),
                        ({"q_min": 5.0, "q_max": 1.0}, "q_min = 5 must be below q_max = 1")):
        inst = Instance(str(path))
        with pytest.raises(Exception):
            for k, v in params.items():
                inst.fmu.setReal([inst.vr[k]], [v])
            inst.init()
        assert any(re.search(msg, m) for _, m in inst.messages), inst.messages
        inst.free()
    inst = Instance(str(path))
    inst.init()
    with pytest.raises(Exception):
        inst.do_step(0.0, 1e6)
    assert any("holds 1e+08 filter updates of 0.01 s, more than the limit" in m for _, m in inst.messages)
    inst.fmu.reset()                               # after an Error: reset before going on
    with pytest.raises(Exception):
        inst.set("F", np.inf)
    assert any("F: value inf is not finite" in m for _, m in inst.messages)
    inst.free()


def test_estimator_fmu_state_save_restore_is_bit_identical(cp, seed000_record, tmp_path):
    us, ys = seed000_record
    path = export_filter_fmu(MFIAE(cp, X0, 1.0, 1e-3, 10.0), tmp_path, fmi_version=2)
    inst = Instance(str(path))
    inst.init()
    names = cp.state_names
    for k in range(1, 200):
        step_filter(inst, (k - 1) * 0.01, us[k - 1], dict(zip(cp.output_names, ys[k])))
    inst.get(*names)
    state = inst.fmu.getFMUstate()
    blob = inst.fmu.serializeFMUstate(state)
    a = []
    for k in range(200, 300):
        step_filter(inst, (k - 1) * 0.01, us[k - 1], dict(zip(cp.output_names, ys[k])))
        a.append(inst.get(*names, "Q_x", "R_y_x"))
    restored = inst.fmu.deSerializeFMUstate(blob)
    inst.fmu.setFMUstate(restored)
    b = []
    for k in range(200, 300):
        step_filter(inst, (k - 1) * 0.01, us[k - 1], dict(zip(cp.output_names, ys[k])))
        b.append(inst.get(*names, "Q_x", "R_y_x"))
    assert np.array_equal(np.array(a), np.array(b))
    inst.free()


def test_the_master_runs_an_estimator_fmu_exactly_like_the_python_component(cp, fmu_paths, tmp_path):
    def parts(estimator):
        model = get_model("cartpole")
        plant = FMUComponent("plant", fmu_paths["cartpole"], 0.01, start=dict(zip(model.state_names, X0)))
        return [estimator, plant, Sensor("sensor", 0.01, ["x", "theta"], noise_std=0.3, seed=2),
                PRBS("force", 0.01, 0.5, 1.0, 7, 28), ProcessNoise("noise", 0.01, model.state_names, 0.2, seed=1)]

    wiring = {"plant.F": "force.out", "sensor.x": "plant.x", "sensor.theta": "plant.theta",
              "ekf.F": "force.out", "ekf.y_x": "sensor.y_x", "ekf.y_theta": "sensor.y_theta",
              **{f"plant.w_{s}": f"noise.w_{s}" for s in ("x", "x_dot", "theta", "theta_dot")}}
    py = Cosimulation(parts(EstimatorComponent("ekf", lambda: MFIAE(cp, X0, 1.0, 1e-3, 10.0))), wiring).run(5.0)
    path = export_filter_fmu(MFIAE(cp, X0, 1.0, 1e-3, 10.0), tmp_path, fmi_version=3)
    fmu = FMUComponent("ekf", path, 0.01, inputs=["F", "y_x", "y_theta"])
    assert fmu.feedthrough["x"] == frozenset({"y_x", "y_theta"})      # from the ModelStructure
    native = Cosimulation(parts(fmu), wiring).run(5.0)
    cols = [f"ekf.{s}" for s in cp.state_names]
    np.testing.assert_allclose(native[cols].to_numpy(), py[cols].to_numpy(), rtol=0, atol=1e-12)


def test_export_refusals(cp, tmp_path):
    with pytest.raises(TypeError, match="cannot be exported"):
        export_filter_fmu(IAE(cp, X0, 1.0, 0.1, 0.1, form="full"), tmp_path)
    with pytest.raises(ValueError, match="diagonal Q"):
        export_filter_fmu(EKF(cp, X0, 1.0, np.full((4, 4), 0.01) + np.eye(4) * 0.1, 0.1), tmp_path)
    with pytest.raises(TypeError, match="needs a filter"):
        export_filter_fmu("EKF", tmp_path)


STEP_PATTERNS = {"T/4": [0.0025], "T/2": [0.005], "T": [0.01], "2T": [0.02], "3T": [0.03],
                 "mixed": [0.015, 0.005, 0.0025, 0.0075, 0.02, 0.01, 0.03]}


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("pattern", list(STEP_PATTERNS))
def test_estimator_fmu_updates_at_its_own_instants_for_any_communication_step(cp, tmp_path, pattern, version):
    """Issue 19: with any communication step the FMU performs the update of every instant
    t_k = k T, predicting with the input set at the last communication point at or before
    t_(k-1) and updating with the measurement set at the last one at or before t_k; at a
    communication point on an instant the output already shows that instant's update."""
    rng = np.random.default_rng(3)
    fine = 0.0025                                  # every communication point lies on this grid
    n_fine = 481
    u_fine = rng.uniform(-1, 1, n_fine)
    y_fine = cp.h(np.array(X0))[None, :] + rng.normal(0, 0.3, (n_fine, 2))
    points, t, i = [0.0], 0.0, 0
    while t < 1.15:
        t = round(t + STEP_PATTERNS[pattern][i % len(STEP_PATTERNS[pattern])], 10)
        points.append(t)
        i += 1
    path = export_filter_fmu(EKF(cp, X0, 1.0, 0.2, 0.1), tmp_path, fmi_version=version)
    assert validate_fmu(str(path)) == []
    inst = Instance(str(path)).init()
    ref, est = EKF(cp, X0, 1.0, 0.2, 0.1), {0: np.array(X0, float)}

    def set_before(t_k):                           # the last communication point at or before t_k
        return round(max(p for p in points if p <= t_k + 1e-9) / fine)

    try:
        for n, t in enumerate(points[:-1]):
            j = round(t / fine)
            inst.set("y_x", y_fine[j, 0])
            inst.set("y_theta", y_fine[j, 1])
            got = inst.get(*cp.state_names)
            k_latest = int(np.floor(t / 0.01 + 1e-6))
            while max(est) < k_latest:
                k = max(est) + 1
                est[k] = ref.step([u_fine[set_before((k - 1) * 0.01)]], y_fine[set_before(k * 0.01)])
            np.testing.assert_allclose(got, est[k_latest], rtol=0, atol=1e-12, err_msg=f"t = {t}")
            inst.set("F", u_fine[j])
            inst.do_step(t, points[n + 1] - t)
    finally:
        inst.free()
    assert max(est) >= 110


def test_estimator_fmu_reaches_an_instant_after_accumulated_rounding(cp, seed000_record, tmp_path):
    """OMSimulator's loop: t += 0.01 (t = 4.999999999999938 after 500 steps), then a last step
    of 6.2e-14 s to 5.0: every update is made once, none twice, none refused."""
    us, ys = seed000_record
    path = export_filter_fmu(EKF(cp, X0, 1.0, 0.2, 0.1), tmp_path, fmi_version=2)
    ref = EKF(cp, X0, 1.0, 0.2, 0.1)
    expected = [ref.x] + [ref.step([us[k - 1]], ys[k]) for k in range(1, 501)]
    inst = Instance(str(path)).init()
    t, k = 0.0, 0
    try:
        while t < 5.0 - 1e-15:
            for n, v in zip(cp.output_names, ys[k]):
                inst.set(n, v)
            np.testing.assert_allclose(inst.get(*cp.state_names), expected[k], rtol=0, atol=1e-12)
            inst.set("F", us[k])
            h = min(0.01, 5.0 - t)
            inst.do_step(t, h)
            t += h
            k = min(k + 1, 500) if h > 1e-9 else k
        assert t == 5.0 and k == 500
        np.testing.assert_allclose(inst.get(*cp.state_names), expected[500], rtol=0, atol=1e-12)
    finally:
        inst.free()

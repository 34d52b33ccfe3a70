"""The co-simulation master: reproduction, multi-rate scheduling, orders, third-party FMU,
refusals and faults."""
from pathlib import Path

import numpy as np
import pytest
from testkit.scenario_files import component, write_scenario

from cosim.components.estimation import EstimatorComponent
from cosim.components.sensors import Sensor
from cosim.components.sources import Constant, Sine
from cosim.core.component import Component
from cosim.core.master import ConfigurationError, CosimError, Cosimulation
from cosim.fmi.fmu_component import FMUComponent
from cosim.scenario import Scenario
from estimators import EKF, discretize
from fmu_models import get_model

DATA = Path(__file__).parents[1] / "data"


class Recorder(Component):
    """Does nothing but count its samples and remember their times and inputs."""

    def __init__(self, name, period, inputs=(), outputs=("count",)):
        super().__init__(name, period, inputs, outputs)
        self.times, self.inputs = [], []

    def reset(self, t0):
        super().reset(t0)
        self.times, self.inputs = [], []

    def output(self, t, u):
        self.times.append(t)
        self.inputs.append(np.array(u))
        return np.full(len(self.output_names), float(len(self.times)))


class Gain(Component):
    def __init__(self, name, period, k=2.0):
        super().__init__(name, period, ["u"], ["y"])
        self.k = k

    def output(self, t, u):
        return self.k * u


class Failing(Component):
    def __init__(self, name, period, at, nan=False):
        super().__init__(name, period, outputs=["y"])
        self.at, self.nan = at, nan

    def output(self, t, u):
        if t >= self.at - 1e-12:
            if self.nan:
                return np.array([np.nan])
            raise RuntimeError("deliberate failure")
        return np.array([1.0])


@pytest.mark.parametrize("name,integrator,substeps", [("cartpole", 2, 4), ("iwp", 1, 1)])
def test_master_reproduces_the_plant_model(fmu_paths, name, integrator, substeps):
    model = get_model(name)
    plant = FMUComponent("plant", fmu_paths[name], 0.01, parameters={"integrator": integrator,
                                                                     "substeps": substeps})
    inp = model.input_names[0]
    src = Sine("src", 0.01, amplitude=0.5, frequency=0.7)
    probe = Recorder("probe", 0.01, inputs=model.state_names)
    conn = {f"plant.{inp}": "src.out", **{f"probe.{s}": f"plant.{s}" for s in model.state_names}}
    df = Cosimulation([plant, src, probe], conn).run(3.0)
    ref = model.simulate(model.x0, lambda t: [0.5 * np.sin(2 * np.pi * 0.7 * t)], 0.01, 300,
                         method=["euler", "rk4"][integrator - 1], substeps=substeps)
    np.testing.assert_allclose(df[[f"plant.{s}" for s in model.state_names]].to_numpy(), ref,
                               rtol=0, atol=1e-10)
    # the probe saw the plant's state at each sample time, and did nothing else
    np.testing.assert_allclose(np.array(probe.inputs), ref, rtol=0, atol=1e-10)
    assert plant.instance is None                    # freed after the run


def test_multirate_counts_and_zero_order_hold(fmu_paths):
    """Plant 1 ms, sensor 5 ms, estimator 10 ms, controller 20 ms, over 1 s."""
    model = get_model("cartpole")
    plant = FMUComponent("plant", fmu_paths["cartpole"], 0.001, parameters={"step_size": 0.001})
    sensor = Sensor("sensor", 0.005, ["x", "theta"])
    ekf = EstimatorComponent("ekf", lambda: EKF(discretize(model, 0.01), model.x0, 1.0, 1e-4, 1e-4))
    ctrl = Recorder("ctrl", 0.02, inputs=["x"], outputs=["F"])
    conn = {"plant.F": "ctrl.F", "sensor.x": "plant.x", "sensor.theta": "plant.theta",
            "ekf.F": "ctrl.F", "ekf.y_x": "sensor.y_x", "ekf.y_theta": "sensor.y_theta",
            "ctrl.x": "ekf.x"}
    cs = Cosimulation([plant, sensor, ekf, ctrl], conn)
    assert cs.step_size == pytest.approx(0.001)
    df = cs.run(1.0)
    counts = {"plant": 1001, "sensor": 201, "ekf": 101, "ctrl": 51}   # outputs at 0..1 s inclusive
    assert cs.sample_counts(1.0) == counts
    assert sensor.n_samples == 201 and ekf.filter.k == 100 and ctrl.n_samples == 51
    np.testing.assert_allclose(ctrl.times, np.arange(51) * 0.02, atol=1e-12)
    t = df.index.to_numpy()
    # the sensor equals the plant at its sample times and holds in between
    on = np.isclose((t / 0.005) % 1, 0, atol=1e-9) | np.isclose((t / 0.005) % 1, 1, atol=1e-9)
    np.testing.assert_allclose(df["sensor.y_x"][on], df["plant.x"][on], atol=1e-15)
    y = df["sensor.y_x"].to_numpy()
    for k in range(len(t)):
        if not on[k]:
            assert y[k] == y[k - 1]
    # the controller output changes only every 20 ms (its sample count)
    F = df["ctrl.F"].to_numpy()
    assert np.count_nonzero(np.diff(F)) == 50
    # the estimator's output is held for 10 ms
    assert np.count_nonzero(np.diff(df["ekf.x"].to_numpy())) <= 100
    # the plant, at 1 ms with Euler 1 ms steps, followed the held force
    assert np.all(np.isfinite(df.to_numpy()))


def test_gauss_seidel_and_jacobi_orders():
    src = Sine("src", 0.1, 1.0, 0.5)
    gain = Gain("gain", 0.1)
    conn = {"gain.u": "src.out"}
    gs = Cosimulation([src, gain], conn).run(1.0)
    jac = Cosimulation([src, gain], conn, order="jacobi").run(1.0)
    np.testing.assert_allclose(gs["gain.y"], 2 * gs["src.out"], atol=1e-15)
    # Jacobi: the gain reads the value from before this step's samples (one sample behind)
    np.testing.assert_allclose(jac["gain.y"].to_numpy()[1:], 2 * jac["src.out"].to_numpy()[:-1], atol=1e-15)


def spring_damper_reference(n, h, force, m=1.0, k=4.0, c=0.4):
    pos, vel, out = 1.0, 0.0, [(1.0, 0.0)]
    for _ in range(n):
        dt = h / 10
        for _ in range(10):
            vel += dt * (force - k * pos - c * vel) / m
            pos += dt * vel
        out.append((pos, vel))
    return np.array(out)


def test_third_party_fmu_runs_from_a_scenario_file(spring_damper_fmu, tmp_path):
    scen = write_scenario(tmp_path / "spring.toml", 2.0,
                          [component("fmu", "body", 0.01, path=spring_damper_fmu, parameters={"k": 4.0}),
                           component("constant", "push", 0.05, value=0.3),
                           component("sensor", "sensor", 0.01, signals=["pos"])],
                          {"body.force": "push.out", "sensor.pos": "body.pos"})
    df = Scenario.load(scen, fmu_dir=tmp_path / "fmus").run()
    ref = spring_damper_reference(200, 0.01, 0.3)
    np.testing.assert_allclose(df[["body.pos", "body.vel"]].to_numpy(), ref, atol=1e-12)
    np.testing.assert_allclose(df["sensor.y_pos"], df["body.pos"], atol=0)


def test_refusals_name_the_problem(fmu_paths, spring_damper_fmu):
    plant = FMUComponent("plant", fmu_paths["cartpole"], 0.01)
    src = Constant("src", 0.01, 0.1)
    probe = Recorder("probe", 0.01, inputs=["a"])
    with pytest.raises(ConfigurationError, match="unknown component 'plnt'.*components: plant, src, probe"):
        Cosimulation([plant, src, probe], {"plnt.F": "src.out", "probe.a": "src.out"})
    with pytest.raises(ConfigurationError, match="has no input 'G'; its inputs: F, w_x"):
        Cosimulation([plant, src, probe], {"plant.G": "src.out", "probe.a": "src.out"})
    with pytest.raises(ConfigurationError, match="has no output 'y'; its outputs: out"):
        Cosimulation([plant, src, probe], {"plant.F": "src.y", "probe.a": "src.out"})
    with pytest.raises(ConfigurationError, match="input probe.a is not connected; available signals: plant.x"):
        Cosimulation([plant, src, probe], {"plant.F": "src.out"})
    with pytest.raises(ConfigurationError, match="connected twice"):
        Cosimulation([plant, src, probe], [("src.out", "plant.F"), ("plant.x", "plant.F"),
                                           ("src.out", "probe.a")])
    with pytest.raises(ConfigurationError, match="'component.port'"):
        Cosimulation([plant, src, probe], {"plant": "src.out"})
    with pytest.raises(ConfigurationError, match="period 0.01 s is not an integer multiple of the base step 0.003"):
        Cosimulation([plant, src, Recorder("probe", 0.01, ["a"])], {"probe.a": "src.out"}, step_size=0.003)
    with pytest.raises(ConfigurationError, match="duplicate component names"):
        Cosimulation([src, Constant("src", 0.01, 1.0)], {})
    with pytest.raises(ConfigurationError, match="order must be one of"):
        Cosimulation([src], {}, order="random")
    with pytest.raises(ConfigurationError, match=r"base steps of 0.01 s: .* is 1.5 steps; the nearest is 2"):
        Cosimulation([src], {}).run(0.015)
    with pytest.raises(KeyError, match="no variable 'mass'.*valid names"):
        FMUComponent("plant", fmu_paths["cartpole"], 0.01, parameters={"mass": 1.0})
    body = FMUComponent("body", spring_damper_fmu, 0.01, outputs=["pos", "steps"])
    assert [p.type for p in body.output_ports] == ["Real", "Integer"]      # typed ports
    with pytest.raises(KeyError, match="'pos' is not an FMU input"):
        FMUComponent("body", spring_damper_fmu, 0.01, inputs=["pos"])
    assert FMUComponent("body", spring_damper_fmu, 0.01).output_names == ["pos", "vel", "steps"]
    with pytest.raises(ValueError, match="period must be a positive"):
        Constant("c", 0.0, 1.0)
    ekf = lambda: EKF(discretize(get_model("cartpole"), 0.01), np.zeros(4), 1.0, 0.1, 0.1)  # noqa: E731
    with pytest.raises(ValueError, match="differs from the filter model's dt"):
        EstimatorComponent("ekf", ekf, period=0.02)


def test_scenario_refusals(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[simulation]\nstop_time = 1\n[[component]]\nname = "a"\ntype = "magic"\nperiod = 0.1\n')
    with pytest.raises(ConfigurationError, match="unknown type 'magic'; valid types: .*fmu"):
        Scenario.load(bad)
    bad.write_text('[simulation]\nstop_time = 1\n[[component]]\nname = "e"\ntype = "estimator"\n'
                   'filter = "PF"\nmodel = "cartpole"\nperiod = 0.01\n')
    with pytest.raises(ConfigurationError, match="unknown filter 'PF'"):
        Scenario.load(bad)
    bad.write_text('[simulation]\nstoptime = 1\n')
    with pytest.raises(ConfigurationError, match="unknown keys"):
        Scenario.load(bad)


@pytest.mark.parametrize("nan", [False, True])
def test_a_failing_component_stops_the_run_with_name_time_and_partial_results(fmu_paths, nan):
    plant = FMUComponent("plant", fmu_paths["cartpole"], 0.01)
    bad = Failing("bad", 0.01, at=0.5, nan=nan)
    with pytest.raises(CosimError, match=r"bad.*t = 0\.5 s") as err:
        Cosimulation([plant, bad], {"plant.F": "bad.y"}).run(2.0)
    assert err.value.component == "bad" and err.value.time == pytest.approx(0.5)
    assert len(err.value.results) == 50 and err.value.results.index[-1] == pytest.approx(0.49)
    assert plant.instance is None


def test_an_fmu_error_stops_the_run_and_the_fmu_is_freed(fmu_paths):
    plant = FMUComponent("plant", fmu_paths["iwp"], 0.01)
    huge = Constant("huge", 0.01, 1e308)
    with pytest.raises(CosimError, match=r"'plant' failed at t = 0 s.*DoStep.*non-finite") as err:
        Cosimulation([plant, huge], {"plant.i": "huge.out"}).run(1.0)
    assert err.value.component == "plant"
    assert len(err.value.results) == 1
    assert plant.instance is None
    # the same component runs again afterwards
    ok = Constant("ok", 0.01, 0.0)
    df = Cosimulation([plant, ok], {"plant.i": "ok.out"}).run(0.1)
    assert len(df) == 11


def test_span_is_rounded_not_refused():
    """A span that is a whole number of steps up to float rounding (Roberts' 1e-5..1e8 s in
    steps of 9999999.999999 s) runs; the recorded times end at the stop time."""
    src = Constant("src", 9999999.999999, 1.0)
    df = Cosimulation([src], {}).run(1e8, 1e-5)
    assert len(df) == 11 and df.index[-1] == pytest.approx(1e8, rel=1e-15)
    df = Cosimulation([Constant("c", 0.1, 1.0)], {}).run(0.3)     # 0.3 / 0.1 = 2.9999999999999996
    assert len(df) == 4

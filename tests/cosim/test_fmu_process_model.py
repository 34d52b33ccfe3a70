"""The estimator component on a Model Exchange FMU's process model: a scenario file's
``model = "plant.fmu"``, in the native kernel and in Python, equal to the same filter on the
CasADi model; the Reference FMU VanDerPol measured by a noisy sensor in the master."""
from __future__ import annotations

import numpy as np
import pytest
from testkit.reference_cases import reference_dir

from cosim.scenario import Scenario
from fmu_models import build_fmu
from fmu_models.errors import ConfigurationError, UnknownNameError

CARTPOLE = """
[simulation]
stop_time = 3.0
engine = "{engine}"

[[component]]
name = "plant"
type = "fmu"
model = "cartpole"
period = 0.01
start = {{ x = 0.5, x_dot = 0.0, theta = 1.8, theta_dot = 0.5 }}

[[component]]
name = "sensor"
type = "sensor"
period = 0.01
signals = ["x", "theta"]
noise_std = 0.31622776601683794
seed = 2

[[component]]
name = "force"
type = "step"
period = 0.01
t_step = 1.0
before = -0.5
after = 0.5

[[component]]
name = "ekf"
type = "estimator"
filter = "EKF"
model = "{model}"
{extra}
period = 0.01
x0 = [0.5, 0.0, 1.8, 0.5]
P0 = 1.0
Q = 0.2
R = 0.1

[connections]
"plant.F" = "force.out"
"sensor.x" = "plant.x"
"sensor.theta" = "plant.theta"
"ekf.F" = "force.out"
"ekf.y_x" = "sensor.y_x"
"ekf.y_theta" = "sensor.y_theta"
"""


def cartpole(folder, model: str, extra: str = "", engine: str = "auto") -> Scenario:
    """The cart-pole FMU measured with noise, an EKF on ``model`` (a name or an FMU's path)."""
    path = folder / f"scenario_{engine}.toml"
    path.write_text(CARTPOLE.format(model=model, extra=extra, engine=engine))
    return Scenario.load(path, folder / ".fmus")


@pytest.fixture(scope="module")
def cartpole_fmu(tmp_path_factory):
    return build_fmu("cartpole", tmp_path_factory.mktemp("cp"), fmi_version=3)


@pytest.mark.parametrize("engine", ["native", "python"])
def test_the_estimator_on_an_fmu_equals_the_estimator_on_casadi(tmp_path, cartpole_fmu, engine):
    """The scenario's EKF on the cart-pole's own FMU (Euler, as the CasADi model) gives the
    CasADi EKF's estimates within 1e-9; the native kernel calls the FMU through the filter's
    compiled step."""
    fmu = cartpole(tmp_path, str(cartpole_fmu), 'measurements = ["y_x", "y_theta"]\ninputs = ["F"]\nmethod = "euler"',
                   engine)
    if engine == "native":
        assert fmu.cosim.component_paths()["ekf"] is None
    a, b = fmu.run(), cartpole(tmp_path, "cartpole", "", engine).run()
    cols = [c for c in b.columns if c.startswith("ekf.")]
    assert len(cols) == 9
    np.testing.assert_allclose(a[cols].to_numpy(), b[cols].to_numpy(), rtol=0, atol=1e-9)


def test_an_fmu_model_needs_its_measurements(tmp_path, cartpole_fmu):
    with pytest.raises(ConfigurationError, match="needs the key 'measurements'"):
        cartpole(tmp_path, str(cartpole_fmu))
    with pytest.raises(UnknownNameError, match="no variable 'y_z'"):
        cartpole(tmp_path, str(cartpole_fmu), 'measurements = ["y_z"]')


VANDERPOL = """
title = "Van der Pol: the Reference FMU in the master, a noisy sensor, an EKF on the same FMU"
[simulation]
stop_time = 20.0

[[component]]
name = "plant"
type = "fmu"
path = "{fmu}"
interface = "me"
solver = "rk4"
solver_step = 0.1
period = 0.1

[[component]]
name = "sensor"
type = "sensor"
period = 0.1
signals = ["x0"]
noise_std = 0.1
seed = 4

[[component]]
name = "ekf"
type = "estimator"
filter = "EKF"
model = "{fmu}"
measurements = ["x0"]
period = 0.1
x0 = [2.0, 0.0]
P0 = 0.01
Q = 1e-3
R = 0.01

[connections]
"sensor.x0" = "plant.x0"
"ekf.x0" = "sensor.y_x0"
"""


def test_the_reference_vanderpol_in_the_master(tmp_path):
    folder = reference_dir()
    if folder is None:
        pytest.skip("the Modelica Reference FMUs are absent (set PENDULUM_COSIM_REFERENCE_FMUS)")
    path = tmp_path / "vdp.toml"
    path.write_text(VANDERPOL.format(fmu=folder / "fmi3" / "VanDerPol.fmu"))
    res = Scenario.load(path).run()
    for state, bound in (("x0", 0.1), ("x1", 0.2)):     # the sensor's noise: 0.1 on x0
        err = (res[f"ekf.{state}"] - res[f"plant.{state}"]).to_numpy()[10:]
        assert np.sqrt(np.mean(err ** 2)) < bound


def test_the_campaigns_building_blocks_take_an_fmu_model(cartpole_fmu):
    """Truth and measurements from the FMU's process model (its own map) equal the plant's,
    and the batched filters on it give the CasADi model's estimates."""
    from cosim.experiments.common import batch_run, seed_pairs, simulate_truth
    from estimators import EKF, FMUProcessModel, discretize
    from fmu_models import get_model

    plant = get_model("cartpole")
    model = FMUProcessModel(cartpole_fmu, 0.01, plant.output_names, plant.input_names, method="euler")

    class Settings:
        runs, seed = 3, 5
    seeds = seed_pairs(Settings, 0)
    us = np.full((101, 1), 0.5)
    x0 = [0.5, 0.0, 1.8, 0.5]
    X, Y = simulate_truth(plant, x0, us, 0.01, 0.2, ["x", "theta"], [0.3, 0.3], seeds)
    Xf, Yf = simulate_truth(model, x0, us, 0.01, 0.2, plant.output_names, [0.3, 0.3], seeds)
    np.testing.assert_allclose(Xf, X, rtol=0, atol=1e-12)
    np.testing.assert_allclose(Yf, Y, rtol=0, atol=1e-12)
    a = batch_run(lambda: EKF(model, x0, 1.0, 0.2, 0.1), X, Y, us)
    b = batch_run(lambda: EKF(discretize(plant, 0.01), x0, 1.0, 0.2, 0.1), X, Y, us)
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.nees, b.nees, rtol=1e-7)


HOSTILE = """
[simulation]
stop_time = 2.0

[[component]]
name = "meas"
type = "step"
period = 0.05
t_step = 0.5
before = 0.5
after = 2.0

[[component]]
name = "ekf"
type = "estimator"
filter = "EKF"
model = "{fmu}"
measurements = ["y"]
model_parameters = {{ mode = {mode}, limit = 0.8 }}
period = 0.05
x0 = [0.5, 0.0]
P0 = 0.01
Q = 1e-4
R = 1e-3

[connections]
"ekf.y" = "meas.out"
"""


@pytest.mark.parametrize("mode,words", [(1, "the derivative of state x1 is nan"),
                                        (2, "fmi3GetContinuousStateDerivatives returned Error"),
                                        (6, "asked for Event Mode")], ids=["nan", "error", "step-event"])
def test_a_hostile_fmu_model_in_a_run_is_one_line(capsys, tmp_path, mode, words):
    """The command line names the FMU's failure in one line, no traceback."""
    from testkit import handwritten

    from cosim.cli import main

    try:
        fmu = handwritten.build("hostile_me", "HostileME", 3, tmp_path / "fmu")
    except handwritten.NotBuildable as e:
        pytest.skip(str(e))
    scenario = tmp_path / "hostile.toml"
    scenario.write_text(HOSTILE.format(fmu=fmu, mode=float(mode)))
    status = main(["run", str(scenario), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert status == 2 and "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and words in lines[0] and "filter state unchanged" in lines[0], err

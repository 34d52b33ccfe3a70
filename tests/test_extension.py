"""Adding a plant model, a filter, a component and an experiment is one file each: this one.

The four definitions below are what a user writes; nothing else in the project changes.
The tests use them from Python, from a scenario file (which names this file as its plugin)
through the command line in a fresh process, export the filter as an FMU and run it in
fmpy, and run the experiment from the command line.
"""
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import casadi as ca
import numpy as np
import pytest

from cosim import Component
from cosim.experiments import Experiment
from estimators import EKF, Parameter
from fmu_models import PlantModel, Variable, register_model

HERE = Path(__file__)
CLI = [sys.executable, "-c", "import sys; from cosim.cli import main; sys.exit(main())"]


# ----------------------------------------------------------------------------- a plant model
@register_model("spring_mass")
def spring_mass() -> PlantModel:
    """A mass on a damped spring, pushed by a force: x'' = (F - k x - c x') / m."""
    def dynamics(x, u, p):
        return ca.vertcat(x[1], (u[0] - p["k"] * x[0] - p["c"] * x[1]) / p["m"])

    return PlantModel("spring_mass", "SpringMass", "mass on a damped spring",
                      [Variable("pos", "m", "position", 0.1), Variable("vel", "m/s", "velocity", 0.0)],
                      [Variable("F", "N", "force")], [Variable("y_pos", "m", "measured position")],
                      [Variable("m", "kg", "mass", 1.0, "positive"), Variable("k", "N/m", "stiffness", 4.0, "positive"),
                       Variable("c", "N.s/m", "damping", 0.4, "nonnegative")],
                      dynamics, lambda x, p: ca.vertcat(x[0]))


# ----------------------------------------------------------------------------- a filter
class ScaledEKF(EKF, register="ScaledEKF"):
    """An EKF whose process noise is scaled by a step parameter ``qscale`` (an FMU parameter
    too, with no exporter change)."""

    name = "ScaledEKF"

    def __init__(self, system, x0, P0, Q, R, qscale: float = 2.0, **kw):
        self.qscale = float(qscale)
        super().__init__(system, x0, P0, Q, R, **kw)

    def step_parameters(self):
        return [Parameter("qscale", self.qscale, "positive", "factor on Q")]

    def predict_expr(self, ctx):
        xp, Pp = super().predict_expr(ctx)
        return xp, Pp + (ctx.params["qscale"][0] - 1) * ctx.Q


# ----------------------------------------------------------------------------- a component
class Gain(Component, kind="gain"):
    """``y = k u``, sampled."""

    def __init__(self, name, period, k=1.0):
        super().__init__(name, period, ["u"], ["y"])
        self.k = float(k)

    def output(self, t, u):
        return np.array([self.k * u[0]])


# ----------------------------------------------------------------------------- an experiment
@dataclass(frozen=True)
class ToySettings:
    """Realisations, seed and the filter's scale of Q."""

    runs: int = 3
    seed: int = 0
    qscale: float = 2.0


class ToyStudy(Experiment, register="toy-study"):
    """RMSE of the ScaledEKF on the spring-mass against the scale of Q."""

    description = "the ScaledEKF on the spring-mass"
    paths = ("fast",)

    configs: ClassVar[dict] = {"default": ToySettings()}

    def run(self, settings, path="fast", backend="processes", n_jobs=None, progress=True):
        from estimators import discretize
        from fmu_models import get_model

        system = discretize(get_model("spring_mass"), 0.01)
        rng = np.random.default_rng(settings.seed)
        errs = []
        for _ in range(settings.runs):
            x, xs, ys = np.array([0.1, 0.0]), [], []
            for _k in range(200):
                x = system.f(x, [0.0]) + rng.normal(0, 1e-3, 2)
                xs.append(x)
                ys.append(system.h(x) + rng.normal(0, 1e-2, 1))
            f = ScaledEKF(system, [0.1, 0.0], 1e-2, 1e-6, 1e-4, qscale=settings.qscale)
            est = f.run(np.zeros((200, 1)), np.array(ys)).x[1:]
            errs.append(float(np.sqrt(np.mean((est - np.array(xs)) ** 2))))
        return (errs,)

    def write_report(self, result, settings, out_dir, path="fast", config="custom", partial=False):
        md = Path(out_dir) / "summary.md"
        md.write_text(f"RMSE per run: {result[0]}\n")
        return md

    def summary(self, result, settings, path="fast", config="custom"):
        return f"toy study: mean RMSE {np.mean(result[0]):.4g}"


# ----------------------------------------------------------------------------- the proof
SCENARIO = f"""
title = "user extensions"
plugins = ["{HERE}"]

[simulation]
stop_time = 1.0

[[component]]
name = "plant"
type = "fmu"
model = "spring_mass"
period = 0.01
parameters = {{ step_size = 0.01 }}

[[component]]
name = "force"
type = "gain"
period = 0.01
k = 0.0

[[component]]
name = "ekf"
type = "estimator"
filter = "ScaledEKF"
model = "spring_mass"
period = 0.01
x0 = [0.1, 0.0]
P0 = 0.01
Q = 1e-6
R = 1e-4
qscale = 3.0

[connections]
"force.u" = "plant.pos"
"plant.F" = "force.y"
"ekf.F" = "force.y"
"ekf.y_pos" = "plant.y_pos"
"""


def _cli(*args, cwd):
    return subprocess.run([*CLI, *args], cwd=cwd, capture_output=True, text=True, timeout=600)


def test_the_four_extensions_are_found_by_name():
    from cosim import COMPONENTS
    from cosim.experiments import EXPERIMENTS
    from estimators import FILTERS
    from fmu_models import get_model, model_names

    assert "spring_mass" in model_names() and get_model("spring_mass", k=9.0).params["k"] == 9.0
    assert FILTERS.get("ScaledEKF") is ScaledEKF and COMPONENTS.get("gain") is Gain
    assert EXPERIMENTS.get("toy-study") is ToyStudy


@pytest.mark.slow
def test_a_user_scenario_runs_from_the_command_line(tmp_path):
    (tmp_path / "s.toml").write_text(SCENARIO)
    proc = _cli("run", "s.toml", "--out", "out", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    import pandas as pd

    df = pd.read_csv(tmp_path / "out" / "results.csv", index_col="time")
    assert abs(df["ekf.pos"].iloc[-1] - df["plant.pos"].iloc[-1]) < 1e-2       # the filter tracks the plant
    assert "ekf" in proc.stdout                                               # the RMSE table names it


def test_the_user_filter_exports_as_an_fmu_with_its_parameter(tmp_path):
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu
    from testkit.fmu_helpers import Instance

    from estimators import discretize
    from fmu_models import get_model

    (tmp_path / "s.toml").write_text(SCENARIO)
    proc = _cli("export-fmu", "s.toml", "--out", "fmus", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    fmu = tmp_path / "fmus" / "ekf.fmu"
    assert validate_fmu(str(fmu)) == []
    names = {v.name: v for v in read_model_description(str(fmu)).modelVariables}
    assert names["qscale"].start == "3.0"
    system = discretize(get_model("spring_mass"), 0.01)
    ys = 0.1 * np.cos(2 * np.arange(1, 51) * 0.01) + 0.01 * np.sin(7 * np.arange(1, 51))
    inst = Instance(str(fmu))
    inst.init()
    got = []
    for k in range(50):                  # the force held over [t, t + h], then the measurement at t + h
        inst.set("F", 0.3)
        inst.do_step(k * 0.01, 0.01)
        inst.set("y_pos", ys[k])
        got.append(inst.get("pos", "vel"))
    inst.free()
    f = ScaledEKF(system, [0.1, 0.0], 0.01, 1e-6, 1e-4, qscale=3.0)
    ours = f.run(np.full((50, 1), 0.3), ys[:, None]).x[1:]
    np.testing.assert_allclose(np.array(got), ours, rtol=0, atol=1e-12)
    plain = EKF(system, [0.1, 0.0], 0.01, 1e-6, 1e-4).run(np.full((50, 1), 0.3), ys[:, None]).x[1:]
    assert np.abs(plain - ours).max() > 1e-6                                 # qscale acts


def test_the_user_experiment_runs_from_the_command_line(tmp_path):
    proc = _cli("--plugin", str(HERE), "experiment", "toy-study", "--out", "toy", "--set", "runs=2",
                "--quiet", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "toy study: mean RMSE" in proc.stdout
    assert "RMSE per run" in (tmp_path / "toy" / "summary.md").read_text()


def test_an_unknown_name_lists_the_registered_ones():
    from fmu_models import get_model
    from fmu_models.errors import UnknownNameError

    with pytest.raises(UnknownNameError, match="valid models: cartpole, iwp"):
        get_model("segway")

"""The hostile user at the Python API (issue 20): every public function given bad, huge or
mismatched arguments raises one of the package's errors (``fmu_models.errors``) that
names the argument; never a bare ValueError, KeyError, TypeError or RuntimeError from
inside, and never a silently wrong result."""
from __future__ import annotations

import numpy as np
import pytest

from fmu_models.errors import PendulumCosimError

TRIES = []


def attempt(label: str, words: str):
    """Register ``fn`` as a try that must raise a PendulumCosimError containing ``words``."""
    def wrap(fn):
        TRIES.append(pytest.param(fn, words, id=label))
        return fn
    return wrap


@pytest.fixture(scope="module")
def cp():
    from fmu_models import get_model

    return get_model("cartpole")


@pytest.fixture(scope="module")
def dm(cp):
    from estimators import discretize

    return discretize(cp, 0.01)


def _ekf(dm, cp, **kw):
    from estimators import EKF

    args = dict(x0=cp.x0, P0=1.0, Q=1e-3, R=1e-2)
    args.update(kw)
    return EKF(dm, args["x0"], args["P0"], args["Q"], args["R"])


# ------------------------------------------------------------------ models
@attempt("get_model-unknown", "unknown model 'cartpol'; valid models: cartpole, iwp")
def _(cp, dm, tmp):
    from fmu_models import get_model
    get_model("cartpol")


@attempt("get_model-not-a-string", "model")
def _(cp, dm, tmp):
    from fmu_models import get_model
    get_model(42)


@attempt("simulate-negative-steps", "n_steps")
def _(cp, dm, tmp):
    cp.simulate(cp.x0, [0.0], 0.01, -5)


@attempt("simulate-nan-state", "x0")
def _(cp, dm, tmp):
    cp.simulate([np.nan, 0, 0, 0], [0.0], 0.01, 5)


@attempt("simulate-dt-zero", "dt")
def _(cp, dm, tmp):
    cp.simulate(cp.x0, [0.0], 0.0, 5)


@attempt("simulate-huge", "GiB")
def _(cp, dm, tmp):
    cp.simulate(cp.x0, [0.0], 0.01, 10**12)


@attempt("simulate-wrong-input-shape", "input")
def _(cp, dm, tmp):
    cp.simulate(cp.x0, np.zeros((3, 2)), 0.01, 5)


@attempt("simulate-unknown-method", "method")
def _(cp, dm, tmp):
    cp.simulate(cp.x0, [0.0], 0.01, 5, method="rk5")


@attempt("linearize-wrong-size", "x")
def _(cp, dm, tmp):
    cp.linearize([0.0, 0.0], [0.0])


@attempt("build_fmu-unknown-version", "fmi_version")
def _(cp, dm, tmp):
    from fmu_models import build_fmu
    build_fmu("cartpole", tmp, fmi_version=4)


@attempt("build_fmu-unknown-model", "unknown model")
def _(cp, dm, tmp):
    from fmu_models import build_fmu
    build_fmu("pendulum", tmp)


@attempt("build_fmu-out-is-a-file", "a file is in the way")
def _(cp, dm, tmp):
    from fmu_models import build_fmu
    (tmp / "f").write_text("x")
    build_fmu("cartpole", tmp / "f")


# ------------------------------------------------------------------ filters
@attempt("discretize-negative-dt", "dt")
def _(cp, dm, tmp):
    from estimators import discretize
    discretize(cp, -0.01)


@attempt("discretize-nan-dt", "dt")
def _(cp, dm, tmp):
    from estimators import discretize
    discretize(cp, float("nan"))


@attempt("discretize-text-dt", "dt")
def _(cp, dm, tmp):
    from estimators import discretize
    discretize(cp, "fast")


@attempt("ekf-P0-not-PD", "P0")
def _(cp, dm, tmp):
    _ekf(dm, cp, P0=-np.eye(4))


@attempt("ekf-P0-asymmetric", "P0")
def _(cp, dm, tmp):
    _ekf(dm, cp, P0=np.triu(np.ones((4, 4))) + np.eye(4))


@attempt("ekf-Q-nan", "Q")
def _(cp, dm, tmp):
    _ekf(dm, cp, Q=float("nan"))


@attempt("ekf-R-wrong-shape", "R")
def _(cp, dm, tmp):
    _ekf(dm, cp, R=np.eye(3))


@attempt("ekf-x0-wrong-length", "x0")
def _(cp, dm, tmp):
    _ekf(dm, cp, x0=[0.0, 0.0])


@attempt("ekf-x0-strings", "x0")
def _(cp, dm, tmp):
    _ekf(dm, cp, x0=["a", "b", "c", "d"])


@attempt("step-nan-y", "")
def _(cp, dm, tmp):
    f = _ekf(dm, cp)
    f.step([0.0], [np.inf, 0.0])


@attempt("step-y-wrong-size", "y")
def _(cp, dm, tmp):
    _ekf(dm, cp).step([0.0], [0.0, 0.0, 0.0])


@attempt("step-u-none", "u")
def _(cp, dm, tmp):
    _ekf(dm, cp).step(None, [0.0, 0.0])


@attempt("run-empty-record", "empty")
def _(cp, dm, tmp):
    _ekf(dm, cp).run(np.zeros((0, 1)), np.zeros((0, 2)))


@attempt("run-mismatched-lengths", "")
def _(cp, dm, tmp):
    _ekf(dm, cp).run(np.zeros((10, 1)), np.zeros((9, 2)))


@attempt("run-unknown-keep", "keep")
def _(cp, dm, tmp):
    _ekf(dm, cp).run(np.zeros((10, 1)), np.zeros((10, 2)), keep="most")


@attempt("rts-empty-record", "empty")
def _(cp, dm, tmp):
    from estimators import rts_smooth
    f = _ekf(dm, cp)
    rts_smooth(f, f.run(np.zeros((0, 1)), np.zeros((0, 2))))


@attempt("rts-run-of-another-model", "another model")
def _(cp, dm, tmp):
    from estimators import discretize, rts_smooth
    run = _ekf(dm, cp).run(np.zeros((10, 1)), np.zeros((10, 2)))
    rts_smooth(_ekf(discretize(cp, 0.02), cp), run)


@attempt("rts-not-a-run", "FilterRun")
def _(cp, dm, tmp):
    from estimators import rts_smooth
    rts_smooth(_ekf(dm, cp), {"x": 1})


@attempt("rts-estimates-only", "keep='all'")
def _(cp, dm, tmp):
    from estimators import rts_smooth
    f = _ekf(dm, cp)
    rts_smooth(f, f.run(np.zeros((10, 1)), np.zeros((10, 2)), keep="estimates"))


@attempt("batch-1e9-runs", "GiB")
def _(cp, dm, tmp):
    from estimators import BatchFilter
    BatchFilter(_ekf(dm, cp), 10**9)


@attempt("batch-zero-runs", "n_runs")
def _(cp, dm, tmp):
    from estimators import BatchFilter
    BatchFilter(_ekf(dm, cp), 0)


@attempt("batch-fractional-runs", "n_runs")
def _(cp, dm, tmp):
    from estimators import BatchFilter
    BatchFilter(_ekf(dm, cp), 2.5)


@attempt("batch-on-failure-unknown", "on_failure")
def _(cp, dm, tmp):
    from estimators import BatchFilter
    BatchFilter(_ekf(dm, cp), 4, on_failure="ignore")


@attempt("em-empty-record", "empty")
def _(cp, dm, tmp):
    from estimators import em_noise
    em_noise(_ekf(dm, cp), np.zeros((0, 1)), np.zeros((0, 2)))


@attempt("em-negative-iterations", "n_iter")
def _(cp, dm, tmp):
    from estimators import em_noise
    em_noise(_ekf(dm, cp), np.zeros((10, 1)), np.zeros((10, 2)), n_iter=-1)


@attempt("em-unknown-structure", "structure")
def _(cp, dm, tmp):
    from estimators import em_noise
    em_noise(_ekf(dm, cp), np.zeros((10, 1)), np.zeros((10, 2)), structure="banded")


@attempt("set_noise-not-PD", "Q")
def _(cp, dm, tmp):
    _ekf(dm, cp).set_noise(Q=-np.eye(4))


@attempt("export_fmu-unknown-version", "fmi_version")
def _(cp, dm, tmp):
    from estimators import export_fmu
    export_fmu(_ekf(dm, cp), tmp, fmi_version=5)


# ------------------------------------------------------------------ co-simulation
@attempt("cosim-not-a-component", "not a cosim.core.component.Component")
def _(cp, dm, tmp):
    from cosim import Cosimulation
    Cosimulation(["plant"], {})


@attempt("cosim-connection-without-dot", "must be written 'component.port'")
def _(cp, dm, tmp):
    from cosim import Constant, Cosimulation
    Cosimulation([Constant("c", 0.01, 1.0)], {"x": "c.out"})


@attempt("cosim-unknown-port", "has no output")
def _(cp, dm, tmp):
    from cosim import Constant, Cosimulation, Sensor
    Cosimulation([Constant("c", 0.01, 1.0), Sensor("s", 0.01, ["x"])], {"s.x": "c.nope"})


@attempt("cosim-run-nan-stop", "stop_time")
def _(cp, dm, tmp):
    from cosim import Constant, Cosimulation
    Cosimulation([Constant("c", 0.01, 1.0)], {}).run(float("nan"))


@attempt("cosim-run-stop-before-start", "base steps")
def _(cp, dm, tmp):
    from cosim import Constant, Cosimulation
    Cosimulation([Constant("c", 0.01, 1.0)], {}).run(1.0, 2.0)


@attempt("cosim-run-output-interval-zero", "output_interval")
def _(cp, dm, tmp):
    from cosim import Constant, Cosimulation
    Cosimulation([Constant("c", 0.01, 1.0)], {}).run(1.0, output_interval=0.0)


@attempt("cosim-run-signal-pattern-matches-nothing", "")
def _(cp, dm, tmp):
    from cosim import Constant, Cosimulation
    Cosimulation([Constant("c", 0.01, 1.0)], {}).run(1.0, signals=["zz.*"])


@attempt("cosim-run-huge", "")
def _(cp, dm, tmp):
    from cosim import Constant, Cosimulation
    Cosimulation([Constant("c", 0.01, 1.0)], {}).run(1e12)


class _NanAt:
    """A component whose output turns NaN at ``at`` [s]."""

    @staticmethod
    def make(at: float):
        from cosim import Component

        class NanAt(Component):
            def output(self, t, u):
                return np.array([np.nan if t >= at - 1e-12 else 1.0])
        return NanAt("b", 0.01, [], ["y"])


@attempt("cosim-nan-in-the-last-step", "signal b.y is nan at t = 1 s")
def _(cp, dm, tmp):
    from cosim import Cosimulation
    Cosimulation([_NanAt.make(1.0)], {}).run(1.0, progress=False)


@attempt("cosim-nan-in-the-last-block-unrecorded", "signal b.y is nan between")
def _(cp, dm, tmp):
    from cosim import Constant, Cosimulation
    Cosimulation([_NanAt.make(0.97), Constant("c", 0.01, 1.0)], {}).run(1.0, signals=["c.*"], output_interval=0.5)


@attempt("fmu-whose-library-does-not-load", "cannot load")
def _(cp, dm, tmp):
    import os
    import zipfile

    from cosim import Cosimulation, FMUComponent
    from fmu_models import build_fmu

    good = build_fmu("cartpole", tmp / "good")
    bad = tmp / "bad.fmu"
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(bad, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            dst.writestr(item, b"not a shared library" if item.filename.endswith(".so") else data)
    cwd = os.getcwd()
    try:
        Cosimulation([FMUComponent("p", bad, 0.01)], {}).run(0.02)
    finally:
        assert os.getcwd() == cwd                # fmpy's chdir undone


@attempt("me-system-connections-not-a-table", "connections must be a table")
def _(cp, dm, tmp):
    from cosim import FMUComponent, MESystem
    from fmu_models import build_fmu

    plant = FMUComponent("p", build_fmu("cartpole", tmp / "f"), 0.01, interface="me")
    MESystem("s", [plant], [("p.x", "p.F")], 0.01)


@attempt("constant-nan", "value")
def _(cp, dm, tmp):
    from cosim import Constant
    Constant("c", 0.01, float("nan"))


@attempt("component-bad-name", "name")
def _(cp, dm, tmp):
    from cosim import Constant
    Constant("a.b", 0.01, 1.0)


@attempt("sensor-negative-noise", "noise_std")
def _(cp, dm, tmp):
    from cosim import Sensor
    Sensor("s", 0.01, ["x"], noise_std=-1.0)


@attempt("sensor-no-signals", "signals")
def _(cp, dm, tmp):
    from cosim import Sensor
    Sensor("s", 0.01, [])


@attempt("step-text-time", "t_step")
def _(cp, dm, tmp):
    from cosim import Step
    Step("f", 0.01, t_step="soon", before=0.0, after=1.0)


@attempt("fmu-component-missing-file", "no FMU file")
def _(cp, dm, tmp):
    from cosim import FMUComponent
    FMUComponent("p", tmp / "missing.fmu", 0.01)


@attempt("fmu-component-a-folder", "")
def _(cp, dm, tmp):
    from cosim import FMUComponent
    FMUComponent("p", tmp, 0.01)


@attempt("scenario-not-a-mapping", "")
def _(cp, dm, tmp):
    from cosim import Scenario
    Scenario(["not", "a", "table"], tmp)


@attempt("open_ssp-missing", "")
def _(cp, dm, tmp):
    from cosim import open_ssp
    with open_ssp(tmp / "nothing.ssp"):
        pass


@attempt("save_results-not-a-frame", "")
def _(cp, dm, tmp):
    from cosim.output import save_results
    save_results([1, 2, 3], tmp)


@attempt("plot-unknown-column", "no column")
def _(cp, dm, tmp):
    import pandas as pd

    from cosim.output import plot_estimates
    plot_estimates(pd.DataFrame({"a": [1.0]}), ["a"], ["b"])


@attempt("output-folder-is-a-file", "is a file")
def _(cp, dm, tmp):
    from cosim.output import OutputFolder
    (tmp / "file").write_text("x")
    with OutputFolder(tmp / "file"):
        pass


@attempt("component-duplicate-port", "c: duplicate input port names: ['u']")
def _(cp, dm, tmp):
    from cosim import Component

    class Sum(Component):
        def output(self, t, u):
            return u[:1]

    Sum("c", 0.01, inputs=["u", "v", "u"], outputs=["y"])


@attempt("plant-duplicate-variable", "model 'twice': duplicate variable names ['a']")
def _(cp, dm, tmp):
    import casadi as ca

    from fmu_models import PlantModel, Variable
    x = [Variable("a", "m", "a", 0.0), Variable("a", "m", "again a", 0.0)]
    PlantModel("twice", "Twice", "a state named twice", x, [Variable("u", "N", "force")],
               [Variable("y", "m", "y")], [], lambda x, u, p: ca.vertcat(x[1], u[0]), lambda x, p: ca.vertcat(x[0]))


@pytest.mark.parametrize("fn, words", TRIES)
def test_api_refuses_with_a_named_error(fn, words, cp, dm, tmp_path):
    with pytest.raises(PendulumCosimError) as e:
        fn(cp, dm, tmp_path)
    assert words in str(e.value), str(e.value)
    assert str(e.value).strip()


def test_the_corpus_is_large():
    assert len(TRIES) >= 60


def test_a_recording_beyond_the_process_memory_limit_is_refused_by_name():
    """Under an address-space limit (``ulimit -v``) a run whose recording would not fit is
    refused before it starts, with what to do, not a bare MemoryError."""
    import resource
    import subprocess
    import sys

    code = ("from cosim import Cosimulation, Constant\n"
            "Cosimulation([Constant(f'c{i}', 1.0, float(i)) for i in range(15)], {}).run(1e7, progress=False)\n")

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (2500 * 2**20, 2500 * 2**20))

    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, preexec_fn=limit)
    assert proc.returncode != 0
    assert "ResourceError: recording 10000002 rows x 15 signals in memory needs 1.19 GiB" in proc.stderr
    assert "stream the rows to a Parquet file" in proc.stderr and "MemoryError" not in proc.stderr


def test_running_out_of_memory_in_a_run_is_named_and_keeps_the_rows():
    from cosim import Component, Constant, Cosimulation
    from fmu_models.errors import ResourceError

    class Hungry(Component):
        def __init__(self):
            super().__init__("hungry", 0.1, outputs=["y"])

        def output(self, t, u):
            if t > 0.45:
                raise MemoryError("Unable to allocate 8.00 EiB")
            return np.array([t])

    with pytest.raises(ResourceError, match=r"ran out of memory at t = 0.5 s \(Unable to allocate 8.00 EiB\); "
                                            "record fewer signals") as e:
        Cosimulation([Hungry(), Constant("c", 0.1, 1.0)], {}).run(1.0, progress=False)
    assert len(e.value.results) == 5

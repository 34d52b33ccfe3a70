"""Signal FMUs, the counter noise generator, and the scenario as an SSP (issue 13): signal
FMUs equal the Python components, the SSP loads with fmpy's reader and runs in fmpy's SSP
simulation and in the project's master with the same plant trajectory."""
import re
import shutil
import subprocess
import tomllib
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu
from testkit.fmu_helpers import Instance

from cosim.cli import main
from cosim.components.control import LQRController
from cosim.components.estimation import EstimatorComponent
from cosim.components.noise import CounterNoise, counter_normal
from cosim.components.sensors import ProcessNoise, Sensor
from cosim.components.sources import PRBS, Constant, Sine, Step
from cosim.core.master import Cosimulation
from cosim.fmi.fmu_component import FMUComponent
from cosim.ssp import export_ssp, open_ssp
from estimators import EKF, discretize
from fmu_models import get_model
from fmu_models.errors import ConfigurationError, FMUError

SCENARIO = Path(__file__).parents[2] / "cosim" / "scenarios" / "seed000_cartpole.toml"


# ---------------------------------------------------------------------------- the generator
def _splitmix_word(seed: int, i: int) -> int:
    """SplitMix64 word i, in Python integers (an independent oracle of the numpy code)."""
    m = (1 << 64) - 1
    z = (seed + (i + 1) * 0x9E3779B97F4A7C15) & m
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & m
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & m
    return z ^ (z >> 31)


def test_counter_generator_matches_its_definition_and_is_random_access():
    import math

    for seed, k, n in ((0, 0, 1), (7, 12345, 4), (2**31 - 1, -3, 2)):
        got = counter_normal(seed, k, n)
        for c in range(n):
            i = (2 * (k * n + c)) & ((1 << 64) - 1)
            a, b = _splitmix_word(seed, i), _splitmix_word(seed, (i + 1) & ((1 << 64) - 1))
            u1, u2 = ((a >> 11) + 1) * 2.0**-53, (b >> 11) * 2.0**-53
            assert got[c] == pytest.approx(math.sqrt(-2 * math.log(u1)) * math.cos(2 * math.pi * u2), abs=1e-15)
    # vectorised over k == one k at a time; the draw at k does not depend on where a run starts
    ks = np.arange(-5, 200)
    np.testing.assert_array_equal(counter_normal(3, ks, 2), np.array([counter_normal(3, k, 2) for k in ks]))
    noise = CounterNoise(3, 2, 0.01)
    np.testing.assert_array_equal(noise.at(1.23), counter_normal(3, 123, 2))


def test_counter_generator_statistics():
    from scipy import stats

    z = counter_normal(11, np.arange(200_000), 2)
    assert abs(z.mean()) < 0.01 and abs(z.std() - 1) < 0.01
    assert stats.kstest(z[:, 0], "norm").pvalue > 1e-3
    assert abs(np.corrcoef(z[:, 0], z[:, 1])[0, 1]) < 0.01            # channels independent
    assert abs(np.corrcoef(z[:-1, 0], z[1:, 0])[0, 1]) < 0.01          # samples independent
    assert not np.allclose(counter_normal(1, np.arange(10), 1), counter_normal(2, np.arange(10), 1))


def test_bad_generator_and_seed_are_refused():
    with pytest.raises(ConfigurationError, match="generator must be one of"):
        Sensor("s", 0.01, ["x"], 0.1, generator="mt19937")
    with pytest.raises(ConfigurationError, match="seed 4294967296 of the counter generator"):
        ProcessNoise("n", 0.01, ["x"], 0.1, seed=2**32, generator="counter")


# ---------------------------------------------------------------------------- signal FMUs
SOURCES = {
    "constant": lambda: Constant("src", 0.01, 1.25),
    "step": lambda: Step("src", 0.01, 0.5, -0.5, 0.5),
    "sine": lambda: Sine("src", 0.01, 2.0, 1.5, 0.3, 0.1),
    "prbs": lambda: PRBS("src", 0.01, 0.5, 0.07, 7, 28),
}


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("kind", list(SOURCES))
def test_source_fmus_equal_the_python_sources(tmp_path, kind, version):
    comp = SOURCES[kind]()
    exported = comp.export_fmu(tmp_path, version)
    assert validate_fmu(str(exported.path)) == []
    fmu = FMUComponent("src", exported.path, 0.01)
    a = Cosimulation([comp], {}).run(2.0)
    b = Cosimulation([fmu], {}).run(2.0)
    np.testing.assert_allclose(b["src.out"].to_numpy(), a["src.out"].to_numpy(), rtol=0, atol=1e-12)


@pytest.mark.parametrize("version", [2, 3])
def test_noise_and_sensor_fmus_equal_the_python_components(tmp_path, version):
    def parts(noise, sensor):
        return [noise, sensor, Sine("sig", 0.01, 1.0, 0.7)]

    wiring = {"sensor.a": "noise.w_a", "sensor.b": "sig.out"}
    noise = ProcessNoise("noise", 0.01, ["a", "b"], [0.2, 0.05], seed=5, generator="counter")
    sensor = Sensor("sensor", 0.01, ["a", "b"], noise_std=[0.3, 0.1], bias=[0.0, 0.2], quantization=[0.0, 0.05],
                    seed=9, generator="counter")
    py = Cosimulation(parts(noise, sensor), wiring).run(3.0, 0.5)        # also from a start time > 0
    n_fmu, s_fmu = noise.export_fmu(tmp_path, version), sensor.export_fmu(tmp_path, version)
    for e in (n_fmu, s_fmu):
        assert validate_fmu(str(e.path)) == [] and e.note == ""
    fm = Cosimulation(parts(FMUComponent("noise", n_fmu.path, 0.01), FMUComponent("sensor", s_fmu.path, 0.01)),
                      wiring).run(3.0, 0.5)
    cols = ["noise.w_a", "noise.w_b", "sensor.y_a", "sensor.y_b"]
    np.testing.assert_allclose(fm[cols].to_numpy(), py[cols].to_numpy(), rtol=0, atol=1e-12)
    q = fm["sensor.y_b"].to_numpy() / 0.05
    assert np.allclose(q, np.round(q))                                    # quantised


def test_signal_fmu_parameters_are_checked_with_a_message(tmp_path):
    path = PRBS("src", 0.01, 0.5, 0.07, 7, 28).export_fmu(tmp_path, 2).path
    for name, value, msg in (("order", 20, "order = 20 must be in [2, 16]"),
                             ("bit_time", -1.0, "bit_time = -1 must be > 0"),
                             ("period", float("nan"), "period = nan is not finite")):
        inst = Instance(str(path))
        with pytest.raises(Exception):
            inst.set(name, value)
            inst.init()
        assert any(msg in m for _, m in inst.messages), inst.messages
        inst.free()


def test_components_without_an_fmu_form_are_refused(tmp_path):
    with pytest.raises(ConfigurationError, match="a sensor with a delay has no FMU form"):
        Sensor("s", 0.01, ["x"], 0.1, delay=2).export_fmu(tmp_path)
    with pytest.raises(ConfigurationError, match="takes a diagonal cov"):
        ProcessNoise("n", 0.01, ["a", "b"], [[1.0, 0.5], [0.5, 1.0]]).export_fmu(tmp_path)
    from cosim import Cosimulation, ExportsFMU, Step

    lqr = LQRController("lqr", get_model("cartpole"), x_op=[0, 0, 0, 0], u_op=[0], period=0.01, Q=1.0, R=1.0)
    assert not isinstance(lqr, ExportsFMU)                  # a declared capability, not a refusal at run time
    src = Step("src", 0.01, 0.0, 0.0, 0.0)
    sim = Cosimulation([lqr, src], {f"lqr.{s}": "src.out" for s in lqr.input_names})
    with pytest.raises(ConfigurationError, match=r"component 'lqr' \(LQRController\) has no FMU form"):
        export_ssp(sim, tmp_path / "ssp")
    assert "generator" in Sensor("s", 0.01, ["x"], 0.1).export_fmu(tmp_path).note     # pcg64: said so


def test_shipped_sources_rebuild_the_fmu(tmp_path):
    """An FMU's sources/ compile on their own (what another platform does)."""
    import fmpy

    from fmu_models.export.pack import find_compiler

    ekf = EKF(discretize(get_model("cartpole"), 0.01), [0.5, 0, 1.8, 0.5], 1.0, 0.2, 0.1)
    comp = EstimatorComponent("ekf", lambda: ekf)
    path = comp.export_fmu(tmp_path / "out", 2).path
    with zipfile.ZipFile(path) as z:
        z.extractall(tmp_path / "x")
    md = (tmp_path / "x" / "modelDescription.xml").read_text()
    files = re.findall(r'<File name="([^"]+)"', md)
    src = tmp_path / "x" / "sources"
    lib = tmp_path / "rebuilt.so"
    subprocess.run([find_compiler(), "-shared", "-fPIC", "-std=c99", f"-I{src}",
                    f"-I{Path(fmpy.__file__).parent / 'c-code'}", *[str(src / f) for f in files],
                    "-o", str(lib), "-lm"], check=True, capture_output=True)
    binary = next((tmp_path / "x" / "binaries").rglob("*.so"))
    shutil.copy(lib, binary)                           # the FMU with the rebuilt binary still runs
    rebuilt = tmp_path / "rebuilt.fmu"
    with zipfile.ZipFile(rebuilt, "w") as z:
        for f in (tmp_path / "x").rglob("*"):
            if f.is_file():
                z.write(f, f.relative_to(tmp_path / "x"))
    inst = Instance(str(rebuilt)).init()
    inst.set("y_x", 0.5)
    inst.set("y_theta", 1.8)
    inst.do_step(0.0, 0.01)
    assert np.isfinite(inst.get("x", "theta")).all()
    inst.free()


# ---------------------------------------------------------------------------- SSP
@pytest.fixture(scope="module")
def seed000_ssp(tmp_path_factory):
    from cosim.scenario import Scenario

    out = tmp_path_factory.mktemp("ssp")
    scenario = Scenario.load(SCENARIO, fmu_dir=out / "build")
    return scenario, export_ssp(scenario, out / "ssp", name="seed000")


def test_seed000_ssp_loads_with_fmpy_and_runs_in_the_master_like_the_scenario(seed000_ssp):
    from fmpy.ssp.ssd import read_ssd

    scenario, ssp = seed000_ssp
    assert ssp.notes == []                              # the scenario uses the counter generator
    ssd = read_ssd(str(ssp.archive))                    # validates against the SSP 1.0 schema
    names = [e.name for e in ssd.system.elements]
    assert names == ["plant", "sensor", "ekf", "mfiae", "force", "noise"]
    params = {p.name: p.value for p in ssd.system.parameterBindings[0].parameterValues[0].parameters}
    assert params["plant.theta"] == "1.8" and params["ekf.Q0_x"] == "0.2"
    assert params["noise.std_w_x"] == repr(float(np.sqrt(0.2)))
    for fmu in ssp.fmus.values():
        assert validate_fmu(str(fmu)) == []
    reference = scenario.run()
    for source in (ssp.archive, ssp.ssd.parent, ssp.ssd):           # archive, folder, .ssd
        with open_ssp(source) as system:
            assert (system.start_time, system.stop_time) == (0.0, 5.0)
            got = system.run()
        assert list(got.columns) == list(reference.columns)
        np.testing.assert_allclose(got.to_numpy(), reference.to_numpy(), rtol=0, atol=1e-12)


def test_fmpy_simulate_ssp_gives_the_masters_plant_trajectory(seed000_ssp):
    """fmpy's SSP simulation (Jacobi, connectors start at 0: its first step sees no force
    and no noise) equals the project's master started from fmpy's state after that step."""
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import read_ssd

    from cosim.scenario import Scenario

    _, ssp = seed000_ssp
    values = read_ssd(str(ssp.archive)).system.parameterBindings[0].parameterValues[0]
    r = simulate_ssp(str(ssp.archive), stop_time=5.0, step_size=0.01, parameter_set=values)
    states = ["x", "x_dot", "theta", "theta_dot"]
    assert r["plant.x"][0] == 0.5           # x(0.01) = x0 + h x_dot0 after a step with w = 0 (Euler)
    spec = tomllib.loads(SCENARIO.read_text())
    spec["component"][0]["start"] = {s: float(r[f"plant.{s}"][0]) for s in states}
    spec["simulation"]["start_time"] = 0.01
    ours = Scenario(spec, SCENARIO.parent, fmu_dir=ssp.ssd.parent / "rebuild").run()
    # fmpy's row i holds the values after its step i, i.e. at t = (i + 1) h
    for s in states:
        np.testing.assert_allclose(r[f"plant.{s}"][:500], ours[f"plant.{s}"].to_numpy()[:500], rtol=0, atol=1e-12)


def test_export_refusals_name_every_problem(tmp_path, fmu_paths):
    model = get_model("cartpole")
    plant = FMUComponent("plant", fmu_paths["cartpole"], 0.01)
    lqr = LQRController("lqr", model, x_op=[0, 0, 0, 0], u_op=[0], period=0.01, Q=1.0, R=1.0)
    sensor = Sensor("sensor", 0.01, ["x"], delay=1)
    cosim = Cosimulation([plant, lqr, sensor], {"plant.F": "lqr.F", "sensor.x": "plant.x",
                                                **{f"lqr.{s}": f"plant.{s}" for s in model.state_names}})
    with pytest.raises(ConfigurationError) as e:
        export_ssp(cosim, tmp_path / "out")
    assert "'lqr' (LQRController) has no FMU form" in str(e.value) and "sensor: a sensor with a delay" in str(e.value)
    assert not any((tmp_path / "out").iterdir())                   # nothing half-written
    cp = discretize(model, 0.01)
    full = EstimatorComponent("ekf", lambda: EKF(cp, model.x0, 1.0, 0.2, 0.1), covariance="full")
    plant2 = FMUComponent("plant", fmu_paths["cartpole"], 0.01)
    probe = Sensor("probe", 0.01, ["p"])
    cosim = Cosimulation([plant2, full, probe], {"ekf.F": "plant.x", "ekf.y_x": "plant.y_x",
                                                 "ekf.y_theta": "plant.y_theta", "probe.p": "ekf.P_0_1"})
    with pytest.raises(ConfigurationError, match="the FMU of 'ekf' has no output 'P_0_1'"):
        export_ssp(cosim, tmp_path / "out2")


def test_open_ssp_refuses_bad_archives_and_cleans_up(tmp_path, seed000_ssp):
    import tempfile

    before = set(Path(tempfile.gettempdir()).glob("pendulum_cosim_ssp_*"))
    (tmp_path / "junk.ssp").write_bytes(b"not a zip")
    with pytest.raises(FMUError, match="not an SSP: not a zip archive"):
        with open_ssp(tmp_path / "junk.ssp"):
            pass
    with zipfile.ZipFile(tmp_path / "empty.ssp", "w") as z:
        z.writestr("readme.txt", "hello")
    with pytest.raises(FMUError, match="it has no SystemStructure.ssd"):
        with open_ssp(tmp_path / "empty.ssp"):
            pass
    _, ssp = seed000_ssp
    text = ssp.ssd.read_text()
    evil = tmp_path / "evil"
    evil.mkdir()
    (evil / "SystemStructure.ssd").write_text(text.replace('source="resources/plant.fmu"',
                                                           'source="../../etc/passwd"'))
    with pytest.raises(FMUError, match="points outside the SSP"):
        with open_ssp(evil):
            pass
    (evil / "SystemStructure.ssd").write_text(text.replace(
        "<ssd:Elements>", "<ssd:Elements><ssd:SignalDictionaryReference name='bus' dictionary='d'/>"))
    with pytest.raises(ConfigurationError, match="element 'bus' is a SignalDictionaryReference, which is not read"):
        with open_ssp(evil):
            pass
    (evil / "SystemStructure.ssd").write_text("<oops")
    with pytest.raises(FMUError, match="not valid XML"):
        with open_ssp(evil):
            pass
    with pytest.raises(FMUError, match="no SSP file"):
        with open_ssp(tmp_path / "missing.ssp"):
            pass
    assert set(Path(tempfile.gettempdir()).glob("pendulum_cosim_ssp_*")) == before


@pytest.mark.slow
def test_cli_export_fmu_and_ssp(tmp_path, capsys):
    assert main(["export-fmu", "seed000_cartpole", "--out", str(tmp_path / "f"), "--fmi-version", "3"]) == 0
    assert sorted(p.name for p in (tmp_path / "f").iterdir()) == [".pendulum-cosim-output", "ekf.fmu", "mfiae.fmu"]
    assert main(["export-fmu", "seed000_cartpole", "--out", str(tmp_path / "g"), "--component", "sensor"]) == 0
    assert main(["export-ssp", "seed000_cartpole", "--out", str(tmp_path / "s")]) == 0
    assert (tmp_path / "s" / "seed000_cartpole.ssp").is_file()
    capsys.readouterr()
    assert main(["export-fmu", "seed000_cartpole", "--out", str(tmp_path / "h"), "--component", "nope"]) == 2
    assert "no component 'nope'" in capsys.readouterr().err
    assert main(["export-ssp", "seed002_wheel_lqr", "--out", str(tmp_path / "lqr")]) == 2
    assert "'lqr' (LQRController) has no FMU form" in capsys.readouterr().err
    assert not (tmp_path / "lqr").exists()                         # the folder it created is gone
    assert main(["export-ssp", "seed000_cartpole", "--out", str(tmp_path / "s")]) == 2   # not empty
    assert "--overwrite" in capsys.readouterr().err
    assert main(["export-ssp", "seed000_cartpole", "--out", str(tmp_path / "s"), "--overwrite"]) == 0


def test_the_ssd_carries_the_step_size_where_omsimulator_reads_it(seed000_ssp):
    _, ssp = seed000_ssp
    text = ssp.ssd.read_text()
    assert ('<ssc:Annotation type="org.openmodelica">' in text
            and '<oms:FixedStepMaster description="oms-ma" stepSize="0.01"' in text)
    with open_ssp(ssp.archive) as system:
        assert system.step_size == 0.01


@pytest.mark.parametrize("h", [0.0025, 0.005, 0.01])
def test_a_fixed_step_master_with_a_step_dividing_the_period_reproduces_the_scenario(seed000_ssp, h):
    """Issue 19: the exported SSP, unedited, in a fixed-step Gauss-Seidel master with
    OMSimulator's time keeping (t += h, a last step of 6e-14 s at h = 0.01) equals the
    project's run at every sample instant: plant and estimates to 1e-12."""
    from testkit.fixed_step_master import run_fixed_step

    scenario, ssp = seed000_ssp
    ref = scenario.run()
    got = run_fixed_step(ssp.archive, h, 5.0)
    k = got["time"] / 0.01
    on = np.abs(k - np.round(k)) < 1e-6
    idx = np.round(k[on]).astype(int)
    assert len(np.unique(idx)) == 501 and (h != 0.01 or len(got["time"]) == 502)   # 500 + the 6e-14 s step
    first = np.unique(idx, return_index=True)[1]          # the first row of each instant
    cols = [c for c in ref.columns if c in got]
    assert {"plant.x", "plant.theta", "ekf.x", "ekf.theta", "mfiae.x", "sensor.y_x"} <= set(cols)
    for c in cols:
        np.testing.assert_allclose(got[c][on][first], ref[c].to_numpy(), rtol=0, atol=1e-12, err_msg=c)


@pytest.mark.parametrize("h", [0.02, 0.03])
def test_a_fixed_step_master_with_a_multiple_of_the_period_equals_the_master_at_that_step(seed000_ssp, h):
    """A step of several periods: every FMU keeps its own instants inside the step with
    its inputs held; the independent master equals the project's master driving the same
    SSP with that one communication step."""
    from testkit.fixed_step_master import run_fixed_step

    _, ssp = seed000_ssp
    stop = 4.98 if h == 0.03 else 5.0
    got = run_fixed_step(ssp.archive, h, stop)
    with open_ssp(ssp.archive, communication_step=h) as system:
        ours = system.run(stop)
    keep = np.r_[True, np.diff(got["time"]) > 1e-9]      # not the row after a last 1e-13 s step
    assert keep.sum() == len(ours)
    cols = [c for c in ours.columns if c in got]
    assert {"plant.x", "ekf.x", "mfiae.theta"} <= set(cols)
    for c in cols:
        np.testing.assert_allclose(got[c][keep], ours[c].to_numpy(), rtol=0, atol=1e-12, err_msg=c)


@pytest.mark.parametrize("version", [2, 3])
def test_a_plant_built_from_its_model_is_exported_in_the_version_asked_for(tmp_path, capsys, version):
    """``export-fmu --fmi-version 3`` of the scenario's plant (built from the model as FMI
    2.0 for the run) writes an FMI 3.0 FMU of the same model, and says so; the SSP of a
    scenario holds FMUs of the version asked for, plant included."""
    out = tmp_path / f"v{version}"
    assert main(["export-fmu", "seed000_cartpole", "--out", str(out), "--component", "plant",
                 "--fmi-version", str(version)]) == 0
    printed = capsys.readouterr().out
    assert read_model_description(str(out / "plant.fmu")).fmiVersion == f"{version}.0"
    assert f"FMI {version}.0" in printed
    assert ("built as FMI 3.0 from its model 'cartpole'" in printed) == (version == 3)
    assert main(["export-ssp", "seed000_cartpole", "--out", str(tmp_path / f"s{version}"), "--fmi-version",
                 str(version)]) == 0
    versions = {p.name: read_model_description(str(p)).fmiVersion
                for p in (tmp_path / f"s{version}" / "resources").glob("*.fmu")}
    assert set(versions.values()) == {f"{version}.0"}, versions

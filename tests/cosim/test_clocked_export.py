"""The clocked form through the scenario exports: ``export-fmu --clocked`` and
``export_ssp(clocked=True)`` write the estimators and signal FMUs with the input clock
``sample``; the clocked SSP runs in the master like the scenario."""
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu

from cosim.cli import main
from cosim.scenario import Scenario
from cosim.ssp import export_ssp, open_ssp
from fmu_models.errors import ConfigurationError

SCENARIO = Path(__file__).parents[2] / "cosim" / "scenarios" / "seed000_cartpole.toml"


def clocks(path) -> list[tuple]:
    md = read_model_description(str(path))
    return [(v.name, v.causality, v.intervalVariability) for v in md.modelVariables if v.type == "Clock"]


@pytest.mark.slow
def test_a_clocked_ssp_runs_in_the_master_like_the_scenario(tmp_path):
    scenario = Scenario.load(SCENARIO, fmu_dir=tmp_path / "build")
    ssp = export_ssp(scenario, tmp_path / "ssp", fmi_version=3, name="seed000", clocked=True)
    for name, fmu in ssp.fmus.items():
        assert validate_fmu(str(fmu)) == []
        assert clocks(fmu) == ([] if name == "plant" else [("sample", "input", "constant")]), name
    assert any("plant: an FMU component has no clocked form" in n for n in ssp.notes)
    reference = scenario.run()
    with open_ssp(ssp.archive) as system:
        assert [c.name for c in system.cosim.components if c.clock_model is not None] == \
            ["sensor", "ekf", "mfiae", "force", "noise"]
        got = system.run()
    assert list(got.columns) == list(reference.columns)
    np.testing.assert_allclose(got.to_numpy(), reference.to_numpy(), rtol=0, atol=1e-12)


@pytest.mark.slow
def test_cli_export_fmu_clocked(tmp_path, capsys):
    assert main(["export-fmu", "seed000_cartpole", "--out", str(tmp_path / "f"), "--fmi-version", "3",
                 "--clocked", "--component", "ekf", "--component", "sensor"]) == 0
    for name in ("ekf", "sensor"):
        assert clocks(tmp_path / "f" / f"{name}.fmu") == [("sample", "input", "constant")]
    assert "(EstimatorComponent ekf, FMI 3.0, clocked, period 0.01 s)" in capsys.readouterr().out
    assert main(["export-ssp", "seed000_cartpole", "--out", str(tmp_path / "s"), "--clocked"]) == 2
    err = capsys.readouterr().err
    assert "export-ssp: the clocked form needs FMI 3.0" in err and "Traceback" not in err
    assert not (tmp_path / "s").exists()


def test_export_ssp_refuses_the_clocked_form_in_fmi2(tmp_path):
    scenario = Scenario.load(SCENARIO, fmu_dir=tmp_path / "build")
    with pytest.raises(ConfigurationError, match="the SSP: the clocked form needs FMI 3.0"):
        export_ssp(scenario, tmp_path / "ssp", fmi_version=2, clocked=True)
    assert not (tmp_path / "ssp").exists()


def test_a_clocked_signal_fmu_keeps_its_period_and_samples_at_each_activation(tmp_path):
    """The clock's interval is the period: another period is refused leaving Initialization
    Mode, with the reason; with the declared one, each activation samples the sine at its time."""
    from fmpy import extract
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi3 import FMU3ScheduledExecution, fmi3LogMessageCallback

    from fmu_models.export.signal_fmu import SignalSpec, build_signal_fmu

    spec = SignalSpec("sine", 0.01, ["out"], reals=[("amplitude", 2.0, "real", "a"), ("frequency", 1.5, "real", "f"),
                                                    ("phase", 0.0, "real", "p"), ("offset", 0.5, "real", "o")])
    path = build_signal_fmu(spec, tmp_path, 3, "ClockedSine", clocked=True)
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    messages = []
    log = fmi3LogMessageCallback(lambda env, status, cat, msg: messages.append(msg.decode()))
    for period in (0.02, 0.01):
        fmu = FMU3ScheduledExecution(guid=md.guid, unzipDirectory=extract(str(path), str(tmp_path / str(period))),
                                     modelIdentifier=md.scheduledExecution.modelIdentifier, instanceName="sine")
        fmu.instantiate(loggingOn=True, logMessage=log)
        fmu.setFloat64([vr["period"]], [period])
        fmu.enterInitializationMode(startTime=0.0)
        if period != 0.01:
            with pytest.raises(FMICallException):
                fmu.exitInitializationMode()
            assert "period = 0.02 differs from the interval 0.01 s of the constant clock sample" in messages[-1]
        else:
            fmu.exitInitializationMode()
            got = []
            for k in range(5):
                fmu.activateModelPartition(vr["sample"], k * 0.01)
                got.append(fmu.getFloat64([vr["out"]])[0])
            np.testing.assert_allclose(got, 0.5 + 2.0 * np.sin(2 * np.pi * 1.5 * np.arange(5) * 0.01), rtol=0,
                                       atol=1e-15)
        fmu.freeInstance()

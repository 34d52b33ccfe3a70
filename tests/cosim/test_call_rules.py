"""The FMI call sequence on every path, checked by a hand-written FMU that logs each call
and each call the standard forbids (tests/data/call_rules): after Error only
FreeInstance, after Fatal nothing, Terminate only after a successful initialisation."""
from __future__ import annotations

import subprocess
import sys

import pytest

from cosim import Constant, Cosimulation, FMUComponent
from fmu_models.errors import CosimError

CLI = [sys.executable, "-c", "import sys; from cosim.cli import main; sys.exit(main())"]


@pytest.fixture
def call_log(tmp_path, monkeypatch):
    path = tmp_path / "calls.log"
    monkeypatch.setenv("CALL_RULES_LOG", str(path))

    def read() -> list[str]:
        return [line.split(" ", 1)[1] for line in path.read_text().splitlines()] if path.exists() else []
    return read


def _run(fmu, stop=0.05, **parameters):
    comp = FMUComponent("cr", fmu, 0.01, parameters=parameters or None)
    src = Constant("src", 0.01, 2.5)
    return Cosimulation([src, comp], {"cr.u": "src.out"}).run(stop)


def _after(calls: list[str], call: str, nth: int = 1) -> list[str]:
    """The calls after the ``nth`` occurrence of ``call``."""
    seen = 0
    for i, c in enumerate(calls):
        if c == call:
            seen += 1
            if seen == nth:
                return calls[i + 1:]
    raise AssertionError(f"{call} not called {nth} times: {calls}")


def test_a_normal_run_keeps_the_sequence(call_rules_fmu, call_log):
    df = _run(call_rules_fmu)
    calls = call_log()
    assert not [c for c in calls if "ILLEGAL" in c], calls
    assert calls[:4] == ["fmi2Instantiate", "fmi2SetupExperiment", "fmi2EnterInitializationMode",
                         "fmi2ExitInitializationMode"]
    assert calls.count("fmi2DoStep") == 5
    assert calls[-2:] == ["fmi2Terminate", "fmi2FreeInstance"]
    assert df["cr.y"].iloc[-1] == 2.5 and df["cr.x"].iloc[-1] == pytest.approx(0.05)


def test_parameters_are_set_before_initialisation(call_rules_fmu, call_log):
    _run(call_rules_fmu, fail_step=0, fail_status=1)
    calls = call_log()
    assert calls.index("fmi2SetInteger") < calls.index("fmi2EnterInitializationMode")
    assert not [c for c in calls if "ILLEGAL" in c], calls


def test_after_error_only_free_instance(call_rules_fmu, call_log):
    with pytest.raises(CosimError, match=r"cr.*fmi2DoStep\(t = .*\) returned error") as e:
        _run(call_rules_fmu, fail_step=3, fail_status=3)
    calls = call_log()
    assert not [c for c in calls if "ILLEGAL" in c], calls
    assert _after(calls, "fmi2DoStep", 3) == ["fmi2FreeInstance"]
    assert len(e.value.results) == 3                      # rows at 0, 0.01, 0.02 before the failure


def test_after_fatal_no_call_at_all(call_rules_fmu, call_log):
    with pytest.raises(CosimError, match=r"fmi2DoStep\(t = .*\) returned fatal"):
        _run(call_rules_fmu, fail_step=2, fail_status=4)
    calls = call_log()
    assert not [c for c in calls if "ILLEGAL" in c], calls
    assert _after(calls, "fmi2DoStep", 2) == []


def test_a_failed_initialisation_only_frees(call_rules_fmu, call_log):
    with pytest.raises(CosimError, match=r"\(reset\): cr: fmi2ExitInitializationMode returned error"):
        _run(call_rules_fmu, fail_init=1, fail_status=3)
    calls = call_log()
    assert not [c for c in calls if "ILLEGAL" in c], calls
    assert _after(calls, "fmi2ExitInitializationMode") == ["fmi2FreeInstance"]


def test_discard_that_is_no_stop_request_is_an_error_then_terminates(call_rules_fmu, call_log):
    """A discard without fmi2Terminated: the run fails naming it; the FMU (not in Error) is
    asked why, then terminated and freed."""
    with pytest.raises(CosimError, match=r"fmi2DoStep\(t = .*\) returned discard"):
        _run(call_rules_fmu, fail_step=2, fail_status=2)
    calls = call_log()
    assert not [c for c in calls if "ILLEGAL" in c], calls
    after = _after(calls, "fmi2DoStep", 2)
    assert after[0] == "fmi2GetBooleanStatus" and after[-2:] == ["fmi2Terminate", "fmi2FreeInstance"]


def test_warnings_do_not_stop_the_run(call_rules_fmu, call_log):
    df = _run(call_rules_fmu, fail_step=2, fail_status=1)
    assert len(df) == 6
    assert call_log()[-2:] == ["fmi2Terminate", "fmi2FreeInstance"]


def test_second_run_instantiates_afresh_after_an_error(call_rules_fmu, call_log):
    comp = FMUComponent("cr", call_rules_fmu, 0.01, parameters={"fail_step": 2})
    sim = Cosimulation([comp], {})
    for _ in range(2):
        with pytest.raises(CosimError):
            sim.run(0.05)
    calls = call_log()
    assert not [c for c in calls if "ILLEGAL" in c], calls
    assert calls.count("fmi2Instantiate") == 2 and calls.count("fmi2FreeInstance") == 2


def test_cli_names_the_failing_call(call_rules_fmu, call_log, tmp_path):
    sc = tmp_path / "s.toml"
    sc.write_text(f'[simulation]\nstop_time = 0.05\n[[component]]\nname = "cr"\ntype = "fmu"\n'
                  f'path = "{call_rules_fmu}"\nperiod = 0.01\nparameters = {{ fail_step = 3, fail_status = 3 }}\n')
    proc = subprocess.run([*CLI, "run", str(sc), "--out", str(tmp_path / "out"), "--no-progress"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0 and "Traceback" not in proc.stderr
    assert "fmi2DoStep(t = 0.02 s, h = 0.01 s) returned error" in proc.stderr
    assert not [c for c in call_log() if "ILLEGAL" in c]

"""Model Exchange on its error paths, with a hand-written FMI 2.0 FMU whose calls return Error
on request and which logs every call the standard forbids (tests/data/me_faults).

An FMU whose ``fmi2GetNominalsOfContinuousStates`` returns Error when the integrator starts
is not continued (after an Error only FreeInstance may follow): it runs on a new instance
with nominal values of 1, with a warning naming it. Every other failure ends the run with a
named error; no library prints a traceback on the way (fmpy's CVODE binding, SUNDIALS)."""
from __future__ import annotations

import logging
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from testkit import handwritten

from cosim import Cosimulation, FMUComponent, MESystem
from fmu_models.errors import CosimError

#: The MEFaults FMU's faults: the call that returns Error (see its C source).
FAULTS = {2: "fmi2GetContinuousStates", 3: "fmi2GetDerivatives", 4: "fmi2NewDiscreteStates",
          5: "fmi2GetEventIndicators", 6: "fmi2GetNominalsOfContinuousStates"}


@pytest.fixture(scope="module")
def faults_fmu(tmp_path_factory) -> Path:
    try:
        return handwritten.build("me_faults", "MEFaults", 2, tmp_path_factory.mktemp("mefaults"))
    except handwritten.NotBuildable as e:
        pytest.skip(str(e))


@pytest.fixture
def call_log(tmp_path, monkeypatch):
    path = tmp_path / "calls.log"
    monkeypatch.setenv("ME_FAULTS_LOG", str(path))
    return lambda: handwritten.logged_calls(path)


def _run(fmu, fault: int = 0, **options):
    return Cosimulation([FMUComponent("mf", fmu, 0.1, parameters={"fault": fault}, **options)], {}).run(1.0)


def test_nominals_error_at_the_start_runs_on_a_new_instance_with_unit_nominals(faults_fmu, call_log, caplog):
    with caplog.at_level(logging.WARNING, logger="cosim.fmu"):
        df = _run(faults_fmu, fault=1)
    calls = call_log()
    np.testing.assert_array_equal(df.to_numpy(), _run(faults_fmu).to_numpy())     # its nominals are 1 anyway
    warning = [r for r in caplog.records if r.name == "cosim.fmu" and r.levelno == logging.WARNING]
    assert len(warning) == 1 and warning[0].getMessage().startswith(
        "mf: MEFaults.fmu returned Error from fmi2GetNominalsOfContinuousStates when the integrator started")
    first = calls.index("fmi2GetNominalsOfContinuousStates")
    assert calls[first + 1:first + 3] == ["fmi2FreeInstance", "fmi2Instantiate"]      # only the free after Error
    assert calls.count("fmi2GetNominalsOfContinuousStates") == 1                      # never asked again
    assert df["mf.crossings"].iloc[-1] == 1 and df["mf.ticks"].iloc[-1] == 4


def test_the_fallback_is_kept_for_the_component_s_next_runs(faults_fmu, call_log, caplog):
    sim = Cosimulation([FMUComponent("mf", faults_fmu, 0.1, parameters={"fault": 1})], {})
    with caplog.at_level(logging.WARNING, logger="cosim.fmu"):
        first, second = sim.run(1.0), sim.run(1.0)
    np.testing.assert_array_equal(first.to_numpy(), second.to_numpy())
    assert caplog.text.count("returned Error from fmi2GetNominalsOfContinuousStates") == 1
    assert call_log().count("fmi2Instantiate") == 3


def test_nominals_error_later_in_the_run_ends_it(faults_fmu, call_log):
    """The call worked at the start; its Error at an event at 0.5 s is the instance's."""
    with pytest.raises(CosimError, match=r"mf: fmi2GetNominalsOfContinuousStates returned error"):
        _run(faults_fmu, fault=6)
    assert call_log()[-2:] == ["fmi2GetNominalsOfContinuousStates", "fmi2FreeInstance"]


def test_a_member_of_a_system_without_nominals(faults_fmu, call_log, caplog):
    def system(fault: int):
        members = [FMUComponent("a", faults_fmu, 0.1), FMUComponent("b", faults_fmu, 0.1, parameters={"fault": fault})]
        return Cosimulation([MESystem("sys", members, {"b.u": "a.x"}, 0.1)], {}).run(1.0)
    with caplog.at_level(logging.WARNING, logger="cosim.fmu"):
        df = system(1)
    np.testing.assert_array_equal(df.to_numpy(), system(0).to_numpy())
    assert "b: MEFaults.fmu returned Error from fmi2GetNominalsOfContinuousStates" in caplog.text
    call_log()


def test_an_isolated_fmu_without_nominals(faults_fmu, call_log):
    np.testing.assert_array_equal(_run(faults_fmu, fault=1, isolate=True).to_numpy(), _run(faults_fmu).to_numpy())
    call_log()


@pytest.mark.parametrize(("fault", "solver"), [(f, s) for f in sorted(FAULTS) for s in ("cvode", "rk4")
                                               if (f, s) != (6, "rk4")])        # a fixed step needs no nominals
def test_every_failure_is_a_named_error_and_only_frees(faults_fmu, call_log, fault, solver):
    with pytest.raises(CosimError, match=rf"mf: {FAULTS[fault]} returned error"):
        _run(faults_fmu, fault=fault, solver=solver)
    assert call_log()[-1] == "fmi2FreeInstance" and "fmi2Terminate" not in call_log()


def test_no_library_prints_a_traceback_on_any_failing_path(faults_fmu, tmp_path):
    """Every failure, alone and in a system, in a process of its own: stderr holds no
    traceback and no "Exception ignored" (fmpy's CVODE binding's destructor after a
    constructor that failed), not even after the garbage is collected."""
    code = textwrap.dedent(f"""
        import gc
        from cosim import Cosimulation, FMUComponent, MESystem
        from fmu_models.errors import CosimError
        fmu = {str(faults_fmu)!r}
        tries = [[FMUComponent("mf", fmu, 0.1, parameters={{"fault": f}}, solver=s)]
                 for f in {sorted(FAULTS)!r} for s in ("cvode", "euler")]
        tries += [[MESystem("sys", [FMUComponent("a", fmu, 0.1, parameters={{"fault": f}})], {{}}, 0.1)]
                  for f in {sorted(FAULTS)!r}]
        tries.append([FMUComponent("mf", fmu, 0.1, parameters={{"fault": 1}})])
        for components in tries:
            try:
                Cosimulation(components, {{}}).run(1.0, progress=False)
                print("ran")
            except CosimError as e:
                print("named:", str(e).splitlines()[0])
            gc.collect()
        """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "ME_FAULTS_LOG": str(tmp_path / "calls.log")})
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr, proc.stderr
    lines = proc.stdout.splitlines()
    assert len([x for x in lines if x.startswith("named:")]) == 3 * len(FAULTS) - 1 and lines[-1] == "ran", lines
    assert "ILLEGAL" not in (tmp_path / "calls.log").read_text()


def test_timing_says_the_solver_s_step(faults_fmu):
    """A Model Exchange FMU left at the default solver_step (None) says what it means."""
    timing = {s: FMUComponent("mf", faults_fmu, 0.1, solver=s).timing() for s in ("cvode", "euler")}
    assert "Model Exchange, cvode solver (variable step)" in timing["cvode"]
    assert "Model Exchange, euler solver (step 0.1 s)" in timing["euler"]
    assert "rk4 solver (step 0.01 s)" in FMUComponent("mf", faults_fmu, 0.1, solver="rk4", solver_step=0.01).timing()

"""FMUs in a process of their own (``isolate=True``): the same results, a crash or a hang
of the FMU's code ends in a named error with the partial results, nothing left behind."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from testkit import reference_cases as rc
from testkit.processes import processes_mentioning

from cosim import Constant, Cosimulation, FMUComponent
from fmu_models.errors import CosimError

CLI = [sys.executable, "-c", "import sys; from cosim.cli import main; sys.exit(main())"]
linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the test FMUs and /proc are Linux's")


def _children() -> list[int]:
    return processes_mentioning("cosim.fmi.isolated")


def _loop(fmu, isolate: bool, **parameters):
    comp = FMUComponent("cr", fmu, 0.01, isolate=isolate, parameters=parameters or None)
    return Cosimulation([Constant("src", 0.01, 2.5), comp], {"cr.u": "src.out"})


@linux_only
def test_isolated_gives_the_same_rows(call_rules_fmu):
    a, b = _loop(call_rules_fmu, False).run(0.5), _loop(call_rules_fmu, True).run(0.5)
    np.testing.assert_array_equal(a.to_numpy(), b.to_numpy())
    assert _children() == []


@pytest.mark.slow
@pytest.mark.skipif(rc.reference_dir() is None, reason="the Reference FMUs are absent")
@pytest.mark.parametrize("label", ["Stair-fmi2-cs", "Stair-fmi3-me", "BouncingBall-fmi3-me", "Feedthrough-fmi3-cs",
                                   "StateSpace-fmi3-cs"])
def test_isolated_reference_fmus_match(label):
    """Stop requests, events, every integer type and arrays across the process boundary."""
    case = next(c for c in rc.cases() if c.label == label)
    comp = lambda iso: FMUComponent("m", rc.fmu_path(case), case.period, interface=case.interface,  # noqa: E731
                                    rtol=rc.RTOL, isolate=iso)
    a = Cosimulation([comp(False)], {}).run(case.stop, case.start)
    b = Cosimulation([comp(True)], {}).run(case.stop, case.start)
    assert list(a.columns) == list(b.columns) and list(a.dtypes) == list(b.dtypes)
    np.testing.assert_array_equal(a.to_numpy(), b.to_numpy())
    assert a.attrs.get("stopped") == b.attrs.get("stopped")


@linux_only
def test_a_crash_is_a_named_error_with_partial_results(call_rules_fmu, tmp_path):
    sim = _loop(call_rules_fmu, True, crash_step=4)
    with pytest.raises(CosimError, match=r"cr: the process running CallRules.fmu died \(signal SIGSEGV\) during "
                                         r"setting the inputs or fmi2DoStep at t = 0.03 s") as e:
        sim.run(1.0)
    assert len(e.value.results) == 4 and e.value.component == "cr"
    assert _children() == []
    again = _loop(call_rules_fmu, True).run(0.05)       # the component is usable again
    assert len(again) == 6


@linux_only
def test_an_fmu_error_in_the_child_keeps_the_call_rules(call_rules_fmu, tmp_path, monkeypatch):
    log = tmp_path / "calls.log"
    monkeypatch.setenv("CALL_RULES_LOG", str(log))
    with pytest.raises(CosimError, match=r"fmi2DoStep\(t = 0.01 s, h = 0.01 s\) returned error"):
        _loop(call_rules_fmu, True, fail_step=2, fail_status=3).run(1.0)
    calls = log.read_text().splitlines()
    assert not [c for c in calls if "ILLEGAL" in c] and calls[-1].endswith("fmi2FreeInstance")
    assert _children() == []


def _scenario(tmp_path, fmu, **parameters) -> str:
    params = ", ".join(f"{k} = {v}" for k, v in parameters.items())
    sc = tmp_path / "s.toml"
    sc.write_text(f'[simulation]\nstop_time = 100.0\n[[component]]\nname = "cr"\ntype = "fmu"\npath = "{fmu}"\n'
                  f"period = 0.01\nisolate = true\nparameters = {{ {params} }}\n")
    return str(sc)


@pytest.mark.slow
@linux_only
def test_cli_crash_leaves_nothing_behind(call_rules_fmu, tmp_path):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    out = tmp_path / "out"
    proc = subprocess.run([*CLI, "run", _scenario(tmp_path, call_rules_fmu, crash_step=50), "--out", str(out),
                           "--no-progress"], capture_output=True, text=True, timeout=120,
                          env={**os.environ, "TMPDIR": str(tmp)})
    assert proc.returncode != 0 and "Traceback" not in proc.stderr
    assert "died (signal SIGSEGV)" in proc.stderr and "t = 0.49 s" in proc.stderr
    partial = [p for p in out.iterdir() if "partial" in p.name]
    assert partial, list(out.iterdir())
    assert list(tmp.iterdir()) == []                   # the unpacked FMU removed
    assert _children() == []


@pytest.mark.slow
@linux_only
def test_ctrl_c_ends_an_fmu_stuck_in_its_code(call_rules_fmu, tmp_path):
    """An FMU that never returns from doStep: Ctrl-C ends the run (exit 130), the child is
    killed, the partial results kept, the temporary folder removed."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    log = tmp_path / "calls.log"
    proc = subprocess.Popen([*CLI, "run", _scenario(tmp_path, call_rules_fmu, hang_step=20), "--out",
                             str(tmp_path / "out"), "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, "TMPDIR": str(tmp), "CALL_RULES_LOG": str(log)})
    t0 = time.monotonic()
    while not (log.exists() and log.read_text().count("fmi2DoStep") >= 20):
        assert time.monotonic() - t0 < 60 and proc.poll() is None, proc.stderr.read() if proc.poll() else "timeout"
        time.sleep(0.05)
    time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "interrupted" in err, err
    assert list(tmp.iterdir()) == []
    assert _children() == []

"""FMI 1.0 FMUs through the master: every FMI 1.0 Reference FMU (Co-Simulation equal to
fmpy's own run, Model Exchange within twice fmpy's own error against fmpy at rtol 1e-10),
through the Python API (FMUComponent and run_fmu) and a scenario file, on both engines and
isolated; and a
hand-written FMI 1.0 FMU (tests/data/call_rules1, Co-Simulation and Model Exchange in one
library) that logs every call the FMI 1.0 call sequences forbid, fails, returns Pending or
crashes on request. Every bad try is a named error, with no traceback and nothing left
behind."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest
from testkit import handwritten
from testkit import reference_cases as rc
from testkit.processes import processes_mentioning

from cosim import Constant, Cosimulation, FMUComponent, MESystem
from cosim.fmu_run import run_fmu
from fmu_models.errors import ConfigurationError, CosimError, FMUError

CLI = [sys.executable, "-c", "import sys; from cosim.cli import main; sys.exit(main())"]
CASES = rc.fmi1_cases()
needs_reference = pytest.mark.skipif(rc.fmi1_dir() is None, reason=(
    "the FMI 1.0 Reference FMUs are absent: expected ../shared/reference-fmus/fmi1 (with cs/ and me/) or that "
    "folder under the one named by PENDULUM_COSIM_REFERENCE_FMUS"))


def _leftovers() -> list[Path]:
    return sorted(Path(tempfile.gettempdir()).glob("pendulum_cosim_*"))


# ---------------------------------------------------------------------------- the Reference FMUs
@needs_reference
def test_every_fmi1_reference_fmu_is_a_case():
    """Six Co-Simulation FMUs and three Model Exchange ones (FMI 1.0 has one interface per FMU)."""
    assert [c.label for c in CASES] == [f"{m}-fmi1-cs" for m in ("BouncingBall", "Dahlquist", "Feedthrough",
                                                                   "Resource", "Stair", "VanDerPol")] + \
        [f"{m}-fmi1-me" for m in ("BouncingBall", "Dahlquist", "Feedthrough")]


def _check(case: rc.Case, df) -> dict:
    r = rc.compare(case, df)
    assert r["rows"] == len(df) > 0, r
    if case.interface == "cs":
        assert r["error"] <= 1e-12 and r["missing"] == 0, r
    else:
        assert r["columns"] == len(df.columns) and r["ratio"] <= 2.0, r
    return r


@needs_reference
@pytest.mark.parametrize("case", CASES, ids=[c.label for c in CASES])
def test_api(case: rc.Case):
    df = rc.run_api(case)
    _check(case, df)
    assert df.attrs["stopped"] is None and df.index[-1] == pytest.approx(case.stop, rel=1e-12)


@needs_reference
@pytest.mark.parametrize("case", CASES, ids=[c.label for c in CASES])
def test_cli(case: rc.Case, tmp_path):
    """A scenario file (``type = "fmu"``) through the command line's main(): the API's rows."""
    df, proc = rc.run_cli(case, tmp_path)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
    api = rc.run_api(case)
    assert list(df.columns) == list(api.columns)
    np.testing.assert_array_equal(df.to_numpy(float), api.to_numpy(float))
    assert _leftovers() == []


@needs_reference
@pytest.mark.parametrize("case", CASES, ids=[c.label for c in CASES])
def test_run_fmu_equals_fmpy(case: rc.Case):
    """The FMU file run on its own (its default experiment, a 500th of it the step) as fmpy's
    ``simulate_fmu`` runs it: Co-Simulation within 1e-12, Model Exchange within twice
    fmpy's own error against fmpy at rtol 1e-10."""
    from fmpy import simulate_fmu

    df = run_fmu(rc.fmu_path(case))
    kw = dict(output_interval=float(df.index[1] - df.index[0]), output=list(df.columns))
    if case.interface == "me":
        kw.update(fmi_type="ModelExchange", record_events=False)
    theirs = simulate_fmu(str(rc.fmu_path(case)), **kw)
    assert len(theirs) == len(df)
    np.testing.assert_allclose(df.index.to_numpy(), theirs["time"], rtol=0, atol=1e-9 * abs(theirs["time"][-1]))
    exact = simulate_fmu(str(rc.fmu_path(case)), relative_tolerance=1e-10, **kw) if case.interface == "me" else None
    for c in df.columns:
        ours, ref = df[c].to_numpy(float), theirs[c].astype(float)
        if exact is None:
            np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-12, err_msg=c)
        else:
            e = exact[c].astype(float)
            assert np.max(np.abs(ours - e)) <= 2 * np.max(np.abs(ref - e)) + 1e-12 * (1 + np.max(np.abs(e))), c


@needs_reference
@pytest.mark.parametrize("case", [c for c in CASES if c.interface == "cs"], ids=lambda c: c.label)
def test_co_simulation_runs_in_the_native_kernel_with_the_python_path_s_results(case: rc.Case):
    """fmiDoStep and fmiGetReal/fmiSetReal through the kernel's function pointers: the same
    rows, bit for bit; ``describe()`` says which path each FMU takes."""
    runs = {}
    for engine in ("python", "native"):
        sim = Cosimulation([FMUComponent("m", rc.fmu_path(case), case.period)], {}, engine=engine)
        runs[engine] = sim.run(case.stop, case.start).to_numpy()
    np.testing.assert_array_equal(runs["python"], runs["native"])
    comp = FMUComponent("m", rc.fmu_path(case), case.period)
    why = comp.native_reason()                 # integer ports are exchanged in Python
    assert (why is None) == (case.model in ("BouncingBall", "Dahlquist", "VanDerPol")), why
    text = Cosimulation([comp], {}).describe()
    assert ("native" if why is None else f"Python ({why})") in text and "FMI 1.0 Co-Simulation doStep" in text


@needs_reference
def test_model_exchange_says_it_runs_in_python():
    case = next(c for c in CASES if c.label == "BouncingBall-fmi1-me")
    comp = FMUComponent("m", rc.fmu_path(case), case.period)
    text = Cosimulation([comp], {}).describe()
    assert "Python (Model Exchange)" in text and "FMI 1.0 Model Exchange, cvode solver (variable step)" in text
    assert repr(comp).endswith("FMI 1.0 ME, period=0.01)")


@pytest.mark.slow
@needs_reference
@pytest.mark.parametrize("label", ["Stair-fmi1-cs", "Feedthrough-fmi1-cs", "BouncingBall-fmi1-me"])
def test_isolated_gives_the_same_rows(label):
    case = next(c for c in CASES if c.label == label)
    runs = [Cosimulation([FMUComponent("m", rc.fmu_path(case), case.period, rtol=rc.RTOL, isolate=iso)], {})
            .run(case.stop, case.start) for iso in (False, True)]
    np.testing.assert_array_equal(runs[0].to_numpy(), runs[1].to_numpy())
    assert processes_mentioning("cosim.fmi.isolated") == []


@needs_reference
def test_an_error_status_of_the_reference_fmu_is_named():
    """A start value of a variable the FMU does not let be set: its fmiSetReal returns Error
    before initialisation, named with the FMU's message; the folder goes with release()."""
    case = next(c for c in CASES if c.label == "BouncingBall-fmi1-cs")
    comp = FMUComponent("ball", rc.fmu_path(case), 0.01, start={"der(h)": 1.0})
    with pytest.raises(CosimError, match=r"ball: fmiSetReal\(der\(h\) = 1.0\) returned error: .+") as e:
        Cosimulation([comp], {}).run(0.1)
    assert "Traceback" not in str(e.value)
    comp.release()
    assert _leftovers() == []


# ---------------------------------------------------------------------------- the hand-written FMU
@pytest.fixture(scope="module")
def fmu1(tmp_path_factory) -> dict[str, Path]:
    """The hand-written FMI 1.0 FMU as Co-Simulation ("cs"), Co-Simulation with an
    asynchronous doStep ("async") and Model Exchange ("me")."""
    out = tmp_path_factory.mktemp("callrules1")
    paths = {}
    for kind in ("cs", "async", "me"):
        (out / kind).mkdir()
        try:
            paths[kind] = handwritten.build("call_rules1", "CallRules1", 1, out / kind, f"{kind}.xml")
        except handwritten.NotBuildable as e:
            pytest.skip(str(e))
    return paths


@pytest.fixture
def call_log(tmp_path, monkeypatch):
    path = tmp_path / "calls.log"
    monkeypatch.setenv("CALL_RULES_LOG", str(path))
    return lambda: handwritten.logged_calls(path)


def _run(fmu, stop=0.05, **parameters):
    comp = FMUComponent("cr", fmu, 0.01, parameters=parameters or None)
    return Cosimulation([Constant("src", 0.01, 2.5), comp], {"cr.u": "src.out"}).run(stop)


def _after(calls: list[str], call: str, nth: int = 1) -> list[str]:
    """The calls after the ``nth`` occurrence of ``call``."""
    at = [i for i, c in enumerate(calls) if c == call]
    assert len(at) >= nth, (call, nth, calls)
    return calls[at[nth - 1] + 1:]


def test_a_normal_run_keeps_the_fmi1_sequence(fmu1, call_log):
    df = _run(fmu1["cs"], fail_step=0)
    calls = call_log()
    assert calls[:3] == ["fmiInstantiateSlave", "fmiSetInteger", "fmiInitializeSlave"]
    assert calls.count("fmiDoStep") == 5 and calls[-2:] == ["fmiTerminateSlave", "fmiFreeSlaveInstance"]
    assert df["cr.y"].iloc[-1] == 2.5 and df["cr.time"].iloc[-1] == pytest.approx(0.05)
    assert "cr.minus_y" not in df.columns                  # a negated alias is no port


def test_integers_and_booleans_travel_as_fmi1_types(fmu1, call_log):
    """Integer and Boolean (a char in FMI 1.0) start values and connections, both ways."""
    a = FMUComponent("a", fmu1["cs"], 0.01, start={"k": -7, "b": True})
    b = FMUComponent("b", fmu1["cs"], 0.01)
    df = Cosimulation([a, b], {"b.k": "a.ko", "b.b": "a.bo"}).run(0.03)
    assert list(df["a.ko"]) == [-7] * 4 and list(df["a.bo"]) == [1] * 4
    assert list(df["b.ko"]) == [-7] * 4 and list(df["b.bo"]) == [1] * 4
    call_log()


def test_a_negated_alias_is_refused_by_name(fmu1):
    for kwargs in ({"outputs": ["minus_y"]}, {"start": {"minus_y": 1.0}}):
        with pytest.raises(ConfigurationError, match=r"'minus_y' cannot be .*FMI 1.0 negated alias"):
            FMUComponent("cr", fmu1["cs"], 0.01, **kwargs)


def test_after_error_only_the_free(fmu1, call_log):
    with pytest.raises(CosimError, match=r"cr: fmiDoStep\(t = 0.02 s, h = 0.01 s\) returned error: fmiDoStep "
                                         r"failed on request at t = 0.02 s") as e:
        _run(fmu1["cs"], fail_step=3, fail_status=3)
    assert _after(call_log(), "fmiDoStep", 3) == ["fmiFreeSlaveInstance"]
    assert len(e.value.results) == 3


def test_after_fatal_no_call_at_all(fmu1, call_log):
    with pytest.raises(CosimError, match=r"fmiDoStep\(t = .*\) returned fatal"):
        _run(fmu1["cs"], fail_step=2, fail_status=4)
    assert _after(call_log(), "fmiDoStep", 2) == []


def test_a_failed_initialisation_only_frees(fmu1, call_log):
    with pytest.raises(CosimError, match=r"\(reset\): cr: fmiInitializeSlave\(t = 0 s\) returned error"):
        _run(fmu1["cs"], fail_init=1, fail_status=3)
    assert _after(call_log(), "fmiInitializeSlave") == ["fmiFreeSlaveInstance"]


def test_discard_names_the_last_successful_time_then_terminates(fmu1, call_log):
    """FMI 1.0 has no stop request: a Discard is an error naming fmiLastSuccessfulTime; the
    FMU (not in Error) is then terminated and freed."""
    with pytest.raises(CosimError, match=r"fmiDoStep\(t = 0.01 s, h = 0.01 s; it computed up to t = 0.01 s "
                                         r"\(fmiLastSuccessfulTime\); FMI 1.0 has no stop request\) returned discard"):
        _run(fmu1["cs"], fail_step=2, fail_status=2)
    assert _after(call_log(), "fmiDoStep", 2) == ["fmiGetRealStatus", "fmiTerminateSlave", "fmiFreeSlaveInstance"]


def test_warnings_do_not_stop_the_run(fmu1, call_log, caplog):
    df = _run(fmu1["cs"], fail_step=2, fail_status=1)
    assert len(df) == 6 and call_log()[-2:] == ["fmiTerminateSlave", "fmiFreeSlaveInstance"]
    assert "[cr] fmiDoStep failed on request at t = 0.02 s" in caplog.text    # printf arguments formatted


def test_a_pending_step_is_waited_for_when_declared(fmu1, call_log):
    """canRunAsynchronuously: fmiGetStatus(fmiDoStepStatus) until the step is done; the same
    rows as without Pending; such an FMU runs in Python (the kernel cannot wait)."""
    sim = Cosimulation([Constant("src", 0.01, 2.5), FMUComponent("cr", fmu1["async"], 0.01, parameters={
        "fail_step": 2, "fail_status": 5, "pending_polls": 3})], {"cr.u": "src.out"})
    df = sim.run(0.05)
    np.testing.assert_array_equal(df.to_numpy(), _run(fmu1["cs"]).to_numpy())
    assert _after(call_log(), "fmiDoStep", 2)[:4] == ["fmiGetStatus"] * 4
    assert sim.component_paths()["cr"] == ("FMI 1.0 asynchronous doStep (canRunAsynchronuously: a Pending step is "
                                           "waited for)")


@pytest.mark.parametrize("engine", ["python", "native"])
def test_pending_without_the_declaration_is_cancelled_and_refused(fmu1, call_log, engine):
    comp = FMUComponent("cr", fmu1["cs"], 0.01, parameters={"fail_step": 2, "fail_status": 5})
    with pytest.raises(CosimError, match=r"fmiDoStep\(t = 0.01 s, h = 0.01 s\) returned pending, but "
                                         r"CallRules1.fmu does not declare canRunAsynchronuously \(FMI 1.0\)"):
        Cosimulation([comp], {}, engine=engine).run(0.05)
    assert _after(call_log(), "fmiDoStep", 2) == ["fmiCancelStep", "fmiFreeSlaveInstance"]


def test_second_run_instantiates_afresh_on_the_kept_library(fmu1, call_log):
    comp = FMUComponent("cr", fmu1["cs"], 0.01, parameters={"fail_step": 4})
    sim = Cosimulation([comp], {})
    for _ in range(2):
        with pytest.raises(CosimError):
            sim.run(0.05)
    assert Cosimulation([FMUComponent("cr", fmu1["cs"], 0.01)], {}).run(0.05).shape == (6, 4)
    calls = call_log()
    assert calls.count("fmiInstantiateSlave") == 3 and calls.count("fmiFreeSlaveInstance") == 3


# ---------------------------------------------------------------------------- Model Exchange
def _me(fmu, stop=1.0, **parameters):
    return Cosimulation([FMUComponent("me", fmu, 0.1, rtol=1e-8, parameters=parameters or None)], {}).run(stop)


def test_model_exchange_keeps_the_fmi1_sequence_and_its_events(fmu1, call_log):
    """x' = -x from 1: x(1) = 1/e; the state event at x = 0.5 and the time events every 0.25 s."""
    df = _me(fmu1["me"])
    assert df["me.x"].iloc[-1] == pytest.approx(np.exp(-1.0), rel=1e-6)
    assert df["me.crossings"].iloc[-1] == 1 and df["me.ticks"].iloc[-1] == 4
    calls = call_log()
    assert calls[:3] == ["fmiInstantiateModel", "fmiSetTime", "fmiInitialize"]
    assert calls.count("fmiEventUpdate") >= 5 and calls.count("fmiCompletedIntegratorStep") > 10
    assert calls[-2:] == ["fmiTerminate", "fmiFreeModelInstance"]


@pytest.mark.parametrize(("fail_call", "call"), [(1, "fmiGetDerivatives"), (2, "fmiEventUpdate"), (4, "fmiInitialize")])
def test_model_exchange_errors_only_free(fmu1, call_log, fail_call, call):
    with pytest.raises(CosimError, match=rf"me: {call} returned error: {call} failed on request"):
        _me(fmu1["me"], fail_call=fail_call)
    assert _after(call_log(), call)[-1:] == ["fmiFreeModelInstance"]
    assert "fmiTerminate" not in call_log()


def test_model_exchange_without_nominals_runs_on_a_new_instance(fmu1, call_log, caplog):
    df = _me(fmu1["me"], fail_call=3)
    np.testing.assert_array_equal(df.to_numpy(), _me(fmu1["me"]).to_numpy())
    assert "me: CallRules1.fmu returned Error from fmiGetNominalContinuousStates" in caplog.text
    calls = call_log()
    assert _after(calls, "fmiGetNominalContinuousStates")[:2] == ["fmiFreeModelInstance", "fmiInstantiateModel"]


def test_fmi1_members_of_a_model_exchange_system(fmu1, call_log):
    """a.x = exp(-t) drives b: b' = a.x - b, b(0) = 1, so b(t) = (1 + t) exp(-t)."""
    a, b = (FMUComponent(n, fmu1["me"], 0.1) for n in "ab")
    df = Cosimulation([MESystem("sys", [a, b], {"b.u": "a.x"}, 0.1, rtol=1e-8)], {}).run(1.0)
    t = df.index.to_numpy()
    np.testing.assert_allclose(df["sys.b.x"].to_numpy(), (1 + t) * np.exp(-t), rtol=1e-6)
    call_log()


# ---------------------------------------------------------------------------- hostile tries
@pytest.fixture
def bad_fmi1(tmp_path, fmu1) -> Path:
    """Broken FMI 1.0 FMUs made from the hand-written one."""
    with zipfile.ZipFile(fmu1["cs"]) as z:
        xml, binary = z.read("modelDescription.xml").decode(), z.read("binaries/linux64/CallRules1.so")
    variants = {"garbage": "<fmiModelDescription fmiVersion='1.0' modelName='x'><ModelVariables><oops",
                "no_identifier": xml.replace(' modelIdentifier="CallRules1"', ""),
                "no_states": xml.replace(' numberOfContinuousStates="0"', ""),
                "other_guid": xml.replace("{8e4f1a2b", "{00000000")}
    for name, text in variants.items():
        with zipfile.ZipFile(tmp_path / f"{name}.fmu", "w") as z:
            z.writestr("modelDescription.xml", text)
            z.writestr("binaries/linux64/CallRules1.so", binary)
    with zipfile.ZipFile(tmp_path / "no_binary.fmu", "w") as z:
        z.writestr("modelDescription.xml", xml)
        z.writestr("binaries/win64/CallRules1.dll", b"MZ")
    return tmp_path


@pytest.mark.parametrize(("name", "message"), [
    ("garbage", r"garbage.fmu: modelDescription.xml is not a valid FMI model description"),
    ("no_identifier", r"no_identifier.fmu declares no modelIdentifier for its Co-Simulation interface \(FMI 1.0\)"),
    ("no_states", r"no_states.fmu: modelDescription.xml is not a valid FMI model description"),
    ("no_binary", r"no_binary.fmu has no binary for this platform \(binaries/linux64/CallRules1.so\); it has "
                  r"binaries for: win64"),
    ("other_guid", r"fmiInstantiateSlave returned no instance"),
])
def test_broken_fmi1_fmus_are_named_errors(bad_fmi1, name, message, call_log):
    with pytest.raises((FMUError, CosimError), match=message):
        comp = FMUComponent("bad", bad_fmi1 / f"{name}.fmu", 0.01)
        try:
            Cosimulation([comp], {}).run(0.05)
        finally:
            comp.release()
    assert _leftovers() == []
    call_log()


@pytest.mark.slow
@pytest.mark.parametrize(("fmu", "table", "message"), [
    ("other_guid", "", "fmiInstantiateSlave returned no instance"),
    ("cs", "parameters = { fail_step = 3, fail_status = 3 }", "fmiDoStep(t = 0.02 s, h = 0.01 s) returned error")])
def test_the_command_line_says_it_in_one_line(fmu1, bad_fmi1, call_log, tmp_path, fmu, table, message):
    """A scenario file's FMI 1.0 FMU that cannot start, or fails in the run: one line, exit
    status 2, no traceback, nothing left behind."""
    sc = tmp_path / "s.toml"
    path = fmu1.get(fmu) or bad_fmi1 / f"{fmu}.fmu"
    sc.write_text(f'[simulation]\nstop_time = 0.05\n[[component]]\nname = "cr"\ntype = "fmu"\n'
                  f'path = "{path}"\nperiod = 0.01\n{table}\n')
    proc = subprocess.run([*CLI, "run", str(sc), "--out", str(tmp_path / "out"), "--no-progress"],
                          capture_output=True, text=True, timeout=120, env={**os.environ, "TMPDIR": str(tmp_path)})
    errors = [x for x in proc.stderr.splitlines() if x.startswith("error:")]
    assert proc.returncode == 2 and len(errors) == 1 and message in errors[0], proc.stderr
    assert "Traceback" not in proc.stderr
    assert not list(tmp_path.glob("pendulum_cosim_*"))
    call_log()


# ---------------------------------------------------------------------------- crashes
linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the crash checks read POSIX signals")


@pytest.mark.slow
@linux_only
def test_a_crash_is_named_by_the_guard(fmu1, tmp_path):
    code = textwrap.dedent(f"""
        from cosim import Cosimulation, FMUComponent
        comp = FMUComponent("cr", {str(fmu1["cs"])!r}, 0.01, parameters={{"crash_step": 3}})
        Cosimulation([comp], {{}}).run(1.0, progress=False)
        """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "TMPDIR": str(tmp_path)})
    assert proc.returncode == -signal.SIGSEGV
    line = next(x for x in proc.stderr.splitlines() if x.startswith("error: the FMU"))
    assert "component 'cr'" in line and "fmiDoStep at t = 0.02 s" in line and "isolate = true" in line, line
    assert "Traceback" not in proc.stderr
    assert not list(tmp_path.glob("pendulum_cosim_*"))


@linux_only
def test_an_isolated_crash_is_a_named_error(fmu1, call_log):
    comp = FMUComponent("cr", fmu1["cs"], 0.01, isolate=True, parameters={"crash_step": 3})
    with pytest.raises(CosimError, match=r"cr: the process running CallRules1.fmu died \(signal SIGSEGV\) during "
                                         r"setting the inputs or fmiDoStep at t = 0.02 s") as e:
        Cosimulation([comp], {}).run(1.0)
    assert len(e.value.results) == 3
    assert processes_mentioning("cosim.fmi.isolated") == []
    comp.release()
    assert _leftovers() == []

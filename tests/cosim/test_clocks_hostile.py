"""Clocks the master cannot honour, clocks the standard forbids, and failures during a
clocked run: each one refused or ended with a named error, the instance ended as the FMI
rules allow, nothing left behind.

The FMU is tests/data/clock_lab (see test_clocks.py); the model descriptions the standard
forbids are ClockLab's with one attribute changed.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cosim import Constant, Cosimulation, FMUComponent, MESystem, Sine
from cosim.core.clocking import MAX_TICKS, ClockTicks
from cosim.fmi.clock_se import SEClockedRun
from cosim.ssp import export_ssp
from fmu_models.errors import (
    ConfigurationError,
    CosimError,
    FMUError,
    Interrupted,
    ResourceError,
    TypeMismatchError,
    UnknownNameError,
)

P = 0.1
CLI = [sys.executable, "-c", "import sys; from cosim.cli import main; sys.exit(main())"]


def lab(path, interface="cs", name="m", period=P, **kw) -> FMUComponent:
    return FMUComponent(name, path, period, interface=interface, **kw)


def sourced(m, times=(5.0,), **kw):
    """m with a source for its triggered clock (no activation before 5 s by default)."""
    return Cosimulation([m, ClockTicks("src", P, times=list(times))], {f"{m.name}.cTrigger": "src.tick"}, **kw)


def mutated(fmu: Path, folder: Path, old: str, new: str, *more: tuple[str, str]) -> Path:
    """A copy of ``fmu`` whose modelDescription.xml has ``old`` replaced by ``new`` (and each
    further ``(old, new)`` pair)."""
    out = folder / "mutated.fmu"
    with zipfile.ZipFile(fmu) as z, zipfile.ZipFile(out, "w") as w:
        for item in z.infolist():
            data = z.read(item)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                for a, b in ((old, new), *more):
                    assert a in text, a
                    text = text.replace(a, b, 1)
                data = text.encode()
            w.writestr(item, data)
    return out


@pytest.fixture
def calls(tmp_path, monkeypatch):
    log = tmp_path / "calls.log"
    monkeypatch.setenv("CLOCK_FMU_LOG", str(log))
    return lambda: log.read_text().splitlines() if log.exists() else []


# ---------------------------------------------------------------- the run cannot honour it
def test_interval_not_a_multiple_of_the_period(clock_lab_fmu):
    """Period 0.15 s: cConst's 0.1 s falls between the instants; the message names the
    period that would honour it (0.05 s)."""
    with pytest.raises(ConfigurationError, match=r"clock 'cConst' \(constant\) ticks every 0.1 s from 0 s, but its "
                                                 r"interval 0.1 s is not a multiple of m's period 0.15 s.*A period of "
                                                 r"0.05 s .* would honour it"):
        sourced(lab(clock_lab_fmu, period=0.15))


def test_shift_not_a_multiple_of_the_period(clock_lab_fmu, tmp_path):
    bad = mutated(clock_lab_fmu, tmp_path, 'intervalDecimal="0.2"\n      shiftDecimal="0.1"',
                  'intervalDecimal="0.2"\n      shiftDecimal="0.05"')
    with pytest.raises(ConfigurationError, match=r"'cFixed'.*its shift 0.05 s is not a multiple of m's period 0.1 s.*"
                                                 r"0.05 s .* would honour it"):
        sourced(lab(bad))


def test_clock_intervals_not_a_multiple(clock_lab_fmu):
    with pytest.raises(ConfigurationError, match=r"'cFixed'.*interval 0.25 s is not a multiple.*0.05 s"):
        sourced(lab(clock_lab_fmu, clock_intervals={"cFixed": 0.25}))


@pytest.mark.parametrize("interface", ["cs", "me", "se"])
def test_interval_from_the_fmu_not_a_multiple(clock_lab_fmu, interface, calls):
    """cFixedP's interval comes from the FMU at initialisation (0.15 s here): refused there,
    before any step, named; the instance is ended and freed."""
    sim = sourced(lab(clock_lab_fmu, interface, start={"pFixedInterval": 0.15}))
    with pytest.raises(CosimError, match=r"\(reset\).*clock 'cFixedP' \(fixed\) has the interval 0.15 s \(from the "
                                         r"FMU at initialisation\), not a multiple of m's period 0.1 s; a period of "
                                         r"0.05 s would honour it") as e:
        sim.run(1.0)
    assert len(e.value.results) == 0
    lines = calls()
    assert lines[-1].endswith("FreeInstance") and not any("ILLEGAL" in x for x in lines)


def test_triggered_clock_without_source(clock_lab_fmu):
    with pytest.raises(ConfigurationError, match=r"triggered input clock m.cTrigger has no source: it is activated "
                                                 r"only through a clock connection"):
        Cosimulation([lab(clock_lab_fmu)], {})


def test_triggered_clock_not_offered_as_a_port(clock_lab_fmu):
    with pytest.raises(ConfigurationError, match=r"m.cTrigger has no source \(it is not among m's inputs: list it"):
        Cosimulation([lab(clock_lab_fmu, inputs=["uConst"])], {})


def test_clock_into_data_and_data_into_clock(clock_lab_fmu):
    m = lab(clock_lab_fmu)
    with pytest.raises(TypeMismatchError, match=r"src.tick -> m.uConst: a Clock output cannot drive a Float64 input: a "
                                                 r"clock connects only to a clock"):
        Cosimulation([m, ClockTicks("src", P, times=[0.5])], {"m.uConst": "src.tick", "m.cTrigger": "src.tick"})
    with pytest.raises(TypeMismatchError, match=r"u.out -> m.cTrigger: a Float64 output cannot drive a Clock input"):
        Cosimulation([m, Constant("u", P, 1.0)], {"m.cTrigger": "u.out"})


@pytest.mark.parametrize("name, words", [("cConst", "is a constant clock: it ticks on its own timing"),
                                         ("cCountdown", "is a countdown clock: it ticks on its own timing"),
                                         ("cOut", "'cOut' is not an FMU input")])
def test_clock_that_is_no_input(clock_lab_fmu, name, words):
    with pytest.raises((TypeMismatchError, UnknownNameError), match=words):
        lab(clock_lab_fmu, inputs=[name])


def test_clock_connection_to_itself(clock_lab_fmu):
    with pytest.raises(ConfigurationError, match=r"m.cOut -> m.cTrigger connects m to itself; .*countdown clock"):
        Cosimulation([lab(clock_lab_fmu)], {"m.cTrigger": "m.cOut"})


def test_cycle_of_clock_connections(clock_lab_fmu):
    a, b = lab(clock_lab_fmu, name="a"), lab(clock_lab_fmu, name="b")
    with pytest.raises(ConfigurationError, match=r"the clock connections form a cycle \(.*a.cOut -> b.cTrigger.*\)"):
        Cosimulation([a, b], {"b.cTrigger": "a.cOut", "a.cTrigger": "b.cOut"})


def test_sink_stepped_less_often_than_its_source(clock_lab_fmu):
    src = ClockTicks("src", 0.05, times=[0.25])
    with pytest.raises(ConfigurationError, match=r"src.tick -> m.cTrigger: m is stepped every 0.1 s, less often than "
                                                 r"its source src \(every 0.05 s\).*a period that divides 0.05 s"):
        Cosimulation([lab(clock_lab_fmu), src], {"m.cTrigger": "src.tick"})


@pytest.mark.parametrize("order", ["given", "jacobi"])
def test_clock_connections_need_the_auto_order(clock_lab_fmu, order):
    with pytest.raises(ConfigurationError, match=rf"clock connections need order = 'auto' \(got '{order}'\)"):
        sourced(lab(clock_lab_fmu), order=order)


def test_refused_options(clock_lab_fmu, typed_fmu, tmp_path):
    with pytest.raises(ConfigurationError, match=r"an FMU with clocks cannot be isolated"):
        lab(clock_lab_fmu, isolate=True)
    with pytest.raises(UnknownNameError, match=r"clock_intervals names 'cNone', not a clock; clocks: cConst"):
        lab(clock_lab_fmu, clock_intervals={"cNone": 0.2})
    with pytest.raises(ConfigurationError, match=r"clock 'cConst' \(input, constant\) takes no interval from the "
                                                 r"importer"):
        lab(clock_lab_fmu, clock_intervals={"cConst": 0.2})
    with pytest.raises(ConfigurationError, match=r"clock 'cFixedP' \(input, fixed, no intervalDecimal\) takes no"):
        lab(clock_lab_fmu, clock_intervals={"cFixedP": 0.2})
    for bad in (0.0, -0.1, float("nan"), float("inf"), "soon", True, None):
        with pytest.raises(ConfigurationError, match=r"clock_intervals cFixed"):
            lab(clock_lab_fmu, clock_intervals={"cFixed": bad})
    with pytest.raises(TypeMismatchError, match=r"clock_intervals must be a table"):
        lab(clock_lab_fmu, clock_intervals=[0.2])
    with pytest.raises(ConfigurationError, match=r"clock_intervals given, but TypedFeedthrough.fmu has no clocks"):
        FMUComponent("t", typed_fmu, P, clock_intervals={"x": 0.1})
    with pytest.raises(TypeMismatchError, match=r"'cConst' is of type Clock; only numeric and Boolean variables"):
        lab(clock_lab_fmu, start={"cConst": 1})


def test_ssp_and_me_system_refuse_a_clocked_fmu(clock_lab_fmu, tmp_path):
    m = lab(clock_lab_fmu)
    with pytest.raises(ConfigurationError, match=r"m: an FMU with clocks has no SSP form here"):
        export_ssp(sourced(m), tmp_path / "x.ssp")
    with pytest.raises(ConfigurationError, match=r"member 'm' has clocks; an ME system does not drive clocks"):
        MESystem("sys", [lab(clock_lab_fmu, "me")], {}, P)


def test_missing_interface_is_named(clock_lab_fmu, tmp_path):
    """A Scheduled Execution FMU asked for Co-Simulation: the interfaces it has are named."""
    se_only = mutated(clock_lab_fmu, tmp_path, '<ModelExchange modelIdentifier="ClockLab" '
                      'needsCompletedIntegratorStep="false"/>', "",
                      ('<CoSimulation modelIdentifier="ClockLab" canHandleVariableCommunicationStepSize="true" '
                       'hasEventMode="true"\n    mightReturnEarlyFromDoStep="true"/>', ""))
    with pytest.raises(ConfigurationError, match=r"has no Co-Simulation interface; it has: Scheduled Execution"):
        lab(se_only, "cs")
    assert lab(se_only, "auto").interface == "se"


# ---------------------------------------------------------------- the standard forbids it
FORBIDDEN = [
    ('name="cOut" valueReference="8" causality="output" intervalVariability="triggered"',
     'name="cOut" valueReference="8" causality="output" intervalVariability="constant" intervalDecimal="0.1"',
     r"'cOut' is an output clock with intervalVariability 'constant'; output clocks must be triggered"),
    ('name="cOut" valueReference="8" causality="output" intervalVariability="triggered"',
     'name="cOut" valueReference="8" causality="output" intervalVariability="triggered" priority="3"',
     r"'cOut' is an output clock with a priority; output clocks must not have one"),
    ('intervalVariability="constant" intervalDecimal="0.1"\n      supportsFraction="true" intervalCounter="1" '
     'resolution="10"', 'intervalVariability="constant"', r"'cConst' is a constant clock without intervalDecimal"),
    ('intervalVariability="countdown"', 'intervalVariability="countdown" intervalDecimal="0.1"',
     r"'cCountdown' \(countdown\) declares intervalDecimal, which only periodic clocks"),
    ('intervalDecimal="0.2"\n      shiftDecimal="0.1"', 'intervalDecimal="0"\n      shiftDecimal="0.1"',
     r"'cFixed': intervalDecimal must be > 0"),
    ('intervalDecimal="0.2"\n      shiftDecimal="0.1"', 'intervalDecimal="NaN"\n      shiftDecimal="0.1"',
     r"'cFixed': intervalDecimal must be finite"),
    ('intervalDecimal="0.2"\n      shiftDecimal="0.1"', 'intervalDecimal="INF"\n      shiftDecimal="0.1"',
     r"'cFixed': intervalDecimal must be finite"),
    ('intervalDecimal="0.2"\n      shiftDecimal="0.1"', 'intervalDecimal="a lot"\n      shiftDecimal="0.1"',
     r"'cFixed': intervalDecimal must be a number"),
    ('intervalDecimal="0.2"\n      shiftDecimal="0.1"', 'intervalDecimal="0.2"\n      shiftDecimal="-0.1"',
     r"'cFixed': shiftDecimal must be >= 0"),
    ('supportsFraction="true" intervalCounter="1" resolution="10"', 'intervalCounter="1" resolution="10"',
     r"'cConst' declares intervalCounter, which only a periodic clock with supportsFraction = true"),
    ('supportsFraction="true" intervalCounter="1" resolution="10"', 'supportsFraction="true" intervalCounter="1"',
     r"'cConst' declares intervalCounter without resolution"),
    ('supportsFraction="true" intervalCounter="1" resolution="10"',
     'supportsFraction="true" intervalCounter="1" resolution="0"', r"'cConst': resolution must be > 0"),
    ('supportsFraction="true" intervalCounter="1" resolution="10"',
     'supportsFraction="true" intervalCounter="2" resolution="10"',
     r"'cConst': intervalDecimal 0.1 s disagrees with intervalCounter / resolution = 2/10 s"),
    ('supportsFraction="true" intervalCounter="1" resolution="10"',
     'supportsFraction="true" intervalCounter="-1" resolution="10"', r"'cConst': intervalCounter must be >= 0"),
    ('intervalVariability="changing"', 'intervalVariability="changing" shiftCounter="2"',
     r"'cChanging' declares shiftCounter without intervalCounter"),
    ('intervalVariability="changing"', 'intervalVariability="sometimes"',
     r"'cChanging' has intervalVariability 'sometimes'; it must be one of constant, fixed"),
    ('name="cTrigger" valueReference="7" causality="input"', 'name="cTrigger" valueReference="7" causality="parameter"',
     r"'cTrigger' has causality 'parameter'; a clock must be an input, output or local"),
    ('name="uConst" valueReference="20" causality="input" variability="discrete" clocks="1"',
     'name="uConst" valueReference="20" causality="input" variability="discrete" clocks="21"',
     r"variable 'uConst' is clocked by value reference 21, which is not a clock"),
    ('hasEventMode="true"', 'hasEventMode="false"',
     r"declares clocks but its Co-Simulation interface has no Event Mode"),
]


@pytest.mark.parametrize("old, new, words", FORBIDDEN, ids=[w[:40] for _, _, w in FORBIDDEN])
def test_forbidden_by_the_standard(clock_lab_fmu, tmp_path, old, new, words):
    with pytest.raises(FMUError, match=words):
        lab(mutated(clock_lab_fmu, tmp_path, old, new))


def test_scheduled_execution_needs_priorities_and_no_local_clock(clock_lab_fmu, tmp_path):
    no_priority = mutated(clock_lab_fmu, tmp_path, 'intervalVariability="changing" priority="4"',
                          'intervalVariability="changing"')
    lab(no_priority, "cs")                                      # ignored in CS and ME
    with pytest.raises(FMUError, match=r"input clock 'cChanging' has no priority; Scheduled Execution requires one"):
        lab(no_priority, "se")
    local = mutated(clock_lab_fmu, tmp_path, 'name="cAlarm" valueReference="9" causality="output"',
                    'name="cAlarm" valueReference="9" causality="local"')
    with pytest.raises(FMUError, match=r"'cAlarm' is a local clock, which Scheduled Execution does not allow"):
        lab(local, "se")


def test_cs_without_variable_steps_refuses_an_activation_between_instants(clock_lab_fmu, tmp_path, calls):
    fixed = mutated(clock_lab_fmu, tmp_path, 'canHandleVariableCommunicationStepSize="true"',
                    'canHandleVariableCommunicationStepSize="false"')
    sim = sourced(lab(fixed, start={"pCountdown": 0.05}))
    with pytest.raises(CosimError, match=r"an activation at t = 0.35 s falls between its communication points, but "
                                         r"the FMU cannot vary its communication step"):
        sim.run(1.0)
    assert not any("ILLEGAL" in x for x in calls())


# ---------------------------------------------------------------- failures during a run
@pytest.mark.parametrize("interface", ["cs", "me", "se"])
def test_fmu_error_during_a_tick(clock_lab_fmu, interface, calls):
    """The FMU fails at its event update at 0.3 s: the run ends with the call, the status
    and the FMU's message named, the rows until then kept, the instance freed without
    fmi3Terminate (after an error only fmi3FreeInstance is allowed)."""
    sim = sourced(lab(clock_lab_fmu, interface, start={"pFailAt": 0.3}))
    call = "ActivateModelPartition\\(cConst, t = 0.3 s\\)" if interface == "se" else \
        "UpdateDiscreteStates\\(t = 0.3 s\\)"
    with pytest.raises(CosimError, match=rf"m: fmi3{call} returned error: requested failure \(pFailAt\)") as e:
        sim.run(1.0)
    assert e.value.component == "m" and e.value.time == pytest.approx(0.3)
    assert len(e.value.results) == (3 if interface == "se" else 4)
    lines = calls()
    failed = next(i for i, x in enumerate(lines) if "requested failure" in x)
    assert [x.split()[1] for x in lines[failed + 1:]] == ["FreeInstance"]


def test_ctrl_c_in_the_clock_update_callback(clock_lab_fmu, monkeypatch, calls):
    """Ctrl-C while the FMU is inside its clockUpdate callback (Python code called from C):
    kept until fmi3ActivateModelPartition returns, then the run stops as for any Ctrl-C
    (Interrupted, rows so far), the instance ended and freed."""
    original = SEClockedRun._intervals

    def interrupted(self, clocks):
        if self.in_callback and self.now is not None and self.now > 0.45:
            os.kill(os.getpid(), signal.SIGINT)              # Ctrl-C arrives inside the callback
        return original(self, clocks)

    monkeypatch.setattr(SEClockedRun, "_intervals", interrupted)
    sim = sourced(lab(clock_lab_fmu, "se"))
    with pytest.raises(Interrupted, match=r"interrupted at t = 0.5 s") as e:
        sim.run(1.0)
    assert len(e.value.partial) == 5
    assert calls()[-1].endswith("FreeInstance")


def test_ticks_flood_is_refused(clock_lab_fmu):
    src = ClockTicks("src", P, interval=1e-9)
    sim = Cosimulation([lab(clock_lab_fmu), src], {"m.cTrigger": "src.tick"})
    with pytest.raises(ResourceError, match=rf"more than {MAX_TICKS}"):
        sim.run(1.0)


@pytest.mark.parametrize("kw, words", [
    (dict(times=[0.1], interval=0.1), "give either times"), (dict(), "give either times"),
    (dict(times=[0.1, float("nan")]), "times"), (dict(times=[0.2, 0.2]), "0.2 s is given twice"),
    (dict(times="0.1 0.2"), "times must be a list"), (dict(interval=0.0), "interval"),
    (dict(interval=0.1, shift=-1), "shift must be >= 0"), (dict(interval=float("inf")), "interval")])
def test_clock_ticks_arguments(kw, words):
    with pytest.raises(ConfigurationError, match=words):
        ClockTicks("src", P, **kw)


def test_clock_ticks_before_the_start(clock_lab_fmu):
    sim = Cosimulation([lab(clock_lab_fmu), ClockTicks("src", P, times=[0.05, 0.5])], {"m.cTrigger": "src.tick"})
    with pytest.raises(ConfigurationError, match=r"activation time 0.05 s is before the start time 0.1 s"):
        sim.run(1.0, 0.1)


def test_two_runs_give_the_same_result(clock_lab_fmu):
    """A component reused: every run starts from a fresh instance and schedule."""
    m = lab(clock_lab_fmu)
    sim = Cosimulation([m, ClockTicks("src", P, times=[0.25]), Sine("u", P, 1.0, 1.0)],
                       {"m.cTrigger": "src.tick", "m.uConst": "u.out"})
    a, ta = sim.run(1.0), sim.clock_ticks
    b, tb = sim.run(1.0), sim.clock_ticks
    pd.testing.assert_frame_equal(a, b)
    pd.testing.assert_frame_equal(ta, tb)


SCENARIO = """title = "clocked"
[simulation]
stop_time = 1.0

[[component]]
name = "m"
type = "fmu"
path = "{path}"
period = 0.1
interface = "{interface}"
clock_intervals = {{ cFixed = 0.4 }}

[[component]]
name = "src"
type = "clock_ticks"
period = 0.1
times = [0.25, 0.5]

[connections]
"m.cTrigger" = "src.tick"
"""


def test_scenario_dry_run_lists_the_clocks(clock_lab_fmu, tmp_path):
    """From a scenario file, --dry-run lists every clock's timing and connections."""
    (tmp_path / "s.toml").write_text(SCENARIO.format(path=clock_lab_fmu, interface="se"))
    dry = subprocess.run([*CLI, "run", "s.toml", "--dry-run"], cwd=tmp_path, capture_output=True, text=True)
    assert dry.returncode == 0, dry.stderr
    assert "m.cFixed: fixed, every 0.4 s from 0.1 s; interval set by the component (clock_intervals)" in dry.stdout
    assert "src.tick: output clock, activated at 0.25, 0.5 s; drives m.cTrigger" in dry.stdout
    assert "src.tick -> m.cTrigger: clock connection" in dry.stdout


@pytest.mark.slow
def test_two_runs_at_once(clock_lab_fmu, tmp_path):
    """Two runs of a clocked scenario at once into two folders both finish, with the same
    results and activations, and leave no unpacked FMU behind."""
    (tmp_path / "s.toml").write_text(SCENARIO.format(path=clock_lab_fmu, interface="se"))
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    env = {**os.environ, "TMPDIR": str(tmp)}
    procs = [subprocess.Popen([*CLI, "run", "s.toml", "--out", f"out{i}", "--no-progress"], cwd=tmp_path, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for i in (1, 2)]
    for p in procs:
        _, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
    r1, r2 = (pd.read_csv(tmp_path / f"out{i}" / "results.csv") for i in (1, 2))
    pd.testing.assert_frame_equal(r1, r2)
    t1, t2 = (pd.read_csv(tmp_path / f"out{i}" / "clock_ticks.csv") for i in (1, 2))
    pd.testing.assert_frame_equal(t1, t2)
    assert list(t1.columns) == ["time", "clock"]
    np.testing.assert_allclose(t1.time[t1.clock == "m.cFixed"], [0.1, 0.5, 0.9])
    assert list(tmp.iterdir()) == []


def test_cli_refusal_has_no_traceback(clock_lab_fmu, tmp_path):
    (tmp_path / "s.toml").write_text(SCENARIO.format(path=clock_lab_fmu, interface="cs").replace(
        "period = 0.1\ninterface", "period = 0.15\ninterface", 1))
    proc = subprocess.run([*CLI, "run", "s.toml", "--out", "out", "--no-progress"], cwd=tmp_path, capture_output=True,
                          text=True)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and "A period of 0.05 s" in proc.stderr
    assert not (tmp_path / "out").exists()


def test_clock_port_of_a_component_without_clocks(clock_lab_fmu):
    """A Python component that declares a Clock port but no clocks cannot take part."""
    from cosim import CLOCK, Component, Port

    class Fake(Component):
        def __init__(self):
            super().__init__("fake", P, outputs=[Port("tick", CLOCK)], feedthrough=False)

        def output(self, t, u):
            return np.array([0.0])

    with pytest.raises(ConfigurationError, match=r"component 'fake' has the clock port 'tick' but declares no clocks"):
        Cosimulation([lab(clock_lab_fmu), Fake()], {"m.cTrigger": "fake.tick"})


@pytest.mark.parametrize("interface", ["cs", "se"])
def test_huge_interval(clock_lab_fmu, interface, calls):
    """An interval of 1e300 s (a multiple of the period): the clock ticks once, at its shift,
    and the pattern of the periodic clocks is computed per instant instead of ahead."""
    sim = sourced(lab(clock_lab_fmu, interface, clock_intervals={"cFixed": 1e300}))
    assert "m.cFixed: fixed, every 1e+300 s from 0.1 s" in sim.describe()
    sim.run(1.0)
    ticks = sim.clock_ticks
    np.testing.assert_allclose(ticks.time[ticks.clock == "m.cFixed"], [0.1])
    assert not any("ILLEGAL" in x for x in calls())

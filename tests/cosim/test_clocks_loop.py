"""A clocked control loop through the master against a hand-written reference loop.

The loop (tests/data/clock_loop, third-party FMI 3.0 FMUs): a Model Exchange plant, a
Model Exchange supervisor whose state event (between base instants) ticks its output clock
``alarm``, and a Co-Simulation controller with Event Mode whose ``sample`` clock ticks at
every instant and whose triggered clock ``mode`` is connected to ``alarm``. The reference
loop below drives the same FMUs through fmpy's FMU3Model / FMU3Slave classes, written from
the FMI 3.0 call sequences (Event Mode, fmi3SetClock, clocked variables exchanged at their
ticks, fmi3GetClock, the event iteration, Step and Continuous-Time Mode) and the master's
documented timing (zero-order hold on a 10 ms grid, outputs at an instant before updates,
an activation between instants at its exact time, Euler steps of 1 ms with state events at
the step where an indicator changes sign), independently of the master's code.
"""
from __future__ import annotations

import ctypes
import os

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Model, FMU3Slave
from testkit.scenario_files import component, write_scenario

from cosim import Cosimulation, FMUComponent

H, H_INT, STOP = 0.01, 0.001, 3.0
COLUMNS = ["plant.p", "plant.v", "supervisor.s", "supervisor.level", "supervisor.alarms", "supervisor.alarm",
           "controller.u", "controller.lastLevel", "controller.modes", "controller.ref"]


def _master(paths, solver="euler"):
    plant = FMUComponent("plant", paths["plant"], H, solver=solver, solver_step=H_INT)
    sup = FMUComponent("supervisor", paths["supervisor"], H, solver=solver, solver_step=H_INT)
    ctl = FMUComponent("controller", paths["controller"], H)
    return Cosimulation([ctl, sup, plant], {"plant.u": "controller.u", "controller.y": "plant.p",
                                            "supervisor.p": "plant.p", "controller.mode": "supervisor.alarm",
                                            "controller.level": "supervisor.level"})


class _ME:
    """One Model Exchange FMU under the reference loop: explicit Euler of fixed steps,
    a last partial step ending on the communication point, a state event at the end of the
    step in which an event indicator changed its sign."""

    def __init__(self, path, name):
        md = read_model_description(path)
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.fmu = FMU3Model(guid=md.guid, unzipDirectory=extract(path), modelIdentifier="ClockLoop",
                             instanceName=name)
        self.fmu.instantiate()
        self.nx, self.nz = md.numberOfContinuousStates, md.numberOfEventIndicators
        self.x, self.dx = (ctypes.c_double * max(self.nx, 1))(), (ctypes.c_double * max(self.nx, 1))()
        self.z = (ctypes.c_double * max(self.nz, 1))()

    def read(self):
        self.fmu.getContinuousStates(self.x, self.nx)
        if self.nz:
            self.fmu.getEventIndicators(self.z, self.nz)

    def iterate(self):
        while True:
            need, term, *_ = self.fmu.updateDiscreteStates()
            assert not term
            if not need:
                return

    def advance(self, t, t_end, on_event):
        """Integrate from t to t_end; ``on_event(te)`` handles a state event (in Event Mode
        and back); returns the time of an event at t_end left for the next instant, or None."""
        tiny = 1e-12 * max(1.0, abs(t_end))
        while t < t_end - tiny:
            tn = min(t_end, t + H_INT)
            if t_end - tn < tiny:
                tn = t_end
            self.fmu.getContinuousStateDerivatives(self.dx, self.nx)
            for i in range(self.nx):
                self.x[i] = self.x[i] + (tn - t) * self.dx[i]
            self.fmu.setTime(t + (tn - t))
            self.fmu.setContinuousStates(self.x, self.nx)
            if self.nz:
                before = [np.sign(self.z[i]) for i in range(self.nz)]
                self.fmu.getEventIndicators(self.z, self.nz)
                if any(np.sign(self.z[i]) != before[i] for i in range(self.nz)):
                    if abs(tn - t_end) <= 1e-9 * H:
                        return tn                      # handled in the next instant's Event Mode
                    on_event(tn)
                    self.read()
            t = tn
        return None


def reference_loop(paths):
    """The loop, by hand: rows at every instant and the activation times of alarm and mode."""
    plant, sup = _ME(paths["plant"], "plant"), _ME(paths["supervisor"], "supervisor")
    md = read_model_description(paths["controller"])
    cvr = {v.name: v.valueReference for v in md.modelVariables}
    ctl = FMU3Slave(guid=md.guid, unzipDirectory=extract(paths["controller"]), modelIdentifier="ClockLoop",
                    instanceName="controller")
    ctl.instantiate(eventModeUsed=True, earlyReturnAllowed=True)
    pv, sv = plant.vr, sup.vr
    for me in (plant, sup):
        me.fmu.enterInitializationMode(startTime=0.0)
        me.fmu.exitInitializationMode()                          # Event Mode
    ctl.enterInitializationMode(startTime=0.0)
    ctl.exitInitializationMode()                                 # Event Mode (eventModeUsed)
    state = {"level": 0.0, "alarms": 0, "count": 0, "lastLevel": 0.0, "modes": 0, "u": 0.0, "ref": 0.0}
    alarm_times, mode_times, rows = [], [], []
    pending_alarm = None                                         # a state event at an instant
    events = []                                                  # the alarms of one step: (time, level)

    def alarm_in_event_mode(te):
        """The supervisor in Event Mode at te: its output clock and the variables it clocks."""
        (ticked,) = sup.fmu.getClock([sv["alarm"]])
        if ticked:
            state["count"] += 1
            state["level"], = sup.fmu.getFloat64([sv["level"]])
            state["alarms"], = sup.fmu.getInt32([sv["alarms"]])
            alarm_times.append(te)
        return ticked

    n = round(STOP / H)
    for k in range(n + 1):
        t = k * H
        # ---- outputs at t, in the order of direct dependencies: plant, supervisor, controller
        p, v = plant.fmu.getFloat64([pv["p"], pv["v"]])
        mode_now = False
        if k == 0:                                               # the supervisor's first Event Mode
            alarm_in_event_mode(t)
            sup.fmu.setFloat64([sv["p"]], [p])
        elif pending_alarm is not None:
            sup.fmu.enterEventMode()
            mode_now = alarm_in_event_mode(t)
            sup.fmu.setFloat64([sv["p"]], [p])
        else:
            sup.fmu.setFloat64([sv["p"]], [p])
        s, = sup.fmu.getFloat64([sv["s"]])
        state["ref"], = ctl.getFloat64([cvr["ref"]])             # unclocked: in Step Mode, before any set
        if k > 0:
            ctl.enterEventMode()
        clocks = [cvr["sample"]] + ([cvr["mode"]] if mode_now else [])
        ctl.setClock(clocks, [True] * len(clocks))
        ctl.setFloat64([cvr["y"]], [p])
        if mode_now:
            ctl.setFloat64([cvr["level"]], [state["level"]])
            mode_times.append(t)
        state["u"], = ctl.getFloat64([cvr["u"]])
        if mode_now:
            state["lastLevel"], = ctl.getFloat64([cvr["lastLevel"]])
            state["modes"], = ctl.getInt32([cvr["modes"]])
        rows.append([p, v, s, state["level"], state["alarms"], state["count"], state["u"], state["lastLevel"],
                     state["modes"], state["ref"]])
        if k == n:
            break
        # ---- updates: the supervisor (the clock's source) first, then the controller, the plant
        end = t + H
        if k == 0 or pending_alarm is not None:
            sup.fmu.setFloat64([sv["p"]], [p])
            sup.iterate()
            sup.fmu.enterContinuousTimeMode()
            sup.read()
            pending_alarm = None
        events.clear()

        def sup_event(te):
            sup.fmu.enterEventMode()
            if alarm_in_event_mode(te):
                events.append((te, state["level"]))
            sup.iterate()
            sup.fmu.enterContinuousTimeMode()

        pending_alarm = sup.advance(t, end, sup_event)
        ctl.updateDiscreteStates()
        ctl.enterStepMode()
        tc = t
        for te, level in events:                                 # the mode clock at each alarm
            ctl.doStep(tc, te - tc)
            ctl.enterEventMode()
            ctl.setClock([cvr["mode"]], [True])
            ctl.setFloat64([cvr["level"]], [level])
            state["lastLevel"], = ctl.getFloat64([cvr["lastLevel"]])
            state["modes"], = ctl.getInt32([cvr["modes"]])
            mode_times.append(te)
            ctl.updateDiscreteStates()
            ctl.enterStepMode()
            tc = te
        ctl.doStep(tc, end - tc)
        if k == 0:
            plant.iterate()
            plant.fmu.enterContinuousTimeMode()
            plant.read()
        plant.fmu.setFloat64([pv["u"]], [state["u"]])
        plant.advance(t, end, lambda te: pytest.fail("the plant has no events"))
    violations = [f.getInt32([99])[0] for f in (plant.fmu, sup.fmu, ctl)]
    for f in (plant.fmu, sup.fmu, ctl):
        f.terminate()
        f.freeInstance()
    return np.array(rows, dtype=float), alarm_times, mode_times, violations


def test_master_equals_the_reference_loop(clock_loop_fmus, tmp_path, monkeypatch):
    """Every recorded signal at every instant and every activation of alarm and mode: the
    master and the hand-written loop agree to 1e-12 (both make the same float operations);
    none of the FMUs saw a call the standard forbids."""
    monkeypatch.setenv("CLOCK_FMU_LOG", str(tmp_path / "calls.log"))
    ref, alarms, modes, ref_violations = reference_loop(clock_loop_fmus)
    sim = _master(clock_loop_fmus)
    df = sim.run(STOP)
    assert ref_violations == [0, 0, 0]
    assert "ILLEGAL" not in (tmp_path / "calls.log").read_text()
    ours = df[COLUMNS].to_numpy(float)
    assert ours.shape == ref.shape
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-12)
    ticks = sim.clock_ticks
    np.testing.assert_allclose(ticks.time[ticks.clock == "supervisor.alarm"].to_numpy(), alarms, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ticks.time[ticks.clock == "controller.mode"].to_numpy(), modes, rtol=0, atol=1e-12)
    assert len(alarms) >= 5 and any(abs(a / H - round(a / H)) > 1e-6 for a in alarms)   # between instants too
    assert (ticks.clock == "controller.sample").sum() == round(STOP / H) + 1
    assert df[["plant.violations", "supervisor.violations", "controller.violations"]].to_numpy().max() == 0


def test_cvode_finds_the_same_alarms_between_instants(clock_loop_fmus, tmp_path, monkeypatch):
    """With CVODE the alarms are located in continuous time (not on the Euler grid): each
    one is at a state where the supervisor's integral reached its limit, between instants,
    and the controller's mode clock ticks at the same time."""
    monkeypatch.setenv("CLOCK_FMU_LOG", str(tmp_path / "calls.log"))
    sim = _master(clock_loop_fmus, solver="cvode")
    df = sim.run(1.0)
    ticks = sim.clock_ticks
    a = ticks.time[ticks.clock == "supervisor.alarm"].to_numpy()
    m = ticks.time[ticks.clock == "controller.mode"].to_numpy()
    np.testing.assert_array_equal(a, m)
    assert len(a) >= 3 and all(abs(x / H - round(x / H)) > 1e-6 for x in a)
    assert df["controller.modes"].iloc[-1] == len(a)
    assert "ILLEGAL" not in (tmp_path / "calls.log").read_text()


@pytest.fixture(autouse=True)
def _no_log_leak(monkeypatch):
    monkeypatch.delenv("CLOCK_FMU_LOG", raising=False)
    yield
    os.environ.pop("CLOCK_FMU_LOG", None)


def test_the_scenario_file_gives_the_reference_loop(clock_loop_fmus, tmp_path):
    """The same loop written as a scenario file: the results and activations of the
    hand-written reference loop."""
    from cosim import Scenario

    sc = Scenario.load(write_scenario(tmp_path / "loop.toml", STOP, [
        component("fmu", "controller", H, path=clock_loop_fmus["controller"]),
        component("fmu", "supervisor", H, path=clock_loop_fmus["supervisor"], solver="euler", solver_step=H_INT),
        component("fmu", "plant", H, path=clock_loop_fmus["plant"], solver="euler", solver_step=H_INT)],
        {"plant.u": "controller.u", "controller.y": "plant.p", "supervisor.p": "plant.p",
         "controller.mode": "supervisor.alarm", "controller.level": "supervisor.level"}))
    df = sc.run()
    ref, _, modes, _ = reference_loop(clock_loop_fmus)
    np.testing.assert_allclose(df[COLUMNS].to_numpy(float), ref, rtol=0, atol=1e-12)
    ticks = sc.cosim.clock_ticks
    np.testing.assert_allclose(ticks.time[ticks.clock == "controller.mode"].to_numpy(), modes, rtol=0, atol=1e-12)


def test_clocked_outputs_carry_their_start_value_until_their_clock_first_ticks(clock_loop_fmus, tmp_path):
    """The supervisor's level and alarm count declare start values (initial = exact): until its
    alarm clock first ticks they are those values, not 0; after, what the FMU gives."""
    import zipfile

    path = tmp_path / "supervisor.fmu"
    with zipfile.ZipFile(clock_loop_fmus["supervisor"]) as src, zipfile.ZipFile(path, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                for name in (b'"level"', b'"alarms"'):
                    start = b'initial="exact" start="0.75"' if name == b'"level"' else b'initial="exact" start="3"'
                    data = data.replace(b"name=" + name, b"name=" + name + b" " + start)
            dst.writestr(item, data)
    df = _master({**clock_loop_fmus, "supervisor": path}).run(STOP)
    plain = _master(clock_loop_fmus).run(STOP)
    first = df.index[df["supervisor.alarm"] > 0][0]
    before, after = df.index < first, df.index >= first
    assert before.sum() >= 3
    assert (df.loc[before, "supervisor.level"] == 0.75).all() and (df.loc[before, "supervisor.alarms"] == 3).all()
    assert (plain.loc[before, "supervisor.level"] == 0).all()
    assert df["supervisor.alarms"].dtype.kind == "i"
    np.testing.assert_array_equal(df.loc[after, "supervisor.level"], plain.loc[after, "supervisor.level"])

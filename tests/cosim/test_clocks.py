"""Clocked FMI 3.0 FMUs in the master: every kind of clock, in Model Exchange, Co-Simulation
with Event Mode and Scheduled Execution, alone and connected.

The FMU is tests/data/clock_lab (hand-written, third-party to the master): it checks the
FMI 3.0 call rules for clocks it receives and answers any violation with an error, so a run
that ends without error, and whose call log has no "ILLEGAL" line, followed them (clocks
set only in Event Mode and exactly at their times, clocked variables exchanged only at
their ticks, the event iteration, output clocks read before the instant ends, countdown
intervals read in every Event Mode, Scheduled Execution partitions in priority order,
...). The expected activation times are computed here from the clocks the FMU documents.
"""
from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from cosim import Component, Cosimulation, FMUComponent, Port, Sine
from cosim.core.clocking import ClockTicks
from fmu_models.errors import CosimError

INTERFACES = ("cs", "me", "se")
P = 0.1
STOP = 1.0
TRIGGERS = (0.25, 0.5, 0.83)


def _f(x) -> Fraction:
    return Fraction(str(x))


def expected(interface: str, stop=STOP, countdown=0.0, fixed=0.2, triggers=TRIGGERS) -> dict[str, list[float]]:
    """ClockLab's activations up to ``stop`` as its documentation says, in exact arithmetic."""
    stop = _f(stop)

    def periodic(interval, shift):
        out, t = [], _f(shift)
        while t <= stop:
            out.append(t)
            t += _f(interval)
        return out

    const = periodic(0.1, 0)
    changing, t, n = [], _f(0.1), 0
    while t <= stop:
        changing.append(t)
        n += 1
        t += _f(0.1) * (1 + n % 3)
    countdown_t = [c + _f(countdown) for i, c in enumerate(const, 1) if i % 4 == 0 and c + _f(countdown) <= stop]
    out = {"cConst": const, "cFixed": periodic(fixed, 0.1), "cFixedP": periodic(0.3, 0.2),
           "cTunable": periodic(0.4, 0.1), "cChanging": changing, "cCountdown": countdown_t,
           "cOut": [c for i, c in enumerate(const, 1) if i % 3 == 0],
           "cTrigger": [_f(x) for x in triggers if _f(x) <= stop]}
    if interface != "se":
        out["cAlarm"] = periodic(0.35, 0.35)
    return {k: [float(x) for x in v] for k, v in out.items()}


def lab(path, interface, **kw) -> FMUComponent:
    return FMUComponent("m", path, P, interface=interface, **kw)


def run_lab(path, interface, triggers=TRIGGERS, stop=STOP, **kw):
    m = lab(path, interface, **kw)
    src = ClockTicks("src", P, times=list(triggers))
    u = Sine("u", P, 1.0, 0.7, offset=0.5)
    sim = Cosimulation([m, src, u], {"m.cTrigger": "src.tick", "m.uConst": "u.out", "m.trigValue": "u.out"})
    df = sim.run(stop)
    return sim, df


def ticks_of(sim, component="m") -> dict[str, np.ndarray]:
    t = sim.clock_ticks
    return {c.split(".", 1)[1]: t.time[t.clock == c].to_numpy() for c in t.clock.unique() if c.startswith(component)}


@pytest.fixture
def calls(tmp_path, monkeypatch):
    """The FMU's call log (CLOCK_FMU_LOG), read after the run."""
    log = tmp_path / "calls.log"
    monkeypatch.setenv("CLOCK_FMU_LOG", str(log))
    return lambda: log.read_text().splitlines() if log.exists() else []


@pytest.mark.parametrize("interface", INTERFACES)
def test_every_clock_ticks_at_its_times(clock_lab_fmu, interface, calls):
    """Constant (counter form), fixed (set and asked), tunable (a fraction), changing,
    countdown, triggered, output clocks: each activation at its time, none missed or extra,
    and no call the standard forbids."""
    sim, df = run_lab(clock_lab_fmu, interface)
    got, want = ticks_of(sim), expected(interface)
    assert set(got) >= set(want) - {"cAlarm"} and set(got) <= set(want)
    for name, times in want.items():
        np.testing.assert_allclose(got.get(name, []), times, rtol=0, atol=1e-9, err_msg=name)
    assert not [line for line in calls() if "ILLEGAL" in line]
    assert df["m.violations"].max() == 0
    assert df["m.constCount"].iloc[-1] == len(want["cConst"])            # the last instant ticks too
    assert df["m.cOut"].iloc[-1] == len(want["cOut"])                    # an output clock's count
    assert df["m.fixedSeen"].iloc[0] == pytest.approx(0.2)               # set in Initialization Mode


@pytest.mark.parametrize("interface", INTERFACES)
def test_clocked_variables_only_at_their_ticks(clock_lab_fmu, interface):
    """yConst = 2 uConst + constCount at each cConst tick (uConst from a sine at that
    instant); fixedValue = yConst of the same instant + 1 where both clocks tick (the
    partitions' dependency); trigSum adds the input at each trigger: at an instant its value
    there, between instants its value at the last instant (zero-order hold)."""
    _, df = run_lab(clock_lab_fmu, interface)
    u = df["u.out"].to_numpy()
    np.testing.assert_allclose(df["m.yConst"], 2 * u + df["m.constCount"], rtol=0, atol=1e-12)
    both = [round(x / P) for x in expected(interface)["cFixed"]]
    np.testing.assert_allclose(df["m.fixedValue"].iloc[both], df["m.yConst"].iloc[both] + 1, rtol=0, atol=1e-12)
    times = df.index.to_numpy()
    held = [u[np.searchsorted(times, x + 1e-9) - 1] for x in TRIGGERS]
    assert df["m.trigSum"].iloc[-1] == pytest.approx(sum(held), abs=1e-12)
    assert df["m.trigCount"].iloc[-1] == len(TRIGGERS)


@pytest.mark.parametrize("interface", INTERFACES)
def test_countdown_between_instants(clock_lab_fmu, interface, calls):
    """A countdown interval of 0.05 s puts its activations between the 0.1 s instants: CS
    steps to them (a variable step), ME makes them time events, SE activates there."""
    sim, _ = run_lab(clock_lab_fmu, interface, start={"pCountdown": 0.05})
    np.testing.assert_allclose(ticks_of(sim)["cCountdown"], expected(interface, countdown=0.05)["cCountdown"],
                               rtol=0, atol=1e-9)
    assert not [line for line in calls() if "ILLEGAL" in line]
    if interface == "cs":
        steps = [[float(w.split("=")[1]) for w in line.split()[2:4]] for line in calls() if " DoStep t=" in line]
        assert any(abs(t - 0.3) < 1e-9 and abs(h - 0.05) < 1e-9 for t, h in steps)


@pytest.mark.parametrize("interface", INTERFACES)
def test_clock_intervals_set_by_the_importer(clock_lab_fmu, interface):
    """clock_intervals sets a fixed clock's interval (fmi3SetIntervalDecimal in
    Initialization Mode): cFixed every 0.4 s instead of its declared 0.2 s."""
    sim, df = run_lab(clock_lab_fmu, interface, clock_intervals={"cFixed": 0.4})
    np.testing.assert_allclose(ticks_of(sim)["cFixed"], expected(interface, fixed=0.4)["cFixed"], atol=1e-9)
    assert df["m.fixedSeen"].iloc[0] == pytest.approx(0.4)


def test_initialization_calls(clock_lab_fmu, calls):
    """In Initialization Mode: cFixed's interval set as a decimal, cTunable's as a fraction
    of its resolution (4/10), cFixedP's interval and shift asked, the aperiodic clocks'
    first intervals asked; constant clocks take their declared interval."""
    run_lab(clock_lab_fmu, "cs")
    lines = calls()
    init = lines[lines.index(next(x for x in lines if "EnterInitializationMode" in x)):
                 lines.index(next(x for x in lines if "ExitInitializationMode" in x))]
    text = "\n".join(init)
    for want in ("SetIntervalDecimal cFixed=0.2", "SetIntervalFraction cTunable=4/10", "GetIntervalDecimal cFixedP",
                 "GetShiftDecimal cFixedP", "GetIntervalDecimal cChanging", "GetIntervalDecimal cCountdown"):
        assert want in text, want
    assert "cConst" not in text


def test_cs_event_mode_sequence(clock_lab_fmu, calls):
    """Co-Simulation with Event Mode: instantiated with eventModeUsed and earlyReturnAllowed;
    at a tick EnterEventMode, SetClock, the event iteration (UpdateDiscreteStates twice after
    a trigger: the FMU asks for a second super-dense instant), the countdown's interval after
    the last UpdateDiscreteStates, EnterStepMode; the state event at 0.35 s: an early return
    with eventHandlingNeeded, Event Mode at lastSuccessfulTime, the rest of the step."""
    run_lab(clock_lab_fmu, "cs")
    lines = [x.split(" ", 1)[1] for x in calls()]
    assert "eventModeUsed=1 earlyReturnAllowed=1" in lines
    early = next(i for i, x in enumerate(lines) if "eventHandlingNeeded at 0.34999" in x or
                 "eventHandlingNeeded at 0.35" in x)
    assert "early=1" in lines[early]
    assert lines[early + 1].startswith(("EnterEventMode t=0.35", "EnterEventMode t=0.34999"))
    after = lines[early + 1:early + 8]
    assert any(x.startswith("GetClock cAlarm=1") for x in after)
    trig = next(i for i, x in enumerate(lines) if x.startswith("SetClock cTrigger"))
    block = lines[trig:next(i for i in range(trig, len(lines)) if lines[i].startswith("EnterStepMode"))]
    assert sum(x.startswith("UpdateDiscreteStates") for x in block) == 2
    assert block[-1].startswith("GetIntervalDecimal cCountdown")


def test_se_priority_order_and_callbacks(clock_lab_fmu, calls):
    """Scheduled Execution: at 0.5 s the partitions due run in priority order (cConst 0,
    cFixed 1, cFixedP 2, cTunable 3, cTrigger 6); the countdown announced in cConst's
    partition at 0.3 s (interval 0) runs at 0.3 s after the others; output clocks are read in
    the clockUpdate callback only."""
    run_lab(clock_lab_fmu, "se")
    lines = [x.split(" ", 1)[1] for x in calls()]
    at = [x.split()[1] for x in lines if x.startswith("ActivateModelPartition") and x.endswith("t=0.5")]
    assert at == ["cConst", "cFixed", "cFixedP", "cTunable", "cTrigger"]
    at = [x.split()[1] for x in lines if x.startswith("ActivateModelPartition") and "t=0.30000" in x]
    assert at == ["cConst", "cFixed", "cChanging", "cCountdown"]
    for i, x in enumerate(lines):
        if x.startswith("GetClock"):
            assert lines[i - 1].startswith(("clockUpdate", "GetClock")), lines[i - 3:i + 1]


@pytest.mark.parametrize("src_if,dst_if", [("cs", "me"), ("me", "cs"), ("se", "se"), ("cs", "se"), ("se", "me")])
def test_output_clock_into_triggered_clock(clock_lab_fmu, src_if, dst_if, calls):
    """A's output clock cOut drives B's triggered clock cTrigger (at the same instant) and
    A's outValue (clocked by cOut) B's trigValue; A's yConst drives B's uConst (two clocks at
    one instant, B's partition after A's)."""
    a, b = FMUComponent("a", clock_lab_fmu, P, interface=src_if), FMUComponent("b", clock_lab_fmu, P, interface=dst_if)
    src = ClockTicks("src", P, times=[0.45])
    sim = Cosimulation([b, a, src], {"b.cTrigger": "a.cOut", "b.trigValue": "a.outValue", "b.uConst": "a.yConst",
                                     "a.cTrigger": "src.tick"})
    df = sim.run(STOP)
    ta, tb = ticks_of(sim, "a."), ticks_of(sim, "b.")
    np.testing.assert_allclose(tb["cTrigger"], ta["cOut"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(df["b.yConst"], 2 * df["a.yConst"] + df["b.constCount"], rtol=0, atol=1e-12)
    out = df["a.outValue"].to_numpy()
    assert df["b.trigSum"].iloc[-1] == pytest.approx(sum(out[round(x / P)] for x in ta["cOut"]), abs=1e-12)
    assert not [line for line in calls() if "ILLEGAL" in line]


@pytest.mark.parametrize("src_if,dst_if", [("cs", "me"), ("me", "cs"), ("cs", "se"), ("me", "se")])
def test_state_event_clock_between_instants(clock_lab_fmu, src_if, dst_if, calls):
    """A's cAlarm ticks at A's state events (0.35 s, 0.7 s): B's triggered clock at the same
    times, also between instants; B reads A's x as A reports it at the alarm."""
    a, b = FMUComponent("a", clock_lab_fmu, P, interface=src_if), FMUComponent("b", clock_lab_fmu, P, interface=dst_if)
    src = ClockTicks("src", P, times=[5.0])
    sim = Cosimulation([b, a, src], {"b.cTrigger": "a.cAlarm", "b.trigValue": "a.x", "a.cTrigger": "src.tick"})
    df = sim.run(STOP)
    tb = ticks_of(sim, "b.")["cTrigger"]
    np.testing.assert_allclose(tb, [0.35, 0.7], rtol=0, atol=1e-9)
    assert df["b.trigCount"].iloc[-1] == 2
    assert not [line for line in calls() if "ILLEGAL" in line]


def test_describe_lists_the_clocks(clock_lab_fmu):
    """describe() shows every clock's timing, priority, source and sinks."""
    m = lab(clock_lab_fmu, "se")
    sim = Cosimulation([m, ClockTicks("src", P, times=[0.5])], {"m.cTrigger": "src.tick"})
    text = sim.describe()
    for want in ("m.cConst: constant, every 0.1 s from 0 s: every instant of m; priority 0",
                 "m.cFixed: fixed, every 0.2 s from 0.1 s", "every 2 instant(s) of m from instant 1",
                 "m.cTrigger: triggered by src.tick", "m.cOut: output clock, activated by the FMU; drives nothing",
                 "src.tick: output clock, activated at 0.5 s; drives m.cTrigger",
                 "src.tick -> m.cTrigger: clock connection"):
        assert want in text, want
    sim = Cosimulation([m, ClockTicks("src", P, times=[0.5]), Sine("u", P, 1.0, 1.0)],
                       {"m.cTrigger": "src.tick", "m.uConst": "u.out"})
    assert "u.out -> m.uConst: clocked by m.cConst: set only at its activations" in sim.describe()


def test_bad_interval_at_run_time_is_named(clock_lab_fmu):
    """A countdown interval the FMU gives at run time is checked: -1 s ends the run at that
    Event Mode with the clock and the value named; the log of the activations until then and
    the rows recorded are kept."""
    m = lab(clock_lab_fmu, "cs", start={"pCountdown": -1.0})
    sim = Cosimulation([m, ClockTicks("src", P, times=[5.0])], {"m.cTrigger": "src.tick"})
    with pytest.raises(CosimError, match="cCountdown.*returned -1.0; an interval must be finite and >= 0") as err:
        sim.run(STOP)
    assert err.value.time == pytest.approx(0.3)
    assert len(err.value.results) == 4
    assert (sim.clock_ticks.clock == "m.cConst").sum() == 4


@pytest.mark.parametrize("interface", INTERFACES)
def test_feedthrough_none_delays_clocked_inputs(clock_lab_fmu, interface, calls):
    """feedthrough='none': a tick's outputs are read before its inputs change (ME, CS: the
    clocked inputs set in the update, before the state changes; SE: the inputs consumed at
    the previous instant), so yConst(t) = 2 u(t - period) + constCount(t)."""
    m = lab(clock_lab_fmu, interface, feedthrough="none")
    assert not any(m.feedthrough.values())
    sim = Cosimulation([m, ClockTicks("src", P, times=[5.0]), Sine("u", P, 1.0, 0.7, offset=0.5)],
                       {"m.cTrigger": "src.tick", "m.uConst": "u.out"})
    df = sim.run(STOP)
    u = df["u.out"].to_numpy()
    before = np.concatenate([[0.0], u[:-1]])                  # uConst's start value before the first instant
    np.testing.assert_allclose(df["m.yConst"], 2 * before + df["m.constCount"], rtol=0, atol=1e-12)
    assert not [line for line in calls() if "ILLEGAL" in line]


@pytest.mark.parametrize("interface", INTERFACES)
def test_clocks_count_from_the_start_time(clock_lab_fmu, interface):
    """Shifts are relative to the start: from 0.5 s cConst ticks at 0.5, 0.6, ..., cFixed
    (shift 0.1 s, interval 0.2 s) at 0.6, 0.8, 1.0."""
    m = lab(clock_lab_fmu, interface)
    sim = Cosimulation([m, ClockTicks("src", P, times=[5.0])], {"m.cTrigger": "src.tick"})
    sim.run(1.0, 0.5)
    got = ticks_of(sim)
    np.testing.assert_allclose(got["cConst"], [0.5, 0.6, 0.7, 0.8, 0.9, 1.0], atol=1e-9)
    np.testing.assert_allclose(got["cFixed"], [0.6, 0.8, 1.0], atol=1e-9)


@pytest.mark.parametrize("interface", INTERFACES)
def test_sink_stepped_more_often_than_its_source(clock_lab_fmu, interface, calls):
    """A source stepped every 0.2 s ticks at 0.25 s and 0.7 s (between its instants): the
    sink, stepped every 0.1 s, gets each activation in the step that holds it."""
    m = lab(clock_lab_fmu, interface)
    src = ClockTicks("src", 0.2, times=[0.25, 0.7])
    sim = Cosimulation([m, src], {"m.cTrigger": "src.tick"})
    df = sim.run(1.0)
    np.testing.assert_allclose(ticks_of(sim)["cTrigger"], [0.25, 0.7], atol=1e-9)
    assert df["m.trigCount"].iloc[-1] == 2
    assert not [line for line in calls() if "ILLEGAL" in line]


@pytest.mark.parametrize("interface", ["cs", "me"])
@pytest.mark.parametrize("when", [0.37, 0.4])
def test_fmu_time_event(clock_lab_fmu, interface, when, calls):
    """The FMU's own time event (its nextEventTime): CS steps to it and handles it in Event
    Mode (the FMU refuses a step over it), ME makes it a time event; at an instant it is
    handled in that instant's Event Mode."""
    _, df = run_lab(clock_lab_fmu, interface, start={"pTimeEvent": when})
    assert df["m.timeEvents"].iloc[-1] == 1
    assert not [line for line in calls() if "ILLEGAL" in line]
    events = [float(x.split("t=")[1]) for x in calls() if " EnterEventMode t=" in x]
    assert any(abs(e - when) < 1e-9 for e in events)


class _Counter(Component):
    """An Int32 output that counts the instants (a discrete signal changing at every one)."""

    def __init__(self, name, period):
        super().__init__(name, period, outputs=[Port("k", "Int32")], feedthrough=False)
        self.k = 0

    def reset(self, t0):
        super().reset(t0)
        self.k = 0

    def output(self, t, u):
        return np.array([float(self.k)])

    def update(self, t, u):
        self.k += 1


@pytest.mark.parametrize("interface", INTERFACES)
def test_discrete_input_without_clock(clock_lab_fmu, interface, calls):
    """A discrete input without clock changing at instants where no clock ticks (period
    0.05 s, the clocks every 0.1 s): ME and CS enter Event Mode to set it (the FMU refuses it
    in Step or Continuous-Time Mode); the FMU sees every value (CS, SE: one instant late, as
    the outputs without clocks there depend on no input directly)."""
    m = FMUComponent("m", clock_lab_fmu, 0.05, interface=interface)
    sim = Cosimulation([m, ClockTicks("src", 0.05, times=[5.0]), _Counter("n", 0.05)],
                       {"m.cTrigger": "src.tick", "m.uMode": "n.k"})
    df = sim.run(0.5)
    assert not [line for line in calls() if "ILLEGAL" in line]
    seen = df["m.modeSeen"].to_numpy()
    k = df["n.k"].to_numpy()
    if interface == "cs":                        # set in the update: seen one instant later (no feedthrough)
        np.testing.assert_array_equal(seen[1:], k[:-1])
    elif interface == "me":                      # set in Event Mode before the outputs: seen at once
        np.testing.assert_array_equal(seen, k)
    else:        # consumed at the update before each activation (no feedthrough), read after it (every 0.1 s)
        np.testing.assert_array_equal(seen[2::2], k[1:-1:2])


def test_streamed_run_keeps_clock_counts_exact(clock_lab_fmu, tmp_path):
    """Streamed to Parquet (and every other instant recorded), the clock counts are integer
    columns equal to the in-memory run's."""
    sim, df = run_lab(clock_lab_fmu, "cs")
    assert df["m.cOut"].dtype == np.int64 and df["src.tick"].dtype == np.int64
    import pandas as pd

    m = lab(clock_lab_fmu, "cs")
    sim2 = Cosimulation([m, ClockTicks("src", P, times=list(TRIGGERS)), Sine("u", P, 1.0, 0.7, offset=0.5)],
                        {"m.cTrigger": "src.tick", "m.uConst": "u.out", "m.trigValue": "u.out"})
    path = sim2.run_to_parquet(tmp_path / "r.parquet", STOP, output_interval=2 * P)
    got = pd.read_parquet(path)
    pd.testing.assert_frame_equal(got, df.iloc[::2], check_freq=False)
    pd.testing.assert_frame_equal(sim.clock_ticks, sim2.clock_ticks)

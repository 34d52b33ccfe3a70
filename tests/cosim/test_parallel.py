"""Parallel stepping in the native kernel (the master's ``threads`` option): the same bits as
the serial run in every topology, failures named as the serial run names them, FMUs that
must not step at once kept apart, the option checked, Ctrl-C and crashes on worker threads
handled, and no thread left behind."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from testkit import handwritten

import estimators
from cosim import Cosimulation, FMUComponent, Sine
from cosim.components.estimation import EstimatorComponent
from cosim.components.sources import Constant
from cosim.core import native_loop
from cosim.core.component import Component
from cosim.scenario import Scenario
from fmu_models import get_model
from fmu_models.errors import ConfigurationError, CosimError

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the test FMU is built for Linux only")


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """The work-bench FMU (tests/data/work_bench), and its variant that declares
    canBeInstantiatedOnlyOncePerProcess: {"plain" | "once": path}."""
    out = tmp_path_factory.mktemp("workbench")
    paths = {}
    for kind, xml in (("plain", "modelDescription.xml"), ("once", "once.xml")):
        (out / kind).mkdir()
        paths[kind] = handwritten.build("work_bench", "WorkBench", 2, out / kind, xml)
    return paths


def wb(work, name, period=0.01, kind="plain", **parameters):
    return FMUComponent(name, work[kind], period, parameters={"work_us": 20.0, **parameters})


def ekf():
    system = estimators.discretize(get_model("cartpole"), 0.01)
    return EstimatorComponent("ekf", lambda: estimators.EKF(system, [0.5, 0, 1.8, 0.5], 1.0, 0.2, 0.1))


class Gain(Component):
    """A Python component, whose update returns to Python between the FMUs' updates."""

    def __init__(self, name, period):
        super().__init__(name, period, ["u"], ["y"])

    def output(self, t, u):
        return 0.5 * u

    def update(self, t, u):
        pass


def step_threads() -> int:
    """The kernel's worker threads in this process (named cosim-step)."""
    tasks = Path("/proc/self/task")
    return sum((tasks / t / "comm").read_text().strip() == "cosim-step" for t in os.listdir(tasks))


def both(make, stop=3.0):
    """(serial, threads=2) results of ``make(threads)``, or their errors, and the threaded
    run's co-simulation."""
    out, sims = [], []
    for threads in (1, 2):
        cs = make(threads)
        sims.append(cs)
        try:
            out.append(cs.run(stop, progress=False))
        except CosimError as e:
            out.append((str(e), e.component, e.time, e.results))
    return out, sims[1]


def assert_same(a, b):
    """The same results bit for bit, but the work-bench FMUs' wall-clock outputs."""
    if isinstance(a, tuple):
        assert a[:3] == b[:3]
        a, b = a[3], b[3]
    clock = [c for c in a.columns if c.endswith((".began", ".ended"))]
    assert list(a.columns) == list(b.columns)
    a, b = a.drop(columns=clock), b.drop(columns=clock)
    assert a.equals(b), a.compare(b) if a.shape == b.shape else (a.shape, b.shape)
    assert a.attrs.get("stopped") == b.attrs.get("stopped")


def test_two_fmus_in_a_chain_give_the_same_bits_on_two_threads(work):
    def make(threads):
        return Cosimulation([Sine("src", 0.01, 1.0, 1.0), wb(work, "a"), wb(work, "b", work_us=30.0)],
                            {"a.u": "src.out", "b.u": "a.x"}, threads=threads)

    (serial, parallel), cs = both(make)
    assert len(serial) == 301
    assert_same(serial, parallel)
    assert cs.stepping.startswith("2 threads: [") and "[a]" in cs.stepping and "[b]" in cs.stepping
    assert "FMUs that may step at once: a, b" in cs.describe()


@pytest.mark.parametrize("version", (2, 3))
def test_multi_rate_fmus_a_filter_and_a_python_component_give_the_same_bits(work, fmu_builds, version):
    """Periods of 1, 2 and 3 base steps (patterns with different FMUs due), a filter's held
    input beside the FMUs, a Python component's update between them, FMI 2.0 and 3.0."""
    def make(threads):
        plant = FMUComponent("plant", fmu_builds["cartpole", version], 0.01, start={"theta": 1.8})
        other = FMUComponent("other", fmu_builds["cartpole", version], 0.02, start={"theta": 1.5})
        return Cosimulation([plant, ekf(), wb(work, "a", 0.02), Gain("gain", 0.01), wb(work, "b", 0.03),
                             wb(work, "c", 0.01), other, Constant("force", 0.01, 0.2)],
                            {"plant.F": "force.out", "ekf.F": "force.out", "ekf.y_x": "plant.y_x",
                             "ekf.y_theta": "plant.y_theta", "a.u": "plant.theta", "gain.u": "a.x",
                             "b.u": "gain.y", "c.u": "b.x", "other.F": "c.x"}, threads=threads)

    (serial, parallel), cs = both(make)
    assert_same(serial, parallel)
    assert cs.stepping.startswith("2 threads")


def test_auto_stays_serial_where_threads_cannot_pay(work):
    """Beside an FMU of 30 µs a step, one of no work: the threads can save no more than its
    step (well under MIN_GAIN) and add a hand-over, whatever the machine's load."""
    cs = Cosimulation([wb(work, "a", work_us=30.0), wb(work, "b", work_us=0.0)], {"b.u": "a.x"})
    serial = cs.run(2.0, progress=False, signals=["*.x"])
    assert cs.threads == "auto"
    assert cs.stepping.startswith("serial: the FMU updates that may step at once took on 2 threads "), cs.stepping
    assert "per base step, serially " in cs.stepping
    cs.threads = 1
    assert cs.run(2.0, progress=False, signals=["*.x"]).equals(serial)
    assert cs.stepping == "serial: threads=1"


def test_auto_tries_threads_and_keeps_them_by_the_measured_times(work, monkeypatch):
    """The rule's paths after the first block, on threads: kept, or serial from then on (on a
    quiet machine, FMU steps of some 100 µs keep the threads; here the thresholds are moved
    so that each path is taken whatever the load), the same bits either way."""
    def make(threads):
        return Cosimulation([wb(work, "a"), wb(work, "b")], {"b.u": "a.x"}, threads="auto" if threads > 1 else 1)

    monkeypatch.setattr(native_loop, "MIN_GAIN", -1.0)
    monkeypatch.setattr(native_loop, "KEEP_RATIO", 1e9)
    (serial, parallel), cs = both(make, stop=5.0)
    assert_same(serial, parallel)
    assert cs.stepping.startswith("2 threads: [") and " (measured: on 2 threads " in cs.stepping
    monkeypatch.setattr(native_loop, "KEEP_RATIO", 0.0)
    assert cs.run(5.0, progress=False).drop(columns=["a.began", "a.ended", "b.began", "b.ended"]).equals(
        serial.drop(columns=["a.began", "a.ended", "b.began", "b.ended"]))
    assert cs.stepping.startswith("serial: the FMU updates that may step at once took on 2 threads")


def test_auto_measures_again_and_takes_the_threads_when_they_pay(work, monkeypatch):
    """The first block says serial; a later measurement, once threads pay (here: once the
    rule is changed by a component at t = 12 s), takes them, the bits unchanged."""
    class Flip(Component):
        def __init__(self):
            super().__init__("flip", 0.01, outputs=["y"])

        def output(self, t, u):
            if t >= 12.0:
                native_loop.KEEP_RATIO, native_loop.MIN_GAIN = 1e9, -1.0
            return np.array([0.0])

    def make(threads):
        return Cosimulation([wb(work, "a"), wb(work, "b"), Flip()], {"b.u": "a.x"},
                            threads="auto" if threads > 1 else 1)

    monkeypatch.setattr(native_loop, "KEEP_RATIO", 0.0)
    monkeypatch.setattr(native_loop, "RECHECK", 2 * native_loop.BLOCK)
    monkeypatch.setattr(native_loop, "RECHECK_SECONDS", 0.0)
    (serial, parallel), cs = both(make, stop=30.0)
    assert_same(serial, parallel)
    assert cs.stepping.startswith("2 threads: [") and " (measured: on 2 threads " in cs.stepping


@pytest.mark.parametrize("failing", [("a",), ("b",), ("a", "b")])
@pytest.mark.parametrize("status", [3, 4])
def test_a_failure_on_any_thread_is_named_as_the_serial_run_names_it(work, failing, status):
    """``b`` steps on the worker thread (``a`` costs more: the calling thread takes it): an
    error of either, or of both at once (the first in the serial order is named)."""
    def make(threads):
        fail = dict(fail_step=200, fail_status=status)
        a = wb(work, "a", work_us=400.0, **(fail if "a" in failing else {}))
        return Cosimulation([Sine("src", 0.01, 1.0, 1.0), a, wb(work, "b", **(fail if "b" in failing else {}))],
                            {"a.u": "src.out", "b.u": "src.out"}, threads=threads)

    (serial, parallel), cs = both(make)
    assert_same(serial, parallel)
    assert serial[1] == failing[0] and "fmi2DoStep" in serial[0] and "t = 1.99 s" in serial[0]
    assert f"doStep 200 of {failing[0]} failed as asked" in serial[0]       # logged from its thread
    assert cs.stepping.startswith("2 threads: [a]; [b]")


@pytest.mark.parametrize("step", [30, 150])             # in the first block (balancing), after it
@pytest.mark.parametrize("stopping", ["a", "b"])
def test_a_stop_request_ends_the_instant_without_stepping_an_fmu_twice(work, stopping, step):
    """Discard with fmi2Terminated: the other FMU's step of that instant, already made on its
    thread, is not made again (its outputs at the last row show it)."""
    def make(threads):
        stop = dict(fail_step=step, fail_status=2)
        return Cosimulation([wb(work, "a", work_us=400.0, **(stop if stopping == "a" else {})),
                             wb(work, "b", **(stop if stopping == "b" else {}))], {"b.u": "a.x"}, threads=threads)

    (serial, parallel), cs = both(make)
    assert_same(serial, parallel)
    assert serial.attrs["stopped"]["component"] == stopping and serial.index[-1] == pytest.approx(step * 0.01)
    assert cs.stepping.startswith("2 threads")


def test_fmus_sharing_a_library_or_declaring_one_instance_per_process_never_step_at_once(work):
    shared = [wb(work, "s0", work_us=300.0), wb(work, "s1", work_us=300.0)]
    shared[1].use_unpacked(shared[0].unpacked)               # one library, loaded once
    cs = Cosimulation(shared, {"s1.u": "s0.x"}, threads=2)
    cs.run(2.0, progress=False)
    assert cs.stepping == "serial: fewer than two FMUs that may step at once"

    def make(threads):
        return Cosimulation([wb(work, "o0", kind="once", work_us=300.0), wb(work, "p0", work_us=300.0),
                             wb(work, "o1", kind="once", work_us=300.0), wb(work, "p1", work_us=300.0)],
                            {"o1.u": "o0.x", "p0.u": "o1.x", "p1.u": "p0.x"}, threads=threads)

    (serial, parallel), cs = both(make, stop=2.0)
    assert_same(serial, parallel)
    assert cs.stepping.startswith("2 threads") and "o0, o1" in re.findall(r"\[([^]]*)]", cs.stepping)
    assert "never at once (canBeInstantiatedOnlyOncePerProcess): o0, o1" in cs.describe()
    times = cs.run(2.0, progress=False, signals=["*.began", "*.ended"])
    o0, o1 = times[["o0.began", "o0.ended"]].to_numpy()[1:], times[["o1.began", "o1.ended"]].to_numpy()[1:]
    assert ((o0[:, 1] <= o1[:, 0]) | (o1[:, 1] <= o0[:, 0])).all()          # never overlapped


@pytest.mark.parametrize("bad", [0, -1, 65, 1.5, True, "many", None, "2"])
def test_a_bad_threads_value_is_refused_by_name(work, bad):
    with pytest.raises(ConfigurationError, match=r"threads must be 'auto' or a whole number from 1 to 64, got"):
        Cosimulation([wb(work, "a")], {}, threads=bad)
    cs = Cosimulation([wb(work, "a")], {}, threads=np.int64(3))
    assert cs.threads == 3 and isinstance(cs.threads, int)
    with pytest.raises(ConfigurationError, match="threads must be"):
        cs.threads = bad
    assert cs.threads == 3


@pytest.mark.slow
def test_a_scenario_and_the_command_line_set_threads(work, tmp_path):
    text = textwrap.dedent(f"""
        [simulation]
        stop_time = 1.0
        threads = THREADS
        [[component]]
        name = "a"
        type = "fmu"
        path = {str(work["plain"])!r}
        period = 0.01
        [[component]]
        name = "b"
        type = "fmu"
        path = {str(work["plain"])!r}
        period = 0.01
        [connections]
        "b.u" = "a.x"
        """)
    path = tmp_path / "s.toml"
    path.write_text(text.replace("THREADS", "2"))
    assert Scenario.load(path).cosim.threads == 2
    path.write_text(text.replace("THREADS", "'two'"))
    with pytest.raises(ConfigurationError, match="threads must be 'auto' or a whole number from 1 to 64, got 'two'"):
        Scenario.load(path)
    path.write_text(text.replace("THREADS", "'auto'"))
    cli = [sys.executable, "-c", "import sys; from cosim.cli import main; sys.exit(main())", "run", str(path)]
    proc = subprocess.run([*cli, "--dry-run", "--threads", "3"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and "parallel stepping (threads=3): on up to 3 threads" in proc.stdout, proc.stderr
    for bad, said in (("x", "--threads must be auto or a whole number, got 'x'"),
                      ("0", "threads must be 'auto' or a whole number from 1 to 64, got 0")):
        proc = subprocess.run([*cli, "--dry-run", "--threads", bad], capture_output=True, text=True, timeout=300)
        assert proc.returncode == 2 and said in proc.stderr and "Traceback" not in proc.stderr, proc.stderr


def test_no_thread_is_left_behind_after_a_run_or_a_failure(work):
    class Watch(Component):
        """Counts the worker threads while the run goes on."""

        def __init__(self):
            super().__init__("watch", 0.01, outputs=["n"])

        def output(self, t, u):
            return np.array([float(step_threads())])

    cs = Cosimulation([wb(work, "a"), wb(work, "b"), Watch()], {"b.u": "a.x"}, threads=2)
    assert cs.run(2.0, progress=False)["watch.n"].iloc[-1] == 1.0        # one worker while it ran
    assert cs.stepping.startswith("2 threads") and step_threads() == 0
    cs = Cosimulation([wb(work, "a"), wb(work, "b", fail_step=150)], {"b.u": "a.x"}, threads=2)
    with pytest.raises(CosimError, match="component 'b' failed at t = 1.49 s"):
        cs.run(2.0, progress=False)
    assert step_threads() == 0


SCRIPT = """
import os, sys
from cosim import Cosimulation, FMUComponent
from fmu_models.errors import Interrupted
comps = [FMUComponent("a", {path!r}, 0.01, parameters={{"work_us": 500.0}}),
         FMUComponent("b", {path!r}, 0.01, parameters={{"work_us": 300.0, {extra}}})]
cs = Cosimulation(comps, {{"b.u": "a.x"}}, threads=2)
print("go", flush=True)
try:
    cs.run(1e4, progress=False)
except Interrupted as e:
    names = [open(f"/proc/self/task/{{t}}/comm").read().strip() for t in os.listdir("/proc/self/task")]
    print(e, len(e.partial), cs.stepping, names.count("cosim-step"), sep="|", flush=True)
"""


@pytest.mark.slow
def test_ctrl_c_during_a_parallel_run_ends_it_with_the_rows_so_far(work):
    proc = subprocess.Popen([sys.executable, "-c", SCRIPT.format(path=str(work["plain"]), extra="")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "go"
    time.sleep(2.0)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0 and "Traceback" not in err, err
    error, rows, stepping, added = out.strip().split("|")
    assert error.startswith("interrupted at t = ") and int(rows) > 64, out
    assert stepping.startswith("2 threads") and added == "0", out           # the worker ended


def test_a_crash_on_a_worker_thread_names_the_fmu_and_the_time(work):
    """``b`` steps on the worker thread (``a`` costs more): the guard names it from the
    faulting thread's own stack, and the time from the master's step counter."""
    script = SCRIPT.format(path=str(work["plain"]), extra='"crash_step": 300')
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert proc.returncode == -signal.SIGSEGV, proc.stderr
    line = next(x for x in proc.stderr.splitlines() if x.startswith("error: the FMU"))
    assert "component 'b'" in line and "(SIGSEGV) in fmi2DoStep at t = 2.99 s" in line, line


def test_describe_says_which_fmus_may_step_at_once(work):
    cs = Cosimulation([wb(work, "a"), Gain("g", 0.01), wb(work, "b")], {"g.u": "a.x", "b.u": "g.y"}, threads=1)
    text = cs.describe()
    assert "parallel stepping (threads=1): never (serial); FMUs that may step at once: none" in text
    assert "last run: no run yet" in text
    cs.threads = "auto"
    assert "FMUs that may step at once: a, b" in cs.describe()
    assert isinstance(cs.run(0.5, progress=False), pd.DataFrame)
    assert "last run: serial: fewer than two FMUs that may step at once" in cs.describe()   # g's update between

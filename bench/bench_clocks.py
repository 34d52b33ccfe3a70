"""Benchmark: the master's own time per clock tick, against bare loops making the same FMI calls.

Run: python bench/bench_clocks.py [--ticks N] [--write-docs]

The FMU is the hand-written tests/data/clock_bench (one constant clock ``tick`` every 1 ms
that clocks the input ``u`` and the output ``y``), built here with the C compiler.
Per tick, in the FMI 3.0 call sequence for clocks:

* Co-Simulation with Event Mode: ``fmi3EnterEventMode``, ``fmi3SetClock(tick)``,
  (``fmi3SetFloat64(u)``), ``fmi3GetFloat64(y)``, ``fmi3UpdateDiscreteStates``,
  ``fmi3EnterStepMode``, ``fmi3DoStep``;
* Scheduled Execution: (``fmi3SetFloat64(u)``), ``fmi3ActivateModelPartition(tick, t)``,
  ``fmi3GetFloat64(y)``;

each made three ways: with fmpy's ``FMU3Slave`` / ``FMU3ScheduledExecution`` methods (what
a user would write), as a raw ctypes loop with every argument prebuilt (the cheapest a
Python loop can be), and by the master (``FMUComponent``, every signal recorded). Two
set-ups: one FMU; two FMUs, ``a.y -> b.u`` (b's clocked input set at each tick).

"master own time per tick" = (master loop - raw loop) / (ticks of all FMUs): what the
master adds to the FMI calls themselves. Times are the CPU time of the running thread
(``time.thread_time``), so that other processes on a shared machine weigh less; the
master's loop is its run of N ticks less its run of 100 ticks (the set-up, instantiation
and teardown cancel). Medians of 7 repeats, all in this run, the three ways interleaved.
"""
from __future__ import annotations

import argparse
import ctypes
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import fmpy
import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3ScheduledExecution, FMU3Slave

from cosim.core.master import Cosimulation
from cosim.fmi.exchange import raw_function
from cosim.fmi.fmu_component import FMUComponent
from fmu_models.infra.compiler import find_compiler, run_compiler

sys.path.append(str(Path(__file__).parent))          # bench/doc_tables.py, from any folder
import doc_tables

H, REPEATS = 0.001, 7
SOURCE = Path(__file__).parents[1] / "tests" / "data" / "clock_bench"
VR_TICK, VR_U, VR_Y = 1, 2, 3
D, B, U32 = ctypes.c_double, ctypes.c_bool, ctypes.c_uint32


def build(folder: Path) -> Path:
    """The ClockBench FMU, compiled for this machine (Linux)."""
    if not sys.platform.startswith("linux"):
        raise SystemExit("bench_clocks builds its FMU for Linux only")
    so = folder / "ClockBench.so"
    run_compiler([find_compiler(), "-shared", "-fPIC", "-O2", f"-I{Path(fmpy.__file__).parent / 'c-code'}",
                  str(SOURCE / "ClockBench.c"), "-o", str(so), "-lm"], "the ClockBench FMU")
    fmu = folder / "ClockBench.fmu"
    with zipfile.ZipFile(fmu, "w") as z:
        z.write(SOURCE / "modelDescription.xml", "modelDescription.xml")
        z.write(so, "binaries/x86_64-linux/ClockBench.so")
    return fmu


def _instances(path: Path, kind: str, count: int) -> list:
    md = read_model_description(str(path))
    out = []
    for i in range(count):
        cls = FMU3Slave if kind == "cs" else FMU3ScheduledExecution
        fmu = cls(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier="ClockBench", instanceName=f"b{i}")
        if kind == "cs":
            fmu.instantiate(eventModeUsed=True, earlyReturnAllowed=True)
        else:
            fmu.instantiate()
        fmu.enterInitializationMode(startTime=0.0)
        fmu.exitInitializationMode()                      # CS: Event Mode; SE: Clock Activation Mode
        out.append(fmu)
    return out


def _close(fmus) -> None:
    for f in fmus:
        f.terminate()
        f.freeInstance()


def fmpy_loop(path: Path, kind: str, count: int, n: int) -> float:
    """The ticks through fmpy's methods."""
    fmus = _instances(path, kind, count)
    rec = np.empty((n + 1, count))
    t0 = time.thread_time()
    for k in range(n + 1):
        t = k * H
        y = 0.0
        for i, f in enumerate(fmus):
            if kind == "cs":
                if k:
                    f.enterEventMode()
                f.setClock([VR_TICK], [True])
                if i:
                    f.setFloat64([VR_U], [y])
            else:
                if i:
                    f.setFloat64([VR_U], [y])
                f.activateModelPartition(VR_TICK, t)
            y, = f.getFloat64([VR_Y])
            rec[k, i] = y
        if k == n:
            break
        if kind == "cs":
            for f in fmus:
                f.updateDiscreteStates()
                f.enterStepMode()
                f.doStep(t, H)
    elapsed = time.thread_time() - t0
    _close(fmus)
    return elapsed


def raw_loop(path: Path, kind: str, count: int, n: int) -> float:
    """The ticks through the FMU's functions with prebuilt ctypes arguments."""
    fmus = _instances(path, kind, count)
    calls = []
    for f in fmus:
        c = ctypes.c_void_p(f.component)
        fn = {name: raw_function(f.dll, f"fmi3{name}") for name in
              ("EnterEventMode", "SetClock", "SetFloat64", "GetFloat64", "UpdateDiscreteStates", "EnterStepMode",
               "DoStep", "ActivateModelPartition")}
        one = ctypes.c_size_t(1)
        ybuf, ubuf = (D * 1)(), (D * 1)()
        flags = [B() for _ in range(5)]
        nxt = D()
        st = [B() for _ in range(3)]
        last = D()
        calls.append((c, fn, one, (U32 * 1)(VR_TICK), (B * 1)(True), (U32 * 1)(VR_U), ubuf, (U32 * 1)(VR_Y), ybuf,
                      [ctypes.byref(x) for x in flags] + [ctypes.byref(nxt)],
                      [ctypes.byref(x) for x in st] + [ctypes.byref(last)]))
    rec = np.empty((n + 1, count))
    Dh, tick = D(H), U32(VR_TICK)
    t0 = time.thread_time()
    for k in range(n + 1):
        t = k * H
        y = 0.0
        for i, (c, fn, one, vt, on, vu, ubuf, vy, ybuf, _, _) in enumerate(calls):
            if kind == "cs":
                if k:
                    fn["EnterEventMode"](c)
                fn["SetClock"](c, vt, one, on)
                if i:
                    ubuf[0] = y
                    fn["SetFloat64"](c, vu, one, ubuf, one)
            else:
                if i:
                    ubuf[0] = y
                    fn["SetFloat64"](c, vu, one, ubuf, one)
                fn["ActivateModelPartition"](c, tick, D(t))
            fn["GetFloat64"](c, vy, one, ybuf, one)
            y = ybuf[0]
            rec[k, i] = y
        if k == n:
            break
        if kind == "cs":
            for c, fn, *_, uds, step in calls:
                fn["UpdateDiscreteStates"](c, *uds)
                fn["EnterStepMode"](c)
                fn["DoStep"](c, D(t), Dh, True, *step)
    elapsed = time.thread_time() - t0
    _close(fmus)
    return elapsed


def master_loop(path: Path, kind: str, count: int, n: int) -> float:
    """The ticks through the master, every signal recorded: its run of ``n`` ticks less its
    run of 100 (the set-up and teardown cancel), scaled to ``n``."""
    comps = [FMUComponent(f"b{i}", path, H, interface=kind) for i in range(count)]
    conns = {f"b{i}.u": f"b{i - 1}.y" for i in range(1, count)}
    sim = Cosimulation(comps, conns)
    spent = []
    for ticks in (100, n):
        t0 = time.thread_time()
        df = sim.run(ticks * H, progress=False)
        spent.append(time.thread_time() - t0)
        assert len(df) == ticks + 1 and df[f"b{count - 1}.y"].iloc[-1] == count * (ticks + 1)
    return (spent[1] - spent[0]) * n / (n - 100)


def medians(fns, *args) -> list[float]:
    """The median time of each of ``fns``, their repeats interleaved (a load that comes and
    goes on a shared machine weighs on all alike)."""
    times = [[] for _ in fns]
    for _ in range(REPEATS):
        for t, fn in zip(times, fns):
            t.append(fn(*args))
    return [float(np.median(t)) for t in times]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ticks", type=int, default=5000, help="ticks of each FMU (default 5000, at least 1000)")
    doc_tables.add_option(ap)
    args = ap.parse_args(argv)
    n = max(args.ticks, 1000)
    figures = {"ticks": n + 1, "us_per_tick": {}}
    with tempfile.TemporaryDirectory() as tmp:
        path = build(Path(tmp))
        print(f"ClockBench FMU, {n + 1} ticks of 1 ms per FMU, medians of {REPEATS}")
        for kind, label in (("cs", "Co-Simulation with Event Mode"), ("se", "Scheduled Execution")):
            for count in (1, 2):
                ticks = (n + 1) * count
                f, r, m = medians((fmpy_loop, raw_loop, master_loop), path, kind, count, n)
                print(f"\n{label}, {count} FMU(s){', a.y -> b.u' if count == 2 else ''}:")
                for name, v in (("fmpy methods", f), ("raw ctypes loop", r), ("master", m)):
                    print(f"  {name:17s} {v * 1e3:8.2f} ms CPU  {v / ticks * 1e6:6.2f} us/tick")
                print(f"  master own time per tick over the raw loop: {(m - r) / ticks * 1e6:+.2f} us; "
                      f"master / fmpy = {m / f:.2f}")
                figures["us_per_tick"][f"{label}, {count}"] = [v / ticks * 1e6 for v in (f, r, m)]
    if args.write_docs:
        doc_tables.write_docs(__file__, figures)


def clocks_table(saved) -> str:
    """The performance page's table: CPU time per tick, three ways, and the master's own time."""
    f = saved["bench_clocks"]["figures"]
    rows = []
    for key, (fmpy_us, raw, master) in f["us_per_tick"].items():
        label, count = key.rsplit(", ", 1)
        rows.append([f"{label}, {count} FMU{'s connected' if count != '1' else ''}", f"{fmpy_us:.2f} µs",
                     f"{raw:.2f} µs", f"{master:.2f} µs", f"{master - raw:.2f} µs"])
    return doc_tables.with_provenance(saved, "bench_clocks", doc_tables.table(
        ["", "fmpy's methods", "raw ctypes loop", "master", "master's own time"], rows))


TABLES = {"clocks": clocks_table}


if __name__ == "__main__":
    main()

"""Benchmark: parallel stepping in the native kernel against the serial native kernel.

Run: python bench/bench_parallel.py [--steps N] [--repeats R] [--quick] [--write-docs]

The FMU is the hand-written tests/data/work_bench (FMI 2.0 Co-Simulation): its doStep
integrates a driven pendulum with a number of substeps set by its parameter ``work_us``
(about that many microseconds of CPU per step). Two of them, ``b`` driven by ``a``'s
output, 10 ms communication steps, every signal recorded. The baseline is the same
co-simulation in the serial native kernel (``threads=1``), in the same run, the repeats
interleaved:

* two FMUs of about 5 ms per step: serial, ``threads=2`` and ``threads="auto"``; the
  speed-up over serial, and the results of each compared bit for bit with the serial
  run's (the FMUs' wall-clock outputs ``began`` and ``ended`` aside);
* a sweep of the cost per step (1 µs .. 5 ms): the three again, and what ``"auto"``
  chose (its rule: :mod:`cosim.core.native_loop`).

Parallel stepping pays only with a free core: the load average is printed before and
after (and the CPUs' idle share is the better guide: the load average trails). Times are
wall times (medians of the repeats), the first base steps (timed on the threads, where
``"auto"`` decides) included. ``--write-docs`` saves the figures and rewrites the
performance page's tables (``bench/doc_tables.py``).
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from cosim.core.master import Cosimulation
from cosim.fmi.fmu_component import FMUComponent

sys.path.append(str(Path(__file__).parents[1] / "tests"))     # the test FMUs' builder (tests/testkit)
from testkit import handwritten  # after the path

sys.path.append(str(Path(__file__).parent))          # bench/doc_tables.py, from any folder
import doc_tables  # after the path

H = 0.01
MODES = (1, 2, "auto")
SWEEP_US = (1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0, 5000.0)


def cosim(fmu: Path, work_us: float, threads) -> Cosimulation:
    """Two work-bench FMUs, ``a.x -> b.u``, each of ``work_us`` per step."""
    comps = [FMUComponent(name, fmu, H, parameters={"work_us": work_us}) for name in ("a", "b")]
    return Cosimulation(comps, {"b.u": "a.x"}, threads=threads)


def one_run(fmu: Path, work_us: float, threads, steps: int):
    """(wall time [s], deterministic results, what the run's stepping was)."""
    cs = cosim(fmu, work_us, threads)
    t0 = time.perf_counter()
    df = cs.run(steps * H, progress=False)
    wall = time.perf_counter() - t0
    return wall, df.drop(columns=[c for c in df.columns if c.endswith((".began", ".ended"))]), cs.stepping


def compare(fmu: Path, work_us: float, steps: int, repeats: int) -> dict:
    """Each mode's median wall time, whether its results equal the serial run's bit for
    bit, and what its last run did."""
    times: dict = {m: [] for m in MODES}
    results, said = {}, {}
    for _ in range(repeats):
        for mode in MODES:
            wall, results[mode], said[mode] = one_run(fmu, work_us, mode, steps)
            times[mode].append(wall)
    return {m: (float(np.median(times[m])), results[m].equals(results[1]), said[m]) for m in MODES}


def serial_step_cost(fmu: Path, work_us: float) -> float:
    """What one doStep of ``work_us`` costs here [s] (a serial run of 200 steps of one FMU)."""
    comp = FMUComponent("a", fmu, H, parameters={"work_us": work_us})
    cs = Cosimulation([comp], {}, threads=1)
    df = cs.run(200 * H, progress=False)
    return float(np.median((df["a.ended"] - df["a.began"]).to_numpy()[1:]))


def big_case(fmu: Path, steps: int, repeats: int) -> dict:
    """The 2 x 5 ms case, printed: per mode, [wall time (s), same bits, what it did]."""
    cost = serial_step_cost(fmu, 5000.0)
    print(f"\ntwo FMUs, work_us = 5000 (one doStep measured at {cost * 1e3:.2f} ms here), {steps} steps, "
          f"medians of {repeats}; baseline: the serial native kernel (threads=1)")
    big = compare(fmu, 5000.0, steps, repeats)
    for mode, (wall, same, said) in big.items():
        print(f"  threads={mode!s:5s} {wall:7.3f} s  {big[1][0] / wall:5.2f}x serial  "
              f"{'same bits' if same else 'DIFFERENT RESULTS'}  ({said})")
    return {"steps": steps, "step_ms": cost * 1e3, "modes": {str(m): list(v) for m, v in big.items()}}


def sweep(fmu: Path, repeats: int) -> list:
    """The sweep of the cost per step, printed: rows [work_us, µs per base step of each
    mode, same bits, what auto did]."""
    print("\nsweep of the cost per step (two FMUs; wall time per base step, medians; x: serial / mode)")
    print(f"  {'work_us':>8s} {'serial':>10s} {'threads=2':>16s} {'auto':>16s}  auto chose")
    rows = []
    for work_us in SWEEP_US:
        steps = int(min(20000, max(300, 0.4 / (2 * work_us * 1e-6))))
        r = compare(fmu, work_us, steps, repeats)
        per = {m: r[m][0] / steps * 1e6 for m in MODES}
        same = all(r[m][1] for m in MODES)
        print(f"  {work_us:8g} {per[1]:8.1f}µs {per[2]:8.1f}µs {per[1] / per[2]:5.2f}x "
              f"{per['auto']:8.1f}µs {per[1] / per['auto']:5.2f}x  {r['auto'][2]}"
              + ("" if same else "  DIFFERENT RESULTS"))
        rows.append([work_us, per[1], per[2], per["auto"], same, r["auto"][2]])
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=600, help="base steps of the 2 x 5 ms case (default 600)")
    ap.add_argument("--repeats", type=int, default=3, help="repeats, interleaved (default 3)")
    ap.add_argument("--quick", action="store_true", help="the 2 x 5 ms case only")
    doc_tables.add_option(ap)
    args = ap.parse_args(argv)
    if args.write_docs and args.quick:
        ap.error("--write-docs needs the sweep: leave out --quick")
    print(f"{os.cpu_count()} cores; load average {os.getloadavg()[0]:.2f} at the start")
    with tempfile.TemporaryDirectory() as tmp:
        fmu = handwritten.build("work_bench", "WorkBench", 2, Path(tmp))
        figures = {"big": big_case(fmu, args.steps, args.repeats)}
        if not args.quick:
            figures["sweep"] = sweep(fmu, args.repeats)
    print(f"\nload average {os.getloadavg()[0]:.2f} at the end")
    if args.write_docs:
        doc_tables.write_docs(__file__, figures)


def _chose(said: str) -> str:
    """What ``threads="auto"`` chose, in short."""
    return "serial" if said.startswith("serial") else said.split(":")[0]


def parallel_table(saved) -> str:
    """The performance page's tables: the 2 x 5 ms case, and the sweep of the cost per step."""
    f = saved["bench_parallel"]["figures"]
    big, modes = f["big"], f["big"]["modes"]
    serial = modes["1"][0]
    head = [f"two FMUs of {big['step_ms']:.2f} ms a step, {big['steps']} steps", "serial (`threads=1`)",
            "`threads=2`", "`threads=\"auto\"`"]
    row = ["wall time"] + [f"{modes[m][0]:.2f} s" + ("" if m == "1" else f" ({serial / modes[m][0]:.2f}x)")
                           for m in ("1", "2", "auto")]
    bits = ["results"] + ["the baseline"] + ["same bits" if modes[m][1] else "DIFFERENT" for m in ("2", "auto")]
    rows = [[f"{w:g} µs", f"{s:.1f}", f"{t:.1f} ({s / t:.2f}x)", f"{a:.1f} ({s / a:.2f}x)", _chose(said),
             "same" if same else "DIFFERENT"] for w, s, t, a, same, said in f["sweep"]]
    return doc_tables.with_provenance(saved, "bench_parallel", doc_tables.table(head, [row, bits]), doc_tables.table(
        ["work per step, each FMU", "serial, µs per step", "`threads=2`", "`\"auto\"`", "auto chose", "bits"], rows))


TABLES = {"parallel": parallel_table}


if __name__ == "__main__":
    main()

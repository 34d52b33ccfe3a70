"""Benchmark and report: what the master does with each Modelica Reference FMU (FMI 2/3,
CS/ME/SE, Python API and ``pendulum-cosim run``), the cost of crash isolation per doStep, and
connected ME FMUs as one system against separate components.

Prints the Markdown tables of the third-party FMUs and performance pages.

Run: python bench/bench_reference_fmus.py [--skip-cli] [--write-docs]
(needs the Reference FMUs: PENDULUM_COSIM_REFERENCE_FMUS names their folder, with fmi2/ and fmi3/)
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from cosim import Constant, Cosimulation, FMUComponent, MESystem

sys.path.append(str(Path(__file__).parents[1] / "tests"))     # after the packages: tests/cosim is no package
sys.path.append(str(Path(__file__).parent))                    # bench/doc_tables.py, from any folder

import doc_tables
from testkit import reference_cases as rc


def _verdict(case, outcome, stopped: bool) -> str:
    if isinstance(outcome, Exception):
        return "refused: " + str(outcome).split(": ", 1)[-1].split(";")[0].split(":")[0]
    r, note = outcome, " (stops at 9 s, as it asks)" if stopped else ""
    if case.interface == "cs":
        if r["reference"] == "none published":
            return "runs (nothing published)" + note
        return f"exact: {r['rows']} rows, error {r['error']:.0f}" + note
    if case.interface == "se":
        ticks = sum(len(t) for t in r["ticks"].values())
        if r["wrong_ticks"]:
            return f"clock ticks differ: {sorted(r['wrong_ticks'])}" + note
        return f"every tick as its table ({ticks} ticks), counters error {r['error']:.0f}" + note
    rel = r["error"] / r["scale"] if r["scale"] else 0.0
    peer = "fmpy's" if r["peer"].startswith("fmpy") else "scipy's"
    return f"relative error {rel:.0e}, {r['ratio']:.2f}x {peer}" + note


def reference_figures(cli: bool) -> dict:
    """Each case's verdict (``[model, FMI version, interface, verdict]``, API), and with ``cli``
    the cases where ``pendulum-cosim run`` does not give the same."""
    verdicts = []
    bad = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, case in enumerate(rc.cases() + rc.fmi1_cases()):
            try:
                df = rc.run_api(case)
                outcome, stopped = rc.compare(case, df), bool(df.attrs.get("stopped"))
            except Exception as e:  # noqa: BLE001 - reported in the table
                outcome, stopped, df = e, False, None
            if cli:
                cdf, proc = rc.run_cli(case, Path(tmp) / str(k))
                same = (proc.returncode != 0 and "Traceback" not in proc.stderr) if df is None else \
                    (cdf is not None and np.array_equal(cdf.to_numpy(float), df.to_numpy(float)))
                if not same:
                    bad.append(case.label)
            verdicts.append([case.model, case.version, case.interface, _verdict(case, outcome, stopped)])
    return {"verdicts": verdicts, "cli_differs": bad if cli else None}


def reference_table(saved) -> str:
    """One row per FMU and FMI version: what the Co-Simulation and the Model Exchange (or
    Scheduled Execution) interface give from Python, and whether the command line gives the same."""
    f = saved["bench_reference_fmus"]["figures"]
    rows: dict = {}
    for model, version, interface, verdict in f["verdicts"]:
        rows.setdefault((model, version), {})[interface] = verdict
    text = doc_tables.table(
        ["Reference FMU", "FMI", "Co-Simulation (vs the published result)",
         "Model Exchange, CVODE rtol 1e-6 (vs CVODE at 1e-10; ratio to fmpy's error at 1e-6)"],
        [[model, f"{version}.0", r.get("cs", "-"), f"Scheduled Execution: {r['se']}" if "se" in r else r.get("me", "-")]
         for (model, version), r in rows.items()])
    if f["cli_differs"] is not None:
        n, bad = len(f["verdicts"]), f["cli_differs"]
        text += (f"\n\nThe command line (`pendulum-cosim run` with a minimal scenario file) gives the same rows or the "
                 f"same refusal in {n - len(bad)} of {n} cases" + (f"; not in {', '.join(bad)}" if bad else "") + ".")
    return doc_tables.with_provenance(saved, "bench_reference_fmus", text)


def _per_step(make, stop: float, repeats: int = 5) -> tuple[float, float]:
    """(seconds per run of ``stop`` s, seconds of a run of one step): the minimum of repeats."""
    full, one = [], []
    for _ in range(repeats):
        sim = make()
        t0 = time.perf_counter()
        sim.run(stop, progress=False)
        full.append(time.perf_counter() - t0)
        sim = make()
        t0 = time.perf_counter()
        sim.run(sim.step_size, progress=False)
        one.append(time.perf_counter() - t0)
    return min(full), min(one)


def isolation_figures() -> dict:
    """Per FMU: round trips per step, µs per step in-process and isolated, the isolated start-up [s]."""
    out = {}
    d = rc.reference_dir()
    for model, inputs in (("Dahlquist", False), ("Feedthrough", True)):
        path = d / "fmi2" / f"{model}.fmu"
        n = 20000

        def make(iso, path=path, inputs=inputs):
            if inputs:
                comp = FMUComponent("m", path, 0.01, inputs=["Float64_continuous_input"],
                                    outputs=["Float64_continuous_output"], isolate=iso)
                return Cosimulation([Constant("c", 0.01, 1.0), comp], {"m.Float64_continuous_input": "c.out"})
            return Cosimulation([FMUComponent("m", path, 0.01, isolate=iso)], {})
        plain_full, plain_one = _per_step(lambda: make(False), n * 0.01)
        iso_full, iso_one = _per_step(lambda: make(True), n * 0.01)
        per_plain = (plain_full - plain_one) / (n - 1)
        per_iso = (iso_full - iso_one) / (n - 1)
        out[model] = {"round_trips": 2 if inputs else 1, "in_process_us": per_plain * 1e6,
                      "isolated_us": per_iso * 1e6, "startup_s": iso_one}
    return out


def _below(us: float) -> str:
    """A per-step cost derived from two run times: below 1 µs the start-up's jitter over
    20 000 steps hides it (the difference may even come out negative)."""
    return f"{us:.1f} µs" if us >= 1 else "under 1 µs"


def isolation_table(saved) -> str:
    f = saved["bench_reference_fmus"]["figures"]["isolation"]
    return doc_tables.with_provenance(saved, "bench_reference_fmus", doc_tables.table(
        ["FMU (CS)", "round trips per step", "in-process per step", "isolated per step", "isolated start-up"],
        [[m, str(r["round_trips"]), _below(r["in_process_us"]), f"{r['isolated_us']:.0f} µs",
          f"{r['startup_s']:.2f} s"] for m, r in f.items()]))


def system_figures() -> list:
    """VanDerPol driving a first-order lag (the hand-written ME test FMU), against scipy:
    ``[coupling, communication step [s], lag error, wall [s]]`` per run."""
    from conftest import build_test_fmu
    from scipy.integrate import solve_ivp

    d = rc.reference_dir()
    with tempfile.TemporaryDirectory() as tmp:
        lag = build_test_fmu("bouncing_me", "BouncingBallME", 2, Path(tmp))
        exact = solve_ivp(lambda t, y: [y[1], (1 - y[0] ** 2) * y[1] - y[0], (y[0] - y[2]) / 0.5], (0, 2.0),
                          [2.0, 0.0, 0.0], method="Radau", rtol=1e-11, atol=1e-13, t_eval=np.arange(0, 2.0001, 0.1))
        rows = []
        for period in (0.1, 0.01):
            for joint in (False, True):
                vdp = FMUComponent("vdp", d / "fmi3" / "VanDerPol.fmu", period, interface="me", rtol=1e-8)
                lg = FMUComponent("lag", lag, period, interface="me", rtol=1e-8)
                parts = [MESystem("s", [vdp, lg], {"lag.u": "vdp.x0"}, period, rtol=1e-8)] if joint else [vdp, lg]
                sim = Cosimulation(parts, {} if joint else {"lag.u": "vdp.x0"})
                t0 = time.perf_counter()
                df = sim.run(2.0, progress=False, output_interval=0.1)
                wall = time.perf_counter() - t0
                col = df["s.lag.x" if joint else "lag.x"].to_numpy()
                err = np.abs(col - exact.y[2]).max()
                label = "one MESystem (one CVODE)" if joint else "separate components (inputs held)"
                rows.append([label, period, float(err), wall])
    return rows


def system_table(rows: list) -> str:
    return doc_tables.table(["coupling", "communication step", "lag error vs scipy", "wall"],
                            [[label, f"{p} s", f"{e:.1e}", f"{w:.2f} s"] for label, p, e, w in rows])


TABLES = {"reference": reference_table, "isolation": isolation_table}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--skip-cli", action="store_true")
    doc_tables.add_option(ap)
    args = ap.parse_args()
    if rc.reference_dir() is None:
        sys.exit("the Reference FMUs are absent: set PENDULUM_COSIM_REFERENCE_FMUS to their folder (with fmi2/ and "
                 "fmi3/)")
    figures = {**reference_figures(not args.skip_cli), "isolation": isolation_figures(), "system": system_figures()}
    saved = {"bench_reference_fmus": {"figures": figures, "run": doc_tables.run_info()}}
    for name, fn in TABLES.items():
        print(f"{name}:\n{fn(saved)}\n")
    print(f"system:\n{system_table(figures['system'])}")
    if args.write_docs:
        doc_tables.write_docs(__file__, figures)


if __name__ == "__main__":
    main()

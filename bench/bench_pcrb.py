"""Benchmark: the cost of the posterior Cramér-Rao bound and of the consistency tests.

1. ``posterior_crb`` over the seed 000 truth (100 realisations x 500 steps, cart-pole),
   beside two baselines measured in the same run: the batched EKF over the same
   realisations (what a campaign pays per filter anyway) and the recursion as printed
   (explicit inverses, one Jacobian call per realisation and step: the numpy oracle of
   the tests);
2. the consistency tests of one filter (NEES and NIS bands, whiteness at lags 1..5);
3. one task of the sweep (7 cells of one scenario) in this process, CPU time, alternated
   twice with the same task with the PCRB and the tests replaced by no-ops (less sensitive
   to other load on the machine than wall times);
4. the whole seed 000 sweep (7 x 7 cells x 4 scenarios x 100 realisations) as the
   command line runs it, and the same sweep with the PCRB and the consistency tests
   replaced by no-ops (the baseline: what the sweep cost before them), on this machine's
   cores. Goal: the sweep with the PCRB under 3 minutes on 2 cores.

Run: python bench/bench_pcrb.py [--skip-sweep] [--out DIR] (DIR: the report of the measured sweep)
"""
from __future__ import annotations

import argparse
import os
import resource
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from cosim.experiments import metrics, seed000, seed000_sweep
from cosim.experiments.campaign import realisation_seeds
from cosim.experiments.common import batch_run
from estimators import posterior_crb

sys.path.insert(0, str(Path(__file__).parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).parent))
from bench_swml import best
from testkit.pcrb_oracle import pcrb_literal


def truth(runs=100):
    s = replace(seed000.CONFIGS["paper"], runs=runs)
    q, r = seed000.true_noise(s.scenarios[0], "eqs")
    X, Y, u = seed000.simulate_truth(s, q, r, [tuple(realisation_seeds(s.seed, 0, k)) for k in range(runs)])
    return s, q, r, X, Y, u


def bound_costs() -> None:
    s, q, r, X, Y, u = truth()
    system = seed000._system(s.T)
    us = u[:-1, None]
    posterior_crb(system, X, us, q, r)                                       # warm (CasADi map built once)
    t_pcrb = best(lambda: posterior_crb(system, X, us, q, r), 5)
    make = seed000.make_filters(system, s, q, r)["EKF true Q,R"]
    batch_run(make, X, Y, u[:, None])                                       # warm (compiled once)
    t_ekf = best(lambda: batch_run(make, X, Y, u[:, None]), 5)
    H = system.H(X[0, 0])
    n_lit = 50                                                              # the printed recursion is slow
    t_lit = best(lambda: pcrb_literal(system.F, lambda x: H, X[:, :n_lit + 1], us, q * np.eye(4), r * np.eye(2),
                                      np.eye(4)), repeats=2) * (s.steps / n_lit)
    print(f"PCRB, {X.shape[0]} realisations x {s.steps} steps (cart-pole): {t_pcrb * 1e3:7.1f} ms")
    print(f"  baseline: the batched EKF over the same realisations: {t_ekf * 1e3:7.1f} ms")
    print(f"  baseline: the printed recursion, per-point Jacobians (timed over {n_lit} steps, scaled): "
          f"{t_lit * 1e3:7.1f} ms")
    out = batch_run(make, X, Y, u[:, None])
    t_tests = best(lambda: metrics.consistency(out.nees, out.nis, 4, 2, 0.95, out.innovation, out.S, 5), 5)
    print(f"consistency tests of one filter (NEES, NIS, whiteness at 5 lags): {t_tests * 1e3:7.1f} ms")


def _no_bound(s, X, u, q, r):
    return np.ones((X.shape[1], X.shape[2]))


def _no_whiteness(innovation, S, confidence=0.95, lags=5):
    return {"acf_max": 0.0, "acf_lag1": 0.0, "acf_band": 1.0, "acf_inside": 1.0, "white_ok": True}


def _no_bands(nees, nis, nx, ny, confidence=0.95):
    z = np.zeros(nees.shape[1])
    return ({"runs": len(nees), "anees": 0.0, "anees_lo": 0.0, "anees_hi": 0.0, "anees_inside": 1.0, "nees_ok": True,
             "anis": 0.0, "anis_lo": 0.0, "anis_hi": 0.0, "anis_inside": 1.0, "nis_ok": True},
            {"anees": z, "anis": z, "nees_lo": z, "nees_hi": z, "nis_lo": z, "nis_hi": z})


def cpu_seconds() -> float:
    """CPU time of this process and of its finished children (the sweep's workers) [s]."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def task_costs() -> None:
    settings = seed000_sweep.SweepSettings()
    cells = [(1.0, f) for f in settings.factors]
    seed000_sweep.cell_task(0, cells[:1], settings.campaign)                 # warm
    saved = seed000.scenario_bound, metrics.whiteness_row, metrics.band_row
    cpu = {"with": [], "without": []}
    for _ in range(2):
        for mode in cpu:
            if mode == "without":
                seed000.scenario_bound, metrics.whiteness_row, metrics.band_row = _no_bound, _no_whiteness, _no_bands
            try:
                t0 = time.process_time()
                seed000_sweep.cell_task(0, cells, settings.campaign)
                cpu[mode].append(time.process_time() - t0)
            finally:
                seed000.scenario_bound, metrics.whiteness_row, metrics.band_row = saved
    print(f"one sweep task (7 cells x {settings.campaign.runs} realisations), CPU: with the PCRB and the tests "
          f"{min(cpu['with']):.2f} s; baseline with no-ops {min(cpu['without']):.2f} s "
          f"(+{min(cpu['with']) / min(cpu['without']) - 1:.0%})")


def sweep_costs(out: str | None) -> None:
    settings = seed000_sweep.SweepSettings()
    seed000_sweep.run(replace(settings, factors=(1.0,), campaign=replace(settings.campaign, runs=2, duration=0.2)),
                      progress=False)                                       # warm the compiled filters
    c0 = cpu_seconds()
    result = seed000_sweep.run(settings, progress=False)
    wall, cpu = result.wall, cpu_seconds() - c0
    if out:
        seed000_sweep.write_report(*result, settings, out)
    print(f"{os.cpu_count()} cores; sweep 7 x 7 cells x 4 scenarios x {settings.campaign.runs} realisations, "
          f"with the PCRB and the consistency tests: {wall:6.1f} s wall, {cpu:6.1f} s CPU "
          f"(load average after: {os.getloadavg()[0]:.1f})")
    saved = seed000.scenario_bound, metrics.whiteness_row, metrics.band_row
    seed000.scenario_bound, metrics.whiteness_row, metrics.band_row = _no_bound, _no_whiteness, _no_bands
    c0 = cpu_seconds()
    try:                         # fork: the workers inherit the no-ops
        base = seed000_sweep.run(settings, progress=False).wall
    finally:
        seed000.scenario_bound, metrics.whiteness_row, metrics.band_row = saved
    print(f"  baseline: the same sweep with the PCRB and the tests replaced by no-ops: {base:6.1f} s wall, "
          f"{cpu_seconds() - c0:6.1f} s CPU (load average after: {os.getloadavg()[0]:.1f})")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--skip-sweep", action="store_true")
    ap.add_argument("--out", help="write the report of the measured sweep here")
    args = ap.parse_args()
    bound_costs()
    task_costs()
    if not args.skip_sweep:
        print(f"load average before the sweeps: {', '.join(f'{v:.1f}' for v in os.getloadavg())}")
        sweep_costs(args.out)


if __name__ == "__main__":
    main()

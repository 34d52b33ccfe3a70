"""Command line: ``pendulum-cosim``.

    pendulum-cosim demo [--out DIR]             run the seed 000 scenario, write results and plot
    pendulum-cosim run SCENARIO.toml --out DIR  run any scenario file
    pendulum-cosim scenarios                    list the scenarios shipped with the package
    pendulum-cosim models                       print both plant models and their Jacobians
    pendulum-cosim experiment NAME [--runs N]   reproduce a paper's experiment (seed000, ...)
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

SCENARIO_DIR = Path(__file__).parent / "scenarios"


def _rmse_table(df, estimators_, truth_prefix="plant"):
    """RMSE of every estimator's states against the plant's, and of the raw measurements."""
    import pandas as pd

    rows = {}
    for est in estimators_:
        cols = [c for c in df.columns if c.startswith(est + ".") and not c.split(".")[1].startswith("P_")
                and c.split(".")[1] != "nis"]
        row = {}
        for c in cols:
            tc = f"{truth_prefix}.{c.split('.')[1]}"
            if tc in df.columns:
                row[c.split(".")[1]] = float(np.sqrt(np.mean((df[c] - df[tc]) ** 2)))
        rows[est] = row
    meas = {}
    for c in df.columns:
        if ".y_" in c and not c.startswith(truth_prefix + "."):
            tc = f"{truth_prefix}.{c.split('.y_')[1]}"
            if tc in df.columns:
                meas[c.split(".y_")[1]] = float(np.sqrt(np.mean((df[c] - df[tc]) ** 2)))
    if meas:
        rows["raw measurement"] = meas
    return pd.DataFrame(rows).T


def _run_scenario(path: Path, out: Path) -> int:
    from .master import CosimError
    from .results import plot_estimates, save_results
    from .scenario import Scenario

    t0 = time.perf_counter()
    sc = Scenario.load(path, fmu_dir=out / "fmus")
    print(f"scenario: {sc.title or path.name}")
    try:
        df = sc.run()
    except CosimError as e:
        if e.results is not None and len(e.results):
            save_results(e.results, out, "results_partial")
            print(f"partial results written to {out}", file=sys.stderr)
        print(f"error: {e}", file=sys.stderr)
        return 1
    wall = time.perf_counter() - t0
    paths = save_results(df, out)
    ests = [c.name for c in sc.cosim.components if type(c).__name__ == "EstimatorComponent"]
    table = _rmse_table(df, ests)
    if len(table):
        print("\nRMSE against the plant's true states:")
        print(table.to_string(float_format=lambda v: f"{v:.4f}"))
        table.to_csv(out / "rmse.csv")
    if sc.plot:
        png = out / "truth_vs_estimate.png"
        measured = [m or None for m in sc.plot.get("measured", [])] or None
        plot_estimates(df, sc.plot["truth"], sc.plot["estimate"], measured, png, sc.title)
        paths.append(png)
    print(f"\n{len(df)} rows x {len(df.columns)} signals, {sc.stop_time:g} s simulated in {wall:.2f} s "
          "(including FMU build)")
    for p in paths:
        print(f"wrote {p}")
    return 0


def _models(args) -> int:
    """Simulate both models (Euler truth map and RK4) and print trajectories and Jacobians."""
    from fmu_models import get_model

    np.set_printoptions(precision=5, suppress=True, linewidth=110)
    runs = {"cartpole": (lambda t: [-0.5 if t < 2.0 else 0.5]),
            "iwp": (lambda t: [0.05 * np.sin(2 * np.pi * t)])}
    for name, u in runs.items():
        m = get_model(name)
        x0 = m.x0 if name == "cartpole" else np.array([0.05, 0.0, 0.0])
        dt, n = 0.01, int(round(args.duration / 0.01))
        print(f"== {m.description}")
        print(f"   states {m.state_names}, input {m.input_names}, params {m.params}")
        xs = m.simulate(x0, u, dt, n, method="euler")
        xr = m.simulate(x0, u, dt, n, method="rk4", substeps=4)
        print(f"   t [s] | Euler (T = {dt} s) state | RK4 (4 substeps) state")
        for k in range(0, n + 1, max(1, n // 10)):
            print(f"   {k * dt:5.2f} | {xs[k]} | {xr[k]}")
        A, B = m.linearize(np.zeros(m.nx), np.zeros(m.nu))
        print("   exact A = df/dx at the upright equilibrium:\n", A)
        print("   exact B = df/du:", B.ravel())
        print()
    return 0


EXPERIMENTS = ("seed000", "seed001", "seed002")


def _experiment(args) -> int:
    out = Path(args.out or f"out/{args.name}")
    if args.name == "seed000":
        from .experiments import seed000 as exp

        settings = exp.Settings(**({"runs": args.runs} if args.runs else {}),
                                **({"seed": args.seed} if args.seed is not None else {}))
        per_run, eps, examples, wall = exp.run(settings, path=args.path, backend=args.backend,
                                               n_jobs=args.jobs, progress=not args.quiet)
        md = exp.write_report(per_run, eps, examples, wall, settings, out, args.path)
        table = exp.summary_table(per_run)
        cols = ["reading", "scenario", "paper EKF", "paper MF-IAE", *exp.FILTERS]
        print(f"Seed 000, Table 3 (eta, eq 44): {settings.runs} realisations, {args.path} path, "
              f"{wall:.2f} s")
        print(table[cols].to_string(index=False, float_format=lambda v: f"{v:.4f}"))
        print(f"\nwrote {md} and the tables and figures beside it")
        return 0
    if args.name == "seed001":
        from .experiments import seed001 as exp

        settings = exp.Settings(**({"runs": args.runs} if args.runs else {}),
                                **({"seed": args.seed} if args.seed is not None else {}))
        table, summary, wall = exp.run(settings, path=args.path, backend=args.backend,
                                       n_jobs=args.jobs, progress=not args.quiet)
        md = exp.write_report(table, summary, wall, settings, out)
        print(f"Seed 001: mean |position error| [m], {settings.runs} realisations, {args.path} path, "
              f"{wall:.2f} s")
        print(table.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
        for case, res in summary.items():
            td = res["KF"]["t_div"]
            when = f"median {np.nanmedian(td):.2f} s" if np.isfinite(td).any() else "never"
            print(f"{case}: KF diverged in {int(np.isfinite(td).sum())} of {len(td)} runs ({when}); "
                  f"EKF in {int(np.isfinite(res['EKF']['t_div']).sum())}")
        print(f"\nwrote {md}")
        return 0
    from .experiments import seed002 as exp

    settings = exp.Settings(**({"runs": args.runs} if args.runs else {}),
                            **({"seed": args.seed} if args.seed is not None else {}))
    per_run, traces, wall = exp.run(settings, path=args.path, backend=args.backend, n_jobs=args.jobs,
                                    progress=not args.quiet)
    md = exp.write_report(per_run, traces, wall, settings, out, args.path)
    print(f"Seed 002: wheel pendulum through the sensor chain, {settings.runs} realisations, "
          f"{args.path} path, {wall:.2f} s")
    print(exp.summary_table(per_run).to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    agg = per_run.groupby("case", sort=False)[["balanced", "bias estimate", "alpha lag [s]",
                                               "alpha amplitude ratio"]].mean()
    print(agg.to_string(float_format=lambda v: f"{v:.4g}"))
    print(f"\nwrote {md}")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="pendulum-cosim",
        description="FMI co-simulation of two benchmark pendulums for nonlinear state estimation. "
                    "Plants run as FMUs built from CasADi models; estimators and other components "
                    "run in Python, each at its own sample period.")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="run the seed 000 cart-pole scenario (EKF and MF-IAE): "
                                       "results table, CSV/Parquet and a truth-vs-estimate plot")
    demo.add_argument("--out", default="out/demo", help="output directory (default out/demo)")
    run = sub.add_parser("run", help="run a scenario file (TOML); see `pendulum-cosim scenarios`")
    run.add_argument("scenario", help="scenario file, or the name of a shipped scenario")
    run.add_argument("--out", required=True, help="output directory")
    sub.add_parser("scenarios", help="list the shipped scenario files")
    models = sub.add_parser("models", help="simulate both plant models, print trajectories and Jacobians")
    models.add_argument("--duration", type=float, default=5.0, help="simulated time [s] (default 5)")
    exp = sub.add_parser("experiment", help="reproduce a paper's experiment as a Monte Carlo "
                                            "campaign; writes tables, figures and summary.md")
    exp.add_argument("name", choices=EXPERIMENTS, help="which experiment")
    exp.add_argument("--runs", type=int, help="realisations per scenario (default: the paper's)")
    exp.add_argument("--path", choices=("fast", "master"), default="fast",
                     help="fast: vectorised truth and batched filters; master: every realisation "
                          "through the co-simulation master with the plant FMU (same numbers)")
    exp.add_argument("--backend", choices=("processes", "serial", "dask"), default="processes",
                     help="parallel backend (dask needs the 'dask' extra)")
    exp.add_argument("--jobs", type=int, help="worker processes (default: all cores)")
    exp.add_argument("--seed", type=int, help="seed of all random streams")
    exp.add_argument("--out", help="output directory (default out/NAME)")
    exp.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    if args.command == "experiment":
        return _experiment(args)
    if args.command == "models":
        return _models(args)
    if args.command == "scenarios":
        for p in sorted(SCENARIO_DIR.glob("*.toml")):
            first = p.read_text().splitlines()[0]
            print(f"{p.stem:24s} {first.split('=', 1)[1].strip().strip(chr(34)) if '=' in first else ''}")
            print(f"{'':24s} {p}")
        return 0
    if args.command == "demo":
        return _run_scenario(SCENARIO_DIR / "seed000_cartpole.toml", Path(args.out))
    path = Path(args.scenario)
    if not path.exists() and (SCENARIO_DIR / f"{args.scenario}.toml").exists():
        path = SCENARIO_DIR / f"{args.scenario}.toml"
    if not path.exists():
        print(f"error: no scenario file {args.scenario!r} (shipped: "
              f"{', '.join(p.stem for p in SCENARIO_DIR.glob('*.toml'))})", file=sys.stderr)
        return 2
    from .master import ConfigurationError
    try:
        return _run_scenario(path, Path(args.out))
    except (ConfigurationError, KeyError, ValueError, TypeError, FileNotFoundError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

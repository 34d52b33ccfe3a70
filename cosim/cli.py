"""Command line ``pendulum-cosim`` (``pendulum-cosim --help`` lists its commands).

Every error of the package's family (:mod:`fmu_models.errors`) and the known library and
system errors print one line ``error: ...`` and exit with status 2 (``--debug``: the
traceback); Ctrl-C and SIGTERM save what finished as partial results and exit with 130.
"""
from __future__ import annotations

import argparse
import contextlib
import logging
import math
import shutil
import sys
import tempfile
import time
import tomllib
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fmu_models import get_model, model_names
from fmu_models.errors import ConfigurationError, FMUError, Interrupted, PendulumCosimError
from fmu_models.export.clocked import check_clocked
from fmu_models.export.platforms import add_platforms, parse_platforms, zig_command
from fmu_models.infra.cli import run_command
from fmu_models.infra.files import atomic_write
from fmu_models.infra.registry import load_plugin
from fmu_models.infra.resources import shipped
from fmu_models.infra.version import VERSION

from .core import crash_guard
from .core.component import ExportsFMU, StateEstimator
from .core.master import Cosimulation
from .core.native import ENGINES
from .experiments import EXPERIMENTS
from .fmi.archive import read_description
from .fmi.description import INTERFACES
from .fmu_run import NAME as FMU_NAME
from .fmu_run import open_fmu
from .output import OutputFolder, plot_estimates, plot_signals, save_results
from .scenario import Scenario
from .ssp import export_component, export_ssp, open_ssp


def _scenario_dir() -> Path:
    """The folder of the scenarios shipped with the package (a named error if it is missing)."""
    return shipped("cosim", "scenarios")


#: The longest ``models --duration`` [s] (1e5 steps of 0.01 s: a report of ten rows).
MAX_MODELS_DURATION = 1000.0


def _number(kind, low=None, what="value", strict=False, high=None):
    def parse(text: str):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{what} must be {'an integer' if kind is int else 'a number'}, "
                                             f"got {text!r}") from None
        if isinstance(v, float) and not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"{what} must be finite, got {text!r}")
        if low is not None and (v <= low if strict else v < low):
            raise argparse.ArgumentTypeError(f"{what} must be {'>' if strict else '>='} {low}, got {text!r}")
        if high is not None and v > high:
            raise argparse.ArgumentTypeError(f"{what} must be at most {high:g}, got {text!r}")
        return v
    return parse


_positive_int = _number(int, 1, "the number")


def _threads(text: str) -> int | str:
    """``--threads``: auto, or a whole number of threads (its range checked by the master)."""
    if text == "auto":
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--threads must be auto or a whole number, got {text!r}") from None


def _estimated(df, est: str) -> list[str]:
    """The states estimator ``est`` outputs (its columns but the covariances and the NIS)."""
    names = [c.split(".", 1)[1] for c in df.columns if c.startswith(est + ".")]
    return [n for n in names if not n.startswith("P_") and n != "nis"]


def _truth_of(df, est: str, estimators_) -> str | None:
    """The component (not an estimator) that outputs every state ``est`` estimates, ``plant``
    first if several do; None if none does."""
    states = _estimated(df, est)
    comps = sorted({c.split(".", 1)[0] for c in df.columns} - set(estimators_), key=lambda c: (c != "plant", c))
    return next((c for c in comps if states and all(f"{c}.{n}" in df.columns for n in states)), None)


def _rms(a, b) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)))


def _rmse_table(df, estimators_):
    """RMSE of every estimator's states against the component that outputs their true
    values (:func:`_truth_of`), and of the raw measurements (``<sensor>.y_<state>``)."""
    import pandas as pd

    rows, truths = {}, set()
    for est in estimators_:
        truth = _truth_of(df, est, estimators_)
        if truth is not None:
            truths.add(truth)
            rows[est] = {n: _rms(df[f"{est}.{n}"], df[f"{truth}.{n}"]) for n in _estimated(df, est)}
    meas = {}
    for truth in sorted(truths):
        for c in df.columns:
            state = c.split(".y_")[1] if ".y_" in c else ""
            if state and not c.startswith(truth + ".") and f"{truth}.{state}" in df.columns:
                meas[state] = _rms(df[c], df[f"{truth}.{state}"])
    if meas:
        rows["raw measurement"] = meas
    return pd.DataFrame(rows).T


def _resolve_target(name: str) -> Path:
    """The file or folder ``name``, or the shipped scenario of that name."""
    path = Path(name)
    if not path.exists() and (_scenario_dir() / f"{name}.toml").exists():
        path = _scenario_dir() / f"{name}.toml"
    if not path.exists():
        raise ConfigurationError(f"no scenario, FMU or SSP file {name!r} (shipped scenarios: "
                                 f"{', '.join(sorted(p.stem for p in _scenario_dir().glob('*.toml')))})")
    return path


def _kind_of(path: Path) -> str:
    """``"fmu"``, ``"ssp"`` or ``"scenario"``: what the file or folder ``path`` holds."""
    if path.is_dir():
        if (path / "SystemStructure.ssd").is_file():
            return "ssp"
        raise ConfigurationError(f"{path} is a folder, not a scenario file, an FMU or an SSP (an unpacked SSP holds "
                                 "a SystemStructure.ssd)")
    if path.suffix.lower() == ".ssd":
        return "ssp"
    if not zipfile.is_zipfile(path):
        if path.suffix.lower() in (".fmu", ".ssp"):
            raise FMUError(f"{path.name} is not an {path.suffix[1:].upper()}: not a zip archive")
        return "scenario"
    with zipfile.ZipFile(path) as z:
        names = set(z.namelist())
    if "modelDescription.xml" in names:
        return "fmu"
    if "SystemStructure.ssd" in names:
        return "ssp"
    raise ConfigurationError(f"{path.name} is a zip archive with neither a modelDescription.xml (an FMU) nor a "
                             "SystemStructure.ssd (an SSP)")


@dataclass
class _Job:
    """What ``run`` runs: a scenario, an FMU or an SSP in the master, its times and recording."""

    kind: str
    title: str
    cosim: Cosimulation
    start_time: float
    stop_time: float
    options: dict = field(default_factory=dict)     # Cosimulation.run keywords
    stream: bool = False
    prefix: str = ""                                # taken off the DataFrame's column names
    extras: Callable | None = None                  # (df, folder) -> paths; None: the plot of the signals
    wall: float = 0.0                               # [s] of the run, set by _record


#: ``run`` options that only an FMU or an SSP takes (a scenario sets them in its own tables).
_FILE_OPTIONS = {"stop_time": "--stop-time", "start_time": "--start-time", "step_size": "--step-size",
                 "start": "--start", "input": "--input", "outputs": "--outputs", "interface": "--interface"}


def _given(args, names) -> list[str]:
    return [_FILE_OPTIONS[n] for n in names if getattr(args, n, None) is not None]


def _start_values(items: list[str] | None) -> dict:
    """``--start NAME=VALUE`` values (a TOML value: a number, true/false, a list)."""
    out = {}
    for item in items or []:
        name, eq, text = item.partition("=")
        if not eq or not name.strip():
            raise ConfigurationError(f"--start {item!r}: write NAME=VALUE")
        try:
            out[name.strip()] = tomllib.loads(f"v = {text.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            raise ConfigurationError(f"--start {item!r}: {text.strip()!r} is not a number, true/false or a list") \
                from None
    return out


def _demo(args) -> int:
    """``demo``: ``run`` of the shipped seed 000 scenario into ``--out``, replaced, with
    ``run``'s own defaults for every other option."""
    scenario = str(shipped("cosim", "scenarios", "seed000_cartpole.toml"))
    return _run(build_parser().parse_args(["run", scenario, "--out", args.out, "--overwrite"]))


def _run(args) -> int:
    """``run``: a scenario file, an FMU or an SSP (see :func:`_kind_of`), read and checked
    before ``--out`` is touched."""
    path = _resolve_target(args.scenario)
    kind = _kind_of(path)
    if kind == "scenario" and _given(args, _FILE_OPTIONS):
        raise ConfigurationError(f"{', '.join(_given(args, _FILE_OPTIONS))}: for an FMU or SSP run; a scenario file "
                                 "sets these in its own tables")
    if kind == "ssp" and _given(args, ("input", "interface")):
        raise ConfigurationError(f"{', '.join(_given(args, ('input', 'interface')))}: for an FMU run, not an SSP")
    if not args.dry_run and not args.out:
        raise ConfigurationError("run needs --out DIR (or --dry-run)")
    with contextlib.ExitStack() as stack:
        t0 = time.perf_counter()
        job = {"scenario": _scenario_job, "fmu": _fmu_job, "ssp": _ssp_job}[kind](path, args, stack)
        for key in ("engine", "threads"):           # over a scenario's [simulation] ones
            if getattr(args, key) is not None:
                setattr(job.cosim, key, getattr(args, key))
        if args.dry_run:
            print(f"{kind}: {job.title}\n{job.cosim.describe()}")
            return 0
        with OutputFolder(Path(args.out), args.overwrite) as folder:
            df, paths = _record(job, folder, False if args.no_progress else None, t0 if kind == "scenario" else None)
            span = f"{job.stop_time - job.start_time:g} s simulated in {job.wall:.2f} s"
            if df is None:
                print(f"\n{span}; streamed")
            else:
                if job.extras is not None:
                    paths += job.extras(df, folder)
                elif len(df.columns):                   # an FMU's or SSP's plot of every recorded signal
                    plot_signals(df, folder / "outputs.png", job.title)
                    paths.append(folder / "outputs.png")
                print(f"\n{len(df)} rows x {len(df.columns)} signals, {span}"
                      + (" (including FMU build)" if kind == "scenario" else ""))
            for written in paths:
                print(f"wrote {written}")
    return 0


def _scenario_job(path: Path, args, stack: contextlib.ExitStack) -> _Job:
    fmus = Path(stack.enter_context(crash_guard.temporary_folder("pendulum_cosim_run_"))) / "fmus"
    sc = Scenario.load(path, fmu_dir=fmus)
    stream = bool(sc.recording.get("stream", False)) if args.stream is None else args.stream
    return _Job("scenario", sc.title or path.name, sc.cosim, sc.start_time, sc.stop_time,
                {k: v for k, v in sc.recording.items() if k != "stream"}, stream,
                extras=lambda df, out: _scenario_extras(sc, df, out, fmus))


def _fmu_job(path: Path, args, stack: contextlib.ExitStack) -> _Job:
    if args.stream:
        raise ConfigurationError("--stream: an FMU run records in memory; choose --outputs or a larger --step-size "
                                 "for a long run, or write a scenario file")
    exp = open_fmu(path, args.stop_time, start_time=args.start_time, step_size=args.step_size,
                   start=_start_values(args.start), inputs=args.input, outputs=args.outputs,
                   interface=args.interface or "auto")
    return _Job("fmu", path.name, exp.cosim, exp.start_time, exp.stop_time, {"signals": [f"{FMU_NAME}.*"]},
                prefix=f"{FMU_NAME}.")


def _ssp_job(path: Path, args, stack: contextlib.ExitStack) -> _Job:
    system = stack.enter_context(open_ssp(path, step_size=args.step_size, start=_start_values(args.start)))
    stop = args.stop_time if args.stop_time is not None else system.stop_time
    if stop is None:
        raise ConfigurationError(f"{path.name}: the SSD has no stop time; give --stop-time")
    start = args.start_time if args.start_time is not None else system.start_time or 0.0
    return _Job("ssp", system.name, system.cosim, start, stop, {"signals": args.outputs} if args.outputs else {},
                bool(args.stream))


def _record(job: _Job, out: Path, progress: bool | None, t0: float | None = None) -> tuple:
    """Run ``job`` into the held folder ``out`` (results, clock ticks; partial ones on failure);
    returns the DataFrame (None when streamed) and the paths written."""
    print(f"{job.kind}: {job.title}")
    job.wall = -(t0 if t0 is not None else time.perf_counter())
    try:
        if job.stream:
            result = job.cosim.run_to_parquet(out / "results.parquet", job.stop_time, job.start_time,
                                              progress=progress, **job.options)
            return None, [result] + _ticks(job, out, "clock_ticks.csv")
        df = job.cosim.run(job.stop_time, job.start_time, progress=progress, **job.options)
    except (PendulumCosimError, KeyboardInterrupt) as e:
        partial = getattr(e, "results", None) if not isinstance(e, Interrupted) else e.partial
        if partial is not None and hasattr(partial, "to_csv") and len(partial):
            save_results(_named(job, partial), out, "results.partial")
            print(f"partial results ({len(partial)} rows) written to {out}/results.partial.*", file=sys.stderr)
        _ticks(job, out, "clock_ticks.partial.csv")
        raise
    finally:
        job.wall += time.perf_counter()
    df = _named(job, df)
    return df, save_results(df, out) + _ticks(job, out, "clock_ticks.csv")


def _named(job: _Job, df):
    if job.prefix:
        df.columns = [c.removeprefix(job.prefix) for c in df.columns]
    return df


def _ticks(job: _Job, out: Path, name: str) -> list[Path]:
    """Every clock activation of the last run (columns time, clock) as ``out/name``, if any."""
    ticks = job.cosim.clock_ticks
    return [] if ticks is None else [atomic_write(out / name, lambda p: ticks.to_csv(p, index=False))]


def _scenario_extras(sc, df, out: Path, fmus: Path) -> list[Path]:
    """A scenario run's FMUs (those it built), RMSE table and plot."""
    paths = []
    for fmu in fmus.rglob("*.fmu"):                 # keep the FMUs the scenario built
        dst = out / "fmus" / fmu.relative_to(fmus)
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(fmu, dst)
    table = _rmse_table(df, [c.name for c in sc.cosim.components if isinstance(c, StateEstimator)])
    if len(table):
        print("\nRMSE against the plant's true states:")
        print(table.to_string(float_format=lambda v: f"{v:.4f}"))
        paths.append(atomic_write(out / "rmse.csv", table.to_csv))
    if sc.plot:
        png = out / "truth_vs_estimate.png"
        measured = [m or None for m in sc.plot.get("measured", [])] or None
        plot_estimates(df, sc.plot["truth"], sc.plot["estimate"], measured, png, sc.title)
        paths.append(png)
    return paths


def _export(args) -> int:
    """export-fmu and export-ssp: write FMUs (or an SSP) of a scenario's components."""
    check_clocked(args.clocked, args.fmi_version, args.command)  # named before anything is written
    platforms = parse_platforms(args.platforms)
    if platforms:
        zig_command()                              # a missing extra is named before anything is written
    path = _resolve_target(args.scenario)
    if _kind_of(path) != "scenario":
        raise ConfigurationError(f"{path.name}: {args.command} writes a scenario's components; this is an "
                                 f"{_kind_of(path).upper()}")
    with tempfile.TemporaryDirectory() as fmus:
        sc = Scenario.load(path, fmu_dir=fmus)
        comps = sc.cosim.by_name
        if args.command == "export-fmu":
            names = list(dict.fromkeys(args.component or [n for n, c in comps.items()
                                                          if isinstance(c, StateEstimator)]))
            unknown = [n for n in names if n not in comps]
            if unknown:
                raise ConfigurationError(f"no component {unknown[0]!r} in {path.name}; components: {', '.join(comps)}")
            if not names:
                raise ConfigurationError(f"{path.name} has no estimator; name components with --component")
            no_form = [n for n in names if not isinstance(comps[n], ExportsFMU)]
            if no_form:
                raise ConfigurationError(f"component {no_form[0]!r} ({type(comps[no_form[0]]).__name__}) has no FMU "
                                         "form")
        with OutputFolder(Path(args.out), args.overwrite) as out:
            if args.command == "export-ssp":
                result = export_ssp(sc, out, fmi_version=args.fmi_version, name=args.name or path.stem,
                                    platforms=platforms, clocked=args.clocked)
                print(f"wrote {result.archive} (and {result.ssd.name}, resources/ beside it): "
                      f"{len(result.fmus)} FMUs, FMI {args.fmi_version}.0")
                for note in result.notes:
                    print(f"note: {note}")
                return 0

            for n in names:
                exported = export_component(comps[n], out, args.fmi_version, args.clocked)
                notes = add_platforms(exported.path, platforms) if platforms else []
                md = read_description(exported.path)
                clocked = ", clocked" if any(v.type == "Clock" for v in md.modelVariables) else ""
                print(f"wrote {exported.path} ({type(comps[n]).__name__} {n}, FMI {str(md.fmiVersion)[:1]}.0{clocked}, "
                      f"period {comps[n].period:g} s)")
                for note in ([exported.note] if exported.note else []) + notes:
                    print(f"note: {note}")
    return 0


def _models(args) -> int:
    """``models``: every registered model's trajectories (Euler truth map, RK4) and Jacobians."""
    dt, n = 0.01, round(args.duration / 0.01)
    for m in map(get_model, model_names()):
        x0 = m.x0 if m.example_x0 is None else np.asarray(m.example_x0, float)
        u = m.example_input or (lambda t, m=m: np.zeros(m.nu))
        print(f"== {m.description}")
        print(f"   states {m.state_names}, input {m.input_names}, params {m.params}")
        with np.printoptions(precision=5, suppress=True, linewidth=110):
            xs = m.simulate(x0, u, dt, n, method="euler")
            xr = m.simulate(x0, u, dt, n, method="rk4", substeps=4)
            print(f"   t [s] | Euler (T = {dt} s) state | RK4 (4 substeps) state")
            for k in range(0, n + 1, max(1, n // 10)):
                print(f"   {k * dt:5.2f} | {xs[k]} | {xr[k]}")
            A, B = m.linearize(np.zeros(m.nx), np.zeros(m.nu))
            print("   exact A = df/dx at x = 0, u = 0:\n", A)
            print("   exact B = df/du:", B.ravel())
        print()
    return 0


def _experiment(args) -> int:
    """Any registered experiment (:mod:`cosim.experiments.experiment`): its settings are validated
    before ``--out`` is touched; an interrupted run writes a partial report."""
    exp = EXPERIMENTS.get(args.name)()
    exp.check_path(args.path)
    if args.scheduler is not None:
        if args.backend != "dask":
            raise ConfigurationError("--scheduler names a dask cluster's scheduler: it goes with --backend dask")
        try:
            import dask
        except ImportError:
            raise ConfigurationError("--backend dask needs dask: pip install 'pendulum-cosim[dask]'") from None
        dask.config.set({"scheduler-address": args.scheduler})
    config = args.config or exp.default_config
    settings = exp.settings(config, args.settings, args.set, args.runs, args.seed)
    out = Path(args.out or f"out/{args.name}" + (f"-{args.config}" if args.config else ""))
    with OutputFolder(out, args.overwrite) as folder:
        try:
            result = exp.run(settings, path=args.path, backend=args.backend, n_jobs=args.jobs, progress=not args.quiet)
        except Interrupted as e:
            if e.partial is not None and len(e.partial[0]):
                md = exp.write_report(e.partial, settings, folder, args.path, config, partial=True)
                print(f"interrupted: partial results ({e}) in {md}", file=sys.stderr)
            raise
        md = exp.write_report(result, settings, folder, args.path, config)
        print(exp.summary(result, settings, args.path, config))
        print(f"\nwrote {md} and the tables and figures beside it")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The ``pendulum-cosim`` argument parser."""
    parser = argparse.ArgumentParser(
        prog="pendulum-cosim",
        description="FMI co-simulation of two benchmark pendulums for nonlinear state estimation. "
                    "Plants run as FMUs built from CasADi models; estimators and other components "
                    "run in Python, each at its own sample period.")
    parser.add_argument("--debug", action="store_true", help="show tracebacks instead of one-line errors")
    parser.add_argument("--version", action="version", version=f"pendulum-cosim {VERSION}")
    parser.add_argument("--plugin", action="append", metavar="MODULE_OR_FILE",
                        help="import a module or .py file first (repeatable): the models, filters, components "
                             "and experiments it defines register themselves")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="run the seed 000 cart-pole scenario (EKF and MF-IAE): "
                                       "results table, CSV/Parquet and a truth-vs-estimate plot")
    demo.add_argument("--out", default="out/demo", help="output directory (default out/demo; "
                                                          "replaced on every demo run)")
    demo.set_defaults(handler=_demo)
    _add_run(sub)
    sub.add_parser("scenarios", help="list the shipped scenario files").set_defaults(handler=_scenarios)
    models = sub.add_parser("models", help="simulate both plant models, print trajectories and Jacobians")
    models.add_argument("--duration", type=_number(float, 0, "the duration", strict=True, high=MAX_MODELS_DURATION),
                        default=5.0, help=f"simulated time [s] (default 5, at most {MAX_MODELS_DURATION:g}: "
                                          "the report prints ten rows of it)")
    models.set_defaults(handler=_models)
    _add_experiment(sub)
    _add_export(sub)
    return parser


def _add_run(sub) -> None:
    run = sub.add_parser("run", help="run a scenario file (TOML; see `pendulum-cosim scenarios`), an FMU or an SSP "
                                     "(archive, folder or .ssd)")
    run.set_defaults(handler=_run)
    run.add_argument("scenario", metavar="PATH", help="scenario file, FMU, SSP, or the name of a shipped scenario")
    run.add_argument("--out", help="output directory (required unless --dry-run)")
    run.add_argument("--overwrite", action="store_true", help="replace the contents of a non-empty --out")
    run.add_argument("--dry-run", action="store_true",
                     help="print the schedule (order, latency of every connection) and stop")
    run.add_argument("--stream", action="store_true", default=None,
                     help="stream the rows to results.parquet in chunks (constant memory; long runs)")
    run.add_argument("--no-progress", action="store_true", help="no progress bar")
    run.add_argument("--engine", choices=ENGINES,
                     help="which loop runs the co-simulation: auto (the native kernel where it can, the "
                          "default unless the scenario's [simulation] engine says otherwise), native "
                          "(refused where the kernel cannot run it) or python")
    run.add_argument("--threads", type=_threads, metavar="N",
                     help="threads that step the FMUs at once in the native kernel: auto (parallel where the "
                          "measured FMU steps pay for it; the default unless the scenario's [simulation] threads "
                          "says otherwise), or a whole number (1: serial)")
    fmu = run.add_argument_group("an FMU or SSP (a scenario file sets these in its own tables)")
    fmu.add_argument("--stop-time", type=_number(float, what="--stop-time"), metavar="T",
                     help="[s] default: the FMU's or SSP's DefaultExperiment (an FMU without one: start + 1 s)")
    fmu.add_argument("--start-time", type=_number(float, what="--start-time"), metavar="T",
                     help="[s] default: the DefaultExperiment's, else 0")
    fmu.add_argument("--step-size", type=_number(float, 0, "--step-size", strict=True), metavar="H",
                     help="[s] the communication step (Model Exchange: the output grid); an SSP: the step of the "
                          "FMUs it names none for. Default: the DefaultExperiment's, else a 500th of the span")
    fmu.add_argument("--start", action="append", metavar="NAME=VALUE",
                     help="a parameter or start value (repeatable; an SSP: component.variable)")
    fmu.add_argument("--input", metavar="CSV", help="FMU inputs: a time column [s] and one column per input, named as "
                                                   "the FMU's inputs")
    fmu.add_argument("--outputs", nargs="+", metavar="NAME",
                     help="what is recorded: FMU variables (default its outputs); an SSP: component.port patterns")
    fmu.add_argument("--interface", choices=[i for i in INTERFACES if i != "auto"],
                     help="an FMU's interface: cs, me or se (default: Co-Simulation if it has it)")


def _add_experiment(sub) -> None:
    exp = sub.add_parser("experiment", help="reproduce a paper's experiment as a Monte Carlo "
                                            "campaign; writes tables, figures and summary.md")
    exp.set_defaults(handler=_experiment)
    exp.add_argument("name", choices=EXPERIMENTS.names(), help="which experiment: " + "; ".join(
        f"{n}: {EXPERIMENTS.get(n).description}" for n in EXPERIMENTS.names()))
    exp.add_argument("--config", help="named configuration (seed000: default = Q0 = R0 = 0.01 I, both readings; "
                                      "paper = Q0 = 1e-3 I, R0 = 10 I, eqs reading)")
    exp.add_argument("--set", action="append", metavar="NAME=VALUE",
                     help="change one setting (repeatable), e.g. --set q0=1e-3 --set mfiae_window=12; "
                          "summary.md lists them all")
    exp.add_argument("--settings", metavar="FILE", help="settings from a TOML file (e.g. a run's settings.toml)")
    exp.add_argument("--runs", type=_positive_int, help="realisations per scenario (default: the paper's)")
    exp.add_argument("--path", choices=("fast", "master"), default="fast",
                     help="fast: vectorised truth and batched filters; master: every realisation "
                          "through the co-simulation master with the plant FMU (same numbers)")
    exp.add_argument("--backend", choices=("processes", "serial", "dask"), default="processes",
                     help="parallel backend (dask needs the 'dask' extra)")
    exp.add_argument("--scheduler", metavar="ADDRESS",
                     help="with --backend dask: the scheduler of a running dask cluster (e.g. tcp://host:8786; "
                          "default: dask's configuration, else a local cluster)")
    exp.add_argument("--jobs", type=_positive_int, help="worker processes (default: all cores)")
    exp.add_argument("--seed", type=_number(int, 0, "the seed"), help="seed of all random streams")
    exp.add_argument("--out", help="output directory (default out/NAME)")
    exp.add_argument("--overwrite", action="store_true", help="replace the contents of a non-empty --out")
    exp.add_argument("--quiet", action="store_true", help="no progress bar")


def _add_export(sub) -> None:
    efmu = sub.add_parser("export-fmu", help="write a scenario's estimators (or other components) as native "
                                             "Co-Simulation FMUs, no Python inside")
    essp = sub.add_parser("export-ssp", help="write a scenario as an SSP (SystemStructure.ssd plus an FMU per "
                                             "component) for other FMI/SSP tools")
    for p in (efmu, essp):
        p.set_defaults(handler=_export)
        p.add_argument("scenario", help="scenario file, or the name of a shipped scenario")
        p.add_argument("--out", required=True, help="output directory")
        p.add_argument("--fmi-version", type=int, choices=(2, 3), default=2, help="FMI version (default 2)")
        p.add_argument("--overwrite", action="store_true", help="replace the contents of a non-empty --out")
        p.add_argument("--clocked", action="store_true",
                       help="FMI 3.0: estimators and signal FMUs with an input clock at their sample period "
                            "(Co-Simulation with Event Mode, Scheduled Execution)")
        p.add_argument("--platforms", metavar="LIST",
                       help="also build binaries for these platforms (comma-separated: linux64,win64,darwin,"
                            "aarch64-linux); needs pip install -e '.[cross]'")
    efmu.add_argument("--component", action="append", metavar="NAME",
                      help="component to export (repeatable; default: every estimator)")
    essp.add_argument("--name", help="system name and archive name (default: the scenario file's name)")


def _scenarios(args) -> int:
    """``scenarios``: the shipped scenario files and their titles."""
    for p in sorted(_scenario_dir().glob("*.toml")):
        first = p.read_text().splitlines()[0]
        print(f"{p.stem:24s} {first.split('=', 1)[1].strip().strip(chr(34)) if '=' in first else ''}")
        print(f"{'':24s} {p}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``pendulum-cosim`` with the arguments ``argv`` (default: ``sys.argv[1:]``);
    returns the exit status (0, 2 on an error, 130 when interrupted)."""
    pre = argparse.ArgumentParser(add_help=False)
    pre.add_argument("--plugin", action="append", default=[])
    pre.add_argument("--debug", action="store_true")
    known, _ = pre.parse_known_args(argv)
    # before the parser: their experiments become choices
    status = run_command(lambda: _load_plugins(known.plugin), debug=known.debug)
    if status:
        return status
    args = build_parser().parse_args(argv)
    if not logging.getLogger().handlers:
        logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s", stream=sys.stderr)
        logging.getLogger("cosim.fmu").setLevel(logging.INFO)
    return run_command(lambda: args.handler(args), debug=args.debug)


def _load_plugins(plugins: list[str]) -> int:
    for plugin in plugins:
        load_plugin(plugin)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Pieces shared by the experiments: the same random streams on the fast path and through
the master, vectorised truth, batched filters, realisations through the master, the
campaign's plumbing, and the reports' tables, figures and files."""
from __future__ import annotations

import tempfile
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import NamedTuple

import casadi as ca
import numpy as np

from estimators import BatchFilter, DiscreteModel
from fmu_models import build_fmu
from fmu_models.errors import Interrupted
from fmu_models.infra.files import atomic_write

from ..components.estimation import EstimatorComponent
from ..components.sensors import ProcessNoise, Sensor
from ..core.master import Cosimulation
from ..fmi.fmu_component import FMUComponent
from . import metrics
from .campaign import realisation_seeds, run_tasks


# ---------------------------------------------------------------------------- the campaign's plumbing
def seed_pairs(settings, key: int, runs: Iterable[int] | None = None) -> list[tuple[int, int]]:
    """The (process, measurement) seeds of the realisations ``runs`` (default all) of task ``key``
    (e.g. a scenario's index): :func:`~cosim.experiments.campaign.realisation_seeds` of ``settings.seed``."""
    runs = range(settings.runs) if runs is None else runs
    return [tuple(realisation_seeds(settings.seed, key, r)) for r in runs]


def run_campaign(tasks: Sequence[tuple[Callable, dict]], assemble: Callable, desc: str, backend: str = "processes",
                 n_jobs: int | None = None, progress: bool = True):
    """``assemble(results, wall)`` of the results of ``tasks`` (run by
    :func:`~cosim.experiments.campaign.run_tasks` with ``desc``, ``backend``, ``n_jobs`` and
    ``progress``) and their wall time [s]. Interrupted, the
    :class:`~fmu_models.errors.Interrupted` raised carries as ``partial`` what ``assemble``
    makes of the finished tasks (None for the others)."""
    t0 = time.perf_counter()
    try:
        results = run_tasks(tasks, backend=backend, n_jobs=n_jobs, progress=progress, desc=desc)
    except Interrupted as e:
        e.partial = assemble(e.partial or [None] * len(tasks), time.perf_counter() - t0)
        raise
    return assemble(results, time.perf_counter() - t0)


def _noise_components(model, T: float, q, measured: Sequence[str], r_std, seed_w: int, seed_v: int):
    """The ProcessNoise (covariance ``q`` on every state) and Sensor of one realisation."""
    return (ProcessNoise("noise", T, model.state_names, q, seed=seed_w),
            Sensor("sensor", T, list(measured), noise_std=r_std, seed=seed_v))


def simulate_truth(model, x0, us: np.ndarray, T: float, q, measured, r_std, seeds, method="euler",
                   substeps=1):
    """Truth ``X`` (runs, N+1, nx) and measurements ``Y`` (runs, N+1, ny), drawing exactly the
    numbers the ProcessNoise and Sensor components draw on the master path (same seeds, same
    order): from the initial state ``x0`` under the inputs ``us`` (N+1, nu) at the period ``T``
    [s], the process noise covariance ``q`` (scalar, diagonal or matrix) and the standard
    deviations ``r_std`` of the ``measured`` states' noise, a realisation per (process,
    measurement) seed pair of ``seeds``. ``model``: a plant model (its truth map by ``method``
    in ``substeps``), or a process model (:class:`~estimators.DiscreteModel`, an FMU's too: its
    own map and period; ``Y`` its outputs if they are the ``measured``)."""
    R, N = len(seeds), len(us) - 1
    noise, sensor = _noise_components(model, T, q, measured, r_std, 0, 0)
    W = np.stack([np.random.default_rng(sw).standard_normal((N + 1, model.nx)) @ noise.L.T
                  for sw, _ in seeds])
    V = np.stack([sensor.noise_std * np.random.default_rng(sv).standard_normal((N + 1, len(measured)))
                  for _, sv in seeds])
    process = isinstance(model, DiscreteModel)
    step = (ca.Function("f", [model.x, model.u], [model.fx]) if process else model.sym.step(method, substeps)).map(R)
    X = np.empty((R, N + 1, model.nx))
    X[:, 0] = x0
    for k in range(N):
        X[:, k + 1] = np.asarray(step(X[:, k].T, np.repeat(us[k][:, None], R, axis=1),
                                      *(() if process else (model.p, T)))).T + W[:, k]
    if process and list(measured) == model.output_names:
        h = ca.Function("h", [model.x], [model.hx]).map(R * (N + 1))
        return X, np.asarray(h(X.reshape(-1, model.nx).T)).T.reshape(R, N + 1, -1) + V
    idx = [model.state_names.index(m) for m in measured]
    return X, X[:, :, idx] + V


class BatchOutcome(NamedTuple):
    """One filter over every realisation: estimates ``x`` (runs, N+1, nx; the initial one at
    k = 0), ``nees`` and ``nis`` (runs, N), the ``failed`` realisations (runs,), the
    ``innovation`` (runs, N, ny) and its covariance ``S`` (runs, N, ny, ny)."""

    x: np.ndarray
    nees: np.ndarray
    nis: np.ndarray
    failed: np.ndarray
    innovation: np.ndarray
    S: np.ndarray


def batch_run(make: Callable, X: np.ndarray, Y: np.ndarray, us: np.ndarray) -> BatchOutcome:
    """Run the filter of ``make`` (a new one per call) over the realisations ``X`` (truth,
    (runs, N+1, nx)) and ``Y`` (measurements, (runs, N+1, ny), row 0 unused) in one native
    call, ``us[k]`` (inputs, (N+1, nu)) held over step k -> k+1; NEES from the full covariance."""
    out = BatchFilter(make(), X.shape[0], on_failure="mark").run(us[:-1], Y[:, 1:])
    with np.errstate(invalid="ignore", over="ignore"):
        nees = metrics.nees(out.x[:, 1:] - X[:, 1:], out.P[:, 1:])
    return BatchOutcome(out.x, nees, out.nis, out.failed.copy(), out.innovation, out.S)


def master_runs(model, x0, source, q, measured: Sequence[str], r_std, makers: dict, T: float, duration: float,
                seeds: Sequence[tuple[int, int]], fmu_dir=None):
    """:func:`simulate_truth`'s realisations (``model`` a plant model, ``x0``, ``q``,
    ``measured``, ``r_std``, ``T``, ``seeds`` as there) through the co-simulation master, ``duration``
    [s] long: the plant FMU (built in ``fmu_dir``, default a temporary folder), the sensor, the
    filters of the factories ``makers`` by name, the input ``source`` (its outputs drive the
    plant's inputs in order) and the process noise, built once, each filter restored to its
    initial state before each run (the numbers of a new filter). Returns truth (runs, N+1, nx),
    the estimates by filter (runs, N+1, nx), and NEES (from the full covariance) and NIS by
    filter (runs, N)."""
    X = np.empty((len(seeds), round(duration / T) + 1, model.nx))
    est = {n: np.empty_like(X) for n in makers}
    nees = {n: np.empty((len(seeds), X.shape[1] - 1)) for n in makers}
    nis = {n: np.empty_like(nees[n]) for n in makers}
    with tempfile.TemporaryDirectory() as tmp:
        plant = FMUComponent("plant", build_fmu(model, fmu_dir or tmp), T, start=dict(zip(model.state_names, x0)))
        states = [p for p in plant.output_names if f"w_{p}" in plant.input_names]
        nx = len(states)
        noise, sensor = _noise_components(model, T, q, measured, r_std, *seeds[0])
        inputs = {u: f"{source.name}.{source.output_names[j]}"
                  for j, u in enumerate(p for p in plant.input_names if not p.startswith("w_"))}
        tags = {name: f"f{i}" for i, name in enumerate(makers)}
        conn = {**{f"plant.{u}": src for u, src in inputs.items()},
                **{f"sensor.{m}": f"plant.{m}" for m in sensor.input_names},
                **{f"plant.w_{x}": f"noise.w_{x}" for x in states}}
        for t in tags.values():
            conn.update({f"{t}.{u}": src for u, src in inputs.items()})
            conn.update({f"{t}.y_{m}": f"sensor.y_{m}" for m in sensor.input_names})
        ests = [EstimatorComponent(tags[n], _restored(makers[n]), T, covariance="full") for n in makers]
        cosim = Cosimulation([plant, sensor, *ests, source, noise], conn)
        for i, (seed_w, seed_v) in enumerate(seeds):
            noise.seed, sensor.seed = int(seed_w), int(seed_v)
            df = cosim.run(duration)
            data = df.to_numpy(dtype=float)                 # every signal here is real: the frame's values
            col = {c: k for k, c in enumerate(df.columns)}
            X[i] = data[:, [col[f"plant.{x}"] for x in states]]
            for name, t in tags.items():
                P = np.empty((len(data), nx, nx))
                for a, x in enumerate(states):
                    P[:, a, a] = data[:, col[f"{t}.P_{x}"]]
                    for b in range(a + 1, nx):
                        P[:, a, b] = P[:, b, a] = data[:, col[f"{t}.P_{a}_{b}"]]
                est[name][i], nis[name][i] = data[:, [col[f"{t}.{x}"] for x in states]], data[1:, col[f"{t}.nis"]]
                with np.errstate(over="ignore", invalid="ignore"):
                    nees[name][i] = metrics.nees(est[name][i][None, 1:] - X[i][None, 1:], P[None, 1:])[0]
    return X, est, nees, nis


def _restored(make):
    """A factory returning one filter of ``make``, restored to its initial state at each call."""
    filt = make()
    initial = filt.snapshot()

    def again():
        filt.restore(initial)
        return filt

    return again


# ---------------------------------------------------------------------------- the reports' tables
def pcrb_columns(rmse_runs: np.ndarray, bound_mse: np.ndarray | None, states: Sequence[str]) -> dict:
    """``pcrb_ratio_<state>`` of each of the ``states``
    (:func:`~cosim.experiments.metrics.pcrb_ratio` of the realisations' RMSE ``rmse_runs``
    (runs, nx) over the bound ``bound_mse`` (K, nx) at steps 1..K), ``pcrb_ratio_max`` and
    ``pcrb_ratio_se_<state>`` (its Monte Carlo standard error); NaN without a bound (None)."""
    if bound_mse is None:
        ratio = se = np.full(len(states), np.nan)
    else:
        ratio, se = metrics.pcrb_ratio(rmse_runs, bound_mse), metrics.pcrb_ratio_se(rmse_runs, bound_mse)
    return {**{f"pcrb_ratio_{x}": float(r) for x, r in zip(states, ratio)}, "pcrb_ratio_max": float(np.max(ratio)),
            **{f"pcrb_ratio_se_{x}": float(e) for x, e in zip(states, se)}}


def error_columns(rmse_runs: np.ndarray, bound_mse: np.ndarray | None, states: Sequence[str]) -> dict:
    """``rmse_<state>`` (the RMSE over all the realisations) of each of the ``states``, then
    :func:`pcrb_columns` of ``rmse_runs`` and ``bound_mse``."""
    return {**{f"rmse_{x}": float(np.sqrt(np.mean(rmse_runs[:, a] ** 2))) for a, x in enumerate(states)},
            **pcrb_columns(rmse_runs, bound_mse, states)}


def pcrb_row(ident: dict, bound_mse: np.ndarray, runs: int, states: Sequence[str]) -> dict:
    """The row of the PCRB itself in a consistency table: the identifying columns ``ident``,
    the ``runs`` it is computed over, per state of ``states`` the root of the bound's mean
    over steps 1..K (``bound_mse``: shape (K+1, nx), from k = 0), and every ratio 1."""
    return {**ident, "filter": "PCRB", "runs": runs,
            **{f"rmse_{x}": float(np.sqrt(bound_mse[1:, a].mean())) for a, x in enumerate(states)},
            **{f"pcrb_ratio_{x}": 1.0 for x in states}, "pcrb_ratio_max": 1.0}


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> list[str]:
    """The lines of a Markdown table of ``header`` and ``rows`` (cells as text)."""
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header), *("| " + " | ".join(r) + " |" for r in rows)]


def settings_table(settings, leave_out: Sequence[str] = ()) -> list[str]:
    """The Markdown table of the dataclass ``settings``, but the fields ``leave_out``."""
    return markdown_table(["setting", "value"],
                          ([k, f"{v}"] for k, v in asdict(settings).items() if k not in leave_out))


def consistency_section(table, keys: Sequence[str], settings, path: str, after: Sequence[str] = ()) -> list[str]:
    """The reports' section on the consistency tests: the rule at ``settings.confidence`` and
    ``settings.whiteness_lags``, the tests of the filters of the consistency ``table`` (its
    PCRB rows left out; :func:`~cosim.experiments.metrics.consistency_markdown` with
    ``keys``), the lines ``after``, and on the master ``path`` why whiteness is not tested."""
    lines = ["## Consistency: chi-square bands of NEES and NIS, whiteness of the innovations", "",
             "Rule: " + metrics.consistency_rule(settings.confidence, settings.whiteness_lags) + ".", "",
             *metrics.consistency_markdown(table[table["filter"] != "PCRB"], keys), "", *after]
    if path == "master":
        lines += ["On the master path the estimator components do not publish their innovations, so whiteness "
                  "is not tested there (the fast path gives the same numbers).", ""]
    return lines


# ---------------------------------------------------------------------------- the reports' files and figures
def report_folder(out_dir, settings_toml: str, tables: dict) -> Path:
    """The folder ``out_dir`` (made if need be) with ``settings.toml`` (the text
    ``settings_toml``) and the ``tables`` (:func:`write_tables`) written into it."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write(out / "settings.toml", lambda p: p.write_text(settings_toml))
    write_tables(out, tables)
    return out


def write_tables(out: Path, tables: dict) -> None:
    """Each DataFrame of ``tables`` into the folder ``out`` under its file name: Parquet for
    ``*.parquet``, else CSV without the index."""
    for name, frame in tables.items():
        atomic_write(out / name, frame.to_parquet if name.endswith(".parquet") else
                     lambda p, frame=frame: frame.to_csv(p, index=False))


#: The line a summary of an interrupted campaign starts with.
PARTIAL_NOTE = ["**PARTIAL RESULTS: the campaign was interrupted; only the tasks that finished are in these tables.**",
                ""]


def write_summary(out: Path, lines: Sequence[str], partial: bool = False) -> Path:
    """``summary.md`` in the folder ``out``: the ``lines`` (the first one a title; with
    ``partial``, :data:`PARTIAL_NOTE` after it); returns its path."""
    if partial:
        lines = [*lines[:2], *PARTIAL_NOTE, *lines[2:]]
    return atomic_write(out / "summary.md", lambda p: p.write_text("\n".join(lines) + "\n"))


def new_figure(rows: int = 1, cols: int = 1, figsize=(8, 4), **subplot_kw):
    """A matplotlib Figure of ``figsize`` (inches) and its ``rows x cols`` axes (2-D array),
    without pyplot (no global backend or state); ``subplot_kw`` go to ``Figure.subplots``
    (e.g. ``sharex=True``)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
    return fig, fig.subplots(rows, cols, squeeze=False, **subplot_kw)


def style_axes(ax, xlabel: str = "", ylabel: str = "", title: str = "", log: bool = False, legend: int = 0,
               ncol: int = 1) -> None:
    """The reports' look of the matplotlib Axes ``ax``: a log y axis if ``log``, the
    ``xlabel``, ``ylabel`` and ``title`` given, a light grid, and a legend of font size
    ``legend`` in ``ncol`` columns (none if 0)."""
    if log:
        ax.set_yscale("log")
    ax.set(**{key: text for key, text in (("xlabel", xlabel), ("ylabel", ylabel)) if text})
    ax.grid(alpha=0.3)
    if legend:
        ax.legend(fontsize=legend, ncol=ncol)
    if title:
        ax.set_title(title)


def save_figure(fig, path: Path) -> None:
    """The matplotlib Figure ``fig`` as a PNG of 100 dpi at ``path``, written whole or not at all."""
    atomic_write(path, lambda p: fig.savefig(p, dpi=100, format="png"))

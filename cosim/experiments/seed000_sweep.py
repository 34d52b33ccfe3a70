"""Where adaptation pays: EKF, IAE, MF-IAE and SWML over a grid of wrong starting Q0 and R0.

Beyond the paper. Each cell of the grid starts the three filters at ``Q0 = fq q I`` and
``R0 = fr r I``, where ``(q, r)`` are the scenario's true variances and ``fq, fr`` run over
``SweepSettings.factors`` (default 1e-3 ... 1e3, 7 x 7 cells), and runs the seed 000
campaign of every scenario (eqs reading) with them: a cell is exactly
``seed000.fast_task`` with ``q0_factor = fq, r0_factor = fr`` (same realisations, same
numbers; the tests check it). Reported per cell and filter: eta (eq 44) over the
true-Q,R EKF's eta (the bound), the average NEES, and for the adaptive filters (and the
EKF whose Q and R EM learned from the same start on a training realisation) the
fraction of realisations in which they are worse than the EKF started at the same Q0,
R0. The sweep's goals (``bound_margin``, ``ekf_margin``, ``nees_factor``) are checked cell by
cell and summarised in ``summary.md``.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from fmu_models.errors import ConfigurationError, Interrupted
from fmu_models.infra.checks import positive
from fmu_models.infra.files import atomic_write

from . import seed000
from .campaign import run_tasks
from .common import new_figure
from .experiment import Experiment
from .settings import apply_overrides, to_toml

ADAPTIVE = ("IAE", "MF-IAE", "EKF EM", "SWML")
FILTERS = ("EKF", *ADAPTIVE)
FACTORS = (1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0, 1000.0)


@dataclass(frozen=True)
class SweepSettings:
    """The grid (``factors``, used for both Q0 and R0), and the campaign settings of every
    cell (``campaign``: a :class:`seed000.Settings`; its ``q0_factor``/``r0_factor`` are
    set per cell, its reading is ``eqs``). Goals: ``bound_margin`` (within this fraction of
    the bound), ``ekf_margin`` (never more than this fraction worse than the EKF),
    ``nees_factor`` (average NEES within this factor of the state dimension)."""

    factors: tuple = FACTORS
    campaign: seed000.Settings = field(default_factory=lambda: replace(seed000.CONFIGS["paper"]))
    bound_margin: float = 0.20
    ekf_margin: float = 0.05
    nees_factor: float = 3.0

    def __post_init__(self):
        if len(self.factors) < 1:
            raise ConfigurationError("factors must list at least one factor")
        for f in self.factors:
            positive(f, "a grid factor")


def cell_task(scenario_index: int, cells: list[tuple[float, float]], settings: seed000.Settings) -> list[dict]:
    """The rows of several cells of one scenario (one process task).

    Parameters
    ----------
    scenario_index
        Which scenario (0-based).
    cells
        (Q0 factor, R0 factor) of each cell.
    settings
        The campaign settings of every cell.
    """
    rows = []
    for fq, fr in cells:
        s = replace(settings, q0_factor=fq, r0_factor=fr, readings=("eqs",))
        res = seed000.fast_task(scenario_index, "eqs", s)
        bound = res["per_run"]["EKF true Q,R"]["eta"]
        ekf = res["per_run"]["EKF"]["eta"]
        for name in FILTERS:
            pr = res["per_run"][name]
            rows.append({"scenario": scenario_index + 1, "q_factor": fq, "r_factor": fr, "filter": name,
                         "eta": float(np.mean(pr["eta"])), "bound": float(np.mean(bound)),
                         "eta_over_bound": float(np.mean(pr["eta"]) / np.mean(bound)),
                         "eta_over_ekf": float(np.mean(pr["eta"]) / np.mean(ekf)),
                         "worse_than_ekf": float(np.mean(pr["eta"] > ekf)) if name != "EKF" else 0.0,
                         "anees": float(np.mean(pr["anees"])), "diverged": int(pr["diverged"].sum())})
    return rows


class SweepResult(NamedTuple):
    """What :func:`run` returns: the ``table`` (one row per scenario, cell and filter) and the
    ``wall`` time [s]."""

    table: pd.DataFrame
    wall: float


def run(settings: SweepSettings = SweepSettings(), backend: str = "processes", n_jobs=None,
        progress: bool = True):
    """Run the sweep; returns ``(table, wall_time)``: one row per scenario, cell and
    filter (see the module documentation). Interrupted, it raises
    :class:`~fmu_models.errors.Interrupted` with the rows of the finished tasks.

    Parameters
    ----------
    settings
        The sweep's settings.
    backend
        Parallel backend.
    n_jobs
        Worker processes.
    progress
        Show a progress bar.
    """
    s = settings.campaign
    cells = [(fq, fr) for fq in settings.factors for fr in settings.factors]
    chunks = [cells[i:i + len(settings.factors)] for i in range(0, len(cells), len(settings.factors))]
    tasks = [(cell_task, dict(scenario_index=i, cells=c, settings=s))
             for i in range(len(s.scenarios)) for c in chunks]
    t0 = time.perf_counter()
    try:
        results = run_tasks(tasks, backend=backend, n_jobs=n_jobs, progress=progress, desc="seed000 sweep")
    except Interrupted as e:
        e.partial = SweepResult(pd.DataFrame([r for rows in (e.partial or []) if rows for r in rows]),
                                time.perf_counter() - t0)
        raise
    return SweepResult(pd.DataFrame([r for rows in results for r in rows]), time.perf_counter() - t0)


def goals(table: pd.DataFrame, settings: SweepSettings, nx: int = 4) -> pd.DataFrame:
    """Per adaptive filter: the share of cells (mean over scenarios) within the bound margin,
    the cells more than ``ekf_margin`` worse than the EKF, and those with an average NEES
    beyond ``nees_factor * nx``.

    Parameters
    ----------
    table
        The sweep's table.
    settings
        The sweep's settings (its goal margins).
    nx
        State dimension.
    """
    cell = table.groupby(["filter", "q_factor", "r_factor"]).mean(numeric_only=True).reset_index()
    rows = []
    for name in ADAPTIVE:
        c = cell[cell["filter"] == name]
        rows.append({"filter": name, "cells": len(c),
                     "within bound margin": int((c["eta_over_bound"] <= 1 + settings.bound_margin).sum()),
                     "worse than EKF by more than margin": int((c["eta_over_ekf"] > 1 + settings.ekf_margin).sum()),
                     "ANEES beyond factor": int((c["anees"] > settings.nees_factor * nx).sum()),
                     "best eta/bound": float(c["eta_over_bound"].min()),
                     "worst eta/bound": float(c["eta_over_bound"].max()),
                     "worst eta/EKF": float(c["eta_over_ekf"].max())})
    return pd.DataFrame(rows)


def write_report(table: pd.DataFrame, wall: float, settings: SweepSettings, out_dir, partial: bool = False) -> Path:
    """``sweep.csv|parquet``, heat maps (``heatmap_<metric>.png``), ``settings.toml`` and
    ``summary.md`` into ``out_dir``.

    Parameters
    ----------
    table
        The sweep's table.
    wall
        Wall time [s].
    settings
        The sweep's settings.
    out_dir
        Output folder.
    partial
        The sweep was interrupted.
    """


    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write(out / "settings.toml", lambda p: p.write_text(
        to_toml(settings.campaign, "seed000-sweep") + f"factors = {list(settings.factors)}\n"))
    atomic_write(out / "sweep.csv", lambda p: table.to_csv(p, index=False))
    atomic_write(out / "sweep.parquet", table.to_parquet)
    lines = ["# Seed 000 robustness sweep: EKF, IAE, MF-IAE, the EM-learned EKF and SWML from wrong Q0 and R0", ""]
    if partial:
        lines += ["**PARTIAL RESULTS: the sweep was interrupted; only finished cells are here.**", ""]
    if len(table):
        g = goals(table, settings)
        atomic_write(out / "goals.csv", lambda p: g.to_csv(p, index=False))
        _heatmaps(table, settings, out)
        n = len(settings.factors) ** 2
        lines += [f"{len(settings.factors)} x {len(settings.factors)} cells (Q0 = fq q, R0 = fr r with "
                  f"f in {', '.join(f'{f:g}' for f in settings.factors)}), "
                  f"{table['scenario'].nunique()} scenarios, {settings.campaign.runs} realisations a cell; "
                  f"wall time {wall:.1f} s.", "",
                  "## Goals (cells averaged over the scenarios)", "",
                  g.to_markdown(index=False, floatfmt=".3f"), "",
                  f"Goals: eta within {settings.bound_margin:.0%} of the bound in most of the {n} cells; never more "
                  f"than {settings.ekf_margin:.0%} worse than the EKF started at the same Q0, R0; average NEES "
                  f"within {settings.nees_factor:g} x nx = {settings.nees_factor * 4:g}.", "",
                  "## eta / bound, mean over scenarios (rows: Q0 factor, columns: R0 factor)", ""]
        for name in FILTERS:
            grid = _grid(table, name, "eta_over_bound")
            lines += [f"**{name}**", "", grid.to_markdown(floatfmt=".2f"), ""]
        lines += ["## Average NEES (state dimension 4)", ""]
        for name in FILTERS:
            lines += [f"**{name}**", "", _grid(table, name, "anees").to_markdown(floatfmt=".3g"), ""]
        lines += ["Heat maps: " + ", ".join(sorted(p.name for p in out.glob("heatmap_*.png"))), ""]
    lines += ["## Settings of every cell", "", "| setting | value |", "|---|---|"]
    lines += [f"| {k} | {v} |" for k, v in asdict(settings.campaign).items() if k not in ("q0_factor", "r0_factor")]
    md = out / "summary.md"
    atomic_write(md, lambda p: p.write_text("\n".join(lines) + "\n"))
    return md


def _grid(table: pd.DataFrame, name: str, metric: str) -> pd.DataFrame:
    t = table[table["filter"] == name]
    g = t.groupby(["q_factor", "r_factor"])[metric].mean().unstack("r_factor")
    g.index = [f"Q0 x{f:g}" for f in g.index]
    g.columns = [f"R0 x{f:g}" for f in g.columns]
    return g


def _heatmaps(table: pd.DataFrame, settings: SweepSettings, out: Path) -> None:

    labels = [f"{f:g}" for f in settings.factors]
    for metric, title, log in (("eta_over_bound", "eta / true-Q,R bound", False),
                               ("anees", "average NEES (nx = 4)", True),
                               ("worse_than_ekf", "share of runs worse than the EKF", False)):
        fig, axes = new_figure(1, len(FILTERS), figsize=(4.6 * len(FILTERS), 4.4))
        grids = [_grid(table, name, metric).to_numpy() for name in FILTERS]
        values = np.log10(np.concatenate([g.ravel() for g in grids]).clip(1e-3)) if log else \
            np.concatenate([g.ravel() for g in grids])
        vmin, vmax = np.nanmin(values), np.nanmax(values)
        for ax, name, g in zip(axes[0], FILTERS, grids):
            shown = np.log10(g.clip(1e-3)) if log else g
            im = ax.imshow(shown, origin="lower", cmap="viridis", vmin=vmin, vmax=vmax)
            ax.set_xticks(range(len(labels)), labels)
            ax.set_yticks(range(len(labels)), labels)
            ax.set_xlabel("R0 / true r")
            ax.set_ylabel("Q0 / true q")
            ax.set_title(name)
            for (i, j), v in np.ndenumerate(g):
                ax.text(j, i, f"{v:.2g}" if log else f"{v:.2f}", ha="center", va="center", fontsize=6,
                        color="w" if (shown[i, j] - vmin) < 0.5 * (vmax - vmin) else "k")
        fig.colorbar(im, ax=list(axes[0]), shrink=0.8, label=("log10 " if log else "") + title)
        fig.suptitle(f"Seed 000 sweep: {title}, mean over scenarios")
        atomic_write(out / f"heatmap_{metric}.png", lambda p, fig=fig: fig.savefig(p, dpi=100, format="png"))


class Sweep(Experiment, register="seed000-sweep"):
    """The robustness map of EKF, IAE, MF-IAE and SWML over wrong starting Q0 and R0 (beyond the
    paper; see the module documentation). ``--set`` names either a sweep setting
    (``factors``, the goal margins) or a setting of every cell's seed 000 campaign."""

    description = "beyond the paper: EKF, IAE, MF-IAE and SWML over a 7 x 7 map of wrong Q0, R0"
    configs = seed000.CONFIGS
    default_config = "paper"
    paths = ("fast",)

    def settings(self, config=None, settings_file=None, overrides=(), runs=None, seed=None):
        """The campaign settings of ``config`` (default ``paper``) with the file, ``runs``,
        ``seed`` and the ``overrides`` that name campaign settings; the others set the
        sweep's own fields."""

        own = {f.name for f in fields(SweepSettings)} - {"campaign"}
        overrides = list(overrides or ())
        mine = [x for x in overrides if x.split("=", 1)[0].strip() in own]
        campaign = Experiment.settings(self, config, settings_file, [x for x in overrides if x not in mine],
                                       runs, seed)
        return apply_overrides(replace(SweepSettings(), campaign=campaign), mine)

    def run(self, settings, path="fast", backend="processes", n_jobs=None, progress=True):
        """:func:`run` (the fast path only)."""
        self.check_path(path)
        return run(settings, backend=backend, n_jobs=n_jobs, progress=progress)

    def write_report(self, result, settings, out_dir, path="fast", config="custom", partial=False):
        """:func:`write_report`."""
        return write_report(*result, settings, out_dir, partial=partial)

    def summary(self, result, settings, path="fast", config="custom"):
        """The goals table."""
        return "\n".join([f"Seed 000 sweep: {len(settings.factors)} x {len(settings.factors)} cells, "
                          f"{settings.campaign.runs} realisations a cell, {result.wall:.1f} s",
                          goals(result.table, settings).to_string(index=False, float_format=lambda v: f"{v:.3f}")])

"""Where adaptation pays (beyond the paper): the filters of seed 000 started at ``Q0 = fq q I``,
``R0 = fr r I`` over a grid of factors; a cell is exactly ``seed000.fast_task`` (eqs reading)
with ``q0_factor = fq, r0_factor = fr``, its goals checked cell by cell (docs/guide/experiments.md).
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from fmu_models.errors import ConfigurationError
from fmu_models.infra.checks import positive

from . import common, metrics, seed000
from .experiment import Experiment
from .settings import apply_overrides, to_toml

ADAPTIVE = ("IAE", "MF-IAE", "EKF EM", "SWML")
#: The filters of the maps; the table also holds the EKF given the true Q and R (the same in
#: every cell of a scenario: it does not start from Q0, R0).
FILTERS = ("EKF", *ADAPTIVE)
TRUE_EKF = seed000.TRUE_EKF
STATES = seed000.STATES
FACTORS = (1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0, 1000.0)


@dataclass(frozen=True)
class SweepSettings:
    """The grid (``factors``, used for both Q0 and R0), and the campaign settings of every
    cell (``campaign``: a :class:`seed000.Settings`; its ``q0_factor``/``r0_factor`` are
    set per cell, its reading is ``eqs``; its ``confidence`` and ``whiteness_lags`` set the
    consistency tests). Goals: ``true_ekf_margin`` (eta within this fraction of the EKF
    given the true Q and R), ``ekf_margin`` (never more than this fraction worse than the
    EKF), ``pcrb_margin`` (every state's RMSE within this fraction above the PCRB)."""

    factors: tuple = FACTORS
    campaign: seed000.Settings = field(default_factory=lambda: replace(seed000.CONFIGS["paper"]))
    true_ekf_margin: float = 0.20
    ekf_margin: float = 0.05
    pcrb_margin: float = 0.10

    def __post_init__(self):
        if not self.factors:
            raise ConfigurationError("factors must list at least one factor")
        for f in self.factors:
            positive(f, "a grid factor")
        for name in ("true_ekf_margin", "ekf_margin", "pcrb_margin"):
            positive(getattr(self, name), name)


def cell_task(scenario_index: int, cells: list[tuple[float, float]], settings: seed000.Settings) -> list[dict]:
    """The rows of the ``cells`` ((Q0 factor, R0 factor) each) of scenario ``scenario_index``
    (0-based) under the campaign ``settings``: per cell, a row per filter of :data:`FILTERS`
    and one for the EKF given the true Q and R."""
    rows = []
    bound, shared = None, {}      # the truth, the PCRB and the EKF given the true Q, R: the same in every cell
    for fq, fr in cells:
        s = replace(settings, q0_factor=fq, r0_factor=fr, readings=("eqs",))
        res = seed000.fast_task(scenario_index, "eqs", s, bound=bound, shared=shared)
        bound = res["bound"]
        true_eta = res["per_run"][TRUE_EKF]["eta"]
        ekf = res["per_run"]["EKF"]["eta"]
        for name in (*FILTERS, TRUE_EKF):
            pr, st = res["per_run"][name], res["steps"][name]
            test, _ = metrics.consistency_row(st["nees"], st["nis"], 4, 2, s.confidence, res["whiteness"][name])
            late = (metrics.after_transient(st["nees"], st["nis"], st["mse"], bound[1:], 2, s.transient_steps,
                                            res["whiteness_late"][name], s.confidence) if s.has_late else
                    dict.fromkeys(("pcrb_ratio_max_late", "anees_late", "anis_late", "consistent_late"), np.nan))
            rows.append({"scenario": scenario_index + 1, "q_factor": fq, "r_factor": fr, "filter": name,
                         "eta": float(np.mean(pr["eta"])), "eta_true_ekf": float(np.mean(true_eta)),
                         "eta_over_true_ekf": float(np.mean(pr["eta"]) / np.mean(true_eta)),
                         "eta_over_ekf": float(np.mean(pr["eta"]) / np.mean(ekf)),
                         "worse_than_ekf": float(np.mean(pr["eta"] > ekf)) if name in ADAPTIVE else 0.0,
                         **common.pcrb_columns(pr["rmse"], bound[1:], STATES), "diverged": int(pr["diverged"].sum()),
                         **test, **late})
    return rows


class SweepResult(NamedTuple):
    """What :func:`run` returns: the ``table`` (one row per scenario, cell and filter) and the
    ``wall`` time [s]."""

    table: pd.DataFrame
    wall: float


def run(settings: SweepSettings = SweepSettings(), backend: str = "processes", n_jobs=None,
        progress: bool = True) -> SweepResult:
    """Run the sweep (``settings``, ``backend``, ``n_jobs``, ``progress`` as :meth:`Experiment.run
    <cosim.experiments.experiment.Experiment.run>`); returns a :class:`SweepResult`
    (interrupted: the rows of the finished tasks as ``partial`` of the Interrupted raised)."""
    s = settings.campaign
    cells = [(fq, fr) for fq in settings.factors for fr in settings.factors]
    chunks = [cells[i:i + len(settings.factors)] for i in range(0, len(cells), len(settings.factors))]
    tasks = [(cell_task, dict(scenario_index=i, cells=c, settings=s))
             for i in range(len(s.scenarios)) for c in chunks]
    return common.run_campaign(tasks, lambda results, wall: SweepResult(
        pd.DataFrame([r for rows in results if rows for r in rows]), wall), "seed000 sweep", backend, n_jobs, progress)


def _cells(table: pd.DataFrame) -> pd.DataFrame:
    """Per filter and cell: the mean over the scenarios of the numbers, the worst state's
    RMSE / PCRB over the scenarios, and in how many scenarios the filter is consistent."""
    g = table.astype({"consistent": float, "consistent_late": float}).groupby(["filter", "q_factor", "r_factor"])
    return g.mean(numeric_only=True).join(g.agg(
        pcrb_ratio_worst=("pcrb_ratio_max", "max"), pcrb_ratio_worst_late=("pcrb_ratio_max_late", "max"),
        scenarios=("scenario", "size"), consistent_scenarios=("consistent", "sum"),
        consistent_scenarios_late=("consistent_late", "sum"))).reset_index()


def goals(table: pd.DataFrame, settings: SweepSettings) -> pd.DataFrame:
    """Per adaptive filter (and the EKF given the true noise), from the sweep's ``table`` and
    the goal margins of its ``settings``: the cells (eta averaged over the scenarios) within
    ``true_ekf_margin`` of the EKF given the true Q and R, those more than ``ekf_margin`` worse
    than the EKF, those with every state of every scenario within ``pcrb_margin`` of the PCRB,
    those consistent in every scenario, and the consistent (cell, scenario) pairs."""
    cell = _cells(table)
    rows = []
    for name in (*ADAPTIVE, TRUE_EKF):
        c = cell[cell["filter"] == name]
        t = table[table["filter"] == name]
        rows.append({"filter": name, "cells": len(c),
                     "within true-Q,R EKF margin": int((c["eta_over_true_ekf"] <= 1 + settings.true_ekf_margin).sum()),
                     "worse than EKF by more than margin": int((c["eta_over_ekf"] > 1 + settings.ekf_margin).sum()),
                     "every state within PCRB margin": int((c["pcrb_ratio_worst"] <= 1 + settings.pcrb_margin).sum()),
                     "worst RMSE/PCRB": float(c["pcrb_ratio_worst"].max()),
                     "consistent cells": int((c["consistent_scenarios"] == c["scenarios"]).sum()),
                     "consistent cell-scenarios": f"{int(t['consistent'].sum())} of {len(t)}",
                     "worst eta/true-Q,R EKF": float(c["eta_over_true_ekf"].max()),
                     "worst eta/EKF": float(c["eta_over_ekf"].max()),
                     **({"after the transient: every state within PCRB margin": int(
                         (c["pcrb_ratio_worst_late"] <= 1 + settings.pcrb_margin).sum()),
                         "after the transient: worst RMSE/PCRB": float(c["pcrb_ratio_worst_late"].max()),
                         "after the transient: consistent cells": int(
                             (c["consistent_scenarios_late"] == c["scenarios"]).sum())}
                        if t["pcrb_ratio_max_late"].notna().all() else {})})
    return pd.DataFrame(rows)


def why_not_consistent(table: pd.DataFrame, name: str = "SWML") -> list[str]:
    """Sentences on the (cell, scenario) pairs of the sweep's ``table`` where the filter
    ``name`` is not consistent: which test fails, and by how much."""
    t = table[(table["filter"] == name) & ~table["consistent"].astype(bool)]
    lines = []
    for _, r in t.sort_values(["q_factor", "r_factor", "scenario"]).iterrows():
        failed = [f"average NEES {r['anees']:.3g} outside [{r['anees_lo']:.2f}, {r['anees_hi']:.2f}]"
                  if not r["nees_ok"] else "",
                  f"average NIS {r['anis']:.3g} outside [{r['anis_lo']:.2f}, {r['anis_hi']:.2f}]" if not r["nis_ok"]
                  else "",
                  f"autocorrelation {r['acf_max']:.3f} beyond {r['acf_band']:.3f}" if r["white_ok"] is False else ""]
        lines.append(f"- Q0 x{r['q_factor']:g}, R0 x{r['r_factor']:g}, scenario {r['scenario']}: "
                     + "; ".join(f for f in failed if f) + f" ({r['anees_inside']:.0%} of the steps' NEES inside).")
    return lines


#: The maps of the report, each (title, metric, aggregate over the scenarios, number format, filters).
GRIDS = (("Worst state's RMSE / PCRB, largest over the scenarios (rows: Q0 factor, columns: R0 factor)",
          "pcrb_ratio_max", "max", ".3f", (*FILTERS, TRUE_EKF)),
         ("eta / eta of the EKF given the true Q and R, mean over scenarios", "eta_over_true_ekf", "mean", ".2f",
          FILTERS),
         ("Average NEES (state dimension 4; mean over scenarios)", "anees", "mean", ".3g", FILTERS),
         ("Scenarios (of 4) in which the filter is consistent", "consistent", "sum", ".0f", FILTERS))


def write_report(table: pd.DataFrame, wall: float, settings: SweepSettings, out_dir, partial: bool = False) -> Path:
    """``sweep.csv|parquet``, ``goals.csv``, heat maps, ``settings.toml`` and ``summary.md`` into
    ``out_dir`` (``table``, ``wall``: a :class:`SweepResult`'s; ``settings``, ``partial`` as
    :meth:`Experiment.write_report <cosim.experiments.experiment.Experiment.write_report>`)."""
    toml = to_toml(settings.campaign, "seed000-sweep") + f"factors = {list(settings.factors)}\n"
    out = common.report_folder(out_dir, toml, {"sweep.csv": table, "sweep.parquet": table})
    lines = ["# Seed 000 robustness sweep: EKF, IAE, MF-IAE, the EM-learned EKF and SWML from wrong Q0 and R0", ""]
    if partial:
        lines += ["**PARTIAL RESULTS: the sweep was interrupted; only finished cells are here.**", ""]
    if len(table):
        g = goals(table, settings)
        common.write_tables(out, {"goals.csv": g})
        _heatmaps(table, settings, out)
        lines += _goal_lines(table, g, wall, settings)
        for title, metric, how, fmt, names in GRIDS:
            lines += [f"## {title}", ""]
            for name in names:
                lines += [f"**{name}**", "", _grid(table, name, metric, how).to_markdown(floatfmt=fmt), ""]
        lines += ["Heat maps: " + ", ".join(sorted(p.name for p in out.glob("heatmap_*.png"))), ""]
    lines += ["## Settings of every cell", "", *common.settings_table(settings.campaign, ("q0_factor", "r0_factor"))]
    return common.write_summary(out, lines)


def _goal_lines(table: pd.DataFrame, g: pd.DataFrame, wall: float, settings: SweepSettings) -> list[str]:
    """The report's regime, its goals table ``g`` in words, and where SWML is not consistent."""
    c, n = settings.campaign, len(settings.factors) ** 2
    misses = why_not_consistent(table, "SWML")
    return [f"Regime: the seed 000 paper campaign (eqs reading) with the filters started at Q0 = fq q I, "
            f"R0 = fr r I; {len(settings.factors)} x {len(settings.factors)} cells (f in "
            f"{', '.join(f'{f:g}' for f in settings.factors)}), {table['scenario'].nunique()} scenarios, "
            f"{c.runs} realisations a cell; wall time {wall:.1f} s.", "",
            "## Goals", "",
            g.to_markdown(index=False, floatfmt=".3f"), "",
            f"Goals: eta (mean over the scenarios) within {settings.true_ekf_margin:.0%} of the EKF given the "
            f"true Q and R in most of the {n} cells; never more than {settings.ekf_margin:.0%} worse than the "
            f"EKF started at the same Q0, R0; every state's RMSE within {settings.pcrb_margin:.0%} of the "
            f"PCRB in every scenario of a cell (worst RMSE/PCRB: the largest over the states and the "
            f"scenarios); consistent in every scenario of a cell. The EKF given the true Q and R does not "
            f"depend on the cell (its row is the reference). The columns 'after the transient' are a "
            f"diagnostic, not the goals: the same numbers over the steps after the first "
            f"{c.transient_steps} ({c.transient_steps * c.T:g} s), where an adaptive filter's start-up no "
            f"longer counts.", "",
            "Consistency rule: " + metrics.consistency_rule(c.confidence, c.whiteness_lags) + ".", "",
            *(["Where SWML is not consistent:", "", *misses, ""] if misses else [])]


def _grid(table: pd.DataFrame, name: str, metric: str, how: str = "mean") -> pd.DataFrame:
    t = table[table["filter"] == name].assign(consistent=lambda d: d["consistent"].astype(float))
    g = t.groupby(["q_factor", "r_factor"])[metric].agg(how).unstack("r_factor")
    return g.rename(index=lambda f: f"Q0 x{f:g}", columns=lambda f: f"R0 x{f:g}").rename_axis(index=None, columns=None)


def _heatmaps(table: pd.DataFrame, settings: SweepSettings, out: Path) -> None:
    """One figure of heat maps per metric, a map per filter of :data:`FILTERS`."""
    labels = [f"{f:g}" for f in settings.factors]
    for metric, how, title, log in (("eta_over_true_ekf", "mean", "eta / eta of the EKF given the true Q, R", False),
                                    ("pcrb_ratio_max", "max", "worst state's RMSE / PCRB (largest over scenarios)",
                                     False),
                                    ("anees", "mean", "average NEES (nx = 4)", True),
                                    ("consistent", "sum", "scenarios consistent (of 4)", False),
                                    ("worse_than_ekf", "mean", "share of runs worse than the EKF", False)):
        fig, axes = common.new_figure(1, len(FILTERS), figsize=(4.6 * len(FILTERS), 4.4))
        grids = [_grid(table, name, metric, how).to_numpy() for name in FILTERS]
        scaled = [np.log10(g.clip(1e-3)) if log else g for g in grids]
        values = np.concatenate([g.ravel() for g in scaled])
        vmin, vmax = np.nanmin(values), np.nanmax(values)
        if vmax == vmin:
            vmax = vmin + 1.0
        for ax, name, g, shown in zip(axes[0], FILTERS, grids, scaled):
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
        fig.suptitle(f"Seed 000 sweep: {title}" + (", mean over scenarios" if how == "mean" else ""))
        common.save_figure(fig, out / f"heatmap_{metric}.png")


class Sweep(Experiment, register="seed000-sweep"):
    """The robustness map over wrong starting Q0 and R0. ``--set`` names either a sweep
    setting (``factors``, the goal margins) or a setting of every cell's seed 000 campaign."""

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
        self.check_path(path)
        return run(settings, backend=backend, n_jobs=n_jobs, progress=progress)

    def write_report(self, result, settings, out_dir, path="fast", config="custom", partial=False):
        return write_report(*result, settings, out_dir, partial=partial)

    def summary(self, result, settings, path="fast", config="custom"):
        return "\n".join([f"Seed 000 sweep: {len(settings.factors)} x {len(settings.factors)} cells, "
                          f"{settings.campaign.runs} realisations a cell, {result.wall:.1f} s",
                          goals(result.table, settings).to_string(index=False, float_format=lambda v: f"{v:.3f}")])

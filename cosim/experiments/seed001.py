"""Seed 001: the Kalman filter on the linearised cart-pole against the EKF, the cart driven by
a constant force for 120 s, in two cases (``CASES``): the KF linearised at the hanging
pendulum, or at the upright equilibrium (seed 000 eq 20) while the pendulum falls from it.
The paper's setting is garbled; our reading is in :class:`Settings` and docs/guide/experiments.md.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar, NamedTuple

import numpy as np
import pandas as pd

from estimators import EKF, KF, discretize, posterior_crb
from fmu_models import get_model

from ..components.sources import Constant
from . import common, metrics
from .experiment import Experiment
from .settings import CommonSettings, check_consistency, to_toml

CASES = {"hanging": (0.0, 0.0, np.pi, 0.0), "upright": (0.0, 0.0, 0.1, 0.0)}
REPORT_TIMES = (1.0, 30.0, 60.0, 90.0, 100.0, 120.0)
PAPER = pd.DataFrame({"time": [1, 30, 60, 90, 100], "KF error": [0.012, 0.0047, 0.045, 0.004, 0.047],
                      "EKF error": [0.006, 0.002, 0.005, 0.011, 0.009]})
FILTERS = ("KF", "EKF")
STATES = ("x", "x_dot", "theta", "theta_dot")
#: The measured states.
MEASURED = ("x", "theta")
#: The prior of the PCRB (``pcrb_prior``).
PCRB_PRIORS = {"known": "the initial state is known exactly (the truth starts at the case's state)",
               "P0": "x_0 ~ N(x0, P0 I), the filters' own prior"}


@dataclass(frozen=True)
class Settings(CommonSettings):
    """Choices of the seed 001 reproduction (the paper's are not recoverable).

    ``runs`` realisations of ``duration`` [s] with period ``T`` [s]; constant ``force``
    [N]; process noise variance ``q`` per step and measurement standard deviation
    ``r_std``; filters start at the true state with ``P0`` (times I) and use the true
    noise; ``divergence_error``: RMS-over-states error above which the KF counts as
    diverged (from the first time it stays above); ``seed``. The limit and consistency:
    ``pcrb_prior`` (:data:`PCRB_PRIORS`), the ``confidence`` of the chi-square bands and
    the whiteness test at lags 1..``whiteness_lags``.
    """

    runs: int = 20
    duration: float = 120.0
    T: float = 0.01
    force: float = 0.05
    q: float = 1e-8
    r_std: float = 0.01
    P0: float = 1e-4
    divergence_error: float = 0.5
    seed: int = 1
    pcrb_prior: str = "known"
    confidence: float = 0.95
    whiteness_lags: int = 5

    def __post_init__(self):
        super().__post_init__()
        check_consistency(self, PCRB_PRIORS)


def make_filters(s: Settings, case: str) -> dict:
    """The KF (linearised at the initial state of ``case``) and the EKF of the settings ``s``,
    started at the true state."""
    system = discretize(get_model("cartpole"), s.T)
    x0 = np.array(CASES[case])
    x_op = x0 if case == "hanging" else np.zeros(4)
    R = s.r_std**2
    return {"KF": lambda: KF(system, x0, s.P0, s.q, R, x_op=x_op, u_op=[0.0]),
            "EKF": lambda: EKF(system, x0, s.P0, s.q, R)}


def _summary(errors: dict, s: Settings, nees: dict, nis: dict, white: dict, bound: np.ndarray) -> dict:
    """Per filter: the errors at the report times, the RMSE, the divergence time, the RMS
    error over the states, the RMSE / PCRB (``bound``: its mean-square error per step,
    k = 0..N) and the consistency tests (``white``: the whiteness rows)."""
    out = {"bound": bound}
    t = np.arange(s.steps + 1) * s.T
    idx = [round(tr / s.T) for tr in REPORT_TIMES if tr <= s.duration]
    for name, err in errors.items():
        rms = metrics.rms_over_states(err)                      # (runs, steps+1)
        # diverged from the first step after which the error stays above the threshold
        stays = np.flip(np.logical_and.accumulate(np.flip(rms > s.divergence_error, axis=1), axis=1), axis=1)
        rmse = np.sqrt(np.mean(err[:, 1:] ** 2, axis=1))
        row, per_step = metrics.consistency_row(nees[name], nis[name], 4, 2, s.confidence, white[name])
        with np.errstate(over="ignore", invalid="ignore"):
            rmse_k = np.sqrt(np.mean(err[:, 1:] ** 2, axis=0))
        out[name] = {"pos_err": np.abs(err[:, idx, 0]), "rmse": rmse, "rms_mean": rms.mean(axis=0),
                     "t_div": np.where(stays.any(axis=1), t[np.argmax(stays, axis=1)], np.nan),
                     "pcrb_ratio": metrics.pcrb_ratio(rmse, bound[1:]), "tests": row, "anees": per_step["anees"],
                     "nees_band": (per_step["nees_lo"], per_step["nees_hi"]), "rmse_k": rmse_k}
    return out


def case_bound(s: Settings, case: str, X: np.ndarray, us: np.ndarray) -> np.ndarray:
    """The PCRB on each state's mean-square error at k = 0..N, shape (N+1, 4), over the
    realisations ``X`` (runs, N+1, 4) of ``case`` with inputs ``us`` (N+1, 1), under the
    settings' ``s.pcrb_prior``."""
    return posterior_crb(discretize(get_model("cartpole"), s.T), X, us[:-1], s.q, s.r_std**2,
                         None if s.pcrb_prior == "known" else s.P0).mse


def _truth(case: str, s: Settings, seeds: list[tuple[int, int]]):
    us = np.full((s.steps + 1, 1), s.force)
    X, Y = common.simulate_truth(get_model("cartpole"), CASES[case], us, s.T, s.q, MEASURED, s.r_std, seeds)
    return X, Y, us


def fast_task(case: str, settings: Settings, runs=None) -> dict:
    """All realisations ``runs`` (default all) of ``case`` (``hanging`` or ``upright``), both
    filters batched, with the PCRB and the consistency tests under the ``settings``."""
    s = settings
    X, Y, us = _truth(case, s, common.seed_pairs(s, list(CASES).index(case), runs))
    errors, nees, nis, white = {}, {}, {}, {}
    for n, m in make_filters(s, case).items():
        res = common.batch_run(m, X, Y, us)
        errors[n], nees[n], nis[n] = res.x - X, res.nees, res.nis
        white[n] = metrics.whiteness_row(res.innovation, res.S, s.confidence, s.whiteness_lags)
    return _summary(errors, s, nees, nis, white, case_bound(s, case, X, us))


def master_task(case: str, settings: Settings, runs=None) -> dict:
    """:func:`fast_task` (``case``, ``settings``, ``runs``) through the co-simulation master
    with the plant FMU (the PCRB on the fast path's truth of the same seeds; no whiteness)."""
    s = settings
    seeds, makers = common.seed_pairs(s, list(CASES).index(case), runs), make_filters(s, case)
    X, est, nees, nis = common.master_runs(get_model("cartpole"), CASES[case], Constant("force", s.T, s.force), s.q,
                                           MEASURED, s.r_std, makers, s.T, s.duration, seeds)
    truth, _, us = _truth(case, s, seeds)
    return _summary({n: est[n] - X for n in makers}, s, nees, nis, {n: metrics.no_whiteness() for n in makers},
                    case_bound(s, case, truth, us))


class Seed001Result(NamedTuple):
    """What :func:`run` returns: the ``table`` of mean position errors at the report times,
    the ``summary`` per case (per filter: errors, divergence times, RMSE, RMSE / PCRB, the
    tests; the PCRB per step under ``"bound"``), the ``wall`` time [s], and ``consistency``:
    a row per case and filter (and the PCRB's) with each state's RMSE, RMSE / PCRB and the
    tests of :func:`~cosim.experiments.metrics.consistency_rule`."""

    table: pd.DataFrame
    summary: dict
    wall: float
    consistency: pd.DataFrame


def run(settings: Settings = Settings(), path: str = "fast", backend="processes", n_jobs=None,
        progress=True) -> Seed001Result:
    """Both cases (``settings``, ``path``, ``backend``, ``n_jobs``, ``progress`` as
    :meth:`Experiment.run <cosim.experiments.experiment.Experiment.run>`); returns a :class:`Seed001Result`."""
    fn = fast_task if path == "fast" else master_task
    return common.run_campaign([(fn, dict(case=c, settings=settings)) for c in CASES],
                               lambda res, wall: _result(res, settings, wall), f"seed001 ({path})", backend, n_jobs,
                               progress)


def _result(res: list, s: Settings, wall: float) -> Seed001Result:
    """The campaign's result from its tasks' (one per case; None: a case that did not finish)."""
    summary = {c: r for c, r in zip(CASES, res) if r is not None}
    times = [tr for tr in REPORT_TIMES if tr <= s.duration]
    rows = [{"case": case, "time": tr, **{f"{n} |x error| [m]": r[n]["pos_err"][:, j].mean() for n in FILTERS}}
            for case, r in summary.items() for j, tr in enumerate(times)]
    cons = []
    for case, r in summary.items():
        cons += [{"case": case, "filter": n, **common.error_columns(r[n]["rmse"], r["bound"][1:], STATES),
                  **r[n]["tests"]} for n in FILTERS]
        cons.append(common.pcrb_row({"case": case}, r["bound"], s.runs, STATES))
    return Seed001Result(pd.DataFrame(rows), summary, wall, pd.DataFrame(cons))


def write_report(result: Seed001Result, settings: Settings, out_dir, path: str = "fast", partial: bool = False) -> Path:
    """The tables, the figures, ``settings.toml`` and ``summary.md`` into ``out_dir``; returns
    ``summary.md`` (``result`` of :func:`run`; ``settings``, ``path``, ``partial`` as
    :meth:`Experiment.write_report <cosim.experiments.experiment.Experiment.write_report>`)."""
    table, summary, wall, cons = result
    s = settings
    out = common.report_folder(out_dir, to_toml(s, "seed001"), {"errors_at_times.csv": table, "consistency.csv": cons})
    _figures(summary, s, out)
    shown = cons[["case", "filter", *[f"rmse_{x}" for x in STATES], *[f"pcrb_ratio_{x}" for x in STATES]]]
    lines = ["# Seed 001: KF on the linearised model against the EKF", "",
             f"Regime: both filters given the true noise (q = {s.q:g} per step, r = {s.r_std:g}^2), started at the "
             f"true state with P0 = {s.P0:g} I; {s.runs} realisations per case, {s.duration:g} s ({s.steps} steps), "
             f"{path} path; wall time {wall:.2f} s.", "",
             "## Settings", "", *common.settings_table(s), "",
             "## Mean absolute cart-position error", "", table.to_markdown(index=False, floatfmt=".4g"), "",
             "Paper (seed 001 Table 1, position errors [m]):", "", PAPER.to_markdown(index=False), "",
             "## Divergence and RMSE", "",
             *common.markdown_table(["case", "filter", "diverged runs", "median time of divergence [s]",
                                     *[f"RMSE {x}" for x in STATES]], _divergence_rows(summary)), "",
             "## RMSE per state over the posterior Cramér-Rao bound", "",
             f"The PCRB is the lowest mean-square error any estimator can have on these {s.runs} realisations "
             f"(prior: {PCRB_PRIORS[s.pcrb_prior]}); each ratio is the RMSE over the realisations and steps 1..K "
             "over the root of the bound's mean over the same steps (1 is the best possible; pcrb_ratio_se_* in "
             "consistency.csv: the Monte Carlo standard error of each ratio).", "",
             shown.to_markdown(index=False, floatfmt=".4g"), "", *common.consistency_section(cons, ["case"], s, path),
             "Figures: " + ", ".join(sorted(p.name for p in out.glob("*.png")))]
    return common.write_summary(out, lines, partial)


def _divergence_rows(summary: dict):
    """Per case and filter: the diverged realisations, their median time of divergence, and
    the RMSE per state (mean over the realisations)."""
    for case, res in summary.items():
        for n in FILTERS:
            td = res[n]["t_div"]
            nd = int(np.isfinite(td).sum())
            yield [case, n, f"{nd} of {len(td)}", f"{np.nanmedian(td):.2f}" if nd else "none",
                   *(f"{v:.3g}" for v in res[n]["rmse"].mean(axis=0))]


def _figures(summary: dict, s: Settings, out: Path) -> None:
    """Per case: the RMS error over the states (mean over the realisations), the average NEES
    with its band, and the RMSE per state against the PCRB."""
    t = np.arange(s.steps + 1) * s.T
    figs = {name: common.new_figure(len(summary), 1, figsize=(8, 3 * len(summary))) for name in ("errors", "nees")}
    for (case, res), ax, ax_nees in zip(summary.items(), figs["errors"][1][:, 0], figs["nees"][1][:, 0]):
        for n in FILTERS:
            ax.semilogy(t, res[n]["rms_mean"], label=n)
        ax.axhline(s.divergence_error, color="k", ls=":", lw=0.8, label="divergence threshold")
        common.style_axes(ax, "time [s]", legend=8, title=f"{case}: RMS error over the states, mean of {s.runs} "
                          "realisations")
        ax_nees.fill_between(t[1:], *res[FILTERS[0]]["nees_band"], color="0.85",
                             label=f"{s.confidence:.0%} band ({s.runs} runs)")
        for n in FILTERS:
            ax_nees.semilogy(t[1:], res[n]["anees"], lw=0.8, label=n)
        common.style_axes(ax_nees, "time [s]", title=f"{case}: average NEES over {s.runs} realisations", legend=8)
    for name, (fig, _) in figs.items():
        common.save_figure(fig, out / f"{name}.png")
    fig, axes = common.new_figure(4, len(summary), figsize=(5 * len(summary), 9), sharex=True)
    for j, (case, res) in enumerate(summary.items()):
        for a, x in enumerate(STATES):
            for n in FILTERS:
                axes[a, j].semilogy(t[1:], res[n]["rmse_k"][:, a], lw=0.8, label=n)
            axes[a, j].semilogy(t[1:], np.sqrt(res["bound"][1:, a]), "k-", lw=1.2, label="sqrt(PCRB)")
            common.style_axes(axes[a, j], ylabel=f"RMSE {x}")
        axes[0, j].set_title(case)
        axes[0, j].legend(fontsize=7)
        axes[-1, j].set_xlabel("time [s]")
    common.save_figure(fig, out / "rmse_pcrb.png")


class Seed001(Experiment, register="seed001"):
    """Seed 001: the KF on the linearised cart-pole against the EKF under a constant force."""

    description = "seed 001: KF on the linearised cart-pole against the EKF, constant force, 120 s"
    configs: ClassVar[dict] = {"default": Settings()}

    def run(self, settings, path="fast", backend="processes", n_jobs=None, progress=True):
        return run(settings, path=self.check_path(path), backend=backend, n_jobs=n_jobs, progress=progress)

    def write_report(self, result, settings, out_dir, path="fast", config="custom", partial=False):
        return write_report(result, settings, out_dir, path, partial)

    def summary(self, result, settings, path="fast", config="custom"):
        lines = [f"Seed 001: mean |position error| [m], {settings.runs} realisations, {path} path, "
                 f"{result.wall:.2f} s", result.table.to_string(index=False, float_format=lambda v: f"{v:.4g}")]
        for case, res in result.summary.items():
            td = res["KF"]["t_div"]
            when = f"median {np.nanmedian(td):.2f} s" if np.isfinite(td).any() else "never"
            lines.append(f"{case}: KF diverged in {int(np.isfinite(td).sum())} of {len(td)} runs ({when}); "
                         f"EKF in {int(np.isfinite(res['EKF']['t_div']).sum())}")
            for n in FILTERS:
                ratio = ", ".join(f"{x} {v:.3f}" for x, v in zip(STATES, res[n]["pcrb_ratio"]))
                lines.append(f"  {n}: RMSE / sqrt(PCRB) {ratio}; "
                             f"{'consistent' if res[n]['tests']['consistent'] else 'not consistent'} "
                             f"(avg NEES {res[n]['tests']['anees']:.3g})")
        return "\n".join(lines)

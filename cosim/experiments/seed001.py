"""Seed 001: Kalman filter on the linearised cart-pole against the EKF, cart driven by a
constant force, 120 s.

Seed 001's setting is garbled in its text: it claims that the KF
on the linearised model tracks the cart until about 100 s and then diverges while the
EKF holds, with position errors at 1, 30, 60, 90 and 100 s. Our reading, every choice in
:class:`Settings`:

* ``"hanging"``: the pendulum hangs (the configuration in which a cart can be pushed for
  100 s), the KF is linearised there, and a constant force of 0.05 N drives the cart;
* ``"upright"``: the pendulum starts 0.1 rad from upright, the KF is linearised at the
  upright equilibrium (seed 000 eq 20's model); the pendulum falls and swings through
  the hanging position, far from the KF's linearisation.

Both filters measure ``[x, theta]`` with noise of standard deviation 0.01, process noise
variance 1e-8 per step, T = 0.01 s (the Euler truth map), 20 realisations. Reported:
mean absolute position error at 1, 30, 60, 90, 100 and 120 s, per-state RMSE, the
first time the KF's error (RMS over the states) exceeds ``divergence_error`` for good,
each filter's RMSE per state as a multiple of the posterior Cramér-Rao bound over the same
realisations (:func:`estimators.posterior_crb`: the limit of any estimator), and the
consistency verdicts of :func:`~cosim.experiments.metrics.consistency_rule` (on the
master path without the whiteness test: the estimator components do not publish their
innovations).
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
from .settings import check_common, check_consistency, to_toml

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
class Settings:
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
        check_common(self)
        check_consistency(self, PCRB_PRIORS)

    @property
    def steps(self) -> int:
        return round(self.duration / self.T)


def make_filters(s: Settings, case: str) -> dict:
    """The KF (linearised at the case's initial state) and the EKF, started at the true state.

    Parameters
    ----------
    s
        The settings.
    case
        Which case (its initial state and KF linearisation point).
    """
    system = discretize(get_model("cartpole"), s.T)
    x0 = np.array(CASES[case])
    x_op = x0 if case == "hanging" else np.zeros(4)
    R = s.r_std**2
    return {"KF": lambda: KF(system, x0, s.P0, s.q, R, x_op=x_op, u_op=[0.0]),
            "EKF": lambda: EKF(system, x0, s.P0, s.q, R)}


def _source(s: Settings):
    return Constant("force", s.T, s.force)


def _summary(errors: dict, s: Settings, nees: dict, nis: dict, white: dict, bound: np.ndarray | None) -> dict:
    """Per filter: the errors at the report times, the RMSE, the divergence time, the RMS
    error over the states, the RMSE per state over the PCRB (``bound``: its mean-square
    error per step, k = 0..N) and the consistency tests (``white``: the whiteness rows)."""
    out = {}
    t = np.arange(s.steps + 1) * s.T
    for name, err in errors.items():
        rms = metrics.rms_over_states(err)                      # (runs, steps+1)
        above = rms > s.divergence_error
        # diverged from the first step after which the error stays above the threshold
        stays = np.flip(np.logical_and.accumulate(np.flip(above, axis=1), axis=1), axis=1)
        t_div = np.where(stays.any(axis=1), t[np.argmax(stays, axis=1)], np.nan)
        idx = [round(tr / s.T) for tr in REPORT_TIMES if tr <= s.duration]
        rmse = np.sqrt(np.mean(err[:, 1:] ** 2, axis=1))
        row, per_step = metrics.consistency_row(nees[name], nis[name], 4, 2, s.confidence, white[name])
        with np.errstate(over="ignore", invalid="ignore"):
            mse = np.mean(err[:, 1:] ** 2, axis=0)
        out[name] = {"pos_err": np.abs(err[:, idx, 0]), "rmse": rmse, "t_div": t_div, "rms_mean": rms.mean(axis=0),
                     "pcrb_ratio": metrics.pcrb_ratio(rmse, bound[1:]),
                     "pcrb_ratio_se": metrics.pcrb_ratio_se(rmse, bound[1:]), "tests": row, "anees": per_step["anees"],
                     "nees_band": (per_step["nees_lo"], per_step["nees_hi"]), "rmse_k": np.sqrt(mse)}
    out["bound"] = bound
    return out


def case_bound(s: Settings, case: str, X: np.ndarray, us: np.ndarray) -> np.ndarray:
    """The PCRB on each state's mean-square error at k = 0..N, shape (N+1, 4), over the
    realisations ``X`` of ``case`` with inputs ``us`` (N+1, 1), under ``s.pcrb_prior``.

    Parameters
    ----------
    s
        The settings.
    case
        Which case.
    X
        The true trajectories (runs, N+1, 4).
    us
        The inputs.
    """
    P0 = None if s.pcrb_prior == "known" else s.P0
    return posterior_crb(discretize(get_model("cartpole"), s.T), X, us[:-1], s.q, s.r_std**2, P0).mse


def _truth(case: str, s: Settings, seeds: list[tuple[int, int]]):
    us = np.full((s.steps + 1, 1), s.force)
    X, Y = common.simulate_truth(get_model("cartpole"), CASES[case], us, s.T, s.q, MEASURED, s.r_std, seeds)
    return X, Y, us


def fast_task(case: str, settings: Settings, runs=None) -> dict:
    """All realisations of one case, both filters batched, with the PCRB and the
    consistency tests.

    Parameters
    ----------
    case
        Which case (``hanging`` or ``upright``).
    settings
        The settings.
    runs
        Which realisations (default all).
    """
    s = settings
    X, Y, us = _truth(case, s, common.seed_pairs(s, list(CASES).index(case), runs))
    errors, nees, nis, white = {}, {}, {}, {}
    for n, m in make_filters(s, case).items():
        res = common.batch_run(m, X, Y, us)
        errors[n], nees[n], nis[n] = res.x - X, res.nees, res.nis
        white[n] = metrics.whiteness_row(res.innovation, res.S, s.confidence, s.whiteness_lags)
    return _summary(errors, s, nees, nis, white, case_bound(s, case, X, us))


def master_task(case: str, settings: Settings, runs=None) -> dict:
    """The same realisations through the co-simulation master with the plant FMU (the
    PCRB on the fast path's truth of the same seeds; no whiteness test).

    Parameters
    ----------
    case, settings, runs
        As :func:`fast_task`.
    """
    s = settings
    model, seeds = get_model("cartpole"), common.seed_pairs(s, list(CASES).index(case), runs)
    makers = make_filters(s, case)
    X, est, nees, nis = common.master_runs(model, dict(zip(model.state_names, CASES[case])), _source(s),
                                           *common.noise_components(model, s.T, s.q, MEASURED, s.r_std, *seeds[0]),
                                           makers, s.T, s.duration, seeds)
    truth, _, us = _truth(case, s, seeds)
    return _summary({n: est[n] - X for n in makers}, s, nees, nis, {n: metrics.no_whiteness() for n in makers},
                    case_bound(s, case, truth, us))


class Seed001Result(NamedTuple):
    """What :func:`run` returns: the ``table`` of mean position errors at the report times,
    the ``summary`` per case (per filter: errors, divergence times, RMSE, RMSE / PCRB, the
    consistency tests; and the PCRB per step under ``"bound"``), the ``wall`` time [s], and
    ``consistency``: one row per case and filter (and one for the PCRB) with each state's
    RMSE, its ratio to the PCRB and the tests of
    :func:`~cosim.experiments.metrics.consistency_rule`."""

    table: pd.DataFrame
    summary: dict
    wall: float
    consistency: pd.DataFrame


def run(settings: Settings = Settings(), path: str = "fast", backend="processes", n_jobs=None,
        progress=True) -> Seed001Result:
    """Both cases; returns a :class:`Seed001Result`.

    Parameters
    ----------
    settings, path, backend, n_jobs, progress
        As :meth:`Experiment.run <cosim.experiments.experiment.Experiment.run>`.
    """
    fn = fast_task if path == "fast" else master_task
    return common.run_campaign([(fn, dict(case=c, settings=settings)) for c in CASES],
                               lambda res, wall: _result(res, settings, wall), f"seed001 ({path})", backend, n_jobs,
                               progress)


def _result(res: list, s: Settings, wall: float) -> Seed001Result:
    """The campaign's result from its tasks' (one per case; None: a case that did not finish)."""
    cases = [c for c, r in zip(CASES, res) if r is not None]
    res = [r for r in res if r is not None]
    times = [tr for tr in REPORT_TIMES if tr <= s.duration]
    rows = [{"case": case, "time": tr, **{f"{n} |x error| [m]": r[n]["pos_err"][:, j].mean() for n in FILTERS}}
            for case, r in zip(cases, res) for j, tr in enumerate(times)]
    cons = []
    for case, r in zip(cases, res):
        cons += [{"case": case, "filter": n,
                  **{f"rmse_{x}": float(np.sqrt(np.mean(r[n]["rmse"][:, a] ** 2))) for a, x in enumerate(STATES)},
                  **common.pcrb_columns(r[n]["rmse"], r["bound"][1:], STATES), **r[n]["tests"]} for n in FILTERS]
        cons.append(common.pcrb_row({"case": case}, r["bound"], s.runs, STATES))
    return Seed001Result(pd.DataFrame(rows), dict(zip(cases, res)), wall, pd.DataFrame(cons))


def write_report(result: Seed001Result, settings: Settings, out_dir, path: str = "fast", partial: bool = False) -> Path:
    """The tables, the figures, ``settings.toml`` and ``summary.md`` into ``out_dir``; returns ``summary.md``.

    Parameters
    ----------
    result, settings, out_dir, path, partial
        As :meth:`Experiment.write_report <cosim.experiments.experiment.Experiment.write_report>`
        (``result``: what :func:`run` returned).
    """
    table, summary, wall, cons = result
    s = settings
    out = common.report_folder(out_dir, to_toml(s, "seed001"), {"errors_at_times.csv": table, "consistency.csv": cons})
    _error_figure(summary, s, out)
    _limit_figures(summary, s, out)
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
    """Per case and filter: the realisations that diverged, their median time of divergence,
    and the RMSE per state (mean over the realisations)."""
    for case, res in summary.items():
        for n in FILTERS:
            td = res[n]["t_div"]
            nd = int(np.isfinite(td).sum())
            yield [case, n, f"{nd} of {len(td)}", f"{np.nanmedian(td):.2f}" if nd else "none",
                   *(f"{v:.3g}" for v in res[n]["rmse"].mean(axis=0))]


def _error_figure(summary: dict, settings: Settings, out: Path) -> None:
    """The RMS error over the states, mean over the realisations, per case."""
    t = np.arange(settings.steps + 1) * settings.T
    fig, axes = common.new_figure(len(summary), 1, figsize=(8, 3 * len(summary)))
    for (case, res), ax in zip(summary.items(), axes[:, 0]):
        for n in FILTERS:
            ax.semilogy(t, res[n]["rms_mean"], label=n)
        ax.axhline(settings.divergence_error, color="k", ls=":", lw=0.8, label="divergence threshold")
        common.style_axes(ax, "time [s]", legend=8,
                          title=f"{case}: RMS error over the states, mean of {settings.runs} realisations")
    common.save_figure(fig, out / "errors.png")


def _limit_figures(summary: dict, settings: Settings, out: Path) -> None:
    """Average NEES with its band, and RMSE against the PCRB, per case."""
    t = np.arange(settings.steps + 1) * settings.T
    fig, axes = common.new_figure(len(summary), 1, figsize=(8, 3 * len(summary)))
    for (case, res), ax in zip(summary.items(), axes[:, 0]):
        lo, hi = res[FILTERS[0]]["nees_band"]
        ax.fill_between(t[1:], lo, hi, color="0.85", label=f"{settings.confidence:.0%} band ({settings.runs} runs)")
        for n in FILTERS:
            ax.semilogy(t[1:], res[n]["anees"], lw=0.8, label=n)
        common.style_axes(ax, "time [s]", title=f"{case}: average NEES over {settings.runs} realisations", legend=8)
    common.save_figure(fig, out / "nees.png")
    fig, axes = common.new_figure(4, len(summary), figsize=(5 * len(summary), 9), sharex=True)
    for j, (case, res) in enumerate(summary.items()):
        for a, x in enumerate(STATES):
            ax = axes[a, j]
            for n in FILTERS:
                ax.semilogy(t[1:], res[n]["rmse_k"][:, a], lw=0.8, label=n)
            ax.semilogy(t[1:], np.sqrt(res["bound"][1:, a]), "k-", lw=1.2, label="sqrt(PCRB)")
            common.style_axes(ax, ylabel=f"RMSE {x}")
        axes[0, j].set_title(case)
        axes[0, j].legend(fontsize=7)
        axes[-1, j].set_xlabel("time [s]")
    common.save_figure(fig, out / "rmse_pcrb.png")


class Seed001(Experiment, register="seed001"):
    """Seed 001: the KF on the linearised cart-pole against the EKF under a constant force."""

    description = "seed 001: KF on the linearised cart-pole against the EKF, constant force, 120 s"
    configs: ClassVar[dict] = {"default": Settings()}

    def run(self, settings, path="fast", backend="processes", n_jobs=None, progress=True):
        """:func:`run`."""
        return run(settings, path=self.check_path(path), backend=backend, n_jobs=n_jobs, progress=progress)

    def write_report(self, result, settings, out_dir, path="fast", config="custom", partial=False):
        """:func:`write_report`."""
        return write_report(result, settings, out_dir, path, partial)

    def summary(self, result, settings, path="fast", config="custom"):
        """The errors at the report times, and the divergence of each filter."""
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

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

import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import ClassVar, NamedTuple

import numpy as np
import pandas as pd

from estimators import EKF, KF, discretize, posterior_crb
from fmu_models import build_fmu, get_model
from fmu_models.infra.files import atomic_write

from ..components.sources import Constant
from ..fmi.fmu_component import FMUComponent
from . import metrics
from .campaign import realisation_seeds, run_tasks
from .common import batch_run, master_realisation, nees_from_outputs, new_figure, noise_components, simulate_truth
from .experiment import Experiment
from .settings import check_common, check_consistency, to_toml

CASES = {"hanging": (0.0, 0.0, np.pi, 0.0), "upright": (0.0, 0.0, 0.1, 0.0)}
REPORT_TIMES = (1.0, 30.0, 60.0, 90.0, 100.0, 120.0)
PAPER = pd.DataFrame({"time": [1, 30, 60, 90, 100], "KF error": [0.012, 0.0047, 0.045, 0.004, 0.047],
                      "EKF error": [0.006, 0.002, 0.005, 0.011, 0.009]})
FILTERS = ("KF", "EKF")
STATES = ("x", "x_dot", "theta", "theta_dot")
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
        row, per_step = metrics.band_row(nees[name], nis[name], 4, 2, s.confidence)
        row.update(white[name])
        row["consistent"] = metrics.verdict(row)
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


def _truth(case: str, s: Settings, runs):
    seeds = [tuple(realisation_seeds(s.seed, list(CASES).index(case), r)) for r in runs]
    us = np.full((s.steps + 1, 1), s.force)
    X, Y = simulate_truth(get_model("cartpole"), CASES[case], us, s.T, s.q, ["x", "theta"], s.r_std, seeds)
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
    runs = list(range(s.runs)) if runs is None else list(runs)
    X, Y, us = _truth(case, s, runs)
    errors, nees, nis, white = {}, {}, {}, {}
    for n, m in make_filters(s, case).items():
        res = batch_run(m, X, Y, us)
        errors[n], nees[n], nis[n] = res.x - X, res.nees, res.nis
        white[n] = metrics.whiteness_row(res.innovation, res.S, s.confidence, s.whiteness_lags)
    return _summary(errors, s, nees, nis, white, case_bound(s, case, X, us))


def master_task(case: str, settings: Settings, runs=None) -> dict:
    """The same realisations through the co-simulation master with the plant FMU (the
    PCRB on the fast path's truth of the same seeds; no whiteness test).

    Parameters
    ----------
    case
        Which case.
    settings
        The settings.
    runs
        Which realisations (default all).
    """
    import tempfile



    s = settings
    runs = list(range(s.runs)) if runs is None else list(runs)
    model = get_model("cartpole")
    makers = make_filters(s, case)
    errors = {n: np.empty((len(runs), s.steps + 1, 4)) for n in makers}
    nees = {n: np.empty((len(runs), s.steps)) for n in makers}
    nis = {n: np.empty((len(runs), s.steps)) for n in makers}
    with tempfile.TemporaryDirectory() as tmp:
        plant = FMUComponent("plant", build_fmu(model, tmp), s.T,
                             start=dict(zip(model.state_names, CASES[case])))
        for i, r in enumerate(runs):
            noise, sensor = noise_components(model, s.T, s.q, ["x", "theta"], s.r_std,
                                             *realisation_seeds(s.seed, list(CASES).index(case), r))
            X, est, cov, nis_r = master_realisation(plant, _source(s), noise, sensor, makers, s.T, s.duration)
            for n in makers:
                errors[n][i] = est[n] - X
                with np.errstate(over="ignore", invalid="ignore"):
                    nees[n][i] = nees_from_outputs(est[n][1:] - X[1:], cov[n][1:])
                nis[n][i] = nis_r[n]
    X, _, us = _truth(case, s, runs)
    return _summary(errors, s, nees, nis, {n: metrics.no_whiteness() for n in makers}, case_bound(s, case, X, us))


def run(settings: Settings = Settings(), path: str = "fast", backend="processes", n_jobs=None,
        progress=True):
    """Both cases; returns a :class:`Seed001Result`.

    Parameters
    ----------
    settings
        The settings.
    path
        ``fast`` or ``master``.
    backend
        Parallel backend.
    n_jobs
        Worker processes.
    progress
        Show a progress bar.
    """
    fn = fast_task if path == "fast" else master_task
    t0 = time.perf_counter()
    res = run_tasks([(fn, dict(case=c, settings=settings)) for c in CASES], backend=backend,
                    n_jobs=n_jobs, progress=progress, desc=f"seed001 ({path})")
    wall = time.perf_counter() - t0
    rows = []
    times = [tr for tr in REPORT_TIMES if tr <= settings.duration]
    for case, r in zip(CASES, res):
        for j, tr in enumerate(times):
            rows.append({"case": case, "time": tr, **{f"{n} |x error| [m]": r[n]["pos_err"][:, j].mean()
                                                      for n in FILTERS}})
    cons = []
    for case, r in zip(CASES, res):
        for n in FILTERS:
            cons.append({"case": case, "filter": n, **{f"rmse_{x}": float(np.sqrt(np.mean(r[n]["rmse"][:, a] ** 2)))
                                                       for a, x in enumerate(STATES)},
                         **{f"pcrb_ratio_{x}": float(r[n]["pcrb_ratio"][a]) for a, x in enumerate(STATES)},
                         "pcrb_ratio_max": float(np.max(r[n]["pcrb_ratio"])),
                         **{f"pcrb_ratio_se_{x}": float(r[n]["pcrb_ratio_se"][a]) for a, x in enumerate(STATES)},
                         **r[n]["tests"]})
        cons.append({"case": case, "filter": "PCRB", "runs": settings.runs,
                     **{f"rmse_{x}": float(np.sqrt(r["bound"][1:, a].mean())) for a, x in enumerate(STATES)},
                     **{f"pcrb_ratio_{x}": 1.0 for x in STATES}, "pcrb_ratio_max": 1.0})
    return Seed001Result(pd.DataFrame(rows), dict(zip(CASES, res)), wall, pd.DataFrame(cons))


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


def write_report(result: Seed001Result, settings: Settings, out_dir, path: str = "fast") -> Path:
    """The tables, the figures, ``settings.toml`` and ``summary.md`` into ``out_dir``; returns ``summary.md``.

    Parameters
    ----------
    result
        What :func:`run` returned.
    settings
        The settings.
    out_dir
        Output folder.
    path
        The path that ran.
    """
    table, summary, wall, cons = result
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write(out / "settings.toml", lambda p: p.write_text(to_toml(settings, "seed001")))
    atomic_write(out / "errors_at_times.csv", lambda p: table.to_csv(p, index=False))
    atomic_write(out / "consistency.csv", lambda p: cons.to_csv(p, index=False))
    t = np.arange(settings.steps + 1) * settings.T
    fig, axes = new_figure(len(summary), 1, figsize=(8, 3 * len(summary)))
    lines = ["# Seed 001: KF on the linearised model against the EKF", "",
             f"Regime: both filters given the true noise (q = {settings.q:g} per step, r = {settings.r_std:g}^2), "
             f"started at the true state with P0 = {settings.P0:g} I; {settings.runs} realisations per case, "
             f"{settings.duration:g} s ({settings.steps} steps), {path} path; wall time {wall:.2f} s.", "",
             "## Settings", "", "| setting | value |", "|---|---|",
             *[f"| {k} | {v} |" for k, v in asdict(settings).items()], "",
             "## Mean absolute cart-position error", "", table.to_markdown(index=False, floatfmt=".4g"), "",
             "Paper (seed 001 Table 1, position errors [m]):", "", PAPER.to_markdown(index=False), "",
             "## Divergence and RMSE", "", "| case | filter | diverged runs | median time of divergence [s] | "
             "RMSE x | RMSE x_dot | RMSE theta | RMSE theta_dot |", "|---|---|---|---|---|---|---|---|"]
    for (case, res), ax in zip(summary.items(), axes[:, 0]):
        for n in FILTERS:
            td = res[n]["t_div"]
            nd = int(np.isfinite(td).sum())
            med = f"{np.nanmedian(td):.2f}" if nd else "none"
            rm = res[n]["rmse"].mean(axis=0)
            lines.append(f"| {case} | {n} | {nd} of {len(td)} | {med} | " + " | ".join(f"{v:.3g}" for v in rm) + " |")
            ax.semilogy(t, res[n]["rms_mean"], label=n)
        ax.axhline(settings.divergence_error, color="k", ls=":", lw=0.8, label="divergence threshold")
        ax.set_title(f"{case}: RMS error over the states, mean of {settings.runs} realisations")
        ax.set_xlabel("time [s]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    atomic_write(out / "errors.png", lambda p: fig.savefig(p, dpi=100, format="png"))
    ratio_cols = [f"pcrb_ratio_{x}" for x in STATES]
    shown = cons[["case", "filter", *[f"rmse_{x}" for x in STATES], *ratio_cols]]
    lines += ["", "## RMSE per state over the posterior Cramér-Rao bound", "",
              f"The PCRB is the lowest mean-square error any estimator can have on these {settings.runs} "
              f"realisations (prior: {PCRB_PRIORS[settings.pcrb_prior]}); each ratio is the RMSE over the "
              "realisations and steps 1..K over the root of the bound's mean over the same steps (1 is the best "
              "possible; pcrb_ratio_se_* in consistency.csv: the Monte Carlo standard error of each ratio).", "",
              shown.to_markdown(index=False, floatfmt=".4g"), "",
              "## Consistency: chi-square bands of NEES and NIS, whiteness of the innovations", "",
              "Rule: " + metrics.consistency_rule(settings.confidence, settings.whiteness_lags) + ".", "",
              *metrics.consistency_markdown(cons[cons["filter"] != "PCRB"], ["case"]), ""]
    if path == "master":
        lines += ["On the master path the estimator components do not publish their innovations, so whiteness "
                  "is not tested there (the fast path gives the same numbers).", ""]
    _limit_figures(summary, settings, out)
    lines += ["Figures: " + ", ".join(sorted(p.name for p in out.glob("*.png")))]
    md = out / "summary.md"
    atomic_write(md, lambda p: p.write_text("\n".join(lines) + "\n"))
    return md


def _limit_figures(summary: dict, settings: Settings, out: Path) -> None:
    """Average NEES with its band, and RMSE against the PCRB, per case."""
    t = np.arange(settings.steps + 1) * settings.T
    fig, axes = new_figure(len(summary), 1, figsize=(8, 3 * len(summary)))
    for (case, res), ax in zip(summary.items(), axes[:, 0]):
        lo, hi = res[FILTERS[0]]["nees_band"]
        ax.fill_between(t[1:], lo, hi, color="0.85", label=f"{settings.confidence:.0%} band ({settings.runs} runs)")
        for n in FILTERS:
            ax.semilogy(t[1:], res[n]["anees"], lw=0.8, label=n)
        ax.set_title(f"{case}: average NEES over {settings.runs} realisations")
        ax.set_xlabel("time [s]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    atomic_write(out / "nees.png", lambda p, fig=fig: fig.savefig(p, dpi=100, format="png"))
    fig, axes = new_figure(4, len(summary), figsize=(5 * len(summary), 9), sharex=True)
    for j, (case, res) in enumerate(summary.items()):
        for a, x in enumerate(STATES):
            ax = axes[a, j]
            for n in FILTERS:
                ax.semilogy(t[1:], res[n]["rmse_k"][:, a], lw=0.8, label=n)
            ax.semilogy(t[1:], np.sqrt(res["bound"][1:, a]), "k-", lw=1.2, label="sqrt(PCRB)")
            ax.set_ylabel(f"RMSE {x}")
            ax.grid(alpha=0.3)
        axes[0, j].set_title(case)
        axes[0, j].legend(fontsize=7)
        axes[-1, j].set_xlabel("time [s]")
    atomic_write(out / "rmse_pcrb.png", lambda p, fig=fig: fig.savefig(p, dpi=100, format="png"))


class Seed001(Experiment, register="seed001"):
    """Seed 001: the KF on the linearised cart-pole against the EKF under a constant force."""

    description = "seed 001: KF on the linearised cart-pole against the EKF, constant force, 120 s"
    configs: ClassVar[dict] = {"default": Settings()}

    def run(self, settings, path="fast", backend="processes", n_jobs=None, progress=True):
        """:func:`run`."""
        return run(settings, path=self.check_path(path), backend=backend, n_jobs=n_jobs, progress=progress)

    def write_report(self, result, settings, out_dir, path="fast", config="custom", partial=False):
        """:func:`write_report`."""
        return write_report(result, settings, out_dir, path)

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

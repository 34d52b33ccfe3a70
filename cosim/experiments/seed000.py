"""Seed 000 section 5: EKF, IAE and MF-IAE on the cart-pole under four noise scenarios.

Truth (SPEC section 1): the Euler map, ``T = 0.01 s``, ``x0 = [0.5, 0, 1.8, 0.5]``, input
-0.5 N switching to +0.5 N at 2 s (Figure 2), 500 steps; process noise ``w ~ N(0, q I)``
added each step, measurement ``y = [x, theta] + v``, ``v ~ N(0, r I)``. Scenarios
``(sigma_q^2, sigma_r^2)``: (0.2, 0.1), (0.2, 0.2), (0.3, 0.1), (0.3, 0.2). Two readings of
the names (SPEC): ``"eqs"`` (eqs 24-25: ``q = sigma_q^2``, ``r = sigma_r^2``) and
``"prose"`` (section 5's text: ``q = sigma_r^2``, ``r = sigma_q^2``).

Filters: EKF, IAE and MF-IAE from the same nominal (wrong) noise setting, and the EKF
given the true Q and R (the bound an adaptive filter tries to reach). The paper gives no
filter settings: every one is in :class:`Settings` and printed with the results.

Two paths give the same numbers: ``fast`` (truth and all filters vectorised over the
realisations) and ``master`` (each realisation through the co-simulation master with the
plant FMU, process-noise and sensor components and the four filters as components).
Both draw realisation ``r`` of scenario ``s`` from the seeds
``realisation_seeds(seed, s, r)``.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from . import metrics
from .campaign import realisation_seeds, run_tasks
from .common import batch_estimates, master_realisation, noise_components
from .common import simulate_truth as common_truth

SCENARIOS = ((0.2, 0.1), (0.2, 0.2), (0.3, 0.1), (0.3, 0.2))
READINGS = {"eqs": "eqs 24-25: sigma_q^2 is the process variance (Q), sigma_r^2 the measurement variance (R)",
            "prose": "section 5 prose: sigma_r^2 is the process variance, sigma_q^2 the measurement variance"}
#: Table 3 of seed 000 (eta, eq 44).
PAPER_ETA = {"EKF": (4.4782, 5.2441, 4.4426, 4.9982), "MF-IAE": (2.2153, 2.2109, 2.6581, 2.6800)}
FILTERS = ("EKF", "IAE", "MF-IAE", "EKF true Q,R")
STATES = ("x", "x_dot", "theta", "theta_dot")


@dataclass(frozen=True)
class Settings:
    """Every choice of the campaign, including those the paper leaves open.

    Attributes: ``runs`` realisations per scenario; ``duration`` [s] and ``T`` [s];
    ``x0``; the input step (``t_step``, ``u_before``, ``u_after``); filters: initial
    estimate ``x0`` (the true initial state), ``P0`` (times I), the nominal noise
    ``q_nominal``, ``r_nominal`` (times I) that EKF, IAE and MF-IAE start from,
    ``iae_window`` and ``mfiae_window`` (N of eq 37; MF-IAE gains are its defaults);
    ``seed`` of all random streams; ``divergence_threshold`` [state units].
    """

    runs: int = 100
    duration: float = 5.0
    T: float = 0.01
    x0: tuple = (0.5, 0.0, 1.8, 0.5)
    t_step: float = 2.0
    u_before: float = -0.5
    u_after: float = 0.5
    P0: float = 1.0
    q_nominal: float = 0.01
    r_nominal: float = 0.01
    iae_window: int = 20
    mfiae_window: int = 50
    seed: int = 2026
    divergence_threshold: float = 1e3
    scenarios: tuple = field(default=SCENARIOS)

    @property
    def steps(self) -> int:
        return int(round(self.duration / self.T))


def true_noise(scenario: tuple, reading: str) -> tuple[float, float]:
    """(process variance q, measurement variance r) of a scenario under a reading."""
    sq, sr = scenario
    if reading not in READINGS:
        raise ValueError(f"reading must be one of {list(READINGS)}, got {reading!r}")
    return (sq, sr) if reading == "eqs" else (sr, sq)


def _system(s: Settings):
    from estimators import discretize
    from fmu_models import get_model

    return discretize(get_model("cartpole"), s.T)


def make_filters(system, s: Settings, q: float, r: float) -> dict:
    """The four filters, by name, as constructors (called once per realisation or batch)."""
    from estimators import EKF, IAE, MFIAE

    x0 = np.array(s.x0)
    return {"EKF": lambda: EKF(system, x0, s.P0, s.q_nominal, s.r_nominal),
            "IAE": lambda: IAE(system, x0, s.P0, s.q_nominal, s.r_nominal, window=s.iae_window),
            "MF-IAE": lambda: MFIAE(system, x0, s.P0, s.q_nominal, s.r_nominal, window=s.mfiae_window),
            "EKF true Q,R": lambda: EKF(system, x0, s.P0, q, r)}


def _input_component(s: Settings):
    from ..sources import Step

    return Step("force", s.T, s.t_step, s.u_before, s.u_after)


def _inputs(s: Settings) -> np.ndarray:
    src = _input_component(s)
    src.reset(0.0)
    return np.array([src.output(k * s.T, None)[0] for k in range(s.steps + 1)])


def _noise(s: Settings, q: float, r: float, seed_w: int, seed_v: int):
    from fmu_models import get_model

    return noise_components(get_model("cartpole"), s.T, q, ["x", "theta"], np.sqrt(r), seed_w, seed_v)


def simulate_truth(s: Settings, q: float, r: float, seeds: list[tuple[int, int]]):
    """Truth ``X`` (runs, steps+1, 4), measurements ``Y`` (runs, steps+1, 2) and the input
    sequence, drawing the same numbers as the components of the master path."""
    from fmu_models import get_model

    u = _inputs(s)
    X, Y = common_truth(get_model("cartpole"), s.x0, u[:, None], s.T, q, ["x", "theta"],
                        np.sqrt(r), seeds)
    return X, Y, u


def _summarise(errors: dict, nees: dict, nis: dict, failed: dict, s: Settings, example: dict) -> dict:
    """Per-filter metrics of one task (errors over k = 1..N)."""
    out = {"eps_k": {}, "per_run": {}, "example": example}
    for name, err in errors.items():
        e = err[:, 1:]
        div = metrics.diverged(e, s.divergence_threshold) | failed[name]
        out["eps_k"][name] = metrics.eps_k(e)
        out["per_run"][name] = {"eta": metrics.eta_per_run(e), "diverged": div,
                                "rmse": np.sqrt(np.mean(e**2, axis=1)),
                                "anees": nees[name].mean(axis=1), "anis": nis[name].mean(axis=1)}
    return out


def fast_task(scenario_index: int, reading: str, settings: Settings, runs=None) -> dict:
    """All realisations of one scenario and reading, every filter batched over them."""
    s = settings
    runs = list(range(s.runs)) if runs is None else list(runs)
    q, r = true_noise(s.scenarios[scenario_index], reading)
    seeds = [tuple(realisation_seeds(s.seed, scenario_index, run)) for run in runs]
    X, Y, u = simulate_truth(s, q, r, seeds)
    errors, nees, nis, failed = {}, {}, {}, {}
    for name, make in make_filters(_system(s), s, q, r).items():
        est, nees[name], nis[name], failed[name] = batch_estimates(make, X, Y, u[:, None], s.x0)
        errors[name] = est - X
    example = {"truth": X[0], "y": Y[0], **{f"est {n}": X[0] + errors[n][0] for n in errors}}
    return _summarise(errors, nees, nis, failed, s, example)


def master_task(scenario_index: int, reading: str, settings: Settings, runs=None, fmu_dir=None) -> dict:
    """The same realisations, each run through the co-simulation master with the plant FMU.

    (NEES on this path uses only the covariance diagonals the estimator components output.)
    """
    import tempfile

    from fmu_models.build import build_fmu

    from ..fmu_component import FMUComponent

    s = settings
    runs = list(range(s.runs)) if runs is None else list(runs)
    q, r = true_noise(s.scenarios[scenario_index], reading)
    makers = make_filters(_system(s), s, q, r)
    X = np.empty((len(runs), s.steps + 1, 4))
    E = {name: np.empty_like(X) for name in makers}
    NIS = {name: np.zeros((len(runs), s.steps)) for name in makers}
    NEES = {name: np.zeros((len(runs), s.steps)) for name in makers}
    with tempfile.TemporaryDirectory() as tmp:
        plant = FMUComponent("plant", build_fmu("cartpole", fmu_dir or tmp), s.T,
                             start=dict(zip(STATES, s.x0)))
        for i, run in enumerate(runs):
            noise, sensor = _noise(s, q, r, *realisation_seeds(s.seed, scenario_index, run))
            X[i], est, pdiag, nis = master_realisation(plant, _input_component(s), noise, sensor,
                                                       makers, s.T, s.duration)
            for n in makers:
                E[n][i], NIS[n][i] = est[n], nis[n]
                NEES[n][i] = np.sum((est[n][1:] - X[i][1:]) ** 2 / pdiag[n][1:], axis=1)
    errors = {n: E[n] - X for n in makers}
    failed = {n: np.zeros(len(runs), dtype=bool) for n in makers}
    example = {"truth": X[0], **{f"est {n}": E[n][0] for n in makers}}
    return _summarise(errors, NEES, NIS, failed, s, example)


# ---------------------------------------------------------------------------- campaign
def run(settings: Settings = Settings(), path: str = "fast", readings=("eqs", "prose"),
        backend: str = "processes", n_jobs=None, progress: bool = True):
    """Run the campaign; returns ``(per_run, eps, examples, wall_time)``.

    ``per_run``: tidy DataFrame, one row per (reading, scenario, filter, realisation);
    ``eps``: DataFrame of eps_k (eq 43) by (reading, scenario, filter) and time.
    """
    if path not in ("fast", "master"):
        raise ValueError(f"path must be 'fast' or 'master', got {path!r}")
    fn = fast_task if path == "fast" else master_task
    keys = [(rd, i) for rd in readings for i in range(len(settings.scenarios))]
    t0 = time.perf_counter()
    if path == "master":
        # one task per scenario and slice of realisations, so both cores stay busy
        chunks = np.array_split(np.arange(settings.runs), max(1, min(settings.runs, 4)))
        tasks = [(fn, dict(scenario_index=i, reading=rd, settings=settings, runs=list(c)))
                 for rd, i in keys for c in chunks if len(c)]
    else:
        chunks = [np.arange(settings.runs)]
        tasks = [(fn, dict(scenario_index=i, reading=rd, settings=settings)) for rd, i in keys]
    results = run_tasks(tasks, backend=backend, n_jobs=n_jobs, progress=progress,
                        desc=f"seed000 ({path})")
    wall = time.perf_counter() - t0
    rows, eps_rows, examples = [], [], {}
    nchunk = len([c for c in chunks if len(c)])
    for j, (rd, i) in enumerate(keys):
        parts = results[j * nchunk:(j + 1) * nchunk]
        run_ids = np.concatenate([c for c in chunks if len(c)])
        q, r = true_noise(settings.scenarios[i], rd)
        for name in FILTERS:
            pr = {k: np.concatenate([p["per_run"][name][k] for p in parts]) for k in parts[0]["per_run"][name]}
            for n, run_id in enumerate(run_ids):
                rows.append({"reading": rd, "scenario": i + 1, "sigma_q2": settings.scenarios[i][0],
                             "sigma_r2": settings.scenarios[i][1], "q_true": q, "r_true": r,
                             "filter": name, "run": int(run_id), "eta": pr["eta"][n],
                             "diverged": bool(pr["diverged"][n]), "anees": pr["anees"][n],
                             "anis": pr["anis"][n],
                             **{f"rmse_{x}": pr["rmse"][n, a] for a, x in enumerate(STATES)}})
            w = np.array([len(c) for c in chunks if len(c)], float)
            eps = sum(p["eps_k"][name] * wi for p, wi in zip(parts, w)) / w.sum()
            for k, e in enumerate(eps, start=1):
                eps_rows.append({"reading": rd, "scenario": i + 1, "filter": name, "k": k,
                                 "time": k * settings.T, "eps": e})
        examples[(rd, i + 1)] = parts[0]["example"]
    return pd.DataFrame(rows), pd.DataFrame(eps_rows), examples, wall


def summary_table(per_run: pd.DataFrame) -> pd.DataFrame:
    """eta (eq 44) per reading, scenario and filter, with the paper's Table 3 beside it.

    eta is the mean over all realisations; ``diverged`` counts the runs flagged, and
    ``eta (no div.)`` excludes them.
    """
    rows = []
    for (rd, sc), g in per_run.groupby(["reading", "scenario"], sort=True):
        row = {"reading": rd, "scenario": sc, "sigma_q2": g["sigma_q2"].iloc[0],
               "sigma_r2": g["sigma_r2"].iloc[0],
               "paper EKF": PAPER_ETA["EKF"][sc - 1], "paper MF-IAE": PAPER_ETA["MF-IAE"][sc - 1]}
        for name in FILTERS:
            f = g[g["filter"] == name]
            row[name] = f["eta"].mean()
            ok = f[~f["diverged"]]
            row[f"{name} diverged"] = int(f["diverged"].sum())
            if f["diverged"].any():
                row[f"{name} (no div.)"] = ok["eta"].mean() if len(ok) else np.nan
        rows.append(row)
    return pd.DataFrame(rows)


def write_report(per_run, eps, examples, wall, settings: Settings, out_dir, path: str) -> Path:
    """Tables (CSV, Parquet), figures (PNG) and a markdown summary into ``out_dir``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    per_run.to_csv(out / "per_run.csv", index=False)
    per_run.to_parquet(out / "per_run.parquet")
    eps.to_csv(out / "eps_k.csv", index=False)
    table = summary_table(per_run)
    table.to_csv(out / "table3.csv", index=False)
    agg = per_run.groupby(["reading", "filter"])[["anees", "anis"] + [f"rmse_{x}" for x in STATES]].mean()
    agg.to_csv(out / "consistency_rmse.csv")

    # Figure 3: scenario 1, first realisation, truth and estimates
    for rd in sorted({k[0] for k in examples}):
        ex = examples[(rd, 1)]
        t = np.arange(ex["truth"].shape[0]) * settings.T
        fig, axes = plt.subplots(4, 1, figsize=(8, 8), sharex=True)
        for a, ax in enumerate(axes):
            ax.plot(t, ex["truth"][:, a], "k-", lw=1.2, label="truth")
            for name, style in (("EKF", "b--"), ("MF-IAE", "r-.")):
                ax.plot(t, ex[f"est {name}"][:, a], style, lw=0.9, label=name)
            ax.set_ylabel(STATES[a])
            ax.grid(alpha=0.3)
        axes[0].legend(fontsize=8)
        axes[-1].set_xlabel("time [s]")
        fig.suptitle(f"Seed 000 Figure 3: scenario 1, realisation 0 ({rd} reading)")
        fig.tight_layout()
        fig.savefig(out / f"figure3_{rd}.png", dpi=100)
        plt.close(fig)
        # Figure 4: eps_k over time
        fig, ax = plt.subplots(figsize=(8, 3.5))
        for name in FILTERS:
            e = eps[(eps.reading == rd) & (eps.scenario == 1) & (eps["filter"] == name)]
            ax.plot(e["time"], e["eps"], lw=1, label=name)
        ax.set_xlabel("time [s]")
        ax.set_ylabel("eps_k (eq 43)")
        ax.set_yscale("log")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        ax.set_title(f"Seed 000 Figure 4: scenario 1, {settings.runs} realisations ({rd} reading)")
        fig.tight_layout()
        fig.savefig(out / f"figure4_{rd}.png", dpi=100)
        plt.close(fig)

    lines = [f"# Seed 000 campaign ({path} path)", "",
             f"{settings.runs} realisations x {len(settings.scenarios)} scenarios x {len(FILTERS)} filters "
             f"x {settings.steps} steps per reading; wall time {wall:.2f} s.", "",
             "## Settings (the paper gives none of the filter settings)", "",
             "| setting | value |", "|---|---|"]
    lines += [f"| {k} | {v} |" for k, v in asdict(settings).items()]
    lines += ["", "Readings of the noise names:", ""] + [f"- **{k}**: {v}" for k, v in READINGS.items()]
    lines += ["", "## Table 3: eta (eq 44), mean over realisations", ""]
    cols = ["reading", "scenario", "sigma_q2", "sigma_r2", "paper EKF", "paper MF-IAE", *FILTERS]
    lines.append("| " + " | ".join(cols) + " |")
    lines.append("|" + "---|" * len(cols))
    for _, row in table.iterrows():
        lines.append("| " + " | ".join(f"{row[c]:.4f}" if isinstance(row[c], float) else str(row[c])
                                       for c in cols) + " |")
    div = {c: int(table[c].sum()) for c in table.columns if c.endswith("diverged")}
    lines += ["", "Diverged realisations (error not finite or above "
              f"{settings.divergence_threshold:g}): " + ", ".join(f"{k[:-9]}: {v}" for k, v in div.items()), "",
              "## Consistency and per-state RMSE (mean over scenarios and realisations)", "",
              agg.to_markdown(floatfmt=".4f"), "",
              "Figures: " + ", ".join(sorted(p.name for p in out.glob("figure*.png")))]
    md = out / "summary.md"
    md.write_text("\n".join(lines) + "\n")
    return md

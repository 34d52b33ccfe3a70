"""Seed 000 section 5: EKF, IAE and MF-IAE on the cart-pole under four noise scenarios.

Truth (seed 000 eqs 12-17): the Euler map, ``T = 0.01 s``, ``x0 = [0.5, 0, 1.8, 0.5]``, 500
steps; process noise ``w ~ N(0, q I)`` added each step, measurement ``y = [x, theta] +
v``, ``v ~ N(0, r I)``. Input: seed 000 Figure 2's PRBS of +/-0.5 N, -0.5 N until 2 s then
+0.5 N: here the maximal-length LFSR sequence of order 7 (taps 7, 6) started from state
28, one bit per second (:func:`figure2_prbs`), whose first five bits ``0 0 1 1 1`` are the
figure. Scenarios ``(sigma_q^2, sigma_r^2)``: (0.2, 0.1), (0.2, 0.2), (0.3, 0.1), (0.3, 0.2).
Two readings of the names (section 5's prose swaps them): ``"eqs"`` (eqs 24-25: ``q = sigma_q^2``, ``r =
sigma_r^2``) and ``"prose"`` (section 5's text: ``q = sigma_r^2``, ``r = sigma_q^2``).

Filters: EKF, IAE and MF-IAE from the same nominal (wrong) noise setting, beside them
the EKF with EM-learned Q and R and SWML (online, beyond the paper: :class:`estimators.SWML`),
and the EKF given the true Q and R (the bound an adaptive filter tries to reach). The paper gives no
filter settings: every one is in :class:`Settings`, and two configurations are named
(:data:`CONFIGS`): ``"default"`` (filters from Q = R = 0.01 I, both readings) and
``"paper"`` (filters from Q0 = 1e-3 I, R0 = 10 I, eqs reading: the regime whose EKF row
matches the paper's Table 3; MF-IAE as eqs 41-42 print it, unit gains, window 10).

Two paths give the same numbers: ``fast`` (truth and all filters over all realisations in
native calls) and ``master`` (each realisation through the co-simulation master with the
plant FMU, process-noise and sensor components and the four filters as components). Both
draw realisation ``r`` of scenario ``s`` from ``realisation_seeds(seed, s, r)`` and compute
NEES from the full covariance.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from estimators import EKF, IAE, MFIAE, SWML, discretize, em_noise
from fmu_models import build_fmu, get_model
from fmu_models.errors import ConfigurationError, Interrupted, UnknownNameError
from fmu_models.infra.checks import positive, positive_int
from fmu_models.infra.files import atomic_write

from ..components.sources import PRBS
from ..fmi.fmu_component import FMUComponent
from . import metrics
from .campaign import realisation_seeds, run_tasks
from .common import (
    batch_estimates,
    master_realisation,
    nees_from_outputs,
    new_figure,
    noise_components,
)
from .common import simulate_truth as common_truth
from .experiment import Experiment
from .settings import check_common, to_toml

SCENARIOS = ((0.2, 0.1), (0.2, 0.2), (0.3, 0.1), (0.3, 0.2))
READINGS = {"eqs": "eqs 24-25: sigma_q^2 is the process variance (Q), sigma_r^2 the measurement variance (R)",
            "prose": "section 5 prose: sigma_r^2 is the process variance, sigma_q^2 the measurement variance"}
#: Table 3 of seed 000 (eta, eq 44).
PAPER_ETA = {"EKF": (4.4782, 5.2441, 4.4426, 4.9982), "MF-IAE": (2.2153, 2.2109, 2.6581, 2.6800)}
#: The filters of the campaign, in the order of its tables.
FILTERS = ("EKF", "IAE", "MF-IAE", "EKF EM", "SWML", "EKF true Q,R")
#: Run index of the training realisation EM learns from (never one of the test runs).
TRAINING_RUN = 2**31 - 1
STATES = ("x", "x_dot", "theta", "theta_dot")


@dataclass(frozen=True)
class Settings:
    """Every choice of the campaign, including those the paper leaves open.

    Truth: ``runs`` realisations per scenario of ``duration`` [s] with period ``T`` [s]
    from ``x0``; input: the PRBS of ``input_amplitude`` [N], LFSR ``input_order`` and
    ``input_seed``, ``input_bit_time`` [s] per bit; ``scenarios`` and ``readings``.
    Filters: initial estimate ``x0``, ``P0`` (times I); nominal noise (what EKF, IAE and
    MF-IAE start from) ``q0``, ``r0`` (times I), or, when ``q0_factor`` / ``r0_factor`` are
    set, that factor times the scenario's true variance (the robustness sweep); IAE:
    ``iae_window``, ``iae_adapt`` ("both", "Q", "R"), ``iae_form``; MF-IAE:
    ``mfiae_window``, ``mfiae_gain_q``, ``mfiae_gain_r``, ``mfiae_q_mapping`` ("literal",
    "gain"), ``mfiae_per_channel``. "EKF EM": an EKF with Q and R learned by EM
    (:func:`estimators.em_noise`, scalar forms, from the nominal values) on one separate
    training realisation of the scenario, ``em_iterations`` at most, relative tolerance
    ``em_tol``. "SWML" (:class:`estimators.SWML`, beyond the paper): window ``swml_window``,
    an update every ``swml_every`` steps, started from the nominal values. ``seed`` of all
    random streams; ``divergence_threshold`` [state units].
    """

    runs: int = 100
    duration: float = 5.0
    T: float = 0.01
    x0: tuple = (0.5, 0.0, 1.8, 0.5)
    input_amplitude: float = 0.5
    input_order: int = 7
    input_seed: int = 28
    input_bit_time: float = 1.0
    scenarios: tuple = SCENARIOS
    readings: tuple = ("eqs", "prose")
    P0: float = 1.0
    q0: float = 0.01
    r0: float = 0.01
    q0_factor: float | None = None
    r0_factor: float | None = None
    iae_window: int = 20
    iae_adapt: str = "both"
    iae_form: str = "diagonal"
    mfiae_window: int = 10
    mfiae_gain_q: float = 1.0
    mfiae_gain_r: float = 1.0
    mfiae_q_mapping: str = "literal"
    mfiae_per_channel: bool = False
    em_iterations: int = 100
    em_tol: float = 1e-6
    swml_window: int = 100
    swml_every: int = 50
    seed: int = 2026
    divergence_threshold: float = 1e3

    def __post_init__(self):

        check_common(self)
        for name in ("P0", "q0", "r0", "input_bit_time", "divergence_threshold", "mfiae_gain_q", "mfiae_gain_r"):
            positive(getattr(self, name), name)
        for name in ("q0_factor", "r0_factor"):
            if getattr(self, name) is not None:
                positive(getattr(self, name), name)

        for name in ("swml_window", "swml_every"):
            positive_int(getattr(self, name), name)
        if self.swml_window % self.swml_every:
            raise ConfigurationError(f"swml_window = {self.swml_window} must be a multiple of swml_every = "
                                     f"{self.swml_every}")
        if len(self.x0) != 4:
            raise ConfigurationError(f"x0 must have 4 entries, got {self.x0}")
        if not self.scenarios or any(len(sc) != 2 or min(sc) <= 0 for sc in self.scenarios):
            raise ConfigurationError(f"scenarios must be pairs of positive variances, got {self.scenarios}")
        bad = [r for r in self.readings if r not in READINGS]
        if bad or not self.readings:
            raise UnknownNameError(f"readings must be among {list(READINGS)}, got {self.readings}")

    @property
    def steps(self) -> int:
        return round(self.duration / self.T)


#: Named configurations (``--config``).
CONFIGS = {"default": Settings(),
           "paper": Settings(q0=1e-3, r0=10.0, readings=("eqs",))}


def true_noise(scenario: tuple, reading: str) -> tuple[float, float]:
    """(process variance q, measurement variance r) of a scenario under a reading."""
    sq, sr = scenario
    if reading not in READINGS:
        raise UnknownNameError(f"reading must be one of {list(READINGS)}, got {reading!r}")
    return (sq, sr) if reading == "eqs" else (sr, sq)


def nominal_noise(s: Settings, q: float, r: float) -> tuple[float, float]:
    """The noise variances (q0, r0) the EKF, IAE and MF-IAE start from."""
    return (s.q0 if s.q0_factor is None else s.q0_factor * q,
            s.r0 if s.r0_factor is None else s.r0_factor * r)


@lru_cache(maxsize=4)
def _system(T: float):

    return discretize(get_model("cartpole"), T)


def learn_noise(system, s: Settings, scenario_index: int, q: float, r: float) -> tuple[float, float]:
    """(q, r) learned by EM from the nominal values on the scenario's training realisation.

    Parameters
    ----------
    system
        The discrete model.
    s
        The campaign's settings.
    scenario_index
        Which scenario (its training realisation).
    q
        True process variance.
    r
        True measurement variance.
    """

    _X, Y, u = simulate_truth(s, q, r, [tuple(realisation_seeds(s.seed, scenario_index, TRAINING_RUN))])
    q0, r0 = nominal_noise(s, q, r)
    f = EKF(system, np.array(s.x0), s.P0, q0, r0)
    res = em_noise(f, u[:-1, None], Y[0, 1:], n_iter=s.em_iterations, tol=s.em_tol, structure="scalar")
    return float(res.Q[0, 0]), float(res.R[0, 0])


def make_filters(system, s: Settings, q: float, r: float, learned=None) -> dict:
    """The filters of :data:`FILTERS`, by name, as constructors (called once per realisation
    or batch); ``learned`` is EM's (q, r) for "EKF EM" (left out if None).

    Parameters
    ----------
    system
        The discrete model.
    s
        The campaign's settings.
    q
        True process variance.
    r
        True measurement variance.
    learned
        The EM-learned (q, r), for the EM EKF.
    """

    x0 = np.array(s.x0)
    q0, r0 = nominal_noise(s, q, r)
    em = {} if learned is None else {"EKF EM": lambda: EKF(system, x0, s.P0, *learned)}
    return {"EKF": lambda: EKF(system, x0, s.P0, q0, r0),
            "IAE": lambda: IAE(system, x0, s.P0, q0, r0, window=s.iae_window, adapt=s.iae_adapt,
                               form=s.iae_form),
            "MF-IAE": lambda: MFIAE(system, x0, s.P0, q0, r0, window=s.mfiae_window, gain_q=s.mfiae_gain_q,
                                    gain_r=s.mfiae_gain_r, q_mapping=s.mfiae_q_mapping,
                                    per_channel=s.mfiae_per_channel),
            **em,
            "SWML": lambda: SWML(system, x0, s.P0, q0, r0, window=s.swml_window, every=s.swml_every),
            "EKF true Q,R": lambda: EKF(system, x0, s.P0, q, r)}


def figure2_prbs(s: Settings):
    """The input source: Figure 2's PRBS (see the module documentation)."""

    return PRBS("force", s.T, s.input_amplitude, s.input_bit_time, s.input_order, s.input_seed)


def _inputs(s: Settings) -> np.ndarray:
    src = figure2_prbs(s)
    src.reset(0.0)
    return np.array([src.output(k * s.T, None)[0] for k in range(s.steps + 1)])


def _noise(s: Settings, q: float, r: float, seed_w: int, seed_v: int):

    return noise_components(get_model("cartpole"), s.T, q, ["x", "theta"], np.sqrt(r), seed_w, seed_v)


def simulate_truth(s: Settings, q: float, r: float, seeds: list[tuple[int, int]]):
    """Truth ``X`` (runs, steps+1, 4), measurements ``Y`` (runs, steps+1, 2) and the input
    sequence, drawing the same numbers as the components of the master path.

    Parameters
    ----------
    s
        The campaign's settings.
    q
        True process variance.
    r
        True measurement variance.
    seeds
        (process, measurement) seed pairs, one per realisation.
    """

    u = _inputs(s)
    X, Y = common_truth(get_model("cartpole"), s.x0, u[:, None], s.T, q, ["x", "theta"], np.sqrt(r), seeds)
    return X, Y, u


def _summarise(errors: dict, nees: dict, nis: dict, failed: dict, s: Settings, example: dict) -> dict:
    """Per-filter metrics of one task (errors over k = 1..N)."""
    out = {"eps_k": {}, "per_run": {}, "example": example}
    for name, err in errors.items():
        e = err[:, 1:]
        div = metrics.diverged(e, s.divergence_threshold) | failed[name]
        with np.errstate(invalid="ignore", over="ignore"):
            out["eps_k"][name] = metrics.eps_k(e)
            out["per_run"][name] = {"eta": metrics.eta_per_run(e), "diverged": div,
                                    "rmse": np.sqrt(np.mean(e**2, axis=1)),
                                    "anees": nees[name].mean(axis=1), "anis": nis[name].mean(axis=1)}
    return out


def fast_task(scenario_index: int, reading: str, settings: Settings, runs=None) -> dict:
    """All realisations of one scenario and reading, every filter over all of them in
    native calls.

    Parameters
    ----------
    scenario_index
        Which scenario (0-based).
    reading
        Which reading of the noise names (``eqs`` or ``prose``).
    settings
        The campaign's settings.
    runs
        Which realisations (default all).
    """
    s = settings
    runs = list(range(s.runs)) if runs is None else list(runs)
    q, r = true_noise(s.scenarios[scenario_index], reading)
    seeds = [tuple(realisation_seeds(s.seed, scenario_index, run)) for run in runs]
    X, Y, u = simulate_truth(s, q, r, seeds)
    system = _system(s.T)
    learned = learn_noise(system, s, scenario_index, q, r)
    errors, nees, nis, failed = {}, {}, {}, {}
    for name, make in make_filters(system, s, q, r, learned).items():
        est, nees[name], nis[name], failed[name] = batch_estimates(make, X, Y, u[:, None], s.x0)
        errors[name] = est - X
    example = {"truth": X[0], "y": Y[0], **{f"est {n}": X[0] + errors[n][0] for n in errors}}
    out = _summarise(errors, nees, nis, failed, s, example)
    out["learned"] = learned
    return out


def master_task(scenario_index: int, reading: str, settings: Settings, runs=None, fmu_dir=None,
                learned=None) -> dict:
    """The same realisations, each run through the co-simulation master with the plant FMU
    (``learned``: the EM-learned ``(q, r)`` of the scenario, if the caller has them).

    Parameters
    ----------
    scenario_index
        Which scenario (0-based).
    reading
        Which reading of the noise names.
    settings
        The campaign's settings.
    runs
        Which realisations (default all).
    fmu_dir
        Where to build the plant FMU (default a temporary folder).
    learned
        The EM-learned (q, r) (default: learned here).
    """
    import tempfile



    s = settings
    runs = list(range(s.runs)) if runs is None else list(runs)
    q, r = true_noise(s.scenarios[scenario_index], reading)
    system = _system(s.T)
    learned = learn_noise(system, s, scenario_index, q, r) if learned is None else learned
    makers = make_filters(system, s, q, r, learned)
    X = np.empty((len(runs), s.steps + 1, 4))
    E = {name: np.empty_like(X) for name in makers}
    NIS = {name: np.zeros((len(runs), s.steps)) for name in makers}
    NEES = {name: np.zeros((len(runs), s.steps)) for name in makers}
    with tempfile.TemporaryDirectory() as tmp:
        plant = FMUComponent("plant", build_fmu("cartpole", fmu_dir or tmp), s.T,
                             start=dict(zip(STATES, s.x0)))
        for i, run in enumerate(runs):
            noise, sensor = _noise(s, q, r, *realisation_seeds(s.seed, scenario_index, run))
            X[i], est, cov, nis = master_realisation(plant, figure2_prbs(s), noise, sensor, makers, s.T,
                                                     s.duration)
            for n in makers:
                E[n][i], NIS[n][i] = est[n], nis[n]
                NEES[n][i] = nees_from_outputs(est[n][1:] - X[i][1:], cov[n][1:])
    errors = {n: E[n] - X for n in makers}
    failed = {n: np.zeros(len(runs), dtype=bool) for n in makers}
    example = {"truth": X[0], **{f"est {n}": E[n][0] for n in makers}}
    out = _summarise(errors, NEES, NIS, failed, s, example)
    out["learned"] = learned
    return out


# ---------------------------------------------------------------------------- campaign
class CampaignResult(NamedTuple):
    """What :func:`run` returns: ``per_run`` (one row per reading, scenario, filter and
    realisation), ``eps`` (eps_k of eq 43 by reading, scenario, filter and time), the
    ``examples`` of Figure 3 by (reading, scenario), and the ``wall`` time [s]."""

    per_run: pd.DataFrame
    eps: pd.DataFrame
    examples: dict
    wall: float


#: Realisations per task on the master path.
MASTER_CHUNK = 10


def run(settings: Settings = Settings(), path: str = "fast", readings=None,
        backend: str = "processes", n_jobs=None, progress: bool = True):
    """Run the campaign; returns ``(per_run, eps, examples, wall_time)``.

    ``per_run``: tidy DataFrame, one row per (reading, scenario, filter, realisation);
    ``eps``: DataFrame of eps_k (eq 43) by (reading, scenario, filter) and time.
    ``readings`` defaults to the settings' readings. Interrupted (Ctrl-C, SIGTERM), it
    raises :class:`~fmu_models.errors.Interrupted` whose ``partial`` holds the same tuple
    for the tasks that finished.

    Parameters
    ----------
    settings
        The campaign's settings.
    path
        ``fast`` or ``master``.
    readings
        The readings to run (default the settings').
    backend
        Parallel backend (:func:`~cosim.experiments.campaign.run_tasks`).
    n_jobs
        Worker processes.
    progress
        Show a progress bar.
    """

    if path not in ("fast", "master"):
        raise UnknownNameError(f"path must be 'fast' or 'master', got {path!r}")
    readings = tuple(settings.readings if readings is None else readings)
    fn = fast_task if path == "fast" else master_task
    keys = [(rd, i) for rd in readings for i in range(len(settings.scenarios))]
    t0 = time.perf_counter()
    if path == "master":
        # one task per scenario and slice of at most MASTER_CHUNK realisations: every core
        # stays busy, and an interrupted campaign keeps all but the last few seconds
        n_chunks = max(4, -(-settings.runs // MASTER_CHUNK))
        chunks = [c for c in np.array_split(np.arange(settings.runs), min(settings.runs, n_chunks)) if len(c)]
    else:
        chunks = [np.arange(settings.runs)]
    extra = {}
    if path == "master":         # EM learns once per scenario, not once per task
        system = _system(settings.T)
        extra = {(rd, i): {"learned": learn_noise(system, settings, i, *true_noise(settings.scenarios[i], rd))}
                 for rd, i in keys}
    tasks = [(fn, dict(scenario_index=i, reading=rd, settings=settings,
                       **({"runs": list(c), **extra[(rd, i)]} if path == "master" else {})))
             for rd, i in keys for c in chunks]
    try:
        results = run_tasks(tasks, backend=backend, n_jobs=n_jobs, progress=progress, desc=f"seed000 ({path})")
    except Interrupted as e:
        done = e.partial or [None] * len(tasks)
        e.partial = _assemble(settings, keys, chunks, done, time.perf_counter() - t0)
        raise
    return _assemble(settings, keys, chunks, results, time.perf_counter() - t0)


def _assemble(settings: Settings, keys, chunks, results, wall):
    """The campaign's tables from the task results (None for tasks that did not finish)."""
    rows, eps_rows, examples = [], [], {}
    n = len(chunks)
    for j, (rd, i) in enumerate(keys):
        parts = [(c, res) for c, res in zip(chunks, results[j * n:(j + 1) * n]) if res is not None]
        if not parts:
            continue
        q, r = true_noise(settings.scenarios[i], rd)
        q0, r0 = nominal_noise(settings, q, r)
        q_em, r_em = parts[0][1]["learned"]
        for name in FILTERS:
            for c, res in parts:
                pr = res["per_run"][name]
                for m, run_id in enumerate(c):
                    rows.append({"reading": rd, "scenario": i + 1, "sigma_q2": settings.scenarios[i][0],
                                 "sigma_r2": settings.scenarios[i][1], "q_true": q, "r_true": r,
                                 "q0": q0, "r0": r0, "q_em": q_em, "r_em": r_em,
                                 "filter": name, "run": int(run_id), "eta": pr["eta"][m],
                                 "diverged": bool(pr["diverged"][m]), "anees": pr["anees"][m],
                                 "anis": pr["anis"][m],
                                 **{f"rmse_{x}": pr["rmse"][m, a] for a, x in enumerate(STATES)}})
            w = np.array([len(c) for c, _ in parts], float)
            eps = sum(res["eps_k"][name] * wi for (_, res), wi in zip(parts, w)) / w.sum()
            for k, e in enumerate(eps, start=1):
                eps_rows.append({"reading": rd, "scenario": i + 1, "filter": name, "k": k,
                                 "time": k * settings.T, "eps": e})
        examples[(rd, i + 1)] = parts[0][1]["example"]
    return CampaignResult(pd.DataFrame(rows), pd.DataFrame(eps_rows), examples, wall)


def summary_table(per_run: pd.DataFrame) -> pd.DataFrame:
    """eta (eq 44) per reading, scenario and filter, with the paper's Table 3 beside it.

    eta is the mean over all realisations; ``diverged`` counts the runs flagged, and
    ``(no div.)`` excludes them; ``<filter> / bound`` is eta over the true-Q,R EKF's.

    Parameters
    ----------
    per_run
        The per-realisation table of :func:`run`.
    """
    rows = []
    for (rd, sc), g in per_run.groupby(["reading", "scenario"], sort=True):
        row = {"reading": rd, "scenario": sc, "sigma_q2": g["sigma_q2"].iloc[0],
               "sigma_r2": g["sigma_r2"].iloc[0], "q0": g["q0"].iloc[0], "r0": g["r0"].iloc[0],
               "paper EKF": PAPER_ETA["EKF"][sc - 1], "paper MF-IAE": PAPER_ETA["MF-IAE"][sc - 1]}
        for name in FILTERS:
            f = g[g["filter"] == name]
            row[name] = f["eta"].mean()
            row[f"{name} ANEES"] = f["anees"].mean()
            row[f"{name} diverged"] = int(f["diverged"].sum())
            if f["diverged"].any():
                ok = f[~f["diverged"]]
                row[f"{name} (no div.)"] = ok["eta"].mean() if len(ok) else np.nan
        row["q_em"], row["r_em"] = g["q_em"].iloc[0], g["r_em"].iloc[0]
        for name in FILTERS[:-1]:
            row[f"{name} / bound"] = row[name] / row["EKF true Q,R"]
        rows.append(row)
    return pd.DataFrame(rows)


def _join(values) -> str:
    return ", ".join(f"{v:.2f}" for v in values)


def agreement(table: pd.DataFrame) -> list[str]:
    """Plain sentences on where the table agrees with the paper's Table 3 and where not."""
    lines = []
    for rd, g in table.groupby("reading", sort=False):
        for label, ours, paper in (("EKF", "EKF", "paper EKF"), ("MF-IAE", "MF-IAE", "paper MF-IAE")):
            ratio = g[ours] / g[paper]
            within = ratio.between(0.9, 1.1)
            cells = _join(ratio)
            verdict = ("agrees with the paper within 10 % in every scenario" if within.all() else
                       f"agrees within 10 % in {int(within.sum())} of {len(g)} scenarios")
            lines.append(f"- {rd} reading, {label}: ours / paper = {cells}; {verdict}.")
        bound = g["MF-IAE / bound"]
        true_q = g["sigma_q2" if rd == "eqs" else "sigma_r2"]
        lines.append(f"- {rd} reading: MF-IAE / true-Q,R bound = {_join(bound)} "
                     f"(paper's MF-IAE / our bound: {_join(g['paper MF-IAE'] / g['EKF true Q,R'])}); "
                     f"IAE / bound = {_join(g['IAE / bound'])}; EKF / bound = {_join(g['EKF / bound'])}; "
                     f"EKF with EM-learned Q, R / bound = {_join(g['EKF EM / bound'])} "
                     f"(learned q / true q = {_join(g['q_em'] / true_q)}); SWML (online, beyond the paper) / "
                     f"bound = {', '.join(f'{v:.3f}' for v in g['SWML / bound'])}.")
    return lines


def write_report(per_run, eps, examples, wall, settings: Settings, out_dir, path: str,
                 config: str = "custom", partial: bool = False) -> Path:
    """Tables (CSV, Parquet), figures (PNG), ``settings.toml`` and a markdown summary into
    ``out_dir``; with ``partial`` the summary says the campaign was interrupted.

    Parameters
    ----------
    per_run
        The per-realisation table.
    eps
        eps_k by reading, scenario, filter and time.
    examples
        Example trajectories for Figure 3.
    wall
        Wall time [s].
    settings
        The settings used.
    out_dir
        Output folder.
    path
        The path that ran.
    config
        The configuration's name.
    partial
        The campaign was interrupted.
    """


    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write(out / "settings.toml", lambda p: p.write_text(to_toml(settings, "seed000")))
    atomic_write(out / "per_run.csv", lambda p: per_run.to_csv(p, index=False))
    atomic_write(out / "per_run.parquet", per_run.to_parquet)
    atomic_write(out / "eps_k.csv", lambda p: eps.to_csv(p, index=False))
    table = summary_table(per_run) if len(per_run) else pd.DataFrame()
    atomic_write(out / "table3.csv", lambda p: table.to_csv(p, index=False))
    agg = (per_run.groupby(["reading", "filter"])[["anees", "anis"] + [f"rmse_{x}" for x in STATES]].mean()
           if len(per_run) else pd.DataFrame())
    atomic_write(out / "consistency_rmse.csv", agg.to_csv)
    _figures(eps, examples, settings, out)

    lines = [f"# Seed 000 campaign ({path} path, configuration: {config})", ""]
    if partial:
        lines += ["**PARTIAL RESULTS: the campaign was interrupted; only the tasks that finished "
                  "are in these tables.**", ""]
    lines += [f"{settings.runs} realisations x {len(settings.scenarios)} scenarios x {len(FILTERS)} filters "
              f"x {settings.steps} steps per reading; wall time {wall:.2f} s.", "",
              "Input: the PRBS of seed 000 Figure 2: maximal-length LFSR of order "
              f"{settings.input_order} started from state {settings.input_seed}, {settings.input_bit_time:g} s "
              f"per bit, +/-{settings.input_amplitude:g} N (its first bits 0 0 1 1 1: -0.5 N until 2 s, "
              "then +0.5 N).", ""]
    if len(table):
        cols = ["reading", "scenario", "sigma_q2", "sigma_r2", "paper EKF", "paper MF-IAE", *FILTERS]
        lines += ["## Table 3: eta (eq 44), mean over realisations", "",
                  "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
        for _, row in table.iterrows():
            lines.append("| " + " | ".join(f"{row[c]:.4f}" if isinstance(row[c], float) else str(row[c])
                                           for c in cols) + " |")
        lines += ["", "## Where we agree with the paper, and where not", "", *agreement(table), ""]
        div = {c: int(table[c].sum()) for c in table.columns if c.endswith("diverged")}
        lines += ["Diverged realisations (error not finite or above "
                  f"{settings.divergence_threshold:g}): " + ", ".join(f"{k[:-9]}: {v}" for k, v in div.items()), "",
                  "## Consistency and per-state RMSE (mean over scenarios and realisations)", "",
                  agg.to_markdown(floatfmt=".4f"), ""]
    lines += ["## Settings (the paper gives none of the filter settings)", "",
              "Rerun with `pendulum-cosim experiment seed000 --settings settings.toml` (this folder's file), "
              "or change one with `--set name=value`.", "", "| setting | value |", "|---|---|"]
    lines += [f"| {k} | {v} |" for k, v in asdict(settings).items()]
    lines += ["", "Readings of the noise names:", ""] + [f"- **{k}**: {v}" for k, v in READINGS.items()]
    lines += ["", "Figures: " + ", ".join(sorted(p.name for p in out.glob("figure*.png")))]
    md = out / "summary.md"
    atomic_write(md, lambda p: p.write_text("\n".join(lines) + "\n"))
    return md


def _figures(eps, examples, settings: Settings, out: Path) -> None:

    for rd in sorted({k[0] for k in examples}):
        if (rd, 1) not in examples:
            continue
        ex = examples[(rd, 1)]
        t = np.arange(ex["truth"].shape[0]) * settings.T
        fig, axes = new_figure(4, 1, figsize=(8, 8), sharex=True)
        for a in range(4):
            ax = axes[a, 0]
            ax.plot(t, ex["truth"][:, a], "k-", lw=1.2, label="truth")
            for name, style in (("EKF", "b--"), ("MF-IAE", "r-.")):
                ax.plot(t, ex[f"est {name}"][:, a], style, lw=0.9, label=name)
            ax.set_ylabel(STATES[a])
            ax.grid(alpha=0.3)
        axes[0, 0].legend(fontsize=8)
        axes[-1, 0].set_xlabel("time [s]")
        fig.suptitle(f"Seed 000 Figure 3: scenario 1, realisation 0 ({rd} reading)")
        atomic_write(out / f"figure3_{rd}.png", lambda p, fig=fig: fig.savefig(p, dpi=100, format="png"))
        fig, axes = new_figure(1, 1, figsize=(8, 3.5))
        ax = axes[0, 0]
        for name in FILTERS:
            e = eps[(eps.reading == rd) & (eps.scenario == 1) & (eps["filter"] == name)]
            ax.plot(e["time"], e["eps"], lw=1, label=name)
        ax.set_xlabel("time [s]")
        ax.set_ylabel("eps_k (eq 43)")
        ax.set_yscale("log")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        ax.set_title(f"Seed 000 Figure 4: scenario 1, {settings.runs} realisations ({rd} reading)")
        atomic_write(out / f"figure4_{rd}.png", lambda p, fig=fig: fig.savefig(p, dpi=100, format="png"))


class Seed000(Experiment, register="seed000"):
    """Seed 000 Table 3: EKF, IAE, MF-IAE (and the EM-learned and true-Q,R EKFs) on the
    cart-pole under four noise scenarios (see the module documentation)."""

    description = "seed 000 Table 3: EKF, IAE and MF-IAE on the cart-pole, four noise scenarios"
    configs = CONFIGS

    def run(self, settings, path="fast", backend="processes", n_jobs=None, progress=True):
        """:func:`run`."""
        return run(settings, path=path, backend=backend, n_jobs=n_jobs, progress=progress)

    def write_report(self, result, settings, out_dir, path="fast", config="custom", partial=False):
        """:func:`write_report`."""
        return write_report(*result, settings, out_dir, path, config, partial=partial)

    def summary(self, result, settings, path="fast", config="custom"):
        """Table 3 beside ours, and the agreement in words."""
        table = summary_table(result.per_run)
        cols = ["reading", "scenario", "paper EKF", "paper MF-IAE", *FILTERS]
        return "\n".join([f"Seed 000, Table 3 (eta, eq 44): configuration {config}, {settings.runs} realisations, "
                          f"{path} path, {result.wall:.2f} s",
                          table[cols].to_string(index=False, float_format=lambda v: f"{v:.4f}"), "",
                          *agreement(table)])

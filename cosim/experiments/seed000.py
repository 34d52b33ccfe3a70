"""Seed 000 section 5 (Table 3): EKF, IAE and MF-IAE on the cart-pole (eqs 12-17, the Euler map)
under four noise scenarios and two readings of their names, beside the EM-learned and SWML
EKFs, the EKF given the true noise and the posterior Cramér-Rao bound, with the consistency
tests; the ``fast`` and ``master`` paths give the same numbers (docs/guide/experiments.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from estimators import EKF, IAE, MFIAE, SWML, discretize, em_noise, posterior_crb
from fmu_models import get_model
from fmu_models.errors import ConfigurationError, UnknownNameError
from fmu_models.infra.checks import positive, positive_int

from ..components.sources import PRBS
from . import common, metrics
from .experiment import Experiment
from .settings import CommonSettings, check_consistency, to_toml

SCENARIOS = ((0.2, 0.1), (0.2, 0.2), (0.3, 0.1), (0.3, 0.2))
READINGS = {"eqs": "eqs 24-25: sigma_q^2 is the process variance (Q), sigma_r^2 the measurement variance (R)",
            "prose": "section 5 prose: sigma_r^2 is the process variance, sigma_q^2 the measurement variance"}
#: Table 3 of seed 000 (eta, eq 44).
PAPER_ETA = {"EKF": (4.4782, 5.2441, 4.4426, 4.9982), "MF-IAE": (2.2153, 2.2109, 2.6581, 2.6800)}
#: The filters of the campaign, in the order of its tables.
FILTERS = ("EKF", "IAE", "MF-IAE", "EKF EM", "SWML", "EKF true Q,R")
#: The name of the EKF given the true Q and R, what an adaptive filter tries to reach (not a bound).
TRUE_EKF = "EKF true Q,R"
#: Run index of the training realisation EM learns from (never one of the test runs).
TRAINING_RUN = 2**31 - 1
#: SWML's prior standard deviation of ``ln q`` and ``ln r`` in the campaigns, ``ln 100`` (a
#: factor 100 either way at one standard deviation).
SWML_PRIOR_SD = math.log(100.0)
STATES = ("x", "x_dot", "theta", "theta_dot")
#: The measured states (``y = [x, theta] + v``).
MEASURED = ("x", "theta")
#: The prior of the PCRB (``pcrb_prior``).
PCRB_PRIORS = {"known": "the initial state is known exactly (the truth starts at x0 in every realisation)",
               "P0": "x_0 ~ N(x0, P0 I), the filters' own prior (J_0 = (P0 I)^-1)"}


@dataclass(frozen=True)
class Settings(CommonSettings):
    """Every choice of the campaign, including those the paper leaves open.

    Truth: ``runs`` realisations per scenario of ``duration`` [s], period ``T`` [s], from ``x0``;
    the PRBS of ``input_amplitude`` [N], LFSR ``input_order`` and ``input_seed``,
    ``input_bit_time`` [s] per bit; the ``scenarios`` and ``readings``. Filters start at ``x0``
    with ``P0`` (times I) and the nominal noise ``q0``, ``r0`` (times I), or ``q0_factor`` /
    ``r0_factor`` times the true variance if set. IAE: ``iae_window``, ``iae_adapt`` ("both",
    "Q", "R"), ``iae_form``. MF-IAE: ``mfiae_window``, ``mfiae_gain_q``, ``mfiae_gain_r``,
    ``mfiae_q_mapping`` ("literal", "gain"), ``mfiae_per_channel``. "EKF EM"
    (:func:`estimators.em_noise` on a separate training realisation): ``em_iterations``,
    ``em_tol``. "SWML" (:class:`estimators.SWML`): ``swml_window``, ``swml_every``,
    ``swml_early_every`` (over the first 20 steps), ``swml_prior_sd`` (none: maximum
    likelihood), ``swml_posterior_average``, ``swml_keep_r_nats``, ``swml_max_fall``. ``seed``;
    ``divergence_threshold`` [state units]; ``pcrb_prior`` (:data:`PCRB_PRIORS`); the
    ``confidence`` of the chi-square bands; whiteness at lags 1..``whiteness_lags``; the
    ``*_late`` diagnostics leave out the first ``transient_steps`` steps (not computed unless
    more than ``whiteness_lags`` steps remain)."""

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
    swml_early_every: int = 1
    swml_prior_sd: float | None = SWML_PRIOR_SD
    swml_posterior_average: bool = True
    swml_keep_r_nats: float = 0.0
    swml_max_fall: float = 10.0
    seed: int = 2026
    divergence_threshold: float = 1e3
    pcrb_prior: str = "known"
    confidence: float = 0.95
    whiteness_lags: int = 5
    transient_steps: int = 100

    def __post_init__(self):
        super().__post_init__()
        check_consistency(self, PCRB_PRIORS)
        positive_int(self.transient_steps, "transient_steps", minimum=0)
        for name in ("P0", "q0", "r0", "input_bit_time", "divergence_threshold", "mfiae_gain_q", "mfiae_gain_r"):
            positive(getattr(self, name), name)
        for name in ("q0_factor", "r0_factor", "swml_prior_sd"):
            if getattr(self, name) is not None:
                positive(getattr(self, name), name)
        for name in ("swml_window", "swml_every", "swml_early_every"):
            positive_int(getattr(self, name), name)
        if self.swml_posterior_average and self.swml_prior_sd is None:
            raise ConfigurationError("swml_posterior_average needs a prior: set swml_prior_sd")
        for name, low in (("swml_keep_r_nats", 0), ("swml_max_fall", 1)):
            if not getattr(self, name) >= low:
                raise ConfigurationError(f"{name} must be >= {low}, got {getattr(self, name)}")
        if self.swml_window % self.swml_every:
            raise ConfigurationError(f"swml_window = {self.swml_window} must be a multiple of swml_every = "
                                     f"{self.swml_every}")
        if len(self.x0) != 4:
            raise ConfigurationError(f"x0 must have 4 entries, got {self.x0}")
        if not self.scenarios or any(len(sc) != 2 or min(sc) <= 0 for sc in self.scenarios):
            raise ConfigurationError(f"scenarios must be pairs of positive variances, got {self.scenarios}")
        if not self.readings or not set(self.readings) <= set(READINGS):
            raise UnknownNameError(f"readings must be among {list(READINGS)}, got {self.readings}")

    @property
    def has_late(self) -> bool:
        """Whether more than ``whiteness_lags`` steps follow ``transient_steps``."""
        return self.transient_steps + self.whiteness_lags < self.steps


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


def learn_noise(system, s: Settings, scenario_index: int, q: float, r: float, shared: dict | None = None
                ) -> tuple[float, float]:
    """(q, r) learned by EM from the nominal values on the training realisation of scenario
    ``scenario_index`` (``system``: the discrete model; ``s``, ``q``, ``r``: the settings and the
    true variances; ``shared``: keeps the training realisation between calls)."""
    shared = {} if shared is None else shared
    if "training" not in shared:
        shared["training"] = simulate_truth(s, q, r, common.seed_pairs(s, scenario_index, [TRAINING_RUN]))
    _X, Y, u = shared["training"]
    f = EKF(system, np.array(s.x0), s.P0, *nominal_noise(s, q, r))
    res = em_noise(f, u[:-1, None], Y[0, 1:], n_iter=s.em_iterations, tol=s.em_tol, structure="scalar")
    return float(res.Q[0, 0]), float(res.R[0, 0])


def make_filters(system, s: Settings, q: float, r: float, learned=None) -> dict:
    """The constructors of :data:`FILTERS` by name (``system``, ``s``, ``q``, ``r`` as
    :func:`learn_noise`); "EKF EM" only with EM's ``learned`` (q, r)."""
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
            "SWML": lambda: SWML(system, x0, s.P0, q0, r0, window=s.swml_window, every=s.swml_every,
                                 early_every=s.swml_early_every, prior_sd=s.swml_prior_sd,
                                 posterior_average=s.swml_posterior_average, keep_r_nats=s.swml_keep_r_nats,
                                 max_fall=s.swml_max_fall),
            "EKF true Q,R": lambda: EKF(system, x0, s.P0, q, r)}


def figure2_prbs(s: Settings):
    """The input source of the settings ``s``: Figure 2's PRBS (by default the LFSR of order 7,
    taps 7, 6, from state 28, a bit per second; its first bits ``0 0 1 1 1``: -0.5 N until 2 s)."""
    return PRBS("force", s.T, s.input_amplitude, s.input_bit_time, s.input_order, s.input_seed)


def simulate_truth(s: Settings, q: float, r: float, seeds: list[tuple[int, int]]):
    """Truth ``X`` (runs, steps+1, 4), measurements ``Y`` (runs, steps+1, 2) and the input
    sequence of the settings ``s`` with the true variances ``q``, ``r``, one realisation per
    (process, measurement) seed pair of ``seeds``: the numbers the master path's components draw."""
    src = figure2_prbs(s)
    src.reset(0.0)
    u = np.array([src.output(k * s.T, None)[0] for k in range(s.steps + 1)])
    X, Y = common.simulate_truth(get_model("cartpole"), s.x0, u[:, None], s.T, q, MEASURED, np.sqrt(r), seeds)
    return X, Y, u


def scenario_bound(s: Settings, X: np.ndarray, u: np.ndarray, q: float, r: float) -> np.ndarray:
    """The PCRB on each state's mean-square error at k = 0..N, shape (N+1, 4), over the
    realisations ``X`` (runs, N+1, 4) with inputs ``u`` (N+1,), under ``s.pcrb_prior``
    (``s``, ``q``, ``r`` as :func:`simulate_truth`)."""
    return posterior_crb(_system(s.T), X, u[:-1, None], q, r, None if s.pcrb_prior == "known" else s.P0).mse


def bound_task(scenario_index: int, reading: str, settings: Settings) -> np.ndarray:
    """:func:`scenario_bound` over all realisations of one scenario and reading (the master
    path's PCRB: the fast path's truth of the same seeds); ``scenario_index``, ``reading``
    and ``settings`` as :func:`fast_task`."""
    q, r = true_noise(settings.scenarios[scenario_index], reading)
    X, _, u = simulate_truth(settings, q, r, common.seed_pairs(settings, scenario_index))
    return scenario_bound(settings, X, u, q, r)


class _FilterRun(NamedTuple):
    """One filter over a task's realisations: errors (runs, N+1, 4), NEES and NIS (runs, N),
    the failed realisations (runs,), the whiteness rows (after the transient: None, not tested)."""

    errors: np.ndarray
    nees: np.ndarray
    nis: np.ndarray
    failed: np.ndarray
    whiteness: dict
    whiteness_late: dict | None


def _fast_filter(make, X: np.ndarray, Y: np.ndarray, u: np.ndarray, s: Settings) -> _FilterRun:
    """One filter batched over the realisations ``X``, ``Y`` with inputs ``u``."""
    res = common.batch_run(make, X, Y, u[:, None])
    L = s.transient_steps
    late = (metrics.whiteness_row(res.innovation[:, L:], res.S[:, L:], s.confidence, s.whiteness_lags)
            if s.has_late else None)
    return _FilterRun(res.x - X, res.nees, res.nis, res.failed,
                      metrics.whiteness_row(res.innovation, res.S, s.confidence, s.whiteness_lags), late)


def _summarise(filters: dict, s: Settings, example: dict, learned) -> dict:
    """A task's result from its :class:`_FilterRun` by filter (errors over k = 1..N), the
    ``example`` realisation and EM's ``learned`` (q, r)."""
    out = {"eps_k": {}, "per_run": {}, "steps": {}, "example": example, "learned": learned,
           "whiteness": {n: f.whiteness for n, f in filters.items()},
           "whiteness_late": {n: f.whiteness_late for n, f in filters.items()}}
    for name, f in filters.items():
        e = f.errors[:, 1:]
        div = metrics.diverged(e, s.divergence_threshold) | f.failed
        with np.errstate(invalid="ignore", over="ignore"):
            out["eps_k"][name] = metrics.eps_k(e)
            out["per_run"][name] = {"eta": metrics.eta_per_run(e), "diverged": div,
                                    "rmse": np.sqrt(np.mean(e**2, axis=1)),
                                    "anees": f.nees.mean(axis=1), "anis": f.nis.mean(axis=1)}
            out["steps"][name] = {"nees": f.nees, "nis": f.nis, "mse": np.mean(e**2, axis=0)}
    return out


def fast_task(scenario_index: int, reading: str, settings: Settings, runs=None, bound=None,
              shared: dict | None = None) -> dict:
    """The realisations ``runs`` (default all) of scenario ``scenario_index`` (0-based) under
    the ``reading`` of the noise names and the campaign's ``settings``, every filter batched in
    native calls, with their PCRB (``bound``, :func:`scenario_bound`; default: computed here)
    and the innovations' whiteness. ``shared``: a dict kept between calls that differ only in
    the nominal noise (the sweep's cells), where the truth, the training realisation and the
    EKF given the true Q and R are computed once (default: nothing kept)."""
    s = settings
    q, r = true_noise(s.scenarios[scenario_index], reading)
    shared = {} if shared is None else shared
    if "truth" not in shared:
        shared["truth"] = simulate_truth(s, q, r, common.seed_pairs(s, scenario_index, runs))
    X, Y, u = shared["truth"]
    system = _system(s.T)
    learned = learn_noise(system, s, scenario_index, q, r, shared)
    filters = {name: shared[name] if name == TRUE_EKF and name in shared else _fast_filter(make, X, Y, u, s)
               for name, make in make_filters(system, s, q, r, learned).items()}
    shared[TRUE_EKF] = filters[TRUE_EKF]
    example = {"truth": X[0], "y": Y[0], **{f"est {n}": X[0] + f.errors[0] for n, f in filters.items()}}
    out = _summarise(filters, s, example, learned)
    out["bound"] = scenario_bound(s, X, u, q, r) if bound is None else bound
    return out


def master_task(scenario_index: int, reading: str, settings: Settings, runs=None, fmu_dir=None,
                learned=None) -> dict:
    """:func:`fast_task` (``scenario_index``, ``reading``, ``settings``, ``runs``) through the
    master with the plant FMU built in ``fmu_dir`` (default a temporary folder); ``learned``:
    the scenario's EM-learned (q, r), if known."""
    s = settings
    q, r = true_noise(s.scenarios[scenario_index], reading)
    system = _system(s.T)
    learned = learn_noise(system, s, scenario_index, q, r) if learned is None else learned
    makers = make_filters(system, s, q, r, learned)
    X, est, nees, nis = common.master_runs(get_model("cartpole"), s.x0, figure2_prbs(s), q, MEASURED, np.sqrt(r),
                                           makers, s.T, s.duration, common.seed_pairs(s, scenario_index, runs),
                                           fmu_dir)
    filters = {n: _FilterRun(est[n] - X, nees[n], nis[n], np.zeros(len(X), dtype=bool), metrics.no_whiteness(),
                             None) for n in makers}
    return _summarise(filters, s, {"truth": X[0], **{f"est {n}": est[n][0] for n in makers}}, learned)


class CampaignResult(NamedTuple):
    """What :func:`run` returns, by reading and scenario: ``per_run`` (a row per filter and
    realisation), ``eps`` (per filter and step: eps_k (eq 43), average NEES and NIS with their
    bands, each state's mean-square error), Figure 3's ``examples``, the ``wall`` time [s],
    ``consistency`` (a row per filter and the PCRB's: RMSE, RMSE / PCRB, the tests and
    verdicts) and ``bound`` (the PCRB per step)."""

    per_run: pd.DataFrame
    eps: pd.DataFrame
    examples: dict
    wall: float
    consistency: pd.DataFrame
    bound: pd.DataFrame


#: Realisations per task on the master path.
MASTER_CHUNK = 50


def run(settings: Settings = Settings(), path: str = "fast", readings=None,
        backend: str = "processes", n_jobs=None, progress: bool = True) -> CampaignResult:
    """Run the campaign of ``readings`` (default the settings'); returns a :class:`CampaignResult`
    (interrupted: ``partial`` of the :class:`~fmu_models.errors.Interrupted` raised holds the
    same for the finished tasks). ``settings``, ``path``, ``backend``, ``n_jobs``, ``progress``
    as :meth:`Experiment.run <cosim.experiments.experiment.Experiment.run>`."""
    if path not in ("fast", "master"):
        raise UnknownNameError(f"path must be 'fast' or 'master', got {path!r}")
    readings = tuple(settings.readings if readings is None else readings)
    keys = [(rd, i) for rd in readings for i in range(len(settings.scenarios))]
    if path == "fast":
        chunks = [np.arange(settings.runs)]
        tasks = [(fast_task, dict(scenario_index=i, reading=rd, settings=settings)) for rd, i in keys]
    else:
        chunks, tasks = _master_tasks(settings, keys)
    return common.run_campaign(tasks, lambda results, wall: _assemble(settings, keys, chunks, results, wall),
                               f"seed000 ({path})", backend, n_jobs, progress)


def _master_tasks(s: Settings, keys: list) -> tuple[list, list]:
    """The master path's chunks and tasks: per scenario, a task per slice of at most
    :data:`MASTER_CHUNK` realisations (EM learned once per scenario), then a PCRB task."""
    n_chunks = max(2, -(-s.runs // MASTER_CHUNK))
    chunks = [c for c in np.array_split(np.arange(s.runs), min(s.runs, n_chunks)) if len(c)]
    system = _system(s.T)
    learned = {(rd, i): learn_noise(system, s, i, *true_noise(s.scenarios[i], rd)) for rd, i in keys}
    tasks = [(master_task, dict(scenario_index=i, reading=rd, settings=s, runs=list(c), learned=learned[(rd, i)]))
             for rd, i in keys for c in chunks]
    return chunks, tasks + [(bound_task, dict(scenario_index=i, reading=rd, settings=s)) for rd, i in keys]


def _assemble(settings: Settings, keys, chunks, results, wall) -> CampaignResult:
    """The campaign's tables from the filter tasks' results by key and chunk (None: not
    finished), then (master path) a PCRB task's per key."""
    n = len(chunks)
    tables, examples = ([], [], [], []), {}
    for j, (rd, i) in enumerate(keys):
        parts = [(c, res) for c, res in zip(chunks, results[j * n:(j + 1) * n]) if res is not None]
        if not parts:
            continue
        bound = parts[0][1].get("bound")
        if bound is None and len(results) > len(keys) * n:
            bound = results[len(keys) * n + j]
        for table, rows in zip(tables, _scenario_tables(settings, rd, i, parts, bound, n == 1)):
            table.extend(rows)
        examples[(rd, i + 1)] = parts[0][1]["example"]
    per_run, eps, cons, bounds = tables
    frames = [pd.concat(t, ignore_index=True) if t else pd.DataFrame() for t in (eps, bounds)]
    return CampaignResult(pd.DataFrame(per_run), frames[0], examples, wall, pd.DataFrame(cons), frames[1])


def _scenario_tables(s: Settings, rd: str, i: int, parts: list, bound, whole: bool) -> tuple[list, list, list, list]:
    """One reading and scenario's per-run and consistency rows, eps_k and bound frames from
    ``parts`` ((runs, result) of its tasks; ``whole``: one task ran all, its whiteness holds)."""
    q, r = true_noise(s.scenarios[i], rd)
    (q0, r0), (q_em, r_em) = nominal_noise(s, q, r), parts[0][1]["learned"]
    ident = {"reading": rd, "scenario": i + 1}
    head = {**ident, "sigma_q2": s.scenarios[i][0], "sigma_r2": s.scenarios[i][1], "q_true": q, "r_true": r,
            "q0": q0, "r0": r0, "q_em": q_em, "r_em": r_em}
    complete = sum(len(c) for c, _ in parts) == s.runs
    per_run, cons, eps, bounds = [], [], [], []
    for name in FILTERS:
        rows, row, frame = _filter_tables(s, head, ident, name, parts, bound if complete else None, whole)
        per_run += rows
        cons.append(row)
        eps.append(frame)
    if bound is not None:
        cons.append(common.pcrb_row(ident, bound, s.runs, STATES))
        bounds.append(_step_frame(ident, np.arange(s.steps + 1), s, bound))
    return per_run, eps, cons, bounds


def _step_frame(ident: dict, k: np.ndarray, s: Settings, mse: np.ndarray, **columns) -> pd.DataFrame:
    """A frame per step ``k``: ``ident``, ``k``, ``time``, ``columns`` and each state's ``mse_<state>``."""
    return pd.DataFrame({**ident, "k": k, "time": k * s.T, **columns,
                         **{f"mse_{x}": mse[:, a] for a, x in enumerate(STATES)}})


def _filter_tables(s: Settings, head: dict, ident: dict, name: str, parts: list, bound, whole: bool):
    """One filter's per-run rows, consistency row and eps_k frame (``bound``: None if unknown)."""
    runs = np.concatenate([c for c, _ in parts])
    pr = {k: np.concatenate([res["per_run"][name][k] for _, res in parts])
          for k in ("eta", "diverged", "anees", "anis", "rmse")}
    rows = [{**head, "filter": name, "run": int(run_id), "eta": pr["eta"][m], "diverged": bool(pr["diverged"][m]),
             "anees": pr["anees"][m], "anis": pr["anis"][m],
             **{f"rmse_{x}": pr["rmse"][m, a] for a, x in enumerate(STATES)}} for m, run_id in enumerate(runs)]
    w = np.array([len(c) for c, _ in parts], float)
    eps = sum(res["eps_k"][name] * wi for (_, res), wi in zip(parts, w)) / w.sum()
    mse = sum(res["steps"][name]["mse"] * wi for (_, res), wi in zip(parts, w)) / w.sum()
    nees, nis = (np.concatenate([res["steps"][name][k] for _, res in parts]) for k in ("nees", "nis"))
    first = parts[0][1]
    tests, per_step = metrics.consistency_row(nees, nis, 4, 2, s.confidence,
                                              first["whiteness"][name] if whole else None)
    late = (metrics.after_transient(nees, nis, mse, bound[1:], 2, s.transient_steps,
                                    first["whiteness_late"][name] if whole else None, s.confidence)
            if bound is not None and s.has_late else {})
    row = {**ident, "filter": name, "eta": float(pr["eta"].mean()), "diverged": int(pr["diverged"].sum()),
           **common.error_columns(pr["rmse"], None if bound is None else bound[1:], STATES), **tests, **late}
    frame = _step_frame({**ident, "filter": name}, np.arange(1, s.steps + 1), s, mse, eps=eps, **per_step)
    return rows, row, frame


def summary_table(per_run: pd.DataFrame) -> pd.DataFrame:
    """eta (eq 44, mean over the realisations) per reading, scenario and filter of ``per_run``
    (the per-realisation table of :func:`run`) beside the paper's Table 3; ``diverged``
    counts the flagged runs, ``(no div.)`` leaves them out, ``<filter> / EKF true Q,R``: eta
    over that of the EKF given the true Q and R."""
    rows = []
    for (rd, sc), g in per_run.groupby(["reading", "scenario"], sort=True):
        row = {"reading": rd, "scenario": sc, **{c: g[c].iloc[0] for c in ("sigma_q2", "sigma_r2", "q0", "r0")},
               "paper EKF": PAPER_ETA["EKF"][sc - 1], "paper MF-IAE": PAPER_ETA["MF-IAE"][sc - 1]}
        for name in FILTERS:
            f = g[g["filter"] == name]
            row[name] = f["eta"].mean()
            row[f"{name} ANEES"] = f["anees"].mean()
            row[f"{name} diverged"] = int(f["diverged"].sum())
            if f["diverged"].any():
                ok = f[~f["diverged"]]
                row[f"{name} (no div.)"] = ok["eta"].mean() if len(ok) else np.nan
        row.update({c: g[c].iloc[0] for c in ("q_em", "r_em")})
        for name in FILTERS[:-1]:
            row[f"{name} / {TRUE_EKF}"] = row[name] / row[TRUE_EKF]
        rows.append(row)
    return pd.DataFrame(rows)


def _join(values) -> str:
    return ", ".join(f"{v:.2f}" for v in values)


def _span(values, fmt: str) -> str:
    """``min-max`` of ``values``, each in the format ``fmt``."""
    return f"{values.min():{fmt}}-{values.max():{fmt}}"


def agreement(table: pd.DataFrame) -> list[str]:
    """Sentences on where the ``table`` of :func:`summary_table` agrees with the paper's Table 3."""
    lines = []
    for rd, g in table.groupby("reading", sort=False):
        for name in ("EKF", "MF-IAE"):
            ratio = g[name] / g[f"paper {name}"]
            within = ratio.between(0.9, 1.1)
            verdict = ("agrees with the paper within 10 % in every scenario" if within.all() else
                       f"agrees within 10 % in {int(within.sum())} of {len(g)} scenarios")
            lines.append(f"- {rd} reading, {name}: ours / paper = {_join(ratio)}; {verdict}.")
        vs = f" / {TRUE_EKF}"
        true_q = g["sigma_q2" if rd == "eqs" else "sigma_r2"]
        lines.append(f"- {rd} reading, eta over the EKF given the true Q and R: MF-IAE {_join(g['MF-IAE' + vs])} "
                     f"(the paper's MF-IAE: {_join(g['paper MF-IAE'] / g[TRUE_EKF])}); IAE {_join(g['IAE' + vs])}; "
                     f"EKF {_join(g['EKF' + vs])}; EKF with EM-learned Q, R {_join(g['EKF EM' + vs])} "
                     f"(learned q / true q = {_join(g['q_em'] / true_q)}); SWML (online, beyond the paper) "
                     f"{', '.join(f'{v:.3f}' for v in g['SWML' + vs])}.")
    return lines


def pcrb_table(consistency: pd.DataFrame) -> pd.DataFrame:
    """Each filter's RMSE / PCRB from the ``consistency`` table of :class:`CampaignResult`: a
    row per reading and filter, a column per scenario and state (``s<scenario> <state>``),
    and the worst."""
    c = consistency[consistency["filter"] != "PCRB"]
    rows = []
    for (rd, name), g in c.groupby(["reading", "filter"], sort=False):
        row = {"reading": rd, "filter": name}
        for _, r in g.sort_values("scenario").iterrows():
            row.update({f"s{r['scenario']} {x}": r[f"pcrb_ratio_{x}"] for x in STATES})
        row["worst"] = float(g["pcrb_ratio_max"].max())
        rows.append(row)
    return pd.DataFrame(rows)


def limit_sentences(consistency: pd.DataFrame) -> list[str]:
    """Sentences from the ``consistency`` table of :class:`CampaignResult`: how far the EKF
    given the true noise, SWML, MF-IAE and the EKF are from the PCRB, per reading and state
    (range over the scenarios)."""
    lines = []
    for rd, g in consistency.groupby("reading", sort=False):
        for name in (TRUE_EKF, "SWML", "MF-IAE", "EKF"):
            f = g[g["filter"] == name]
            if not len(f) or f["pcrb_ratio_max"].isna().all():
                continue
            per_state = "; ".join(f"{x} {_span(f[f'pcrb_ratio_{x}'], '.3f')}" for x in STATES)
            lines.append(f"- {rd} reading, {name}: RMSE / sqrt(PCRB) over the {len(f)} scenarios: {per_state}.")
    return lines


def transient_sentences(consistency: pd.DataFrame, settings: Settings) -> list[str]:
    """The diagnostic beside the verdicts (not the rule), from the ``consistency`` table of
    :class:`CampaignResult`: each filter's worst RMSE / PCRB, average NEES and verdict after
    the first ``settings.transient_steps`` steps."""
    c = consistency[consistency["filter"] != "PCRB"]
    if "consistent_late" not in c or c["consistent_late"].isna().all():
        return [f"(The diagnostic after the first {settings.transient_steps} steps is not computed: the record has "
                f"{settings.steps} steps.)", ""] if not settings.has_late else []
    lines = [f"Diagnostic, not the rule: the same over the steps after the first {settings.transient_steps} "
             f"({settings.transient_steps * settings.T:g} s), where an adaptive filter's start-up no longer "
             "counts:", ""]
    for (rd, name), g in c.groupby(["reading", "filter"], sort=False):
        lines.append(f"- {rd} reading, {name}: worst state's RMSE / PCRB {_span(g['pcrb_ratio_max_late'], '.3f')} "
                     f"(all steps: {_span(g['pcrb_ratio_max'], '.3f')}); average NEES {_span(g['anees_late'], '.3g')} "
                     f"(all steps: {_span(g['anees'], '.3g')}); consistent in "
                     f"{int(g['consistent_late'].astype(bool).sum())} of {len(g)} scenarios (all steps: "
                     f"{int(g['consistent'].astype(bool).sum())}).")
    return lines + [""]


def write_report(result: CampaignResult, settings: Settings, out_dir, path: str = "fast",
                 config: str = "custom", partial: bool = False) -> Path:
    """Tables, figures, ``settings.toml`` and ``summary.md`` into ``out_dir``; returns
    ``summary.md`` (``result`` of :func:`run`; ``settings``, ``path``, ``config``, ``partial`` as
    :meth:`Experiment.write_report <cosim.experiments.experiment.Experiment.write_report>`)."""
    per_run, eps, examples, wall, cons, bound = result
    table = summary_table(per_run) if len(per_run) else pd.DataFrame()
    out = common.report_folder(out_dir, to_toml(settings, "seed000"),
                               {"per_run.csv": per_run, "per_run.parquet": per_run, "eps_k.csv": eps,
                                "consistency.csv": cons, "pcrb.csv": bound, "table3.csv": table})
    _figures(eps, examples, settings, out)
    _limit_figures(eps, bound, settings, out)
    lines = [f"# Seed 000 campaign ({path} path, configuration: {config})", "", *_regime(settings, config, wall)]
    if len(table):
        lines += _table3_section(table, settings)
    if len(cons):
        lines += [*_limit_section(cons, settings), *common.consistency_section(
            cons, ["reading", "scenario"], settings, path, transient_sentences(cons, settings))]
    lines += ["## Settings (the paper gives none of the filter settings)", "",
              "Rerun with `pendulum-cosim experiment seed000 --settings settings.toml` (this folder's file), "
              "or change one with `--set name=value`.", "", *common.settings_table(settings), "",
              "Readings of the noise names:", "", *[f"- **{k}**: {v}" for k, v in READINGS.items()], "",
              "Files: per_run.csv|parquet (every realisation), eps_k.csv (per step: eps_k, average NEES and NIS "
              "with their bands, mean-square errors), consistency.csv (per scenario and filter: RMSE, RMSE / PCRB, "
              "the tests), pcrb.csv (the bound per step), table3.csv.", "",
              "Figures: " + ", ".join(sorted(p.name for p in out.glob("figure*.png")))]
    return common.write_summary(out, lines, partial)


def _regime(settings: Settings, config: str, wall: float) -> list[str]:
    """The report's lines on the regime: the filters' start, the size of the campaign, the input."""
    s = settings
    regime = (f"filters from Q0 = {s.q0:g} I, R0 = {s.r0:g} I" if s.q0_factor is None
              else f"filters from Q0 = {s.q0_factor:g} q I, R0 = {s.r0_factor:g} r I")
    return [f"Regime: configuration {config} ({regime}, P0 = {s.P0:g} I, readings {', '.join(s.readings)}); "
            f"{s.runs} realisations x {len(s.scenarios)} scenarios x {len(FILTERS)} filters x {s.steps} steps per "
            f"reading; wall time {wall:.2f} s.", "",
            f"Input: the PRBS of seed 000 Figure 2: maximal-length LFSR of order {s.input_order} started from state "
            f"{s.input_seed}, {s.input_bit_time:g} s per bit, +/-{s.input_amplitude:g} N (its first bits 0 0 1 1 1: "
            "-0.5 N until 2 s, then +0.5 N).", ""]


def _table3_section(table: pd.DataFrame, settings: Settings) -> list[str]:
    """The report's Table 3 beside the paper's, the agreement in words and the divergences."""
    cols = ["reading", "scenario", "sigma_q2", "sigma_r2", "paper EKF", "paper MF-IAE", *FILTERS]
    div = {c: int(table[c].sum()) for c in table.columns if c.endswith("diverged")}
    return ["## Table 3: eta (eq 44), mean over realisations", "",
            *common.markdown_table(cols, ([f"{row[c]:.4f}" if isinstance(row[c], float) else str(row[c])
                                           for c in cols] for _, row in table.iterrows())),
            "", "## Where we agree with the paper, and where not", "", *agreement(table), "",
            f"Diverged realisations (error not finite or above {settings.divergence_threshold:g}): "
            + ", ".join(f"{k[:-9]}: {v}" for k, v in div.items()), ""]


def _limit_section(cons: pd.DataFrame, settings: Settings) -> list[str]:
    """The report's section on the PCRB: the bound per state and every filter's RMSE over it."""
    pc = cons[cons["filter"] == "PCRB"]
    lines = ["## How far from the best possible: RMSE per state over the posterior Cramér-Rao bound", "",
             "The PCRB (Tichavský, Muravchik and Nehorai 1998) is the lowest mean-square error any estimator can "
             f"have on these realisations ({settings.runs} of them, Jacobians exact, expectations over the same "
             f"truth the filters ran on; prior: {PCRB_PRIORS[settings.pcrb_prior]}). Each entry is a filter's "
             "RMSE over the realisations and the steps 1..K divided by the root of the bound's mean over the same "
             "steps (1.000 is the best possible; the EKF given the true Q and R is a filter, not the limit).", ""]
    if len(pc):
        lines += ["Root of the bound (mean over the steps): " + "; ".join(
            f"{r['reading']} scenario {r['scenario']}: " + ", ".join(f"{x} {r[f'rmse_{x}']:.4g}" for x in STATES)
            for _, r in pc.iterrows()), ""]
    tab = pcrb_table(cons)
    if len(tab):
        lines += [tab.to_markdown(index=False, floatfmt=".3f"), "", _scatter_sentence(cons, settings.runs), "",
                  *limit_sentences(cons), ""]
    return lines


def _scatter_sentence(cons: pd.DataFrame, runs: int) -> str:
    """The largest Monte Carlo standard error of a ratio of a filter within 2x of the PCRB."""
    near = cons[(cons["filter"] != "PCRB") & (cons["pcrb_ratio_max"] < 2)]
    se = near[[c for c in near.columns if c.startswith("pcrb_ratio_se_")]].to_numpy(float)
    if not np.isfinite(se).any():
        return ""
    return (f"Each ratio is itself a Monte Carlo estimate over the {runs} realisations: its standard error (from "
            f"the spread of the realisations' mean-square errors; consistency.csv, pcrb_ratio_se_*) is at most "
            f"{np.nanmax(se):.3f} for the filters within 2x of the bound, so a ratio within about two standard "
            "errors of 1 is at the limit, and one slightly below 1 is scatter, not an estimator beating the bound.")


def _limit_figures(eps: pd.DataFrame, bound: pd.DataFrame, settings: Settings, out: Path) -> None:
    """NEES and NIS over time with their bands, and RMSE against the PCRB (scenario 1)."""
    if not len(eps):
        return
    for rd in sorted(set(eps["reading"])):
        e1 = eps[(eps.reading == rd) & (eps.scenario == eps.scenario.min())]
        sc = int(e1["scenario"].iloc[0])
        for stat, label, ny in (("anees", "average NEES", 4), ("anis", "average NIS", 2)):
            fig, ((ax,),) = common.new_figure(1, 1, figsize=(8, 4))
            first = e1[e1["filter"] == FILTERS[0]]
            ax.fill_between(first["time"], first[f"{stat[1:]}_lo"], first[f"{stat[1:]}_hi"], color="0.85",
                            label=f"{settings.confidence:.0%} band ({settings.runs} runs)")
            for name in FILTERS:
                f = e1[e1["filter"] == name]
                ax.plot(f["time"], f[stat], lw=0.9, label=name)
            ax.axhline(ny, color="k", lw=0.6, ls=":")
            common.style_axes(ax, "time [s]", f"{label} over {settings.runs} runs",
                              f"Seed 000: {label} with its chi-square band, scenario {sc} ({rd} reading)", True, 7, 2)
            common.save_figure(fig, out / f"figure_{stat[1:]}_{rd}.png")
        b = bound[(bound.reading == rd) & (bound.scenario == sc)] if len(bound) else bound
        fig, axes = common.new_figure(4, 1, figsize=(8, 9), sharex=True)
        for ax, x in zip(axes[:, 0], STATES):
            for name in ("EKF", "MF-IAE", "SWML", TRUE_EKF):
                f = e1[e1["filter"] == name]
                ax.plot(f["time"], np.sqrt(f[f"mse_{x}"]), lw=0.9, label=name)
            if len(b):
                ax.plot(b["time"].iloc[1:], np.sqrt(b[f"mse_{x}"].iloc[1:]), "k-", lw=1.4, label="sqrt(PCRB)")
            common.style_axes(ax, ylabel=f"RMSE {x}", log=True)
        axes[0, 0].legend(fontsize=7, ncol=3)
        axes[-1, 0].set_xlabel("time [s]")
        fig.suptitle(f"Seed 000: RMSE over {settings.runs} runs against the PCRB, scenario {sc} ({rd} reading)")
        common.save_figure(fig, out / f"figure_rmse_pcrb_{rd}.png")


def _figures(eps, examples, settings: Settings, out: Path) -> None:
    """Figures 3 (scenario 1, realisation 0: truth and the EKF's and MF-IAE's estimates) and
    4 (scenario 1: eps_k of every filter) of the paper, one per reading."""
    for rd in sorted(rd for rd, sc in examples if sc == 1):
        ex = examples[(rd, 1)]
        t = np.arange(ex["truth"].shape[0]) * settings.T
        fig, axes = common.new_figure(4, 1, figsize=(8, 8), sharex=True)
        for a, ax in enumerate(axes[:, 0]):
            ax.plot(t, ex["truth"][:, a], "k-", lw=1.2, label="truth")
            for name, style in (("EKF", "b--"), ("MF-IAE", "r-.")):
                ax.plot(t, ex[f"est {name}"][:, a], style, lw=0.9, label=name)
            common.style_axes(ax, ylabel=STATES[a])
        axes[0, 0].legend(fontsize=8)
        axes[-1, 0].set_xlabel("time [s]")
        fig.suptitle(f"Seed 000 Figure 3: scenario 1, realisation 0 ({rd} reading)")
        common.save_figure(fig, out / f"figure3_{rd}.png")
        fig, axes = common.new_figure(1, 1, figsize=(8, 3.5))
        for name in FILTERS:
            e = eps[(eps.reading == rd) & (eps.scenario == 1) & (eps["filter"] == name)]
            axes[0, 0].plot(e["time"], e["eps"], lw=1, label=name)
        common.style_axes(axes[0, 0], "time [s]", "eps_k (eq 43)",
                          f"Seed 000 Figure 4: scenario 1, {settings.runs} realisations ({rd} reading)", True, 8)
        common.save_figure(fig, out / f"figure4_{rd}.png")


class Seed000(Experiment, register="seed000"):
    """Seed 000 Table 3: EKF, IAE, MF-IAE (and the EM-learned and true-Q,R EKFs) on the
    cart-pole under four noise scenarios (see the module documentation)."""

    description = "seed 000 Table 3: EKF, IAE and MF-IAE on the cart-pole, four noise scenarios"
    configs = CONFIGS

    def run(self, settings, path="fast", backend="processes", n_jobs=None, progress=True):
        return run(settings, path=path, backend=backend, n_jobs=n_jobs, progress=progress)

    def write_report(self, result, settings, out_dir, path="fast", config="custom", partial=False):
        return write_report(result, settings, out_dir, path, config, partial=partial)

    def summary(self, result, settings, path="fast", config="custom"):
        table = summary_table(result.per_run)
        cols = ["reading", "scenario", "paper EKF", "paper MF-IAE", *FILTERS]
        cons = result.consistency
        verdicts = [f"- {r['reading']} scenario {r['scenario']}, {r['filter']}: "
                    f"{'consistent' if r['consistent'] else 'not consistent'} (avg NEES {r['anees']:.3g})"
                    for _, r in cons[cons["filter"] != "PCRB"].iterrows()]
        return "\n".join([f"Seed 000, Table 3 (eta, eq 44): configuration {config}, {settings.runs} realisations, "
                          f"{path} path, {result.wall:.2f} s",
                          table[cols].to_string(index=False, float_format=lambda v: f"{v:.4f}"), "",
                          *agreement(table), "", "RMSE per state / sqrt(PCRB):", *limit_sentences(cons), "",
                          f"Consistency at {settings.confidence:.0%} (see summary.md for the rule):", *verdicts])

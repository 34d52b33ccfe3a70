"""Seed 002: the inertia-wheel pendulum balanced by LQR on the estimate of an EKF (augmented
with the gyro offset, :func:`estimators.augment_rate_bias`) fed by the sensor chain of
:mod:`cosim.components.imu`, under seed 002's two noise settings (``CASES``); ``master`` steps
the plant FMU, ``fast`` the same CasADi model (docs/guide/experiments.md).
"""
from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar, NamedTuple

import numpy as np
import pandas as pd

from estimators import EKF, augment_rate_bias, discretize
from fmu_models import build_fmu, get_model

from ..components.control import LQRController
from ..components.estimation import EstimatorComponent
from ..components.imu import Accelerometer, Encoder, Gyroscope, TiltFusion
from ..components.plant_model import ModelComponent
from ..core.master import Cosimulation
from ..fmi.fmu_component import FMUComponent
from . import common
from .campaign import realisation_seeds
from .experiment import Experiment
from .settings import CommonSettings, to_toml

CASES = {"Q = R = 0.01": (0.01, 0.01), "Q = 0.01, R = 0.1": (0.01, 0.1)}
STATES = ("alpha", "alpha_dot", "phi_dot")


@dataclass(frozen=True)
class Settings(CommonSettings):
    """Choices of the seed 002 reproduction.

    Plant: RK4 with ``substeps`` internal steps per ``T`` [s], ``alpha0`` [rad] initial
    tilt, ``duration`` [s]. Sensors (all at ``T``): accelerometer at ``r_acc`` [m] with
    noise ``acc_std`` [m/s^2]; gyroscope noise ``gyro_std`` [rad/s] and offset
    ``gyro_bias`` [rad/s]; encoder ``counts_per_rev`` and ``encoder_offset`` [rad/s].
    Fusion KF: ``fusion_q_angle``, ``fusion_q_bias``, ``fusion_r``. EKF: initial estimate
    zero, ``P0`` (times I). LQR: weights ``lqr_q`` (diagonal) and ``lqr_r``, current
    limit ``i_max`` [A]. ``runs`` realisations; ``seed``; the loop counts as balanced if
    ``|alpha|`` stays below ``balanced_within`` [rad] over the second half.
    """

    runs: int = 10
    duration: float = 10.0
    T: float = 0.01
    substeps: int = 10
    alpha0: float = 0.1
    r_acc: float = 0.08
    acc_std: float = 0.05
    gyro_std: float = 0.01
    gyro_bias: float = 0.05
    counts_per_rev: int = 1024
    encoder_offset: float = 0.0
    fusion_q_angle: float = 1e-6
    fusion_q_bias: float = 1e-9
    fusion_r: float = 1e-3
    P0: float = 0.01
    lqr_q: tuple = (100.0, 1.0, 1e-4)
    lqr_r: float = 1.0
    i_max: float = 5.0
    balanced_within: float = 0.05
    seed: int = 3


def _components(s: Settings, case: str, run: int, path: str, fmu_path=None):
    model = get_model("iwp")
    outs = list(STATES) + ["der(alpha_dot)"]
    # the sensors sample before the new current is applied: the accelerometer reads
    # der(alpha_dot) with the current held over the last step (feedthrough "none"), which
    # also opens the loop plant -> sensors -> filters -> LQR -> plant
    if path == "master":
        plant = FMUComponent("plant", fmu_path, s.T, outputs=outs, start={"alpha": s.alpha0},
                             parameters={"integrator": 2, "substeps": s.substeps}, feedthrough="none")
    else:
        plant = ModelComponent("plant", model, s.T, "rk4", s.substeps, start={"alpha": s.alpha0},
                               outputs=outs, feedthrough="none")
    sa, sg = realisation_seeds(s.seed, list(CASES).index(case), run)
    q, r = CASES[case]
    system = augment_rate_bias(discretize(model, s.T), "y_alpha_dot")
    ekf = EstimatorComponent("ekf", lambda: EKF(system, np.zeros(4), s.P0, q, r))
    comps = [plant,
             Accelerometer("acc", s.T, s.r_acc, noise_std=s.acc_std, seed=sa),
             Gyroscope("gyro", s.T, noise_std=s.gyro_std, bias=s.gyro_bias, seed=sg),
             Encoder("encoder", s.T, s.counts_per_rev, s.encoder_offset),
             TiltFusion("fusion", s.T, s.fusion_q_angle, s.fusion_q_bias, s.fusion_r),
             ekf,
             LQRController("lqr", model, s.T, list(s.lqr_q), [[s.lqr_r]], u_limits=(-s.i_max, s.i_max))]
    conn = {"plant.i": "lqr.i", "acc.alpha": "plant.alpha", "acc.alpha_dot": "plant.alpha_dot",
            "acc.alpha_ddot": "plant.der(alpha_dot)", "gyro.alpha_dot": "plant.alpha_dot",
            "encoder.phi_dot": "plant.phi_dot", "fusion.a_t": "acc.a_t", "fusion.a_r": "acc.a_r",
            "fusion.omega": "gyro.omega", "ekf.i": "lqr.i", "ekf.y_alpha": "fusion.alpha",
            "ekf.y_alpha_dot": "fusion.alpha_dot", "ekf.y_phi_dot": "encoder.phi_dot",
            "lqr.alpha": "ekf.alpha", "lqr.alpha_dot": "ekf.alpha_dot", "lqr.phi_dot": "ekf.phi_dot"}
    return comps, conn


def _lag_and_gain(truth, est, T, max_lag=50):
    """Lag [s] maximising the cross-correlation of est against truth, and std(est)/std(truth)."""
    a, b = truth - truth.mean(), est - est.mean()
    lags = range(max_lag + 1)
    corr = [np.dot(a[: len(a) - L], b[L:]) for L in lags]
    return lags[int(np.argmax(corr))] * T, float(b.std() / a.std()) if a.std() > 0 else np.nan


def realisations(case: str, settings: Settings, runs, path: str = "fast") -> list[dict]:
    """The metrics of realisations ``runs`` of ``case`` (the EKF's noise setting) under the
    ``settings``, a dict per realisation, on the ``path`` ``fast`` (plant model in Python) or
    ``master`` (plant FMU)."""
    s = settings
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        fmu = build_fmu("iwp", tmp) if path == "master" else None
        for run in runs:
            comps, conn = _components(s, case, run, path, fmu)
            df = Cosimulation(comps, conn).run(s.duration)
            half = df.index >= s.duration / 2
            truth = df[[f"plant.{x}" for x in STATES]].to_numpy()
            est = df[[f"ekf.{x}" for x in STATES]].to_numpy()
            fed = df[["fusion.alpha", "fusion.alpha_dot", "encoder.phi_dot"]].to_numpy()
            lag, gain = _lag_and_gain(truth[half, 0], est[half, 0], s.T)
            row = {"case": case, "run": run, "balanced": bool(np.abs(truth[half, 0]).max() < s.balanced_within),
                   "bias estimate": float(df["ekf.bias_y_alpha_dot"][half].mean()),
                   "alpha lag [s]": lag, "alpha amplitude ratio": gain,
                   "max |i| [A]": float(df["lqr.i"].abs().max())}
            for j, x in enumerate(STATES):
                row[f"RMSE EKF {x}"] = float(np.sqrt(np.mean((est[half, j] - truth[half, j]) ** 2)))
                row[f"RMSE fed {x}"] = float(np.sqrt(np.mean((fed[half, j] - truth[half, j]) ** 2)))
            out.append(row)
            if run == runs[0]:
                out[-1]["_trace"] = df
    return out


class Seed002Result(NamedTuple):
    """What :func:`run` returns: ``per_run`` (one row per case and realisation), example
    ``traces`` by case, and the ``wall`` time [s]."""

    per_run: pd.DataFrame
    traces: dict
    wall: float


def run(settings: Settings = Settings(), path: str = "fast", backend="processes", n_jobs=None,
        progress=True) -> Seed002Result:
    """Both cases, each in two tasks (``settings``, ``path``, ``backend``, ``n_jobs``,
    ``progress`` as :meth:`Experiment.run <cosim.experiments.experiment.Experiment.run>`);
    returns a :class:`Seed002Result`."""
    chunks = [c for c in np.array_split(np.arange(settings.runs), 2) if len(c)]
    tasks = [(realisations, dict(case=c, settings=settings, runs=[int(r) for r in ch], path=path))
             for c in CASES for ch in chunks]
    return common.run_campaign(tasks, _result, f"seed002 ({path})", backend, n_jobs, progress)


def _result(res: list, wall: float) -> Seed002Result:
    """The campaign's result from its tasks' (lists of realisations; None: a task that did not finish)."""
    rows = [r for part in res if part is not None for r in part]
    traces = {r["case"]: r.pop("_trace") for r in rows if "_trace" in r}
    per_run = pd.DataFrame(rows)
    if len(per_run):
        per_run = per_run.sort_values(["case", "run"]).reset_index(drop=True)
    return Seed002Result(per_run, traces, wall)


def summary_table(per_run: pd.DataFrame) -> pd.DataFrame:
    """Per case and state: RMSE of the EKF and of its input (``per_run``: the per-realisation
    table of :func:`run`), and what the EKF adds."""
    rows = []
    for case, g in per_run.groupby("case", sort=False):
        for x, fed in zip(STATES, ("fused tilt", "raw gyro (with offset)", "raw encoder")):
            e, f = g[f"RMSE EKF {x}"].mean(), g[f"RMSE fed {x}"].mean()
            rows.append({"case": case, "state": x, "EKF input": fed, "RMSE input": f, "RMSE EKF": e,
                         "EKF / input": e / f})
    return pd.DataFrame(rows)


def write_report(per_run, traces, wall, settings: Settings, out_dir, path: str, partial: bool = False) -> Path:
    """The tables, the figure, ``settings.toml`` and ``summary.md`` into ``out_dir`` (``per_run``,
    ``traces``, ``wall``: a :class:`Seed002Result`'s; ``settings``, ``path``, ``partial`` as
    :meth:`Experiment.write_report <cosim.experiments.experiment.Experiment.write_report>`)."""
    table = summary_table(per_run)
    out = common.report_folder(out_dir, to_toml(settings, "seed002"),
                               {"per_run.csv": per_run, "ekf_vs_inputs.csv": table})
    if traces:                               # an interrupted run may have none
        fig, axes = common.new_figure(3, len(traces), figsize=(5 * len(traces), 7), sharex=True)
        for c, (case, df) in enumerate(traces.items()):
            for j, (x, fed) in enumerate(zip(STATES, ("fusion.alpha", "fusion.alpha_dot", "encoder.phi_dot"))):
                ax = axes[j, c]
                ax.plot(df.index, df[fed], ".", ms=1.5, color="0.7", label="EKF input")
                ax.plot(df.index, df[f"plant.{x}"], "k-", lw=1, label="truth")
                ax.plot(df.index, df[f"ekf.{x}"], "r--", lw=1, label="EKF")
                common.style_axes(ax, ylabel=x)
            axes[0, c].set_title(case)
            axes[0, c].legend(fontsize=7)
            axes[-1, c].set_xlabel("time [s]")
        common.save_figure(fig, out / "estimates.png")
    agg = per_run.groupby("case", sort=False)[["balanced", "bias estimate", "alpha lag [s]",
                                               "alpha amplitude ratio", "max |i| [A]"]].mean()
    return common.write_summary(out, [
        f"# Seed 002: wheel pendulum, EKF on the sensor chain, LQR on the estimate ({path} path)", "",
        f"{settings.runs} realisations per case, {settings.duration:g} s; wall time {wall:.2f} s.", "",
        "## Settings", "", *common.settings_table(settings), "",
        "## What the EKF adds over its inputs (RMSE over the second half, mean of realisations)", "",
        table.to_markdown(index=False, floatfmt=".4g"), "",
        "## Loop, offset, lag and attenuation (means; balanced = fraction of realisations)", "",
        agg.to_markdown(floatfmt=".4g"), "",
        f"The gyroscope offset is {settings.gyro_bias} rad/s.", "", "Figure: estimates.png" if traces else ""],
        partial)


class Seed002(Experiment, register="seed002"):
    """Seed 002: the wheel pendulum through the sensor chain, balanced by LQR on the bias EKF."""

    description = "seed 002: wheel pendulum, sensor chain, bias EKF and LQR on the estimate"
    configs: ClassVar[dict] = {"default": Settings()}

    def run(self, settings, path="fast", backend="processes", n_jobs=None, progress=True):
        return run(settings, path=self.check_path(path), backend=backend, n_jobs=n_jobs, progress=progress)

    def write_report(self, result, settings, out_dir, path="fast", config="custom", partial=False):
        return write_report(*result, settings, out_dir, path, partial)

    def summary(self, result, settings, path="fast", config="custom"):
        agg = result.per_run.groupby("case", sort=False)[["balanced", "bias estimate", "alpha lag [s]",
                                                          "alpha amplitude ratio"]].mean()
        return "\n".join([f"Seed 002: wheel pendulum through the sensor chain, {settings.runs} realisations, "
                          f"{path} path, {result.wall:.2f} s",
                          summary_table(result.per_run).to_string(index=False, float_format=lambda v: f"{v:.4g}"),
                          agg.to_string(float_format=lambda v: f"{v:.4g}")])

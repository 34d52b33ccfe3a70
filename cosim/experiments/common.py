"""Pieces shared by the experiments: the same random streams on the fast path and through
the master, vectorised truth, batched filters, and one realisation through the master."""
from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from estimators import BatchFilter

from ..components.estimation import EstimatorComponent
from ..components.sensors import ProcessNoise, Sensor
from ..core.master import Cosimulation


def noise_components(model, T: float, q, measured: Sequence[str], r_std, seed_w: int, seed_v: int):
    """The ProcessNoise (covariance ``q`` on every state) and Sensor (``measured`` states,
    standard deviations ``r_std``) components of one realisation.

    Parameters
    ----------
    model
        The plant model.
    T
        Sample period [s].
    q
        Process noise covariance (scalar, diagonal or matrix).
    measured
        The measured states.
    r_std
        Measurement noise standard deviations.
    seed_w
        Seed of the process noise.
    seed_v
        Seed of the measurement noise.
    """
    return (ProcessNoise("noise", T, model.state_names, q, seed=seed_w),
            Sensor("sensor", T, list(measured), noise_std=r_std, seed=seed_v))


def simulate_truth(model, x0, us: np.ndarray, T: float, q, measured, r_std, seeds, method="euler",
                   substeps=1):
    """Truth ``X`` (runs, N+1, nx) and measurements ``Y`` (runs, N+1, ny) for inputs ``us``
    (N+1, nu), drawing exactly the numbers the ProcessNoise and Sensor components draw in
    the master path (same seeds, same order). ``Y`` uses the model's measurement if
    ``measured`` equals its measured states, else it picks the named states.

    Parameters
    ----------
    model
        The plant model.
    x0
        Initial state.
    us
        Inputs, shape (N+1, nu).
    T
        Sample period [s].
    q
        Process noise covariance.
    measured
        The measured states.
    r_std
        Measurement noise standard deviations.
    seeds
        (process, measurement) seed pairs, one per realisation.
    method
        Integration method of the truth map.
    substeps
        Its substeps.
    """
    R, N = len(seeds), len(us) - 1
    noise, sensor = noise_components(model, T, q, measured, r_std, 0, 0)
    W = np.stack([np.random.default_rng(sw).standard_normal((N + 1, model.nx)) @ noise.L.T
                  for sw, _ in seeds])
    V = np.stack([sensor.noise_std * np.random.default_rng(sv).standard_normal((N + 1, len(measured)))
                  for _, sv in seeds])
    step = model.sym.step(method, substeps).map(R)
    X = np.empty((R, N + 1, model.nx))
    X[:, 0] = x0
    for k in range(N):
        X[:, k + 1] = np.asarray(step(X[:, k].T, np.repeat(us[k][:, None], R, axis=1),
                                      model.p, T)).T + W[:, k]
    idx = [model.state_names.index(m) for m in measured]
    return X, X[:, :, idx] + V


class BatchOutcome(NamedTuple):
    """One filter over every realisation (what :func:`batch_run` returns): estimates ``x``
    (runs, N+1, nx) with the initial one at k = 0, ``nees`` and ``nis`` (runs, N), the
    ``failed`` realisations (runs,), the ``innovation`` (runs, N, ny) and its covariance
    ``S`` (runs, N, ny, ny)."""

    x: np.ndarray
    nees: np.ndarray
    nis: np.ndarray
    failed: np.ndarray
    innovation: np.ndarray
    S: np.ndarray


def batch_run(make: Callable, X: np.ndarray, Y: np.ndarray, us: np.ndarray) -> BatchOutcome:
    """Run one filter over all realisations in one native call; NEES from the full
    covariance. ``us`` (N+1, nu): ``us[k]`` is held over step k -> k+1.

    Parameters
    ----------
    make
        Returns a new filter (the template of every realisation).
    X
        Truth, shape (runs, N+1, nx).
    Y
        Measurements, shape (runs, N+1, ny); row 0 is not used.
    us
        Inputs, shape (N+1, nu).
    """
    R = X.shape[0]
    out = BatchFilter(make(), R, on_failure="mark").run(us[:-1], Y[:, 1:])
    e = out.x[:, 1:] - X[:, 1:]
    with np.errstate(invalid="ignore", over="ignore"):
        nees = np.einsum("rki,rki->rk", e, np.linalg.solve(out.P[:, 1:], e[..., None])[..., 0])
    return BatchOutcome(out.x, nees, out.nis, out.failed.copy(), out.innovation, out.S)


def batch_estimates(make: Callable, X: np.ndarray, Y: np.ndarray, us: np.ndarray, x0):
    """Run one filter over all realisations in one native call: estimates (runs, N+1, nx)
    (the initial estimate at k = 0), NEES (from the full covariance) and NIS (runs, N), and
    the realisations that failed (:func:`batch_run` without the innovations).

    Parameters
    ----------
    make
        Returns a new filter (the template of every realisation).
    X
        Truth, shape (runs, N+1, nx).
    Y
        Measurements, shape (runs, N+1, ny); row 0 is not used.
    us
        Inputs, shape (N+1, nu).
    x0
        The initial estimate (unused: the template carries it; kept for the callers' symmetry).
    """
    out = batch_run(make, X, Y, us)
    return out.x, out.nees, out.nis, out.failed


def nees_from_outputs(err: np.ndarray, P: np.ndarray) -> np.ndarray:
    """NEES ``e^T P^{-1} e`` for errors (steps, nx) and covariances (steps, nx, nx)."""
    return np.einsum("ki,ki->k", err, np.linalg.solve(P, err[..., None])[..., 0])


def covariance_from_frame(df, tag: str, states) -> np.ndarray:
    """Full covariances (steps, nx, nx) from an estimator component's outputs
    (``P_<state>`` diagonal, ``P_<i>_<j>`` above it; ``covariance="full"``).

    Parameters
    ----------
    df
        The co-simulation results.
    tag
        The estimator component's name.
    states
        The state names.
    """
    n = len(states)
    P = np.empty((len(df), n, n))
    for i, s in enumerate(states):
        P[:, i, i] = df[f"{tag}.P_{s}"].to_numpy()
        for j in range(i + 1, n):
            P[:, i, j] = P[:, j, i] = df[f"{tag}.P_{i}_{j}"].to_numpy()
    return P


def new_figure(rows: int = 1, cols: int = 1, figsize=(8, 4), **subplot_kw):
    """A matplotlib Figure of ``figsize`` (inches) and its ``rows x cols`` axes (2-D array),
    without pyplot (no global backend or state); ``subplot_kw`` go to ``Figure.subplots``
    (e.g. ``sharex=True``)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
    return fig, fig.subplots(rows, cols, squeeze=False, **subplot_kw)


def master_realisation(plant, source, noise, sensor, makers: dict, T: float, duration: float):
    """One realisation through the co-simulation master: plant FMU, sensor, the filters,
    the source and the process noise (the order follows from the wiring). Returns truth
    (N+1, nx), estimates by filter (N+1, nx), their full covariances (N+1, nx, nx) and
    NIS (N,). Many realisations: :class:`MasterRealisations`.

    Parameters
    ----------
    plant
        The plant FMU component.
    source
        The input source component.
    noise
        The process-noise component.
    sensor
        The sensor component.
    makers
        Filter factories by name.
    T
        Sample period [s].
    duration
        Simulated time [s].
    """

    return MasterRealisations(plant, source, noise, sensor, makers, T).run(noise.seed, sensor.seed, duration)


class MasterRealisations:
    """The co-simulation of :func:`master_realisation` built once for many realisations that
    differ only in the seeds of the process noise and the sensor: each filter is built once
    and restored to its initial state before each run
    (:meth:`~estimators.base.KalmanBase.restore`, the numbers of a new filter).

    Parameters
    ----------
    plant, source, noise, sensor, makers, T
        As :func:`master_realisation`.
    """

    def __init__(self, plant, source, noise, sensor, makers: dict, T: float):
        states = [p for p in plant.output_names if f"w_{p}" in plant.input_names]
        inp = [p for p in plant.input_names if not p.startswith("w_")]
        self.tags = tags = {name: f"f{i}" for i, name in enumerate(makers)}
        ests = [EstimatorComponent(tags[n], _restored(makers[n]), T, covariance="full") for n in makers]
        conn = {**{f"plant.{u}": f"{source.name}.{source.output_names[j]}" for j, u in enumerate(inp)},
                **{f"sensor.{m}": f"plant.{m}" for m in sensor.input_names},
                **{f"plant.w_{x}": f"noise.w_{x}" for x in states}}
        for t in tags.values():
            conn.update({f"{t}.{u}": f"{source.name}.{source.output_names[j]}" for j, u in enumerate(inp)})
            conn.update({f"{t}.y_{m}": f"sensor.y_{m}" for m in sensor.input_names})
        self.noise, self.sensor, self.states = noise, sensor, states
        self.cosim = Cosimulation([plant, sensor, *ests, source, noise], conn)
        self._columns = None

    def run(self, seed_w: int, seed_v: int, duration: float):
        """One realisation with process-noise seed ``seed_w`` and sensor seed ``seed_v``,
        ``duration`` [s] long; returns what :func:`master_realisation` returns."""
        self.noise.seed, self.sensor.seed = int(seed_w), int(seed_v)
        df = self.cosim.run(duration)
        data = df.to_numpy(dtype=float)                 # every signal here is real: the frame's values
        if self._columns is None:
            self._columns = self._index(list(df.columns))
        xi, ei, pi, ni = self._columns
        n = len(self.states)
        X = data[:, xi]
        est, cov, nis = {}, {}, {}
        for name in self.tags:
            est[name] = data[:, ei[name]]
            P = np.empty((len(data), n, n))
            for (i, j), c in pi[name].items():
                P[:, i, j] = data[:, c]
                if i != j:
                    P[:, j, i] = data[:, c]
            cov[name] = P
            nis[name] = data[1:, ni[name]]
        return X, est, cov, nis

    def _index(self, columns: list):
        """Column positions: truth, estimates, covariance entries (i, j) and NIS by filter."""
        col = {c: i for i, c in enumerate(columns)}
        states, n = self.states, len(self.states)
        xi = [col[f"plant.{x}"] for x in states]
        ei = {nm: [col[f"{t}.{x}"] for x in states] for nm, t in self.tags.items()}
        pi = {nm: {**{(i, i): col[f"{t}.P_{x}"] for i, x in enumerate(states)},
                   **{(i, j): col[f"{t}.P_{i}_{j}"] for i in range(n) for j in range(i + 1, n)}}
              for nm, t in self.tags.items()}
        ni = {nm: col[f"{t}.nis"] for nm, t in self.tags.items()}
        return xi, ei, pi, ni


def _restored(make):
    """A factory returning one filter of ``make``, restored to its initial state at each call."""
    filt = make()
    initial = filt.snapshot()

    def again():
        filt.restore(initial)
        return filt

    return again

"""Pieces shared by the experiments: the same random streams on the fast path and through
the master, vectorised truth, batched filters, and one realisation through the master."""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from ..sensors import ProcessNoise, Sensor


def noise_components(model, T: float, q, measured: Sequence[str], r_std, seed_w: int, seed_v: int):
    """The ProcessNoise (covariance ``q`` on every state) and Sensor (``measured`` states,
    standard deviations ``r_std``) components of one realisation."""
    return (ProcessNoise("noise", T, model.state_names, q, seed=seed_w),
            Sensor("sensor", T, list(measured), noise_std=r_std, seed=seed_v))


def simulate_truth(model, x0, us: np.ndarray, T: float, q, measured, r_std, seeds, method="euler",
                   substeps=1):
    """Truth ``X`` (runs, N+1, nx) and measurements ``Y`` (runs, N+1, ny) for inputs ``us``
    (N+1, nu), drawing exactly the numbers the ProcessNoise and Sensor components draw in
    the master path (same seeds, same order). ``Y`` uses the model's measurement if
    ``measured`` equals its measured states, else it picks the named states."""
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


def batch_estimates(make: Callable, X: np.ndarray, Y: np.ndarray, us: np.ndarray, x0):
    """Run one filter batched over the realisations: estimates (runs, N+1, nx) (the initial
    estimate at k = 0), NEES and NIS (runs, N), and the realisations that failed."""
    from estimators import BatchFilter

    R, N1, nx = X.shape
    batch = BatchFilter(make(), R, on_failure="mark")
    est = np.empty_like(X)
    est[:, 0] = x0
    nees, nis = np.zeros((R, N1 - 1)), np.zeros((R, N1 - 1))
    for k in range(1, N1):
        est[:, k] = batch.step(us[k - 1], Y[:, k])
        e = est[:, k] - X[:, k]
        nees[:, k - 1] = np.einsum("ri,ri->r", e, np.linalg.solve(batch.P, e[..., None])[..., 0])
        nis[:, k - 1] = batch.nis
    return est, nees, nis, batch.failed.copy()


def master_realisation(plant, source, noise, sensor, makers: dict, T: float, duration: float):
    """One realisation through the co-simulation master: plant FMU, sensor, the filters,
    then the source (so the filters predict with the input held over the last step) and
    the process noise. Returns truth (N+1, nx), estimates by filter (N+1, nx), their
    covariance diagonals and NIS (N,)."""
    from ..estimation import EstimatorComponent
    from ..master import Cosimulation

    states = [p for p in plant.output_names if f"w_{p}" in plant.input_names]
    inp = [p for p in plant.input_names if not p.startswith("w_")]
    tags = {name: f"f{i}" for i, name in enumerate(makers)}
    ests = [EstimatorComponent(tags[n], makers[n], T) for n in makers]
    conn = {**{f"plant.{u}": f"{source.name}.{source.output_names[j]}" for j, u in enumerate(inp)},
            **{f"sensor.{m}": f"plant.{m}" for m in sensor.input_names},
            **{f"plant.w_{x}": f"noise.w_{x}" for x in states}}
    for t in tags.values():
        conn.update({f"{t}.{u}": f"{source.name}.{source.output_names[j]}" for j, u in enumerate(inp)})
        conn.update({f"{t}.y_{m}": f"sensor.y_{m}" for m in sensor.input_names})
    df = Cosimulation([plant, sensor, *ests, source, noise], conn).run(duration)
    X = df[[f"plant.{x}" for x in states]].to_numpy()
    est = {n: df[[f"{t}.{x}" for x in states]].to_numpy() for n, t in tags.items()}
    pdiag = {n: df[[f"{t}.P_{x}" for x in states]].to_numpy() for n, t in tags.items()}
    nis = {n: df[f"{t}.nis"].to_numpy()[1:] for n, t in tags.items()}
    return X, est, pdiag, nis

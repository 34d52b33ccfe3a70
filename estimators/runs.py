"""The results of the filters' whole-record operations as plain data with their names, and a record of Q and R.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

__all__ = ["BatchRun", "EMResult", "FilterRun", "NoiseHistory", "Smoothed"]


@dataclass
class FilterRun:
    """Every step's estimate and diagnostics of a run of ``N`` steps: row ``k - 1`` holds step
    ``k = 1..N``, except in ``x``, ``P``, ``Q`` and ``R``, whose row 0 is the initial value.

    Attributes
    ----------
    x, P : ndarray, shapes (N + 1, nx), (N + 1, nx, nx)
        Estimates and their covariances.
    x_prior, P_prior, K : ndarray, shapes (N, nx), (N, nx, nx), (N, nx, ny), or None
        Predictions and gains (None with ``keep="estimates"``, as ``innovation`` and ``S``).
    innovation, S : ndarray, shapes (N, ny), (N, ny, ny), or None
        Innovations and their covariances (0, and 1 on the diagonal, in missing channels).
    nis, accepted : ndarray, shape (N,)
        The NIS; False where the gate refused the measurement.
    mask : ndarray of bool, shape (N, ny)
        The channels used (valid, not NaN, accepted).
    us : ndarray, shape (N, nu)
        The inputs (the smoother needs them).
    Q, R : ndarray, shapes (N + 1, nx), (N + 1, ny)
        Diagonals of Q and R in force after each step.
    log_likelihood : float
        ``-1/2 sum_k (nis_k + log det(2 pi S_k))`` over the valid channels.
    state_names, output_names : list of str
        The model's names (columns of :meth:`to_frame`).
    filter_name, model, jacobians : str
        The filter's ``name``, the model's :attr:`~estimators.DiscreteModel.identity` and
        :attr:`~estimators.DiscreteModel.jacobians`.
    """

    x: np.ndarray
    P: np.ndarray
    x_prior: np.ndarray | None
    P_prior: np.ndarray | None
    innovation: np.ndarray | None
    S: np.ndarray | None
    K: np.ndarray | None
    nis: np.ndarray
    accepted: np.ndarray
    mask: np.ndarray
    us: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    log_likelihood: float
    state_names: list = field(default_factory=list)
    output_names: list = field(default_factory=list)
    filter_name: str = ""
    model: str = ""
    jacobians: str = ""

    def __len__(self) -> int:
        """Number of steps ``N``."""
        return len(self.nis)

    def to_frame(self) -> pd.DataFrame:
        """DataFrame by step ``k`` (0..N): estimate, variances, innovation (if kept), NIS (NaN at 0)."""
        data = _estimates(self.x, self.P, self.state_names)
        if self.innovation is not None:
            for j, name in enumerate(self.output_names):
                data[f"innovation_{name}"] = np.r_[np.nan, self.innovation[:, j]]
        data["nis"] = np.r_[np.nan, self.nis]
        data["accepted"] = np.r_[True, self.accepted]
        return pd.DataFrame(data, index=pd.RangeIndex(len(self.x), name="k"))


def _estimates(x: np.ndarray, P: np.ndarray, names) -> dict:
    """The columns of the estimates ``x`` (N, nx) and of the variances ``P[:, i, i]``, by name."""
    return {**{n: x[:, i] for i, n in enumerate(names)}, **{f"P_{n}": P[:, i, i] for i, n in enumerate(names)}}


@dataclass
class BatchRun:
    """The result of :meth:`~estimators.BatchFilter.run` (``R`` realisations, ``N`` steps);
    the attributes of :class:`FilterRun`, with a leading axis of length R.

    Attributes
    ----------
    x, P, nis, accepted, Q, R, state_names, output_names, innovation, S, jacobians
        As :class:`FilterRun`, shapes (R, N + 1, nx), (R, N + 1, nx, nx), (R, N), (R, N),
        (R, N + 1, nx), (R, N + 1, ny), -, -, (R, N, ny), (R, N, ny, ny).
    failed : ndarray of bool, shape (R,)
        Realisations whose input or estimate became non-finite (their values from that
        step on are not meaningful).
    """

    x: np.ndarray
    P: np.ndarray
    nis: np.ndarray
    accepted: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    failed: np.ndarray
    state_names: list = field(default_factory=list)
    output_names: list = field(default_factory=list)
    innovation: np.ndarray | None = None
    S: np.ndarray | None = None
    jacobians: str = ""


@dataclass
class Smoothed:
    """Smoothed estimates of a record of N steps.

    Attributes
    ----------
    x, P : ndarray, shapes (N + 1, nx), (N + 1, nx, nx)
        Smoothed states ``E[x_k | all measurements]``, k = 0..N, and their covariances.
    P_lag, C : ndarray, shape (N, nx, nx)
        ``Cov(x_{k+1}, x_k | all)`` for k = 0..N-1, and the smoother gains.
    state_names : list of str
        The model's state names.
    """

    x: np.ndarray
    P: np.ndarray
    P_lag: np.ndarray
    C: np.ndarray
    state_names: list = field(default_factory=list)

    def to_frame(self) -> pd.DataFrame:
        """DataFrame indexed by step k with the smoothed states and variances."""
        return pd.DataFrame(_estimates(self.x, self.P, self.state_names), index=pd.RangeIndex(len(self.x), name="k"))


@dataclass
class EMResult:
    """What :func:`~estimators.em_noise` learned.

    Attributes
    ----------
    Q, R, x0, P0 : ndarray
        The learned values (unlearned ones as given).
    log_likelihood : list of float
        The record's log-likelihood at each iteration's parameters (first: the start, last: the result).
    iterations : int
        M-steps done.
    converged : bool
        True if the stopping rule met ``tol`` before ``n_iter``.
    """

    Q: np.ndarray
    R: np.ndarray
    x0: np.ndarray
    P0: np.ndarray
    log_likelihood: list
    iterations: int
    converged: bool


class NoiseHistory:
    """Rows ``(k, diag Q, diag R)``; appending one costs a few array writes.

    Parameters
    ----------
    nx, ny : int
        Sizes of Q and R.
    capacity : int
        Rows allocated at first (doubled when full).

    Attributes
    ----------
    rows : ndarray, shape (capacity, 1 + nx + ny)
        The allocated rows; the first ``count[0]`` are written (an array: compiled code appends too).
    """

    def __init__(self, nx: int, ny: int, capacity: int = 1024):
        self.nx, self.ny = nx, ny
        self.rows = np.empty((capacity, 1 + nx + ny))
        self.count = np.zeros(1, dtype=np.int64)

    def append_flat(self, k: int, Q: np.ndarray, R: np.ndarray) -> None:
        """Add the row of step ``k`` from the flat (column-major) ``Q`` (nx*nx) and ``R`` (ny*ny)."""
        n = len(self)
        if n == len(self.rows):
            self.rows = np.concatenate([self.rows, np.empty_like(self.rows)])
        row = self.rows[n]
        row[0] = k
        row[1:1 + self.nx] = Q[:: self.nx + 1]
        row[1 + self.nx:] = R[:: self.ny + 1]
        self.count[0] = n + 1

    def __len__(self):
        return int(self.count[0])

    def to_frame(self, state_names, output_names) -> pd.DataFrame:
        """DataFrame indexed by step k with columns ``Q_<state>`` and ``R_<output>``."""
        cols = [f"Q_{n}" for n in state_names] + [f"R_{n}" for n in output_names]
        rows = self.rows[: len(self)]
        return pd.DataFrame(rows[:, 1:], index=pd.Index(rows[:, 0].astype(int), name="k"), columns=cols)

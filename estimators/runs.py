"""The results of the filters' whole-record operations, as plain data with their names attached:
:class:`FilterRun` (:meth:`~estimators.base.KalmanBase.run`), :class:`BatchRun`
(:meth:`~estimators.BatchFilter.run`), :class:`Smoothed` (:func:`~estimators.rts_smooth`)
and :class:`EMResult` (:func:`~estimators.em_noise`). Each carries the state and output
names of its model, so :meth:`FilterRun.to_frame` needs nothing else. A filter's growing
record of how its Q and R changed is a :class:`NoiseHistory`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

__all__ = ["BatchRun", "EMResult", "FilterRun", "NoiseHistory", "Smoothed"]


@dataclass
class FilterRun:
    """Every step's estimate and diagnostics of a run of ``N`` steps (arrays indexed by step
    ``k = 1..N`` in row ``k - 1``, except ``x``, ``P``, ``Q`` and ``R``, which also hold the
    initial values in row 0).

    Attributes
    ----------
    x : ndarray, shape (N + 1, nx)
        Estimates, row 0 the initial one.
    P : ndarray, shape (N + 1, nx, nx)
        Their covariances.
    x_prior, P_prior : ndarray, shapes (N, nx), (N, nx, nx), or None
        Predictions (None with ``keep="estimates"``).
    innovation : ndarray, shape (N, ny), or None
        Innovations (0 in missing channels).
    S : ndarray, shape (N, ny, ny), or None
        Innovation covariances (1 on the diagonal of missing channels).
    K : ndarray, shape (N, nx, ny), or None
        Gains.
    nis : ndarray, shape (N,)
    accepted : ndarray of bool, shape (N,)
        False where the gate refused the measurement.
    mask : ndarray of bool, shape (N, ny)
        The channels used (valid, not NaN, accepted).
    us : ndarray, shape (N, nu)
        The inputs (the smoother needs them).
    Q, R : ndarray, shapes (N + 1, nx), (N + 1, ny)
        Diagonals of Q and R in force after each step (row 0: initial).
    log_likelihood : float
        Gaussian log-likelihood of the measurements,
        ``-1/2 sum_k (nis_k + log det(2 pi S_k))`` over the valid channels.
    state_names, output_names : list of str
        The model's names (columns of :meth:`to_frame`).
    filter_name : str
        The filter that produced the run (its ``name``).
    model : str
        The :attr:`~estimators.DiscreteModel.identity` of the model it ran on.
    jacobians : str
        How that model's Jacobians were computed (:attr:`~estimators.DiscreteModel.jacobians`).
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
        """Tidy DataFrame indexed by step ``k`` (0..N) with the estimate, the covariance
        diagonal, the innovation (if kept) and NIS (NaN at k = 0)."""
        data = {name: self.x[:, i] for i, name in enumerate(self.state_names)}
        data.update({f"P_{name}": self.P[:, i, i] for i, name in enumerate(self.state_names)})
        if self.innovation is not None:
            for j, name in enumerate(self.output_names):
                data[f"innovation_{name}"] = np.r_[np.nan, self.innovation[:, j]]
        data["nis"] = np.r_[np.nan, self.nis]
        data["accepted"] = np.r_[True, self.accepted]
        return pd.DataFrame(data, index=pd.RangeIndex(len(self.x), name="k"))


@dataclass
class BatchRun:
    """The result of :meth:`~estimators.BatchFilter.run` (``R`` realisations, ``N`` steps).

    Attributes
    ----------
    x : ndarray, shape (R, N + 1, nx)
        Estimates, with the initial one at index 0.
    P : ndarray, shape (R, N + 1, nx, nx)
        Their covariances.
    nis : ndarray, shape (R, N)
    accepted : ndarray of bool, shape (R, N)
    Q, R : ndarray, shapes (R, N + 1, nx), (R, N + 1, ny)
        Diagonals of Q and R after each step (row 0: initial).
    failed : ndarray of bool, shape (R,)
        Realisations whose input or estimate became non-finite (their values from that
        step on are not meaningful).
    state_names, output_names : list of str
        The model's names.
    innovation : ndarray, shape (R, N, ny), or None
        Innovations (0 in missing channels), for whiteness tests.
    S : ndarray, shape (R, N, ny, ny), or None
        Their predicted covariances (1 on the diagonal of missing channels).
    jacobians : str
        How the model's Jacobians were computed (:attr:`~estimators.DiscreteModel.jacobians`).
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
    x : ndarray, shape (N + 1, nx)
        Smoothed states ``E[x_k | all measurements]``, k = 0..N.
    P : ndarray, shape (N + 1, nx, nx)
        Their covariances.
    P_lag : ndarray, shape (N, nx, nx)
        ``Cov(x_{k+1}, x_k | all)`` for k = 0..N-1.
    C : ndarray, shape (N, nx, nx)
        Smoother gains.
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
        data = {n: self.x[:, i] for i, n in enumerate(self.state_names)}
        data.update({f"P_{n}": self.P[:, i, i] for i, n in enumerate(self.state_names)})
        return pd.DataFrame(data, index=pd.RangeIndex(len(self.x), name="k"))


@dataclass
class EMResult:
    """What :func:`~estimators.em_noise` learned.

    Attributes
    ----------
    Q, R, x0, P0 : ndarray
        The learned values (unlearned ones as given).
    log_likelihood : list of float
        The log-likelihood of the record at each iteration's parameters (the first entry
        at the starting values, the last at the returned ones).
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
    """Rows ``(k, diag Q, diag R)``; append costs one array write.

    Parameters
    ----------
    nx, ny : int
        Sizes of Q and R.
    capacity : int
        Rows allocated at first (doubled when full).
    """

    def __init__(self, nx: int, ny: int, capacity: int = 1024):
        self.nx, self.ny = nx, ny
        self._rows = np.empty((capacity, 1 + nx + ny))
        self.count = np.zeros(1, dtype=np.int64)      # rows written (an array: compiled code appends too)

    @property
    def rows(self) -> np.ndarray:
        """The allocated rows (capacity, 1 + nx + ny); the first ``count`` are written."""
        return self._rows

    @property
    def _n(self) -> int:
        return int(self.count[0])

    def append(self, k: int, qr_diag) -> None:
        """Add the row ``k, qr_diag`` where ``qr_diag = [diag Q, diag R]`` (nx + ny)."""
        self._row(k)[1:] = qr_diag

    def append_flat(self, k: int, Q: np.ndarray, R: np.ndarray) -> None:
        """Add the row of step ``k`` from the flat (column-major) ``Q`` (nx*nx) and ``R``
        (ny*ny), taking their diagonals without building an intermediate array."""
        row = self._row(k)
        row[1:1 + self.nx] = Q[:: self.nx + 1]
        row[1 + self.nx:] = R[:: self.ny + 1]

    def _row(self, k: int) -> np.ndarray:
        n = self._n
        if n == len(self._rows):
            self._rows = np.concatenate([self._rows, np.empty_like(self._rows)])
        row = self._rows[n]
        row[0] = k
        self.count[0] = n + 1
        return row

    def __len__(self):
        return self._n

    def to_frame(self, state_names, output_names) -> pd.DataFrame:
        """DataFrame indexed by step k with columns ``Q_<state>`` and ``R_<output>``."""
        cols = [f"Q_{n}" for n in state_names] + [f"R_{n}" for n in output_names]
        rows = self._rows[: self._n]
        return pd.DataFrame(rows[:, 1:], index=pd.Index(rows[:, 0].astype(int), name="k"),
                            columns=cols)

"""A growing record of how a filter's Q and R changed (diagonals), cheap to append to."""
from __future__ import annotations

import numpy as np
import pandas as pd


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

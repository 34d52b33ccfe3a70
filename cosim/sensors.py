"""Sensor and process-noise components (seeded Gaussian noise)."""
from __future__ import annotations

from collections import deque
from typing import Sequence

import numpy as np

from .component import Component


def _per_channel(value, n, what, owner, positive=False):
    a = np.broadcast_to(np.asarray(value, float), (n,)).copy()
    if not np.all(np.isfinite(a)) or (positive and np.any(a < 0)):
        raise ValueError(f"{owner}: {what} must be finite{' and >= 0' if positive else ''}, got {value!r}")
    return a


class Sensor(Component):
    """Samples signals and adds seeded Gaussian noise, a bias, quantisation and a delay.

    ``y = q(s + bias + v)``, ``v ~ N(0, noise_std^2)``, quantised to ``quantization``
    steps (0: none), then delayed by ``delay`` samples. Input ports are ``signals``;
    output ports are ``y_<signal>``.

    Parameters
    ----------
    name : str
    period : float
        Sample period [s].
    signals : sequence of str
        Names of the measured signals (input ports).
    noise_std : float or sequence
        Standard deviation per channel (default 0).
    bias : float or sequence
        Constant offset per channel (default 0).
    quantization : float or sequence
        Quantisation step per channel, 0 for none (default 0).
    delay : int
        Delay in samples (default 0); until filled, the first measurement is repeated.
    seed : int
        Seed of the noise generator (numpy PCG64; default 0).
    """

    def __init__(self, name: str, period: float, signals: Sequence[str], noise_std=0.0,
                 bias=0.0, quantization=0.0, delay: int = 0, seed: int = 0):
        signals = list(signals)
        super().__init__(name, period, inputs=signals, outputs=[f"y_{s}" for s in signals])
        n = len(signals)
        self.noise_std = _per_channel(noise_std, n, "noise_std", name, positive=True)
        self.bias = _per_channel(bias, n, "bias", name)
        self.quantization = _per_channel(quantization, n, "quantization", name, positive=True)
        if int(delay) != delay or delay < 0:
            raise ValueError(f"{name}: delay must be a non-negative integer of samples, got {delay!r}")
        self.delay, self.seed = int(delay), int(seed)

    def reset(self, t0):
        super().reset(t0)
        self.rng = np.random.default_rng(self.seed)
        self._queue = deque(maxlen=self.delay + 1)
        return np.zeros(len(self.output_names))

    def sample(self, t, u):
        y = u + self.bias + self.noise_std * self.rng.standard_normal(len(u))
        q = self.quantization
        if q.any():
            y = np.where(q > 0, np.round(y / np.where(q > 0, q, 1)) * q, y)
        self._queue.append(y)
        self.n_samples += 1
        return self._queue[0]


class ProcessNoise(Component):
    """Seeded Gaussian samples ``w ~ N(0, cov)`` for an FMU's process-noise inputs.

    Connect its ports ``w_<state>`` to the plant FMU's inputs of the same names; the
    plant adds them to its states at the end of its step (seed 000 eq 12).

    Parameters
    ----------
    name : str
    period : float
        Sample period [s] (the plant's communication step).
    states : sequence of str
        State names; output ports are ``w_<state>``.
    cov : float, sequence or ndarray
        Covariance: scalar (times identity), diagonal, or full matrix.
    seed : int
        Seed of the generator (numpy PCG64; default 0).
    """

    def __init__(self, name: str, period: float, states: Sequence[str], cov, seed: int = 0):
        states = list(states)
        super().__init__(name, period, outputs=[f"w_{s}" for s in states])
        n = len(states)
        c = np.asarray(cov, float)
        c = c * np.eye(n) if c.ndim == 0 else (np.diag(c) if c.ndim == 1 else c)
        if c.shape != (n, n) or not np.all(np.isfinite(c)) or np.abs(c - c.T).max() > 1e-12 * max(1, np.abs(c).max()):
            raise ValueError(f"{name}: cov must be a finite symmetric ({n}, {n}) matrix, a diagonal or a scalar")
        w, V = np.linalg.eigh(c)
        if w.min() < -1e-12 * max(1.0, w.max()):
            raise ValueError(f"{name}: cov is not positive semi-definite (eigenvalues {w})")
        self.L = V * np.sqrt(np.clip(w, 0, None))     # L L^T = cov, also for singular cov
        self.cov, self.seed = c, int(seed)

    def reset(self, t0):
        super().reset(t0)
        self.rng = np.random.default_rng(self.seed)
        return np.zeros(len(self.output_names))

    def sample(self, t, u):
        self.n_samples += 1
        return self.L @ self.rng.standard_normal(len(self.output_names))

"""Gaussian noise streams for the sensor and process-noise components: numpy's PCG64 drawn per
instant (``"pcg64"``), or the counter-based generator of the signal FMUs (``"counter"``,
:func:`~cosim.components.noise.counter_normal`), described in the guide's page on co-simulation
(docs/guide/cosimulation.md)."""
from __future__ import annotations

import numpy as np

from fmu_models.errors import ConfigurationError, UnknownNameError
from fmu_models.infra.checks import positive, positive_int

__all__ = ["GENERATORS", "CounterNoise", "PerInstantNoise", "counter_normal", "make_noise"]

#: The noise generators by name (numpy's PCG64, and the counter-based one the signal FMUs use).
GENERATORS = ("pcg64", "counter")
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1, _M2 = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)
#: Largest seed of the counter generator (the signal FMUs hold it in an FMI Int32).
MAX_COUNTER_SEED = 2**31 - 1


def _splitmix64(seed: np.uint64, i: np.ndarray) -> np.ndarray:
    """Words ``i`` of SplitMix64 seeded with ``seed`` (Steele, Lea and Flood, OOPSLA 2014)."""
    z = seed + (i + np.uint64(1)) * _GOLDEN
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    return z ^ (z >> np.uint64(31))


def counter_normal(seed: int, k, n: int) -> np.ndarray:
    """Standard normal draws of the counter generator.

    Parameters
    ----------
    seed : int
        0 .. 2**31 - 1.
    k : int or array of int
        Sample indices (``round(t / period)``), any sign.
    n : int
        Number of channels.

    Returns
    -------
    ndarray, shape ``np.shape(k) + (n,)``
    """
    kk = np.asarray(k, dtype=np.int64).astype(np.uint64)      # two's complement for k < 0
    i = np.uint64(2) * (kk[..., None] * np.uint64(n) + np.arange(n, dtype=np.uint64))
    a, b = (_splitmix64(np.uint64(seed), j) for j in (i, i + np.uint64(1)))
    u1 = ((a >> np.uint64(11)) + np.uint64(1)).astype(float) * 2.0**-53
    u2 = (b >> np.uint64(11)).astype(float) * 2.0**-53
    return np.sqrt(-2.0 * np.log(u1)) * np.cos(2 * np.pi * u2)


class PerInstantNoise:
    """``n`` standard normal numbers per instant from a seeded PCG64 stream (a repeated call at
    the same instant returns the same draw). They are drawn :data:`BLOCK` instants at a time into
    ``block`` (the same numbers as one vector at a time) so that the native kernel reads the rows
    :meth:`at` reads: ``state`` holds the current row and the rows drawn, ``last`` the instant of the current
    row (NaN before the first); ``on_refill`` callables run after every new block."""

    #: Instants drawn at a time.
    BLOCK = 256

    def __init__(self, seed: int, n: int):
        self.rng, self.n = np.random.default_rng(seed), n
        self.block = np.empty((self.BLOCK, n))
        self.state = np.array([-1, 0], dtype=np.int64)
        self.last = np.array([np.nan])
        self.on_refill: list = []

    def refill(self) -> None:
        """Draw the next block of instants (the current row becomes row -1: none)."""
        self.rng.standard_normal(out=self.block)
        self.state[0], self.state[1] = -1, len(self.block)
        for fn in self.on_refill:
            fn()

    def at(self, t: float) -> np.ndarray:
        """The draw of instant ``t`` [s], shape (n,)."""
        if t != self.last[0]:
            if self.state[0] + 1 >= self.state[1]:
                self.refill()
            self.state[0] += 1
            self.last[0] = t
        return self.block[self.state[0]].copy()


class CounterNoise:
    """``n`` standard normal numbers at sample ``round(t / period)`` [s] of the counter
    generator (:func:`.counter_normal`) with ``seed``."""

    def __init__(self, seed: int, n: int, period: float):
        self.seed, self.n, self.period = seed, n, period
        self.t, self.value = None, None

    def at(self, t: float) -> np.ndarray:
        """The draw of instant ``t`` [s], shape (n,)."""
        if t != self.t:
            self.t, self.value = t, counter_normal(self.seed, int(np.rint(t / self.period)), self.n)
        return self.value


def make_noise(generator: str, seed: int, n: int, period: float, owner: str):
    """A noise stream of ``generator`` (:data:`.GENERATORS`), ``seed``, ``n`` channels drawn at
    ``period`` [s]; errors name ``owner`` (the component)."""
    if generator not in GENERATORS:
        raise UnknownNameError(f"{owner}: generator must be one of {GENERATORS}, got {generator!r}")
    if generator == "counter":
        seed = positive_int(seed, f"{owner}: seed", minimum=0)
        if seed > MAX_COUNTER_SEED:
            raise ConfigurationError(f"{owner}: seed {seed} of the counter generator must be <= {MAX_COUNTER_SEED}")
        return CounterNoise(seed, n, positive(period, f"{owner}: period"))
    return PerInstantNoise(seed, n)

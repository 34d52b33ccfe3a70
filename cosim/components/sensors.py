"""Sensor and process-noise components: seeded Gaussian noise drawn once per sample instant (a
repeated ``output`` call at the same instant, as in an iterated loop, reuses it), so reentrant."""
from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from fmu_models.errors import ConfigurationError
from fmu_models.export.signal_fmu import SignalSpec, build_signal_fmu, channel_params
from fmu_models.infra.checks import float_array, positive_int

from ..core.component import Component, ExportedFMU, bind_protocol
from ..core.native import OP_NOISE, Op
from .noise import make_noise


def _per_channel(value, n, what, owner, positive=False):
    """``value`` (one or ``n`` numbers) as ``n`` finite numbers (``positive``: >= 0), or the named error."""
    a = float_array(value, f"{owner}: {what}")
    try:
        a = np.broadcast_to(a, (n,)).copy()
    except ValueError:
        raise ConfigurationError(f"{owner}: {what} must be one value or {n}, got {value!r}") from None
    if not np.all(np.isfinite(a)) or (positive and np.any(a < 0)):
        raise ConfigurationError(f"{owner}: {what} must be finite{' and >= 0' if positive else ''}, got {value!r}")
    return a


class _Noisy(Component):
    """A component drawing seeded noise per instant, in Python or in the native kernel."""

    reentrant = True

    def _noise_setup(self, seed: int, generator: str, n: int) -> None:
        """Check and keep the seed and the generator of ``n`` channels."""
        self.seed = positive_int(seed, f"{self.name}: seed", minimum=0)
        self.generator, self._channels = generator, n
        make_noise(generator, self.seed, n, self.period, self.name)          # checks the choice now

    def reset(self, t0):
        super().reset(t0)
        self._noise = make_noise(self.generator, self.seed, self._channels, self.period, self.name)

    def _noise_reason(self, cls, methods) -> str | None:
        """Why this component runs in Python: its own calls (beyond ``cls``'s), or the counter generator."""
        kind = type(self)
        if any(getattr(kind, m) is not getattr(cls, m) for m in ("output", "update", "reset", *methods)):
            return "a Python component (its own output or update)"
        if self.generator != "pcg64":
            return "the counter generator runs in Python"
        return None

    def bind(self, values, inputs, outputs, integers=None):
        """The Python component's calls (:func:`~cosim.core.component.bind_protocol`), which
        the native kernel runs itself when :meth:`native_reason` is None."""
        output_fn, update_fn = bind_protocol(self, values, values, inputs, outputs, integers)
        if self.native_reason() is None:
            rows, fields, keep = self._native_rows(values, inputs)
            idx = np.ascontiguousarray(np.arange(len(values))[outputs], dtype=np.int64)
            noise = self._noise
            output_fn.native = [Op(OP_NOISE, dict(fields, buf=rows.ctypes.data, n=rows.shape[1], idx=idx.ctypes.data,
                                                  cur=noise.state.ctypes.data, w=noise.last.ctypes.data),
                                   (noise, rows, idx, *keep), hook=noise.refill)]
            update_fn.native = []
        return output_fn, update_fn

    def _export(self, kind: str, reals: list, description: str, folder: Path, fmi_version: int, clocked: bool,
                inputs: Sequence[str] = ()) -> ExportedFMU:
        """This component as a signal FMU of ``kind`` (drawing from the counter generator)."""
        spec = SignalSpec(kind, self.period, self.output_names, inputs=list(inputs), reals=reals,
                          ints=[("seed", self.seed, 0, 2**31 - 1, "seed of the counter noise generator")],
                          description=description)
        path = build_signal_fmu(spec, folder, fmi_version, self._fmu_identifier(), f"{self.name}.fmu", clocked)
        note = "" if self.generator == "counter" else (
            f"{self.name}: the FMU draws from the counter generator, the component from PCG64 "
            "(same statistics, another realisation); set generator = \"counter\" for the same noise")
        return ExportedFMU(path, spec.parameters(), note)


class Sensor(_Noisy, kind="sensor"):
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
    noise_std, bias, quantization : float or sequence
        Standard deviation, constant offset and quantisation step (0: none) per channel
        (default 0).
    delay : int
        Delay in samples (default 0); until filled, the first measurement is repeated.
    seed, generator : int, {"pcg64", "counter"}
        Seed (default 0) and generator of the noise: numpy's PCG64 drawn sequentially (default),
        or the counter-based generator the signal FMUs use (:mod:`cosim.components.noise`).
    """

    def __init__(self, name: str, period: float, signals: Sequence[str], noise_std=0.0,
                 bias=0.0, quantization=0.0, delay: int = 0, seed: int = 0, generator: str = "pcg64"):
        signals = [signals] if isinstance(signals, str) else list(signals)
        if not signals:
            raise ConfigurationError(f"{name}: a sensor needs at least one signal to measure (signals is empty)")
        super().__init__(name, period, inputs=signals, outputs=[f"y_{s}" for s in signals])
        n = len(signals)
        self.noise_std = _per_channel(noise_std, n, "noise_std", name, positive=True)
        self.bias = _per_channel(bias, n, "bias", name)
        self.quantization = _per_channel(quantization, n, "quantization", name, positive=True)
        self.delay = positive_int(delay, f"{name}: delay (samples)", minimum=0)
        self._noise_setup(seed, generator, n)

    def reset(self, t0):
        super().reset(t0)
        self._queue = deque(maxlen=max(self.delay, 1))

    def _measure(self, t, u):
        y = u + self.bias + self.noise_std * self._noise.at(t)
        q = self.quantization
        if q.any():
            y = np.where(q > 0, np.round(y / np.where(q > 0, q, 1)) * q, y)
        return y

    def native_reason(self) -> str | None:
        """Why this sensor's calls run in Python (None: in the native kernel, ``y = u + bias +
        std z`` with ``z`` the row of the instant in the noise stream's block)."""
        return self._noise_reason(Sensor, ("_measure",)) or (
            "a sensor with a delay or quantisation" if self.delay or self.quantization.any() else None)

    def _native_rows(self, values, inputs):
        """The rows the kernel reads, its fields and what they point to."""
        uidx = np.ascontiguousarray(np.arange(len(values))[inputs], dtype=np.int64)
        return self._noise.block, dict(flag=1, uidx=uidx.ctypes.data, ub=self.bias.ctypes.data,
                                       yb=self.noise_std.ctypes.data), (uidx, self.bias, self.noise_std)

    def output(self, t, u):
        """The sample ``delay`` instants old (the first one until that many exist)."""
        y = self._measure(t, u)                    # drawn at every instant, delayed or not
        return self._queue[0] if self.delay and self._queue else y

    def update(self, t, u):
        if self.delay:
            self._queue.append(self._measure(t, u))

    def export_fmu(self, folder: Path, fmi_version: int = 2, clocked: bool = False) -> ExportedFMU:
        """This sensor as a signal FMU (kind ``sensor``, :mod:`fmu_models.export.signal_fmu`) drawing
        from the counter generator (``clocked``: its clocked form, FMI 3.0); refused with a delay."""
        if self.delay:
            raise ConfigurationError(f"{self.name}: a sensor with a delay has no FMU form (delay = {self.delay})")
        sig = self.input_names
        reals = (channel_params("std", sig, self.noise_std, "nonnegative", "noise standard deviation")
                 + channel_params("bias", sig, self.bias, "real", "bias")
                 + channel_params("quantization", sig, self.quantization, "nonnegative", "quantisation step (0: none)"))
        return self._export("sensor", reals, f"sensor {self.name}: y = q(s + bias + std z) (pendulum-cosim)", folder,
                            fmi_version, clocked, sig)


class ProcessNoise(_Noisy, kind="process_noise"):
    """Seeded Gaussian samples ``w ~ N(0, cov)`` for an FMU's process-noise inputs ``w_<state>``,
    which the plant adds to its states at the end of its step (seed 000 eq 12).

    Parameters
    ----------
    name : str
    period : float
        Sample period [s] (the plant's communication step).
    states : sequence of str
        State names; output ports are ``w_<state>``.
    cov : float, sequence or ndarray
        Covariance: scalar (times identity), diagonal, or full matrix. For a diagonal one,
        channel ``i`` is draw ``i`` times its standard deviation; for a full one,
        ``L v`` with ``L = V sqrt(Lambda)`` from its eigendecomposition.
    seed, generator
        As for :class:`Sensor`.
    """

    def __init__(self, name: str, period: float, states: Sequence[str], cov, seed: int = 0,
                 generator: str = "pcg64"):
        states = list(states)
        super().__init__(name, period, outputs=[f"w_{s}" for s in states])
        n = len(states)
        c = float_array(cov, f"{name}: cov")
        c = c * np.eye(n) if c.ndim == 0 else (np.diag(c) if c.ndim == 1 and len(c) == n else c)
        if c.shape != (n, n) or not np.all(np.isfinite(c)) or np.abs(c - c.T).max() > 1e-12 * max(1, np.abs(c).max()):
            raise ConfigurationError(f"{name}: cov must be a finite symmetric ({n}, {n}) matrix, a diagonal "
                                     "or a scalar")
        w, V = np.linalg.eigh(c)
        if w.min() < -1e-12 * max(1.0, w.max()):
            raise ConfigurationError(f"{name}: cov is not positive semi-definite (eigenvalues {w})")
        self._diagonal = not np.count_nonzero(c - np.diag(np.diag(c)))
        if self._diagonal:
            self.L = np.diag(np.sqrt(np.diag(c)))      # channel i scales draw i
        else:
            self.L = V * np.sqrt(np.clip(w, 0, None))  # L L^T = cov, also for singular cov
        self.cov = c
        self._noise_setup(seed, generator, n)

    def output(self, t, u):
        return self.L @ self._noise.at(t)

    def native_reason(self) -> str | None:
        """Why this component's calls run in Python (None: in the native kernel, which reads
        the rows ``L v`` of the noise stream's block, computed when the block is drawn)."""
        return self._noise_reason(ProcessNoise, ())

    def _native_rows(self, values, inputs):
        """The rows ``L v`` of the noise block (as :meth:`output`), the kernel's fields, what they point to."""
        noise, L = self._noise, self.L
        rows = np.empty_like(noise.block)
        d = np.diag(L).copy()
        # a diagonal L with d > 0: L v is d v exactly (each entry one non-zero product plus
        # exact zeros, in any order), except for the sign of a zero draw's entry
        diagonal = self._diagonal and bool(np.all(d > 0))

        def derive() -> None:
            block = noise.block
            if diagonal:
                np.multiply(block, d, out=rows)
                for i in np.flatnonzero((block == 0).any(axis=1)):
                    rows[i] = L @ block[i]
            else:
                for i, v in enumerate(block):
                    rows[i] = L @ v

        noise.on_refill.append(derive)
        return rows, dict(flag=0), ()

    def export_fmu(self, folder: Path, fmi_version: int = 2, clocked: bool = False) -> ExportedFMU:
        """This noise source as a signal FMU (kind ``noise``, :mod:`fmu_models.export.signal_fmu`)
        drawing from the counter generator (``clocked``: its clocked form, FMI 3.0); refused for a
        non-diagonal ``cov``."""
        if not self._diagonal:
            raise ConfigurationError(f"{self.name}: the noise FMU takes a diagonal cov; this one has "
                                     "off-diagonal entries")
        reals = channel_params("std", self.output_names, np.sqrt(np.diag(self.cov)), "nonnegative",
                               "standard deviation")
        return self._export("noise", reals, f"Gaussian noise {self.name} (pendulum-cosim)", folder, fmi_version,
                            clocked)

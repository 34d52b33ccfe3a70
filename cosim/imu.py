"""The wheel pendulum's sensor chain (seed 002): accelerometer, gyroscope, encoder and the
accelerometer-gyroscope fusion filter, as co-simulation components.

Geometry: the pendulum angle ``alpha`` is measured from the upright vertical; the
sensor board sits on the pendulum at distance ``r`` from the pivot. Body axes: ``r``
(radial, from the pivot towards the sensor), ``t`` (tangential, towards increasing
alpha), ``z`` (the pivot axis). An accelerometer measures the specific force
``a - g`` (with ``g`` pointing down), which in body axes is::

    a_t = r alpha'' - g sin(alpha)
    a_r = g cos(alpha) - r alpha'^2
    a_z = 0

At rest it reads ``(-g sin alpha, g cos alpha)``, so ``atan2(-a_t, a_r)`` is the tilt.
"""
from __future__ import annotations

import numpy as np

from .component import Component
from .sensors import _per_channel

G = 9.81


def _noise(rng, std, n):
    return std * rng.standard_normal(n)


class Accelerometer(Component):
    """3-axis accelerometer at distance ``r`` [m] from the pivot, in body axes.

    Input ports ``alpha`` [rad], ``alpha_dot`` [rad/s], ``alpha_ddot`` [rad/s^2]; output
    ports ``a_t``, ``a_r``, ``a_z`` [m/s^2] (see the module documentation).

    Parameters
    ----------
    name : str
    period : float
        Sample period [s].
    r : float
        Distance of the sensor from the pivot [m], >= 0.
    noise_std : float or sequence
        Standard deviation per axis [m/s^2] (default 0).
    bias : float or sequence
        Constant offset per axis [m/s^2] (default 0).
    g : float
        Gravitational acceleration [m/s^2] (default 9.81).
    seed : int
        Noise seed (default 0).
    """

    def __init__(self, name, period, r, noise_std=0.0, bias=0.0, g=G, seed=0):
        super().__init__(name, period, ["alpha", "alpha_dot", "alpha_ddot"], ["a_t", "a_r", "a_z"])
        if not (np.isfinite(r) and r >= 0):
            raise ValueError(f"{name}: r must be a distance >= 0 m, got {r!r}")
        if not g > 0:
            raise ValueError(f"{name}: g must be > 0")
        self.r, self.g, self.seed = float(r), float(g), int(seed)
        self.noise_std = _per_channel(noise_std, 3, "noise_std", name, positive=True)
        self.bias = _per_channel(bias, 3, "bias", name)

    def reset(self, t0):
        super().reset(t0)
        self.rng = np.random.default_rng(self.seed)
        return np.array([0.0, self.g, 0.0])

    def sample(self, t, u):
        alpha, alpha_dot, alpha_ddot = u
        self.n_samples += 1
        a = np.array([self.r * alpha_ddot - self.g * np.sin(alpha),
                      self.g * np.cos(alpha) - self.r * alpha_dot**2, 0.0])
        return a + self.bias + _noise(self.rng, self.noise_std, 3)


class Gyroscope(Component):
    """Rate gyroscope: ``omega = alpha_dot + b(t) + v``.

    The offset ``b`` starts at ``bias`` and, with ``drift_std > 0``, drifts as a random
    walk of ``drift_std`` [rad/s per sqrt(s)]. Input ``alpha_dot``, output ``omega``.

    Parameters
    ----------
    name : str
    period : float
    noise_std : float
        White noise standard deviation [rad/s] (default 0).
    bias : float
        Initial offset [rad/s] (default 0).
    drift_std : float
        Random-walk intensity of the offset [rad/s/sqrt(s)] (default 0: constant).
    seed : int
        Noise seed (default 0).
    """

    def __init__(self, name, period, noise_std=0.0, bias=0.0, drift_std=0.0, seed=0):
        super().__init__(name, period, ["alpha_dot"], ["omega"])
        for what, v in (("noise_std", noise_std), ("drift_std", drift_std)):
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name}: {what} must be >= 0, got {v!r}")
        if not np.isfinite(bias):
            raise ValueError(f"{name}: bias must be finite")
        self.noise_std, self.bias0, self.drift_std = float(noise_std), float(bias), float(drift_std)
        self.seed = int(seed)

    def reset(self, t0):
        super().reset(t0)
        self.rng = np.random.default_rng(self.seed)
        self.b = self.bias0
        return np.array([self.b])

    def sample(self, t, u):
        if self.n_samples and self.drift_std:
            self.b += self.drift_std * np.sqrt(self.period) * self.rng.standard_normal()
        self.n_samples += 1
        return np.array([u[0] + self.b + self.noise_std * self.rng.standard_normal()])


class Encoder(Component):
    """Incremental encoder on the wheel: speed from counted increments over each period.

    The wheel angle is integrated from the input ``phi_dot`` at the encoder's own rate
    (rectangle rule over each period, exact for a speed held over the period); the
    output ``phi_dot`` is ``(counts_k - counts_{k-1}) 2 pi / (counts_per_rev period) +
    offset`` with ``counts = floor(phi counts_per_rev / (2 pi))``.

    Parameters
    ----------
    name : str
    period : float
        Sample period [s], > 0.
    counts_per_rev : int
        Increments per wheel revolution (resolution), > 0.
    offset : float
        Constant offset added after counting [rad/s] (seed 002 observes one; default 0).
    """

    def __init__(self, name, period, counts_per_rev, offset=0.0):
        super().__init__(name, period, ["phi_dot"], ["phi_dot"])
        if int(counts_per_rev) != counts_per_rev or counts_per_rev <= 0:
            raise ValueError(f"{name}: counts_per_rev must be a positive integer, got {counts_per_rev!r}")
        self.cpr, self.offset = int(counts_per_rev), float(offset)

    def reset(self, t0):
        super().reset(t0)
        self.phi, self.counts, self.speed = 0.0, 0, 0.0
        return np.array([self.offset])

    def sample(self, t, u):
        if self.n_samples:
            self.phi += self.speed * self.period
        self.speed = float(u[0])
        self.n_samples += 1
        # an angle within 1e-9 counts of an edge has crossed it (float rounding of the sum)
        counts = int(np.floor(self.phi * self.cpr / (2 * np.pi) + 1e-9))
        rate = (counts - self.counts) * 2 * np.pi / (self.cpr * self.period)
        self.counts = counts
        return np.array([rate + self.offset])


class TiltFusion(Component):
    """Kalman filter fusing accelerometer tilt and gyro rate: state ``[alpha, b]`` (tilt and
    gyro offset), ``alpha_{k+1} = alpha_k + T (omega_k - b_k)``, ``b_{k+1} = b_k``;
    measurement ``atan2(-a_t, a_r)`` (the tilt at rest).

    Input ports ``a_t``, ``a_r`` (accelerometer), ``omega`` (gyroscope); output ports
    ``alpha`` (fused tilt), ``alpha_dot`` (the gyro rate as measured, or corrected by the
    offset estimate with ``correct_rate=True``), ``bias`` (offset estimate). Runs on
    :class:`estimators.KF` (the model is linear).

    Parameters
    ----------
    name : str
    period : float
        Sample period [s] (the filter's T).
    q_angle : float
        Process variance of the tilt per step [rad^2] (default 1e-6).
    q_bias : float
        Process variance of the offset per step [(rad/s)^2] (default 1e-8).
    r_tilt : float
        Variance of the accelerometer tilt [rad^2] (default 1e-3).
    correct_rate : bool
        Output ``omega - b`` instead of the raw rate (default False: seed 002's EKF sees
        the raw gyro rate and removes the offset itself).
    """

    def __init__(self, name, period, q_angle=1e-6, q_bias=1e-8, r_tilt=1e-3, correct_rate=False):
        super().__init__(name, period, ["a_t", "a_r", "omega"], ["alpha", "alpha_dot", "bias"])
        from estimators import linear_model

        T = self.period
        self.system = linear_model([[1.0, -T], [0.0, 1.0]], [[T], [0.0]], [[1.0, 0.0]], T,
                                   ["alpha", "bias"], ["omega"], ["tilt"])
        self.q_angle, self.q_bias, self.r_tilt = float(q_angle), float(q_bias), float(r_tilt)
        self.correct_rate = bool(correct_rate)
        self._make()                     # validates the covariances now

    def _make(self):
        from estimators import KF

        self.filter = KF(self.system, [0.0, 0.0], [1.0, 0.1], [self.q_angle, self.q_bias],
                         [[self.r_tilt]])

    def reset(self, t0):
        super().reset(t0)
        self._make()
        self.omega_prev = 0.0
        return np.zeros(3)

    def sample(self, t, u):
        a_t, a_r, omega = u
        tilt = np.arctan2(-a_t, a_r)
        if self.n_samples:
            x = self.filter.step([self.omega_prev], [tilt])
        else:
            x = self.filter.update([tilt])
        self.n_samples += 1
        self.omega_prev = omega
        rate = omega - x[1] if self.correct_rate else omega
        return np.array([x[0], rate, x[1]])

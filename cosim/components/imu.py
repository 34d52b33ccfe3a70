"""The wheel pendulum's sensor chain (seed 002): accelerometer, gyroscope, encoder and the
accelerometer-gyroscope fusion filter; their equations are in the guide's page on
co-simulation (docs/guide/cosimulation.md)."""
from __future__ import annotations

import numpy as np

from estimators import KF, linear_model
from fmu_models.errors import ConfigurationError
from fmu_models.infra.checks import finite, positive, positive_int

from ..core.component import Component
from .noise import PerInstantNoise
from .sensors import _per_channel

G = 9.81


class Accelerometer(Component, kind="accelerometer"):
    """3-axis accelerometer at distance ``r`` [m] from the pivot, in body axes.

    Input ports ``alpha`` [rad], ``alpha_dot`` [rad/s], ``alpha_ddot`` [rad/s^2]; output
    ports ``a_t``, ``a_r``, ``a_z`` [m/s^2].

    Parameters
    ----------
    name : str
    period : float
        Sample period [s].
    r : float
        Distance of the sensor from the pivot [m], >= 0.
    noise_std, bias : float or sequence
        Standard deviation and constant offset per axis [m/s^2] (default 0).
    g : float
        Gravitational acceleration [m/s^2] (default 9.81).
    seed : int
        Noise seed (default 0).
    """

    reentrant = True

    def __init__(self, name, period, r, noise_std=0.0, bias=0.0, g=G, seed=0):
        super().__init__(name, period, ["alpha", "alpha_dot", "alpha_ddot"], ["a_t", "a_r", "a_z"])
        self.r = finite(r, f"{name}: r [m]")
        if self.r < 0:
            raise ConfigurationError(f"{name}: r must be a distance >= 0 m, got {r!r}")
        self.g, self.seed = positive(g, f"{name}: g"), positive_int(seed, f"{name}: seed", minimum=0)
        self.noise_std = _per_channel(noise_std, 3, "noise_std", name, positive=True)
        self.bias = _per_channel(bias, 3, "bias", name)

    def reset(self, t0):
        super().reset(t0)
        self._noise = PerInstantNoise(self.seed, 3)

    def output(self, t, u):
        alpha, alpha_dot, alpha_ddot = u
        a = np.array([self.r * alpha_ddot - self.g * np.sin(alpha),
                      self.g * np.cos(alpha) - self.r * alpha_dot**2, 0.0])
        return a + self.bias + self.noise_std * self._noise.at(t)


class Gyroscope(Component, kind="gyroscope"):
    """Rate gyroscope: ``omega = alpha_dot + b(t) + v``, the offset ``b`` a random walk from
    ``bias``. Input ``alpha_dot``, output ``omega``.

    Parameters
    ----------
    name : str
    period : float
    noise_std, bias : float
        White noise standard deviation and initial offset [rad/s] (default 0).
    drift_std : float
        Random-walk intensity of the offset [rad/s/sqrt(s)] (default 0: constant).
    seed : int
        Noise seed (default 0).
    """

    reentrant = True

    def __init__(self, name, period, noise_std=0.0, bias=0.0, drift_std=0.0, seed=0):
        super().__init__(name, period, ["alpha_dot"], ["omega"])
        for what, v in (("noise_std", noise_std), ("drift_std", drift_std)):
            if finite(v, f"{name}: {what}") < 0:
                raise ConfigurationError(f"{name}: {what} must be >= 0, got {v!r}")
            setattr(self, what, float(v))
        self.bias0 = finite(bias, f"{name}: bias")
        self.seed = positive_int(seed, f"{name}: seed", minimum=0)

    def reset(self, t0):
        super().reset(t0)
        self.rng = np.random.default_rng(self.seed)
        self.b, self._t, self._v = self.bias0, None, 0.0

    def _draw(self, t):
        # the same random numbers, in the same order, as one draw pair per instant
        if t != self._t:
            if self._t is not None and self.drift_std:
                self.b += self.drift_std * np.sqrt(self.period) * self.rng.standard_normal()
            self._t, self._v = t, self.rng.standard_normal()
        return self._v

    def output(self, t, u):
        v = self._draw(t)                           # first: it moves the offset b
        return np.array([u[0] + self.b + self.noise_std * v])


class Encoder(Component, kind="encoder"):
    """Incremental encoder on the wheel: the output ``phi_dot`` is ``(counts_k - counts_{k-1})
    2 pi / (counts_per_rev period) + offset``, ``counts = floor(phi counts_per_rev / (2 pi))``,
    with the wheel angle integrated from the input ``phi_dot`` held over each period.

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

    reentrant = True

    def __init__(self, name, period, counts_per_rev, offset=0.0):
        # the count at t_k reflects the speed up to t_k^-: no direct feedthrough
        super().__init__(name, period, ["phi_dot"], ["phi_dot"], feedthrough=False)
        self.cpr = positive_int(counts_per_rev, f"{name}: counts_per_rev")
        self.offset = finite(offset, f"{name}: offset")

    def reset(self, t0):
        super().reset(t0)
        self.phi, self.counts = 0.0, 0

    def _counts(self):
        # an angle within 1e-9 counts of an edge has crossed it (float rounding of the sum)
        return int(np.floor(self.phi * self.cpr / (2 * np.pi) + 1e-9))

    def output(self, t, u):
        rate = (self._counts() - self.counts) * 2 * np.pi / (self.cpr * self.period)
        return np.array([rate + self.offset])

    def update(self, t, u):
        self.counts = self._counts()
        self.phi += float(u[0]) * self.period


class TiltFusion(Component, kind="tilt_fusion"):
    """Kalman filter (:class:`estimators.KF`) fusing accelerometer tilt and gyro rate: state
    ``[alpha, b]`` (tilt and gyro offset), ``alpha_{k+1} = alpha_k + T (omega_k - b_k)``,
    ``b_{k+1} = b_k``; measurement ``atan2(-a_t, a_r)``.

    Input ports ``a_t``, ``a_r``, ``omega``; output ports ``alpha`` (fused tilt),
    ``alpha_dot`` (the gyro rate, or ``omega - b``) and ``bias`` (offset estimate).

    Parameters
    ----------
    name : str
    period : float
        Sample period [s] (the filter's T).
    q_angle, q_bias : float
        Process variances per step of the tilt [rad^2] and the offset [(rad/s)^2] (default 1e-6, 1e-8).
    r_tilt : float
        Variance of the accelerometer tilt [rad^2] (default 1e-3).
    correct_rate : bool
        Output ``omega - b`` instead of the raw rate (default False: seed 002's EKF removes
        the offset itself).
    """

    def __init__(self, name, period, q_angle=1e-6, q_bias=1e-8, r_tilt=1e-3, correct_rate=False):
        # the tilt and offset follow the accelerometer now and the gyro rate of the previous
        # instant (the filter's input); the rate output is the gyro rate now
        super().__init__(name, period, ["a_t", "a_r", "omega"], ["alpha", "alpha_dot", "bias"],
                         feedthrough={"alpha": ["a_t", "a_r"], "bias": ["a_t", "a_r"],
                                      "alpha_dot": ["a_t", "a_r", "omega"]})
        T = self.period
        self.system = linear_model([[1.0, -T], [0.0, 1.0]], [[T], [0.0]], [[1.0, 0.0]], T,
                                   ["alpha", "bias"], ["omega"], ["tilt"])
        self.q_angle, self.q_bias, self.r_tilt = float(q_angle), float(q_bias), float(r_tilt)
        self.correct_rate = bool(correct_rate)
        self.reset(0.0)                             # a first filter checks the covariances

    def reset(self, t0):
        super().reset(t0)
        self.filter = KF(self.system, [0.0, 0.0], [1.0, 0.1], [self.q_angle, self.q_bias], [[self.r_tilt]])
        self.omega_prev = None

    def output(self, t, u):
        a_t, a_r, omega = u
        tilt = np.arctan2(-a_t, a_r)
        x = self.filter.update([tilt]) if self.omega_prev is None else self.filter.step([self.omega_prev], [tilt])
        rate = omega - x[1] if self.correct_rate else omega
        return np.array([x[0], rate, x[1]])

    def update(self, t, u):
        self.omega_prev = float(u[2])

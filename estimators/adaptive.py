"""Adaptive EKFs driven by a window of innovations (seed 000 eq 37), adapted inside the step.

The window is a ring in the state; ``C_I`` (eq 37) is recomputed from it at every step (no
running sum that could drift), so the adaptation runs batched, natively over a record and as an FMU.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from fmu_models.errors import ConfigurationError
from fmu_models.infra.checks import float_array, positive_int

from .discrete import DiscreteModel
from .ekf import EKF
from .protocol import Parameter, StepContext, StepResult
from .runtime import matrix

__all__ = ["AdaptationRecord", "WindowedAdaptiveEKF", "bound_parameters", "bounds_around"]

#: Default bounds, this factor either side of the initial variances.
BOUND_FACTOR = 1e4


def bounds_around(initial: np.ndarray, given, what: str) -> tuple[float, float]:
    """``(low, high)`` bounds for adapted variances: ``given``, or a factor :data:`BOUND_FACTOR`
    below the smallest and above the largest ``initial`` variance (``what`` names them)."""
    if given is None:
        return float(np.min(initial)) / BOUND_FACTOR, float(np.max(initial)) * BOUND_FACTOR
    b = float_array(given, what)
    if b.shape != (2,) or not (np.isfinite(b).all() and 0 < b[0] < b[1]):
        raise ConfigurationError(f"{what} must be (low, high) with 0 < low < high, got {given!r}")
    return float(b[0]), float(b[1])


def bound_parameters(q_bounds, r_bounds) -> list[Parameter]:
    """The step parameters ``q_bounds``, ``r_bounds`` (FMU ``q_min``, ``q_max``, ``r_min``, ``r_max``)."""
    return [Parameter(f"{c}_bounds", b, "positive", (f"smallest adapted {what} variance",
                                                      f"largest adapted {what} variance"),
                      (f"{c}_min", f"{c}_max"), increasing=True)
            for c, b, what in (("q", q_bounds, "process"), ("r", r_bounds, "measurement"))]


class AdaptationRecord:
    """Mixin (before the filter class; call ``_init_adaptation_record`` at the end of ``__init__``):
    records Q and R in the noise history whenever the step's output ``adapted`` says it adapted them."""

    def _init_adaptation_record(self) -> None:
        self._adapted_flag = memoryview(self._out("adapted"))

    def after_step(self) -> None:
        """After a step that adapted: :meth:`on_adapted`."""
        if self._adapted_flag[0]:
            self.on_adapted()

    def on_adapted(self) -> None:
        """Runs after every step from Python that adapted Q and R: records them."""
        self._record()

    def records_only(self) -> bool:
        """Whether :meth:`on_adapted` only records Q and R (then a co-simulation kernel that
        runs the compiled step may write the record itself)."""
        return type(self).on_adapted is AdaptationRecord.on_adapted and type(self).after_step is \
            AdaptationRecord.after_step

    def after_run(self, outputs: dict) -> None:
        """Records the Q and R of every step of a native run that adapted."""
        adapted = outputs["adapted"].ravel()
        for i in np.flatnonzero(adapted):
            self.history.append_flat(self.k - len(adapted) + i + 1, outputs["Q_new"][i], outputs["R_new"][i])


class WindowedAdaptiveEKF(AdaptationRecord, EKF):
    """Base of :class:`~estimators.IAE` and :class:`~estimators.MFIAE` (Q and R are state).

    Parameters
    ----------
    system, x0, P0, Q, R, gate, nan_is_missing, backend
        As :class:`~estimators.base.KalmanBase` (Q and R are the initial values).
    window : int
        N, the number of innovations in ``C_I`` (eq 37). Until N are stored, Q and R keep
        their initial values (a step with a missing channel or a gated measurement leaves
        the window, and Q and R, unchanged).
    """

    adapts_noise = True

    def __init__(self, system: DiscreteModel, x0, P0, Q, R, window: int, gate: float | None = None,
                 nan_is_missing: bool = True, backend: str = "compiled"):
        self.window = positive_int(window, "window")
        super().__init__(system, x0, P0, Q, R, gate, nan_is_missing, backend)
        self._init_adaptation_record()

    def config_key(self) -> tuple:
        return (self.window,)

    def adapt_noise(self, ctx: StepContext, result: StepResult, C_I: ca.SX) -> tuple[ca.SX, ca.SX]:
        """``(Q_new, R_new)`` from the step's symbols ``ctx``, its ``result`` and ``C_I`` (eq 37); the outputs
        it declares are 0 until the window is full."""
        raise NotImplementedError

    def extra_state(self) -> dict:
        """The innovation window (``ring``, ny x window) and the count of innovations stored."""
        return {"ring": np.zeros(self.system.ny * self.window), "count": np.zeros(1)}

    def adapt_expr(self, ctx: StepContext, result: StepResult) -> dict:
        """Push a complete, accepted innovation into the window; once it is full, Q and R from
        :meth:`adapt_noise`. Declares the output ``adapted``."""
        ny, N = self.system.ny, self.window
        ring, count = ca.reshape(ctx.state["ring"], ny, N), ctx.state["count"]
        push = result.accepted * ca.mmin(ctx.valid)      # a complete, accepted vector enters
        shifted = ca.horzcat(ring[:, 1:], result.innovation) if N > 1 else result.innovation
        ring_new = ca.if_else(push, shifted, ring)
        count_new = count + push
        C_I = ca.mtimes(ring_new, ring_new.T) / N                          # eq 37
        declared = set(ctx.outputs)
        Q_new, R_new = self.adapt_noise(ctx, result, C_I)
        adapted = push * (count_new >= N)
        for name in [n for n in ctx.outputs if n not in declared]:
            ctx.outputs[name] = ca.if_else(adapted, ctx.outputs[name], ca.SX.zeros(ctx.outputs[name].shape))
        ctx.output("adapted", adapted)
        return {"Q": ca.if_else(adapted, Q_new, ctx.Q), "R": ca.if_else(adapted, R_new, ctx.R),
                "ring": ring_new, "count": count_new}

    def innovation_covariance(self) -> np.ndarray:
        """C_I of eq 37 from the innovations stored so far (at most ``window``), (ny, ny)."""
        ny = self.system.ny
        n = int(min(self._now("count")[0], self.window))
        ring = matrix(self._now("ring"), ny, self.window)[:, self.window - n:]
        return ring @ ring.T / max(n, 1)

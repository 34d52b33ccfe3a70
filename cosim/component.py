"""The component protocol of the co-simulation master.

Two kinds of component take part:

* a *discrete* component (:class:`Component`) is a sampled block: at each of its sample
  instants ``t`` (every ``period`` seconds) the master calls ``sample(t, u)`` with its
  inputs' values at ``t``, and the outputs it returns are the values at ``t``, held
  (zero-order hold) until its next sample. Sources, sensors, estimators and
  controllers are discrete components;
* an *FMU* component (:class:`~cosim.fmu_component.FMUComponent`) advances in time:
  inputs set at ``t`` are held over ``[t, t + period]`` and its outputs belong to
  ``t + period`` (FMI Co-Simulation semantics).

Every port is one float. Write a new component by subclassing :class:`Component` and
implementing :meth:`Component.sample` (and :meth:`Component.reset` if it has state).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from fmu_models.checks import positive


def check_name(name: str, what: str = "component name") -> str:
    """``name`` if it is an identifier, else ValueError naming ``what`` it is."""
    if not isinstance(name, str) or not name.isidentifier():
        raise ValueError(f"{what} {name!r} must be an identifier (letters, digits, _)")
    return name


def check_period(period, owner: str) -> float:
    """A component's sample period [s] as a positive finite float, else ValueError naming
    the ``owner`` component."""
    return positive(period, f"{owner}: sample period")


class Component:
    """A discrete-time block of the co-simulation.

    Parameters
    ----------
    name : str
        Unique identifier of the component in a co-simulation.
    period : float
        Sample period [s].
    inputs : sequence of str
        Input port names; all must be connected.
    outputs : sequence of str
        Output port names.

    Attributes
    ----------
    kind : str
        ``"discrete"``.
    n_samples : int
        Number of ``sample`` calls since the last reset.
    """

    kind = "discrete"

    def __init__(self, name: str, period: float, inputs: Sequence[str] = (),
                 outputs: Sequence[str] = ()):
        self.name = check_name(name)
        self.period = check_period(period, name)
        self.input_names = [check_name(p, f"{name}: input port") for p in inputs]
        self.output_names = [check_name(p, f"{name}: output port") for p in outputs]
        for ports in (self.input_names, self.output_names):
            if len(set(ports)) != len(ports):
                raise ValueError(f"{name}: duplicate port names in {ports}")
        self.n_samples = 0

    def __repr__(self):
        return (f"{type(self).__name__}({self.name!r}, period={self.period}, "
                f"inputs={self.input_names}, outputs={self.output_names})")

    def reset(self, t0: float) -> np.ndarray:
        """Prepare a run starting at ``t0`` [s]; return the outputs held before the first
        sample (shape ``(n_outputs,)``, default zeros)."""
        self.n_samples = 0
        return np.zeros(len(self.output_names))

    def sample(self, t: float, u: np.ndarray) -> np.ndarray:
        """Outputs at sample time ``t`` [s] from inputs ``u`` (shape ``(n_inputs,)``)."""
        raise NotImplementedError

    def close(self) -> None:
        """Release resources (called by the master at the end of every run)."""

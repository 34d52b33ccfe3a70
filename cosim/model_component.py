"""A plant stepped from its CasADi model in Python: the FMU's semantics without an FMU.

Same ports and behaviour as the plant FMUs of :mod:`fmu_models`: inputs (the model's
inputs and one process-noise input ``w_<state>`` per state, added at the end of each
step), outputs (the states, the measured outputs and, on request, ``der(<state>)``).
The step is the same CasADi expression the FMU's C code is generated from, so a
co-simulation with this component reproduces one with the FMU (the experiments' fast
paths use it).
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from fmu_models.plant import PlantModel, check_method

from .component import check_name, check_period


class ModelComponent:
    """A :class:`~fmu_models.PlantModel` as a continuous co-simulation component.

    Parameters
    ----------
    name : str
    model : PlantModel
    period : float
        Communication step [s].
    method : {"euler", "rk4"}
        Integrator (as the FMU's ``integrator``).
    substeps : int
        Internal steps per period (the FMU's ``substeps`` with ``step_size = period``).
    start : mapping, optional
        Initial states by name (default: the model's ``x0``).
    outputs : sequence of str, optional
        Output ports; default: states and measured outputs. ``der(<state>)`` allowed.

    Attributes
    ----------
    kind : str
        ``"fmu"``: the master steps it like an FMU.
    """

    kind = "fmu"

    def __init__(self, name: str, model: PlantModel, period: float, method: str = "euler",
                 substeps: int = 1, start: Mapping[str, float] | None = None,
                 outputs: Sequence[str] | None = None):
        self.name, self.period = check_name(name), check_period(period, name)
        check_method(method, substeps)
        self.model, self.method, self.substeps = model, method, int(substeps)
        self.input_names = model.input_names + [f"w_{s}" for s in model.state_names]
        available = model.state_names + model.output_names + [f"der({s})" for s in model.state_names]
        self.output_names = list(outputs) if outputs is not None else model.state_names + model.output_names
        for p in self.output_names:
            if p not in available:
                raise KeyError(f"{name}: no output {p!r}; valid outputs: {', '.join(available)}")
        x0 = dict(zip(model.state_names, model.x0))
        for k, v in (start or {}).items():
            if k not in x0:
                raise KeyError(f"{name}: no state {k!r}; states: {', '.join(x0)}")
            x0[k] = float(v)
        self.x0 = np.array(list(x0.values()))
        self._step = model.sym.step(method, self.substeps)
        self.connected_inputs = list(self.input_names)

    def use_inputs(self, names: Sequence[str]) -> None:
        """Inputs set at each step (the connected ones); the others stay zero."""
        self.connected_inputs = list(names)

    def _outputs(self):
        m = self.model
        vals = dict(zip(m.state_names, self.x))
        if any(p in m.output_names for p in self.output_names):
            vals.update(zip(m.output_names, m.h(self.x)))
        if any(p.startswith("der(") for p in self.output_names):
            vals.update((f"der({s})", v) for s, v in zip(m.state_names, m.f(self.x, self.u)))
        self.out_view[:] = [vals[p] for p in self.output_names]
        return self.out_view

    def reset(self, t0: float) -> np.ndarray:
        self.x, self.u, self.w = self.x0.copy(), np.zeros(self.model.nu), np.zeros(self.model.nx)
        self.in_view = np.zeros(len(self.connected_inputs))
        self.out_view = np.zeros(len(self.output_names))
        names = self.model.input_names
        self._in_index = [("u", names.index(p)) if p in names else ("w", self.model.state_names.index(p[2:]))
                          for p in self.connected_inputs]
        return self._outputs()

    def advance(self, t: float, h: float) -> np.ndarray:
        for (kind, i), v in zip(self._in_index, self.in_view):
            (self.u if kind == "u" else self.w)[i] = v
        if abs(h - self.period) > 1e-12 * self.period:
            raise ValueError(f"{self.name}: step {h} s differs from the period {self.period} s")
        x = np.asarray(self._step(self.x, self.u, self.model.p, h)).ravel() + self.w
        if not np.all(np.isfinite(x)):
            raise FloatingPointError(f"{self.name}: the state became non-finite at t = {t + h:g} s")
        self.x = x
        return self._outputs()

    def close(self) -> None:
        """Nothing to free."""

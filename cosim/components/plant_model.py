"""A plant stepped from its CasADi model in Python: the FMU's semantics without an FMU (the
same step expression the FMU's C code is generated from, so a co-simulation with it
reproduces one with the FMU)."""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from fmu_models.errors import NumericalError, UnknownNameError
from fmu_models.infra.checks import finite
from fmu_models.plant import PlantModel, check_method

from ..core.component import Component


class ModelComponent(Component, kind="plant_model"):
    """A :class:`~fmu_models.PlantModel` as a continuous co-simulation component, with the
    ports of its plant FMU: inputs (the model's, and ``w_<state>`` added at the end of each
    step), outputs (states, measured outputs and ``der(<state>)``).

    Parameters
    ----------
    name : str
    model : PlantModel
    period : float
        Communication step [s].
    method, substeps : {"euler", "rk4"}, int
        Integrator and its steps per period (the FMU's ``integrator``, and ``substeps`` with
        ``step_size = period``).
    start : mapping, optional
        Initial states by name (default: the model's ``x0``).
    outputs : sequence of str, optional
        Output ports (default: states and measured outputs).
    feedthrough : {"model", "none"}
        ``der(<state>)`` at ``t`` uses the input at ``t`` ("model", default, as the FMU's
        ModelStructure) or the input of the previous step ("none").
    """

    reentrant = True
    holds_inputs = True

    @classmethod
    def from_scenario(cls, name, table, context):
        """``model`` by name (with ``model_parameters``), the other keys as the constructor's."""
        return context.construct_with_model(cls, name, table)

    def __init__(self, name: str, model: PlantModel, period: float, method: str = "euler",
                 substeps: int = 1, start: Mapping[str, float] | None = None,
                 outputs: Sequence[str] | None = None, feedthrough: str = "model"):
        substeps = check_method(method, substeps)
        if feedthrough not in ("model", "none"):
            raise UnknownNameError(f"{name}: feedthrough must be 'model' or 'none', got {feedthrough!r}")
        self.model, self.method, self.substeps = model, method, substeps
        inputs = model.input_names + [f"w_{s}" for s in model.state_names]
        available = model.state_names + model.output_names + [f"der({s})" for s in model.state_names]
        outs = list(outputs) if outputs is not None else model.state_names + model.output_names
        for p in outs:
            if p not in available:
                raise UnknownNameError(f"{name}: no output {p!r}; valid outputs: {', '.join(available)}")
        ft = ({p: model.input_names for p in outs if p.startswith("der(")} if feedthrough == "model" else False)
        super().__init__(name, period, inputs, outs, feedthrough=ft, port_names_are_identifiers=False)
        self.feedthrough_mode = feedthrough
        x0 = dict(zip(model.state_names, model.x0))
        for k, v in (start or {}).items():
            if k not in x0:
                raise UnknownNameError(f"{name}: no state {k!r}; states: {', '.join(x0)}")
            x0[k] = finite(v, f"{name}: start value of {k}")
        self.x0 = np.array(list(x0.values()))
        self._step = model.sym.step(method, self.substeps)
        self.use_inputs(self.input_names)

    def timing(self) -> str:
        return (f"plant model in Python ({self.method}, {self.substeps} substep(s)): outputs at t; "
                f"inputs held over [t, t + {self.period:g}]")

    def required_inputs(self) -> list[str]:
        """None: unconnected inputs stay zero."""
        return []

    def use_inputs(self, names: Sequence[str], sources=None) -> None:
        """Inputs set at each step (the connected ones), in this order; the others stay zero
        (``sources``: not needed, every port is real)."""
        self.connected_inputs = list(names)
        model_in = self.model.input_names
        self._in_index = [("u", model_in.index(p)) if p in model_in else ("w", self.model.state_names.index(p[2:]))
                          for p in self.connected_inputs]

    def reset(self, t0: float) -> None:
        super().reset(t0)
        self.x, self.u, self.w = self.x0.copy(), np.zeros(self.model.nu), np.zeros(self.model.nx)

    def output(self, t: float, u: np.ndarray) -> np.ndarray:
        m = self.model
        vals = dict(zip(m.state_names, self.x))
        if any(p in m.output_names for p in self.output_names):
            vals.update(zip(m.output_names, m.h(self.x)))
        if any(p.startswith("der(") for p in self.output_names):
            uu = self.u
            if self.feedthrough_mode == "model":
                uu = self.u.copy()
                for (kind, i), v in zip(self._in_index, u):
                    if kind == "u":
                        uu[i] = v
            vals.update((f"der({s})", v) for s, v in zip(m.state_names, m.f(self.x, uu)))
        return np.array([vals[p] for p in self.output_names])

    def update(self, t: float, u: np.ndarray) -> None:
        """Set the inputs and step over ``[t, t + period]``, then add the noise ``w``."""
        for (kind, i), v in zip(self._in_index, u):
            (self.u if kind == "u" else self.w)[i] = v
        x = np.asarray(self._step(self.x, self.u, self.model.p, self.period)).ravel() + self.w
        if not np.all(np.isfinite(x)):
            raise NumericalError(f"{self.name}: the state became non-finite at t = {t + self.period:g} s")
        self.x = x

"""Variables of a plant FMU and their value references, shared by the XML and the C code.

Real value references, in this order (the ModelVariables index is the reference + 1):
parameters, ``step_size``, states, ``der(state)``, inputs, noise inputs ``w_<state>``,
measured outputs. Then two Integer (enumeration) parameters: ``integrator`` and
``substeps``, and the independent variable ``time``.
"""
from __future__ import annotations

from dataclasses import dataclass

from .plant import PlantModel
from .variables import Variable

#: Default internal step [s]: seed 000's sampling period T.
DEFAULT_STEP_SIZE = 0.01


def derivative_unit(unit: str) -> str:
    """Unit of the time derivative of a quantity in ``unit`` (``"m/s"`` -> ``"m/s2"``)."""
    if unit.endswith("/s"):
        return unit + "2"
    return "1/s" if unit == "1" else unit + "/s"


@dataclass(frozen=True)
class FmuVariable:
    name: str
    vr: int
    type: str              # "Real" | "Enumeration" | "Integer"
    causality: str
    variability: str
    initial: str | None
    start: float | int | None
    unit: str | None
    description: str
    derivative_of: int | None = None   # 1-based index of the state
    kind: str = ""                     # param | step | state | der | input | noise | output | int
    declared_type: str | None = None   # of an Enumeration
    min: int | None = None             # of an Integer
    max: int | None = None             # of an Integer


class FmuLayout:
    """The FMU's variables for one :class:`PlantModel`, in ModelVariables order."""

    def __init__(self, model: PlantModel):
        self.model = model
        v: list[FmuVariable] = []

        def add(**kw):
            v.append(FmuVariable(vr=len(v), **kw))

        for p, val in zip(model.parameters, model.p):
            add(name=p.name, type="Real", causality="parameter", variability="fixed",
                initial="exact", start=float(val), unit=p.unit, description=p.description,
                kind="param")
        add(name="step_size", type="Real", causality="parameter", variability="fixed",
            initial="exact", start=DEFAULT_STEP_SIZE, unit="s",
            description="internal integration step is step_size/substeps; a communication step "
                        "that is not a multiple of it ends with a partial step", kind="step")
        first_state = len(v) + 1
        for s in model.states:
            add(name=s.name, type="Real", causality="output", variability="continuous",
                initial="exact", start=float(s.start), unit=s.unit,
                description=s.description + " (continuous state)", kind="state")
        for i, s in enumerate(model.states):
            add(name=f"der({s.name})", type="Real", causality="local", variability="continuous",
                initial="calculated", start=None, unit=derivative_unit(s.unit),
                description=f"time derivative of {s.name}", derivative_of=first_state + i,
                kind="der")
        for u in model.inputs:
            add(name=u.name, type="Real", causality="input", variability="continuous",
                initial=None, start=float(u.start), unit=u.unit, description=u.description,
                kind="input")
        for s in model.states:
            add(name=f"w_{s.name}", type="Real", causality="input", variability="continuous",
                initial=None, start=0.0, unit=s.unit,
                description=f"process noise added to {s.name} at the end of each Co-Simulation "
                            "step (seed 000 eq 12); not used in Model Exchange", kind="noise")
        for y in model.outputs:
            add(name=y.name, type="Real", causality="output", variability="continuous",
                initial="calculated", start=None, unit=y.unit, description=y.description,
                kind="output")
        self.n_real = len(v)
        add(name="integrator", type="Enumeration", causality="parameter", variability="fixed",
            initial="exact", start=1, unit=None,
            description="Co-Simulation integrator: 1 = euler (seed 000 truth map), 2 = rk4",
            kind="int", declared_type="Integrator")
        add(name="substeps", type="Integer", causality="parameter", variability="fixed",
            initial="exact", start=1, unit=None,
            description="internal steps per step_size (both integrators)", kind="int", min=1)
        add(name="time", type="Real", causality="independent", variability="continuous",
            initial=None, start=None, unit="s", description="simulation time", kind="time")
        self.variables = tuple(v)

    def of_kind(self, kind: str) -> list[FmuVariable]:
        return [x for x in self.variables if x.kind == kind]

    def first_vr(self, kind: str) -> int:
        return self.of_kind(kind)[0].vr

    def by_name(self, name: str) -> FmuVariable:
        for x in self.variables:
            if x.name == name:
                return x
        raise KeyError(f"no FMU variable {name!r}; valid names: "
                       f"{', '.join(x.name for x in self.variables)}")


__all__ = ["DEFAULT_STEP_SIZE", "FmuLayout", "FmuVariable", "Variable", "derivative_unit"]

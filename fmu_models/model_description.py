"""``modelDescription.xml`` of a plant FMU (FMI 2.0 and FMI 3.0), its ModelStructure from the
structural sparsity of the CasADi expressions."""
from __future__ import annotations

import casadi as ca

from .fmu_layout import FmuLayout
from .plant import PlantModel
from .xml_writer import Description, Unknown, fmi2, fmi3


def _dependency_kind(entry: ca.SX, model: PlantModel) -> str:
    """FMI 2.0 dependenciesKind of one Jacobian entry."""
    s = model.sym
    if ca.depends_on(entry, ca.vertcat(s.x, s.u)):
        return "dependent"
    return "fixed" if ca.depends_on(entry, s.p) else "constant"


class _Structure:
    """Dependencies of derivatives and outputs, from the structural sparsity of the CasADi expressions."""

    def __init__(self, model: PlantModel, lay: FmuLayout):
        s = model.sym
        self.model, self.lay = model, lay
        idx = {v.name: v.vr + 1 for v in lay.variables}
        self.state_idx = [idx[n] for n in model.state_names]
        self.input_idx = [idx[n] for n in model.input_names]
        self.param_idx = [idx[p.name] for p in model.parameters]
        self.der_idx = [idx[f"der({n})"] for n in model.state_names]
        self.out_idx = [idx[n] for n in model.output_names]
        self.Jf = ca.jacobian(s.xdot, ca.vertcat(s.x, s.u))
        self.Jh = ca.jacobian(s.y, s.x)
        self.Jfp = ca.jacobian(s.xdot, s.p)
        self.Jhp = ca.jacobian(s.y, s.p)

    def _deps(self, J, row, known):
        deps, kinds = [], []
        for col, k in enumerate(known):
            if J.sparsity().has_nz(row, col) and not (J[row, col].is_zero()):
                deps.append(k)
                kinds.append(_dependency_kind(J[row, col], self.model))
        return deps, kinds

    def derivative(self, i, initial=False):
        deps, kinds = self._deps(self.Jf, i, self.state_idx + self.input_idx)
        if initial:
            deps += self._deps(self.Jfp, i, self.param_idx)[0]
        return deps, kinds

    def output(self, j, initial=False):
        deps, kinds = self._deps(self.Jh, j, self.state_idx)
        if initial:
            deps += self._deps(self.Jhp, j, self.param_idx)[0]
        return deps, kinds


_ITEMS = (("euler", 1, "forward Euler (seed 000 eqs 14-17)"), ("rk4", 2, "classical Runge-Kutta 4"))


def _description(model: PlantModel, guid: str, source_files=()) -> Description:
    lay = FmuLayout(model)
    st = _Structure(model, lay)
    outputs = [Unknown(k, [k], ["constant"]) for k in st.state_idx]
    outputs += [Unknown(k, *st.output(j)) for j, k in enumerate(st.out_idx)]
    derivatives = [Unknown(k, *st.derivative(i)) for i, k in enumerate(st.der_idx)]
    initial = [Unknown(k, st.derivative(i, True)[0]) for i, k in enumerate(st.der_idx)]
    initial += [Unknown(k, st.output(j, True)[0]) for j, k in enumerate(st.out_idx)]
    return Description(model_name=model.fmu_name, identifier=model.fmu_name, guid=guid,
                       description=model.description, variables=lay.variables, outputs=outputs,
                       derivatives=derivatives, initial_unknowns=initial, model_exchange=True,
                       directional=True, enumerations={"Integrator": _ITEMS}, source_files=source_files)


def fmi2_xml(model: PlantModel, guid: str, source_files: list[str]) -> str:
    """FMI 2.0 model description of a plant, with Model Exchange and Co-Simulation."""
    return fmi2(_description(model, guid, source_files))


def fmi3_xml(model: PlantModel, token: str) -> str:
    """FMI 3.0 model description of a plant, with Model Exchange and Co-Simulation."""
    return fmi3(_description(model, token))

"""``modelDescription.xml`` of a plant FMU (FMI 2.0 and FMI 3.0)."""
from __future__ import annotations

import datetime as _dt
from xml.sax.saxutils import quoteattr

import casadi as ca

from .fmu_layout import FmuLayout
from .plant import PlantModel

# SI base-unit exponents of every unit string the models use (FMI <BaseUnit>).
_BASE_UNITS = {
    "m": dict(m=1), "m/s": dict(m=1, s=-1), "m/s2": dict(m=1, s=-2),
    "rad": dict(rad=1), "rad/s": dict(rad=1, s=-1), "rad/s2": dict(rad=1, s=-2),
    "N": dict(kg=1, m=1, s=-2), "kg": dict(kg=1), "N.s/m": dict(kg=1, s=-1),
    "N.m.s/rad": dict(kg=1, m=2, s=-1, rad=-1), "kg.m2": dict(kg=1, m=2), "A": dict(A=1),
    "N.m/A": dict(kg=1, m=2, s=-2, A=-1), "1": {}, "1/s": dict(s=-1), "s": dict(s=1),
}


def _attrs(**kw) -> str:
    return "".join(f" {k}={quoteattr(str(v))}" for k, v in kw.items() if v is not None)


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


def _unknown(tag, index, deps, kinds=None, key="index", indent=6):
    """One ModelStructure entry; FMI 2.0 refers by ``index``, FMI 3.0 by ``valueReference``."""
    a = {key: index, "dependencies": " ".join(map(str, sorted(deps)))}
    if kinds is not None:
        order = sorted(range(len(deps)), key=lambda i: deps[i])
        a["dependenciesKind"] = " ".join(kinds[i] for i in order)
    return f"{' ' * indent}<{tag}{_attrs(**a)}/>"


def _units_xml(lay: FmuLayout) -> list[str]:
    units = sorted({v.unit for v in lay.variables if v.unit})
    out = ["  <UnitDefinitions>"]
    for u in units:
        base = _BASE_UNITS.get(u)
        if base is None:
            raise ValueError(f"unit {u!r} has no SI base-unit entry in model_description._BASE_UNITS")
        out.append(f"    <Unit{_attrs(name=u)}>" + (f"<BaseUnit{_attrs(**base)}/>" if base else "")
                   + "</Unit>")
    out.append("  </UnitDefinitions>")
    return out


_GENERATION = dict(generationTool="pendulum-cosim (CasADi code generation)",
                   generationDateAndTime=_dt.datetime(2026, 1, 1).strftime("%Y-%m-%dT%H:%M:%SZ"))
_LOG_CATEGORIES = ('  <LogCategories><Category name="logStatusError" description="errors"/>'
                   '<Category name="logAll" description="everything"/></LogCategories>')
_DEFAULT_EXPERIMENT = f"  <DefaultExperiment{_attrs(startTime=0.0, stopTime=5.0, stepSize=0.01)}/>"
_ITEMS = ('<Item name="euler" value="1" description="forward Euler (seed 000 eqs 14-17)"/>'
          '<Item name="rk4" value="2" description="classical Runge-Kutta 4"/>')


def fmi2_xml(model: PlantModel, guid: str, source_files: list[str]) -> str:
    """FMI 2.0 model description with Model Exchange and Co-Simulation."""
    lay = FmuLayout(model)
    ident = model.fmu_name
    caps = dict(modelIdentifier=ident, canGetAndSetFMUstate="true", canSerializeFMUstate="true",
                providesDirectionalDerivative="true", canNotUseMemoryManagementFunctions="false")
    srcs = "".join(f"<File{_attrs(name=f)}/>" for f in source_files)
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           "<fmiModelDescription" + _attrs(
               fmiVersion="2.0", modelName=ident, guid=guid, description=model.description,
               **_GENERATION, variableNamingConvention="structured",
               numberOfEventIndicators=0) + ">",
           f"  <ModelExchange{_attrs(**caps, completedIntegratorStepNotNeeded='true')}>"
           f"<SourceFiles>{srcs}</SourceFiles></ModelExchange>",
           f"  <CoSimulation{_attrs(**caps, canHandleVariableCommunicationStepSize='true', canInterpolateInputs='false', maxOutputDerivativeOrder=0)}>"
           f"<SourceFiles>{srcs}</SourceFiles></CoSimulation>",
           *_units_xml(lay),
           "  <TypeDefinitions>",
           f'    <SimpleType name="Integrator"><Enumeration>{_ITEMS}</Enumeration></SimpleType>',
           "  </TypeDefinitions>", _LOG_CATEGORIES, _DEFAULT_EXPERIMENT,
           "  <ModelVariables>"]
    for v in lay.variables:
        head = _attrs(name=v.name, valueReference=v.vr, description=v.description,
                      causality=v.causality, variability=v.variability, initial=v.initial)
        if v.type == "Real":
            inner = f"<Real{_attrs(unit=v.unit, derivative=v.derivative_of, start=None if v.start is None else repr(v.start))}/>"
        elif v.type == "Enumeration":
            inner = f"<Enumeration{_attrs(declaredType='Integrator', start=v.start)}/>"
        else:
            inner = f"<Integer{_attrs(start=v.start, min=1)}/>"
        out.append(f"    <ScalarVariable{head}>{inner}</ScalarVariable>")
    out.append("  </ModelVariables>")
    st = _Structure(model, lay)
    out.append("  <ModelStructure>")
    out.append("    <Outputs>")
    for i, k in enumerate(st.state_idx):
        out.append(_unknown("Unknown", k, [k], ["constant"]))
    for j, k in enumerate(st.out_idx):
        out.append(_unknown("Unknown", k, *st.output(j)))
    out.append("    </Outputs>")
    out.append("    <Derivatives>")
    for i, k in enumerate(st.der_idx):
        out.append(_unknown("Unknown", k, *st.derivative(i)))
    out.append("    </Derivatives>")
    out.append("    <InitialUnknowns>")
    unknowns = [(k, st.derivative(i, True)[0]) for i, k in enumerate(st.der_idx)]
    unknowns += [(k, st.output(j, True)[0]) for j, k in enumerate(st.out_idx)]
    for k, deps in sorted(unknowns):
        out.append(_unknown("Unknown", k, deps))
    out.append("    </InitialUnknowns>")
    out.append("  </ModelStructure>")
    out.append("</fmiModelDescription>")
    return "\n".join(out) + "\n"


def fmi3_xml(model: PlantModel, token: str) -> str:
    """FMI 3.0 model description with Model Exchange and Co-Simulation.

    ModelStructure dependencies are value references (FMI 3.0), here index - 1.
    """
    lay = FmuLayout(model)
    ident = model.fmu_name
    caps = dict(modelIdentifier=ident, canGetAndSetFMUState="true", canSerializeFMUState="true",
                providesDirectionalDerivative="true", providesAdjointDerivatives="true")
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           "<fmiModelDescription" + _attrs(
               fmiVersion="3.0", modelName=ident, instantiationToken=token,
               description=model.description, **_GENERATION,
               variableNamingConvention="structured") + ">",
           f"  <ModelExchange{_attrs(**caps, needsCompletedIntegratorStep='false')}/>",
           f"  <CoSimulation{_attrs(**caps, canHandleVariableCommunicationStepSize='true', maxOutputDerivativeOrder=0, hasEventMode='false', providesIntermediateUpdate='false')}/>",
           *_units_xml(lay),
           f'  <TypeDefinitions><EnumerationType name="Integrator">{_ITEMS}</EnumerationType></TypeDefinitions>',
           _LOG_CATEGORIES, _DEFAULT_EXPERIMENT,
           "  <ModelVariables>"]
    # FMI 3.0 wants the independent variable first; value references stay those of the layout
    ordered = sorted(lay.variables, key=lambda v: v.kind != "time")
    for v in ordered:
        a = dict(name=v.name, valueReference=v.vr, description=v.description,
                 causality=v.causality, variability=v.variability, initial=v.initial)
        if v.type == "Real":
            deriv = None if v.derivative_of is None else v.derivative_of - 1
            start = None if v.start is None else repr(v.start)
            out.append(f"    <Float64{_attrs(**a, start=start, unit=v.unit, derivative=deriv)}/>")
        elif v.type == "Enumeration":
            out.append(f"    <Enumeration{_attrs(**a, declaredType='Integrator', start=v.start)}/>")
        else:
            out.append(f"    <Int32{_attrs(**a, start=v.start, min=1)}/>")
    out.append("  </ModelVariables>")
    st = _Structure(model, lay)
    vr = lambda idx: [i - 1 for i in idx]   # noqa: E731  index -> value reference
    out.append("  <ModelStructure>")
    for k in st.state_idx:
        out.append(_unknown3("Output", k - 1, [k - 1], ["constant"]))
    for j, k in enumerate(st.out_idx):
        deps, kinds = st.output(j)
        out.append(_unknown3("Output", k - 1, vr(deps), kinds))
    for i, k in enumerate(st.der_idx):
        deps, kinds = st.derivative(i)
        out.append(_unknown3("ContinuousStateDerivative", k - 1, vr(deps), kinds))
    unknowns = [(k, st.derivative(i, True)[0]) for i, k in enumerate(st.der_idx)]
    unknowns += [(k, st.output(j, True)[0]) for j, k in enumerate(st.out_idx)]
    for k, deps in sorted(unknowns):
        out.append(_unknown3("InitialUnknown", k - 1, vr(deps)))
    out.append("  </ModelStructure>")
    out.append("</fmiModelDescription>")
    return "\n".join(out) + "\n"


def _unknown3(tag, vr, deps, kinds=None):
    return _unknown(tag, vr, deps, kinds, key="valueReference", indent=4)


def build_description_xml(model: PlantModel, source_files: list[str]) -> str:
    """FMI 3.0 ``sources/buildDescription.xml``: how to compile the shipped C sources."""
    files = "".join(f"<SourceFile{_attrs(name=f)}/>" for f in source_files)
    return ('<?xml version="1.0" encoding="UTF-8"?>\n<fmiBuildDescription fmiVersion="3.0">'
            f'<BuildConfiguration{_attrs(modelIdentifier=model.fmu_name)}>'
            f'<SourceFileSet language="C99">{files}</SourceFileSet></BuildConfiguration>'
            "</fmiBuildDescription>\n")

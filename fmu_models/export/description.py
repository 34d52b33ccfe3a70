"""``modelDescription.xml`` for FMI 2.0 and 3.0 of an FMU (plant, estimator or signal) from one
:class:`~fmu_models.export.description.Description`: its variables, ModelStructure, interfaces
and capabilities."""
from __future__ import annotations

import re
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from xml.sax.saxutils import quoteattr

from ..errors import ConfigurationError
from ..infra.version import VERSION

__all__ = ["SYMBOLS", "Description", "Unknown", "base_units", "fmi2", "fmi3", "xml_attrs"]

#: SI base-unit exponents of the unit symbols a unit string is made of (FMI <BaseUnit>);
#: ``rad`` is kept as FMI's own base "unit" of angles.
SYMBOLS = {"m": dict(m=1), "kg": dict(kg=1), "s": dict(s=1), "A": dict(A=1), "K": dict(K=1), "mol": dict(mol=1),
           "cd": dict(cd=1), "rad": dict(rad=1), "N": dict(kg=1, m=1, s=-2), "J": dict(kg=1, m=2, s=-2),
           "W": dict(kg=1, m=2, s=-3), "V": dict(kg=1, m=2, s=-3, A=-1), "Pa": dict(kg=1, m=-1, s=-2),
           "Hz": dict(s=-1), "1": {}}


def base_units(unit: str) -> dict | None:
    """The SI base-unit exponents of ``unit`` written as symbols of :data:`SYMBOLS` joined by
    ``.`` and one ``/`` with integer powers (``"N.m.s/rad"``, ``"m/s2"``, ``"kg.m2"``), or
    None for a unit this does not read (it is then declared without a ``<BaseUnit>``)."""
    num, _, den = unit.partition("/")
    if not num:
        return None
    total: Counter[str] = Counter()
    for part, sign in ((num, 1), (den, -1)):
        for token in part.split(".") if part else []:
            m = re.fullmatch(r"([A-Za-z]+|1)(-?\d+)?", token)
            if not m or m.group(1) not in SYMBOLS:
                return None
            for base, e in SYMBOLS[m.group(1)].items():
                total[base] += e * sign * int(m.group(2) or 1)
    return {k: v for k, v in total.items() if v}


_GENERATION = dict(generationTool=f"pendulum-cosim {VERSION} (CasADi code generation)",
                   generationDateAndTime="2026-01-01T00:00:00Z")
_LOG_CATEGORIES = ('  <LogCategories><Category name="logStatusError" description="errors"/>'
                   '<Category name="logAll" description="everything"/></LogCategories>')


def xml_attrs(**kw) -> str:
    """`` name="value"`` for each keyword whose value is not None, quoted and escaped."""
    return "".join(f" {k}={quoteattr(str(v))}" for k, v in kw.items() if v is not None)


@dataclass(frozen=True)
class Unknown:
    """A ModelStructure entry: variable ``index`` (1-based), ``deps`` the 1-based indices of
    what it depends on (None: everything, the FMI default), ``kinds`` the FMI 2.0
    dependenciesKind of each (or None)."""

    index: int
    deps: Sequence[int] | None = None
    kinds: Sequence[str] | None = None


@dataclass
class Description:
    """Everything the XML states about an FMU.

    Attributes
    ----------
    model_name, identifier, guid, description : str
        ``modelName``, ``modelIdentifier``, ``guid`` / ``instantiationToken``, ``description``.
    variables, outputs, derivatives, initial_unknowns : sequence of FmuVariable, sequence of Unknown
        In ModelVariables order (value reference = index - 1); the ModelStructure.
    model_exchange, directional, variable_step, clocked : bool
        A Model Exchange interface too; directional derivatives; ``canHandleVariableCommunicationStepSize``;
        FMI 3.0 clocks (Co-Simulation with Event Mode, and a Scheduled Execution interface).
    default_step, stop_time : float
        The DefaultExperiment [s].
    enumerations, source_files : dict, sequence of str
        Enumeration types (name -> [(item, value, description)]); the C files of ``sources/`` to compile.
    """

    model_name: str
    identifier: str
    guid: str
    description: str
    variables: Sequence
    outputs: Sequence[Unknown] = ()
    derivatives: Sequence[Unknown] = ()
    initial_unknowns: Sequence[Unknown] = ()
    model_exchange: bool = False
    directional: bool = False
    variable_step: bool = True
    default_step: float = 0.01
    stop_time: float = 5.0
    enumerations: dict = field(default_factory=dict)
    source_files: Sequence[str] = ()
    clocked: bool = False


def _units(variables) -> list[str]:
    units = sorted({v.unit for v in variables if v.unit})
    rows = []
    for u in units:
        base = base_units(u)
        inner = f"<BaseUnit{xml_attrs(**base)}/>" if base else ""
        rows.append(f"    <Unit{xml_attrs(name=u)}>{inner}</Unit>")
    return ["  <UnitDefinitions>", *rows, "  </UnitDefinitions>"] if units else []


def _items(items) -> str:
    return "".join(f"<Item{xml_attrs(name=n, value=v, description=d)}/>" for n, v, d in items)


def _unknown(tag: str, u: Unknown, key: str, shift: int, indent: int) -> str:
    a = {key: u.index - shift}
    if u.deps is not None:
        order = sorted(range(len(u.deps)), key=lambda i: u.deps[i])
        a["dependencies"] = " ".join(str(u.deps[i] - shift) for i in order)
        if u.kinds is not None:
            a["dependenciesKind"] = " ".join(u.kinds[i] for i in order)
    return f"{' ' * indent}<{tag}{xml_attrs(**a)}/>"


def _bool(flag: bool) -> str:
    return "true" if flag else "false"


def _variable(v, fmi3: bool) -> str:
    """The ModelVariables element of the variable ``v``, in FMI 3.0's or 2.0's names and order."""
    head = xml_attrs(name=v.name, valueReference=v.vr, description=v.description, causality=v.causality,
                     variability=v.variability, initial=v.initial)
    start = v.start
    if v.start is not None and v.type in ("Real", "Boolean"):
        start = repr(v.start) if v.type == "Real" else _bool(v.start)
    if v.type == "Clock":
        tag, attrs = "Clock", v.clock or {}
    elif v.type == "Real" and fmi3:
        derivative = None if v.derivative_of is None else v.derivative_of - 1
        tag, attrs = "Float64", dict(start=start, unit=v.unit, derivative=derivative)
    elif v.type == "Real":
        tag, attrs = "Real", dict(unit=v.unit, derivative=v.derivative_of, start=start)
    elif v.type in ("Enumeration", "Boolean"):
        tag, attrs = v.type, dict(declaredType=v.declared_type, start=start)
    else:
        tag, attrs = "Int32" if fmi3 else "Integer", dict(start=start, min=v.min, max=v.max)
    if fmi3:
        return f"    <{tag}{head}{xml_attrs(clocks=' '.join(map(str, v.clocks)) or None, **attrs)}/>"
    return f"    <ScalarVariable{head}><{tag}{xml_attrs(**attrs)}/></ScalarVariable>"


def _document(d: Description, version: int, interfaces: list[str], types: list[str], variables: list[str],
              structure: list[str]) -> str:
    """The text of the FMI ``version`` (2 or 3) model description made of these parts."""
    root = xml_attrs(fmiVersion=f"{version}.0", modelName=d.model_name,
                     **{"guid" if version == 2 else "instantiationToken": d.guid}, description=d.description,
                     **_GENERATION, variableNamingConvention="structured",
                     numberOfEventIndicators=0 if version == 2 else None)
    experiment = xml_attrs(startTime=0.0, stopTime=d.stop_time, stepSize=d.default_step)
    return "\n".join(['<?xml version="1.0" encoding="UTF-8"?>', f"<fmiModelDescription{root}>", *interfaces,
                      *_units(d.variables), *types, _LOG_CATEGORIES, f"  <DefaultExperiment{experiment}/>",
                      "  <ModelVariables>", *variables, "  </ModelVariables>", "  <ModelStructure>", *structure,
                      "  </ModelStructure>", "</fmiModelDescription>", ""])


def fmi2(d: Description) -> str:
    """The FMI 2.0 model description."""
    if d.clocked or any(v.type == "Clock" for v in d.variables):
        raise ConfigurationError(f"{d.identifier}: clocks are FMI 3.0 only; an FMI 2.0 FMU cannot have them")
    caps = dict(modelIdentifier=d.identifier, canGetAndSetFMUstate="true", canSerializeFMUstate="true",
                providesDirectionalDerivative=_bool(d.directional), canNotUseMemoryManagementFunctions="false")
    srcs = f"<SourceFiles>{''.join(f'<File{xml_attrs(name=f)}/>' for f in d.source_files)}</SourceFiles>"
    interfaces = [f"  <ModelExchange{xml_attrs(**caps, completedIntegratorStepNotNeeded='true')}>{srcs}</ModelExchange>"
                  ] if d.model_exchange else []
    cs = xml_attrs(**caps, canHandleVariableCommunicationStepSize=_bool(d.variable_step), canInterpolateInputs="false",
                   maxOutputDerivativeOrder=0)
    interfaces.append(f"  <CoSimulation{cs}>{srcs}</CoSimulation>")
    types = ["  <TypeDefinitions>",
             *[f'    <SimpleType{xml_attrs(name=n)}><Enumeration>{_items(items)}</Enumeration></SimpleType>'
               for n, items in d.enumerations.items()],
             "  </TypeDefinitions>"] if d.enumerations else []
    variables = [_variable(v, fmi3=False) for v in d.variables]
    structure = []
    for tag, entries in (("Outputs", d.outputs), ("Derivatives", d.derivatives),
                         ("InitialUnknowns", sorted(d.initial_unknowns, key=lambda u: u.index))):
        if entries:
            structure += [f"    <{tag}>", *[_unknown("Unknown", u, "index", 0, 6) for u in entries], f"    </{tag}>"]
    return _document(d, 2, interfaces, types, variables, structure)


def fmi3(d: Description) -> str:
    """The FMI 3.0 model description (dependencies are value references, index - 1)."""
    caps = dict(modelIdentifier=d.identifier, canGetAndSetFMUState="true", canSerializeFMUState="true",
                providesDirectionalDerivatives=_bool(d.directional), providesAdjointDerivatives=_bool(d.directional))
    interfaces = [f"  <ModelExchange{xml_attrs(**caps, needsCompletedIntegratorStep='false')}/>"
                  ] if d.model_exchange else []
    cs = xml_attrs(**caps, canHandleVariableCommunicationStepSize=_bool(d.variable_step), maxOutputDerivativeOrder=0,
                   hasEventMode=_bool(d.clocked), providesIntermediateUpdate="false")
    interfaces.append(f"  <CoSimulation{cs}/>")
    if d.clocked:
        se = {k: v for k, v in caps.items() if k != "providesDirectionalDerivatives"}
        interfaces.append(f"  <ScheduledExecution{xml_attrs(**se)}/>")
    types = "".join(f"<EnumerationType{xml_attrs(name=n)}>{_items(items)}</EnumerationType>"
                    for n, items in d.enumerations.items())
    # FMI 3.0 wants the independent variable first; value references stay those of the layout
    variables = [_variable(v, fmi3=True) for v in sorted(d.variables, key=lambda v: v.causality != "independent")]
    structure = [_unknown("Output", u, "valueReference", 1, 4) for u in d.outputs]
    structure += [_unknown("ContinuousStateDerivative", u, "valueReference", 1, 4) for u in d.derivatives]
    structure += [_unknown("InitialUnknown", Unknown(u.index, u.deps, None), "valueReference", 1, 4)
                  for u in sorted(d.initial_unknowns, key=lambda u: u.index)]
    return _document(d, 3, interfaces,
                     [f"  <TypeDefinitions>{types}</TypeDefinitions>"] if types else [], variables, structure)

"""A co-simulation written as an SSP 1.0 (:func:`export_ssp`): the SSD, an FMU per component in
``resources/`` and both as a ``.ssp`` archive (the user guide's page "Taking the estimator to another tool")."""
from __future__ import annotations

import inspect
import os
import tempfile
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree import ElementTree as ET

from fmu_models.errors import ConfigurationError, FMUError
from fmu_models.export.clocked import check_clocked
from fmu_models.export.platforms import add_platforms
from fmu_models.infra.version import VERSION

from ..core.component import PORT_TYPES, ExportedFMU, ExportsFMU
from ..core.master import Cosimulation
from ..core.schedule import base_step
from ..fmi.archive import read_description
from .schema import NS
from .system import FMU_TYPE

__all__ = ["ANNOTATION", "OMS_ANNOTATION", "SSPExport", "export_component", "export_ssp"]

#: Annotation type of the project's additions to the SSD (the components' periods).
ANNOTATION = "org.pendulum-cosim"
PC_NS = "https://github.com/pendulum-cosim/ssp"
#: OMSimulator's vendor annotation (its schema oms.xsd) holding the master's step size.
OMS_ANNOTATION = "org.openmodelica"
OMS_NS = "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd"
_SSP_TYPES = {"real": "Real", "integer": "Integer", "boolean": "Boolean"}


@dataclass
class SSPExport:
    """What :func:`export_ssp` wrote.

    Attributes
    ----------
    ssd, archive, fmus, notes
        ``SystemStructure.ssd``, the ``.ssp`` file, each component's FMU by name, and where the SSP
        differs from the scenario (e.g. the noise generator).
    """

    ssd: Path
    archive: Path
    fmus: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)


def _value_text(kind: str, value) -> str:
    if kind == "boolean":
        return "true" if value else "false"
    return str(int(value)) if kind == "integer" else repr(float(value))


def _sub(parent, tag: str, **attributes) -> ET.Element:
    """A child element of ``parent`` with the ``attributes`` that are not None."""
    return ET.SubElement(parent, tag, {k: str(v) for k, v in attributes.items() if v is not None})


def _ssd_text(name: str, components, exported: dict[str, ExportedFMU], variables: dict, connections: dict,
              start_time: float, stop_time: float | None, description: str, step_size: float) -> str:
    """The SSD; ``variables``: each component's FMU variables by name."""
    root = ET.Element("ssd:SystemStructureDescription", {
        "xmlns:ssd": NS["ssd"], "xmlns:ssc": NS["ssc"], "xmlns:ssv": NS["ssv"], "xmlns:pc": PC_NS, "version": "1.0",
        "name": name, "generationTool": f"pendulum-cosim {VERSION}"})
    system = _sub(root, "ssd:System", name=name, description=description or None)
    params = [(f"{c.name}.{key}", PORT_TYPES[variables[c.name][key].type], value)
              for c in components for key, value in exported[c.name].parameters.items()]
    if params:
        values = _sub(_sub(_sub(system, "ssd:ParameterBindings"), "ssd:ParameterBinding"), "ssd:ParameterValues")
        values = _sub(_sub(values, "ssv:ParameterSet", version="1.0", name="parameters"), "ssv:Parameters")
        for n, kind, value in params:
            _sub(_sub(values, "ssv:Parameter", name=n), f"ssv:{_SSP_TYPES[kind]}", value=_value_text(kind, value))
    elements = _sub(system, "ssd:Elements")
    for c in components:
        own = variables[c.name]
        element = _sub(elements, "ssd:Component", name=c.name, type=FMU_TYPE, source=f"resources/{c.name}.fmu")
        conns = [(p, "input") for p in c.input_names if p in own] + [(p, "output") for p in c.output_names if p in own]
        if conns:
            connectors = _sub(element, "ssd:Connectors")
            for p, k in conns:
                _sub(_sub(connectors, "ssd:Connector", name=p, kind=k), f"ssc:{_SSP_TYPES[PORT_TYPES[own[p].type]]}")
        timing = _sub(_sub(element, "ssd:Annotations"), "ssc:Annotation", type=ANNOTATION)
        _sub(timing, "pc:Timing", period=repr(c.period))
    if connections:
        wires = _sub(system, "ssd:Connections")
        for (dc, dp), (sc, sp) in connections.items():
            _sub(wires, "ssd:Connection", startElement=sc, startConnector=sp, endElement=dc, endConnector=dp)
    oms = _sub(_sub(system, "ssd:Annotations"), "ssc:Annotation", type=OMS_ANNOTATION)
    oms = _sub(_sub(oms, "oms:Annotations", **{"xmlns:oms": OMS_NS}), "oms:SimulationInformation")
    _sub(oms, "oms:FixedStepMaster", description="oms-ma", stepSize=repr(float(step_size)), relativeTolerance="1e-4")
    _sub(root, "ssd:DefaultExperiment", startTime=repr(float(start_time)),
         stopTime=None if stop_time is None else repr(float(stop_time)))
    ET.indent(root, "  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def export_component(c, folder: Path, fmi_version: int, clocked: bool) -> ExportedFMU:
    """The component ``c`` as an FMU in ``folder`` (:meth:`~cosim.core.component.ExportsFMU.export_fmu`
    in FMI ``fmi_version``); ``clocked``: its clocked form if its ``export_fmu`` takes the
    option, else its unclocked form with a note saying so."""
    if not clocked:
        return c.export_fmu(folder, fmi_version)
    if "clocked" not in inspect.signature(c.export_fmu).parameters:
        e = c.export_fmu(folder, fmi_version)
        note = f"{c.name}: {type(c).__name__} has no clocked form; written unclocked"
        return ExportedFMU(e.path, e.parameters, "; ".join(n for n in (e.note, note) if n))
    return c.export_fmu(folder, fmi_version, clocked=True)


def export_ssp(system, out_dir, fmi_version: int = 2, name: str | None = None,
               stop_time: float | None = None, platforms: Sequence[str] = (), clocked: bool = False) -> SSPExport:
    """Write a scenario (or a co-simulation) as an SSP into ``out_dir``.

    Parameters
    ----------
    system, out_dir : Scenario or Cosimulation, path
        What to export (a :class:`cosim.scenario.Scenario` brings its times and title); the folder for
        ``SystemStructure.ssd``, ``resources/`` and ``<name>.ssp`` (created if missing; only those are replaced).
    fmi_version : {2, 3}
        FMI version of the FMUs it builds (those of ``fmu`` components are copied as they are).
    name, stop_time : str, float, optional
        System and archive name (default ``system``); ``DefaultExperiment`` stop time [s] (default the scenario's).
    platforms : sequence of str, optional
        Platforms to cross-compile every FMU for (:func:`fmu_models.export.platforms.add_platforms`).
    clocked : bool
        Estimators and signal FMUs in their clocked form (FMI 3.0 only, :mod:`fmu_models.export.clocked`;
        the importer schedules the clock ``sample``); others unclocked, with a note.

    Raises
    ------
    ConfigurationError
        Components without an FMU form (all named at once), a connection to a port the
        exported FMU lacks, or ``clocked`` with FMI 2.0.
    """
    check_clocked(clocked, fmi_version, "the SSP")
    cosim = system if isinstance(system, Cosimulation) else system.cosim
    stop = stop_time if stop_time is not None else getattr(system, "stop_time", None)
    name = name or "system"
    if not name.replace("-", "_").isidentifier():
        raise ConfigurationError(f"SSP name {name!r} must be letters, digits, '_' or '-'")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=out_dir, prefix=".ssp-") as tmp:
        tmp = Path(tmp)
        resources = tmp / "resources"
        resources.mkdir()
        exported = _export_all(cosim.components, resources, fmi_version, clocked)
        notes = [e.note for e in exported.values() if e.note]
        for n, e in exported.items() if platforms else ():
            try:
                notes += add_platforms(e.path, platforms)
            except FMUError as err:
                raise FMUError(f"component {n!r}: {err}") from None
        variables = {n: {v.name: v for v in read_description(e.path).modelVariables} for n, e in exported.items()}
        _check_connections(cosim.connections, variables)
        step = float(base_step({c.name: c.period for c in cosim.components})[0])
        text = _ssd_text(name, cosim.components, exported, variables, cosim.connections,
                         getattr(system, "start_time", 0.0), stop, getattr(system, "title", ""), step)
        _move_into(out_dir, tmp, text, name, [c.name for c in cosim.components])
    return SSPExport(out_dir / "SystemStructure.ssd", out_dir / f"{name}.ssp",
                     {c.name: out_dir / "resources" / f"{c.name}.fmu" for c in cosim.components}, notes)


def _export_all(components, resources: Path, fmi_version: int, clocked: bool) -> dict[str, ExportedFMU]:
    """Every component as an FMU in ``resources``; those that cannot be are all named at once."""
    exported, refused = {}, []
    for c in components:
        if not isinstance(c, ExportsFMU):
            refused.append(f"component {c.name!r} ({type(c).__name__}) has no FMU form")
            continue
        try:
            exported[c.name] = export_component(c, resources, fmi_version, clocked)
        except ConfigurationError as e:
            refused.append(str(e))
    if refused:
        raise ConfigurationError("cannot export as an SSP: " + "; ".join(refused))
    return exported


def _check_connections(connections: dict, variables: dict) -> None:
    """Every connection's ends are variables of the exported FMUs."""
    for (dc, dp), (sc, sp) in connections.items():
        for comp, port, kind in ((sc, sp, "output"), (dc, dp, "input")):
            have = {n for n, v in variables[comp].items() if v.causality == kind}
            if port not in have:
                raise ConfigurationError(f"cannot export as an SSP: the FMU of {comp!r} has no {kind} {port!r} "
                                         f"(connection {sc}.{sp} -> {dc}.{dp}); its {kind}s: "
                                         f"{', '.join(sorted(have))}")


def _move_into(out_dir: Path, tmp: Path, ssd_text: str, name: str, components: list[str]) -> None:
    """The SSD and the archive written in ``tmp`` and the FMUs there, moved into ``out_dir``."""
    (tmp / "SystemStructure.ssd").write_text(ssd_text, encoding="utf-8")
    fmus = [f"resources/{c}.fmu" for c in components]
    with zipfile.ZipFile(tmp / f"{name}.ssp", "w", zipfile.ZIP_DEFLATED) as z:
        for rel in ["SystemStructure.ssd", *fmus]:
            z.write(tmp / rel, rel)
    (out_dir / "resources").mkdir(exist_ok=True)
    for rel in [*fmus, "SystemStructure.ssd", f"{name}.ssp"]:     # the FMUs before what names them
        os.replace(tmp / rel, out_dir / rel)

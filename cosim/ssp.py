"""A co-simulation as an SSP (System Structure and Parameterization 1.0), and back.

:func:`export_ssp` writes a scenario whose every component is an FMU or can be written as
one (:meth:`cosim.core.component.ExportsFMU.export_fmu`: FMUs, estimators, sources, process
noise and sensors) as

* ``SystemStructure.ssd``: one ``Component`` per component (``source`` =
  ``resources/<name>.fmu``) with a connector per port, the connections, one system-level
  ``ParameterBinding`` holding every parameter and start value as ``<component>.<variable>``,
  the start and stop time as ``DefaultExperiment``, and each component's sample period in
  an annotation (``type="org.pendulum-cosim"``), since SSP 1.0 has no place for it; and the
  communication step (the greatest common divisor of the periods) in OMSimulator's
  vendor annotation on the System (``type="org.openmodelica"``, ``oms:FixedStepMaster``),
  which OMSimulator reads instead of its default 1 ms step;
* ``resources/<name>.fmu``: the FMUs;
* ``<name>.ssp``: the same two as one archive (what most tools open).

Noise components draw from the counter generator in their FMUs (:mod:`cosim.components.noise`):
give them ``generator = "counter"`` for the scenario to draw the same noise in the
project's master; otherwise the export says so in its notes.

:func:`open_ssp` reads such an SSP (a ``.ssp`` archive or its unpacked folder, flat
systems of Co-Simulation FMUs) into a :class:`~cosim.core.master.Cosimulation` of
:class:`~cosim.fmi.fmu_component.FMUComponent` objects, so the project's master runs what other
tools run.

Importers differ in how they order the FMUs within a step. fmpy's ``simulate_ssp``
(FMI 2.0 only) steps every FMU with the connector values of the previous step (Jacobi)
and starts every connector at 0, so over its first step the plant sees 0 for the force
and the noise; after that a plant driven by sources gets the same inputs as in the
project's master.
"""
from __future__ import annotations

import contextlib
import inspect
import os
import tempfile
import zipfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree import ElementTree as ET

from fmu_models.errors import ConfigurationError, FMUError
from fmu_models.export.clocked import check_clocked
from fmu_models.export.description import xml_attrs
from fmu_models.export.platforms import add_platforms
from fmu_models.infra.checks import finite, positive
from fmu_models.infra.version import VERSION

from .core.component import PORT_TYPES, ExportedFMU, ExportsFMU
from .core.master import Cosimulation
from .core.schedule import base_step
from .fmi.archive import Extraction, read_description
from .fmi.fmu_component import FMUComponent

__all__ = ["SSPExport", "SSPSystem", "export_component", "export_ssp", "open_ssp"]

NS = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
      "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
      "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues"}
#: Annotation type of the project's additions to the SSD (the components' periods).
ANNOTATION = "org.pendulum-cosim"
_PC_NS = "https://github.com/pendulum-cosim/ssp"
#: OMSimulator's vendor annotation (its schema oms.xsd) holding the master's step size.
OMS_ANNOTATION = "org.openmodelica"
_OMS_NS = "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd"
_SSP_TYPES = {"real": "Real", "integer": "Integer", "boolean": "Boolean"}


@dataclass
class SSPExport:
    """What :func:`export_ssp` wrote.

    Attributes
    ----------
    ssd : Path
        ``SystemStructure.ssd``.
    archive : Path
        The ``.ssp`` file.
    fmus : dict of str to Path
        Each component's FMU.
    notes : list of str
        Where the SSP differs from the scenario (e.g. the noise generator).
    """

    ssd: Path
    archive: Path
    fmus: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)


def _value_xml(kind: str, value) -> str:
    if kind == "boolean":
        return f'<ssv:Boolean value="{"true" if value else "false"}"/>'
    if kind == "integer":
        return f'<ssv:Integer value="{int(value)}"/>'
    return f'<ssv:Real value="{float(value)!r}"/>'


def _ssd_text(name: str, components, exported: dict[str, ExportedFMU], descriptions: dict, connections: dict,
              start_time: float, stop_time: float | None, description: str, step_size: float) -> str:
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<ssd:SystemStructureDescription xmlns:ssd="{NS["ssd"]}" xmlns:ssc="{NS["ssc"]}" '
             f'xmlns:ssv="{NS["ssv"]}" xmlns:pc="{_PC_NS}" version="1.0"{xml_attrs(name=name)}'
             f'{xml_attrs(generationTool=f"pendulum-cosim {VERSION}")}>',
             f"  <ssd:System{xml_attrs(name=name, description=description or None)}>"]
    params = []
    for c in components:
        variables = {v.name: v for v in descriptions[c.name].modelVariables}
        for key, value in exported[c.name].parameters.items():
            params.append((f"{c.name}.{key}", PORT_TYPES[variables[key].type], value))
    if params:
        lines += ["    <ssd:ParameterBindings>", "      <ssd:ParameterBinding>", "        <ssd:ParameterValues>",
                  '          <ssv:ParameterSet version="1.0" name="parameters">', "            <ssv:Parameters>"]
        lines += [f"              <ssv:Parameter{xml_attrs(name=n)}>{_value_xml(k, v)}</ssv:Parameter>"
                  for n, k, v in params]
        lines += ["            </ssv:Parameters>", "          </ssv:ParameterSet>", "        </ssd:ParameterValues>",
                  "      </ssd:ParameterBinding>", "    </ssd:ParameterBindings>"]
    lines.append("    <ssd:Elements>")
    for c in components:
        variables = {v.name: v for v in descriptions[c.name].modelVariables}
        lines.append(f'      <ssd:Component{xml_attrs(name=c.name, type="application/x-fmu-sharedlibrary")}'
                     f'{xml_attrs(source=f"resources/{c.name}.fmu")}>')
        conns = [(p, "input") for p in c.input_names if p in variables]
        conns += [(p, "output") for p in c.output_names if p in variables]
        if conns:
            lines.append("        <ssd:Connectors>")
            lines += [f"          <ssd:Connector{xml_attrs(name=p, kind=k)}>"
                      f"<ssc:{_SSP_TYPES[PORT_TYPES[variables[p].type]]}/></ssd:Connector>" for p, k in conns]
            lines.append("        </ssd:Connectors>")
        lines += ["        <ssd:Annotations>",
                  f'          <ssc:Annotation type="{ANNOTATION}"><pc:Timing{xml_attrs(period=repr(c.period))}/>'
                  "</ssc:Annotation>",
                  "        </ssd:Annotations>", "      </ssd:Component>"]
    lines.append("    </ssd:Elements>")
    if connections:
        lines.append("    <ssd:Connections>")
        for (dc, dp), (sc, sp) in connections.items():
            lines.append(f"      <ssd:Connection{xml_attrs(startElement=sc, startConnector=sp, endElement=dc)}"
                         f"{xml_attrs(endConnector=dp)}/>")
        lines.append("    </ssd:Connections>")
    lines += ["    <ssd:Annotations>",
              f'      <ssc:Annotation type="{OMS_ANNOTATION}">',
              f'        <oms:Annotations xmlns:oms="{_OMS_NS}">',
              "          <oms:SimulationInformation>",
              f"            <oms:FixedStepMaster{xml_attrs(description='oms-ma', stepSize=repr(float(step_size)))}"
              f"{xml_attrs(relativeTolerance='1e-4')}/>",
              "          </oms:SimulationInformation>",
              "        </oms:Annotations>",
              "      </ssc:Annotation>",
              "    </ssd:Annotations>"]
    lines += ["  </ssd:System>",
              f"  <ssd:DefaultExperiment{xml_attrs(startTime=repr(float(start_time)))}"
              f"{xml_attrs(stopTime=None if stop_time is None else repr(float(stop_time)))}/>",
              "</ssd:SystemStructureDescription>"]
    return "\n".join(lines) + "\n"


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
    system : Scenario or Cosimulation
        What to export (a :class:`cosim.scenario.Scenario` brings its start and stop
        time and title).
    out_dir : path
        Folder for ``SystemStructure.ssd``, ``resources/`` and ``<name>.ssp`` (created if
        missing; those files are replaced, nothing else is touched).
    fmi_version : {2, 3}
        FMI version of the FMUs the export builds (FMU files of ``fmu`` components are
        copied as they are). fmpy simulates SSPs of FMI 2.0 FMUs only.
    name : str, optional
        System name and archive name (default ``system``).
    stop_time : float, optional
        The ``DefaultExperiment`` stop time (default the scenario's).
    platforms : sequence of str, optional
        Platforms to cross-compile every FMU for besides this one
        (:func:`fmu_models.export.platforms.add_platforms`; needs the ``cross`` extra).
    clocked : bool
        Write the estimators and signal FMUs in their clocked form (FMI 3.0 only,
        :mod:`fmu_models.export.clocked`): each has an input clock ``sample`` at its sample
        period, which an FMI 3.0 importer schedules from the FMU itself (no clock connection
        in the SSD); components without a clocked form are written unclocked (a note says so).

    Raises
    ------
    ConfigurationError
        Components without an FMU form (all named at once), a connection to a port the
        exported FMU lacks, or ``clocked`` with FMI 2.0.
    """
    check_clocked(clocked, fmi_version, "the SSP")

    cosim = system if isinstance(system, Cosimulation) else system.cosim
    start = getattr(system, "start_time", 0.0)
    stop = stop_time if stop_time is not None else getattr(system, "stop_time", None)
    title = getattr(system, "title", "")
    name = name or "system"
    if not name.replace("-", "_").isidentifier():
        raise ConfigurationError(f"SSP name {name!r} must be letters, digits, '_' or '-'")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=out_dir, prefix=".ssp-") as tmp:
        tmp = Path(tmp)
        resources = tmp / "resources"
        resources.mkdir()
        exported, refused = {}, []
        for c in cosim.components:
            if not isinstance(c, ExportsFMU):
                refused.append(f"component {c.name!r} ({type(c).__name__}) has no FMU form")
                continue
            try:
                exported[c.name] = export_component(c, resources, fmi_version, clocked)
            except ConfigurationError as e:
                refused.append(str(e))
        if refused:
            raise ConfigurationError("cannot export as an SSP: " + "; ".join(refused))
        platform_notes = []
        for n, e in exported.items():
            if platforms:
                try:
                    platform_notes += add_platforms(e.path, platforms)
                except FMUError as err:
                    raise FMUError(f"component {n!r}: {err}") from None
        descriptions = {n: read_description(e.path) for n, e in exported.items()}
        for (dc, dp), (sc, sp) in cosim.connections.items():
            for comp, port, kind in ((sc, sp, "output"), (dc, dp, "input")):
                have = {v.name for v in descriptions[comp].modelVariables if v.causality == kind}
                if port not in have:
                    raise ConfigurationError(f"cannot export as an SSP: the FMU of {comp!r} has no {kind} {port!r} "
                                             f"(connection {sc}.{sp} -> {dc}.{dp}); its {kind}s: "
                                             f"{', '.join(sorted(have))}")
        step = float(base_step({c.name: c.period for c in cosim.components})[0])
        text = _ssd_text(name, cosim.components, exported, descriptions, cosim.connections, start, stop, title, step)
        (tmp / "SystemStructure.ssd").write_text(text, encoding="utf-8")
        archive = tmp / f"{name}.ssp"
        with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as z:
            z.write(tmp / "SystemStructure.ssd", "SystemStructure.ssd")
            for c in cosim.components:
                z.write(resources / f"{c.name}.fmu", f"resources/{c.name}.fmu")
        (out_dir / "resources").mkdir(exist_ok=True)
        for c in cosim.components:
            os.replace(resources / f"{c.name}.fmu", out_dir / "resources" / f"{c.name}.fmu")
        os.replace(tmp / "SystemStructure.ssd", out_dir / "SystemStructure.ssd")
        os.replace(archive, out_dir / f"{name}.ssp")
    return SSPExport(out_dir / "SystemStructure.ssd", out_dir / f"{name}.ssp",
                     {c.name: out_dir / "resources" / f"{c.name}.fmu" for c in cosim.components},
                     [e.note for e in exported.values() if e.note] + platform_notes)


# ---------------------------------------------------------------------------- reading
@dataclass
class SSPSystem:
    """An SSP opened by :func:`open_ssp`.

    Attributes
    ----------
    cosim : Cosimulation
        The system's FMUs, connections and parameters in the project's master.
    start_time, stop_time : float or None
        From the SSD's ``DefaultExperiment``.
    name : str
    step_size : float or None
        The communication step of OMSimulator's annotation (``oms:FixedStepMaster``), if any.
    """

    cosim: object
    start_time: float | None
    stop_time: float | None
    name: str
    step_size: float | None = None

    def run(self, stop_time: float | None = None, **kw):
        """Run to ``stop_time`` (default the SSD's) from the SSD's start time; keywords go
        to :meth:`cosim.core.master.Cosimulation.run`. Returns the results DataFrame."""
        stop = stop_time if stop_time is not None else self.stop_time
        if stop is None:
            raise ConfigurationError(f"{self.name}: the SSD has no stop time; give stop_time")
        return self.cosim.run(stop, self.start_time or 0.0, **kw)


def _q(tag: str) -> str:
    prefix, local = tag.split(":")
    return f"{{{NS[prefix]}}}{local}"


def _value(p: ET.Element, where: str):
    for tag, conv in (("ssv:Real", float), ("ssv:Integer", int), ("ssv:Boolean", lambda s: s == "true")):
        e = p.find(tag, NS)
        if e is not None:
            try:
                return conv(e.get("value"))
            except (TypeError, ValueError):
                raise ConfigurationError(f"{where}: parameter {p.get('name')!r} has the bad value "
                                         f"{e.get('value')!r}") from None
    raise ConfigurationError(f"{where}: parameter {p.get('name')!r} is not Real, Integer or Boolean")


def _bindings(element: ET.Element, where: str) -> list[tuple[str, object]]:
    out = []
    for b in element.findall("ssd:ParameterBindings/ssd:ParameterBinding", NS):
        if b.get("source"):
            raise ConfigurationError(f"{where}: parameter files (source={b.get('source')!r}) are not supported; "
                                     "give the values inline")
        if b.find("ssd:ParameterMapping", NS) is not None:
            raise ConfigurationError(f"{where}: parameter mappings are not supported")
        for p in b.findall("ssd:ParameterValues/ssv:ParameterSet/ssv:Parameters/ssv:Parameter", NS):
            out.append((p.get("name"), _value(p, where)))
    return out


def _number(text, what: str) -> float:
    """An attribute as a finite float, or a ConfigurationError naming ``what``."""

    return finite(text, what)


#: The largest SystemStructure.ssd read (checked before parsing; an SSD of a few hundred
#: components is well under 1 MiB).
MAX_SSD_BYTES = 16 * 2**20


def _parse_ssd(ssd_file: Path) -> ET.Element:
    """Parse the SSD, refusing an oversized one before reading it, in 1 MiB pieces (Ctrl-C
    is seen between them)."""
    size = ssd_file.stat().st_size
    if size > MAX_SSD_BYTES:
        raise FMUError(f"{ssd_file.name}: {size / 2**20:.0f} MiB, more than {MAX_SSD_BYTES // 2**20} MiB for a "
                       "system structure description; refused before parsing")
    parser = ET.XMLParser()
    try:
        with open(ssd_file, "rb") as f:
            while chunk := f.read(1 << 20):
                parser.feed(chunk)
        return parser.close()
    except ET.ParseError as e:
        raise FMUError(f"{ssd_file.name}: not valid XML: {e}") from None


def _period(comp: ET.Element, md, name: str) -> float:
    for a in comp.findall("ssd:Annotations/ssc:Annotation", NS):
        if a.get("type") == ANNOTATION:
            t = a.find(f"{{{_PC_NS}}}Timing")
            if t is not None and t.get("period"):
                return _number(t.get("period"), f"component {name!r}: the period of its {ANNOTATION} annotation")
    step = getattr(md.defaultExperiment, "stepSize", None) if md.defaultExperiment else None
    if step:
        return _number(step, f"component {name!r}: its FMU's DefaultExperiment stepSize")
    raise ConfigurationError(f"component {name!r}: no sample period (no {ANNOTATION} annotation and no "
                             "DefaultExperiment stepSize in its FMU)")


def _oms_step(system: ET.Element, where: str) -> float | None:
    for a in system.findall("ssd:Annotations/ssc:Annotation", NS):
        if a.get("type") == OMS_ANNOTATION:
            master = a.find(f".//{{{_OMS_NS}}}FixedStepMaster")
            if master is not None and master.get("stepSize"):
                return _number(master.get("stepSize"), f"{where}: the stepSize of its {OMS_ANNOTATION} annotation")
    return None


@contextlib.contextmanager
def open_ssp(path, communication_step: float | None = None) -> Iterator[SSPSystem]:
    """Open the SSP at ``path`` (a ``.ssp`` archive, its unpacked folder, or its
    ``SystemStructure.ssd``) as an :class:`.SSPSystem`; a context manager that removes what
    it unpacked.

    ``communication_step`` [s], if given, steps every FMU with that one step instead of its
    own period, as a tool with a single fixed-step master does (the project's FMUs keep
    their own sample instants under any step).

    Each ``Component`` becomes an :class:`~cosim.fmi.fmu_component.FMUComponent` with its
    connectors as ports, the parameter bindings (inline values, system or component
    level) as parameters and start values, and the period of the
    ``org.pendulum-cosim`` annotation (else the FMU's default step size).

    Raises
    ------
    FMUError
        A missing, damaged or hostile archive.
    ConfigurationError
        What this reader does not support (nested systems, parameter files or mappings,
        transformations, connections to the system's own connectors), named.
    """


    if communication_step is not None:
        communication_step = positive(communication_step, "open_ssp: communication_step [s]")
    path = Path(path)
    extraction = None
    if path.is_dir():
        root = path
    elif path.name.endswith(".ssd"):
        root = path.parent
    else:
        extraction = Extraction(path, required="SystemStructure.ssd", label="SSP")
        root = Path(extraction.directory)
    try:
        ssd_file = path if path.name.endswith(".ssd") else root / "SystemStructure.ssd"
        if not ssd_file.is_file():
            raise FMUError(f"{path} holds no SystemStructure.ssd")
        tree = _parse_ssd(ssd_file)
        where = ssd_file.name
        system = tree.find("ssd:System", NS)
        if tree.tag != _q("ssd:SystemStructureDescription") or system is None:
            raise FMUError(f"{where}: not an SSP 1.0 system structure description")
        if system.find("ssd:Elements/ssd:System", NS) is not None:
            raise ConfigurationError(f"{where}: nested systems are not supported")
        params: dict[str, dict] = {}
        for full, value in _bindings(system, where):
            comp, _, var = (full or "").partition(".")
            params.setdefault(comp, {})[var] = value
        components = []
        for comp in system.findall("ssd:Elements/ssd:Component", NS):
            cname, source = comp.get("name"), comp.get("source")
            if not cname or not source:
                raise ConfigurationError(f"{where}: a Component without {'a name' if not cname else 'a source'} "
                                         f"({'source ' + repr(source) if source else 'name ' + repr(cname)}); "
                                         "every Component needs name and source (its FMU)")
            kind = comp.get("type", "application/x-fmu-sharedlibrary")
            if kind != "application/x-fmu-sharedlibrary":
                raise ConfigurationError(f"component {cname!r}: type {kind!r} is not an FMU")
            fmu = (root / source).resolve()
            if root.resolve() not in fmu.parents:
                raise FMUError(f"component {cname!r}: source {source!r} points outside the SSP")
            md = read_description(fmu)
            conns = comp.findall("ssd:Connectors/ssd:Connector", NS)
            values = {**{k: v for k, v in _bindings(comp, where)}, **params.get(cname, {})}
            components.append(FMUComponent(
                cname, fmu, communication_step or _period(comp, md, cname),
                inputs=[c.get("name") for c in conns if c.get("kind") == "input"],
                outputs=[c.get("name") for c in conns if c.get("kind") == "output"],
                parameters=values))
        wiring = []
        for c in system.findall("ssd:Connections/ssd:Connection", NS):
            if c.get("startElement") is None or c.get("endElement") is None:
                raise ConfigurationError(f"{where}: connections to the system's own connectors are not supported")
            if len(c):
                raise ConfigurationError(f"{where}: transformations on connections are not supported "
                                         f"({c.get('startElement')}.{c.get('startConnector')})")
            wiring.append((f"{c.get('startElement')}.{c.get('startConnector')}",
                           f"{c.get('endElement')}.{c.get('endConnector')}"))
        exp = tree.find("ssd:DefaultExperiment", NS)
        start = _number(exp.get("startTime"), f"{where}: DefaultExperiment startTime") \
            if exp is not None and exp.get("startTime") else None
        stop = _number(exp.get("stopTime"), f"{where}: DefaultExperiment stopTime") \
            if exp is not None and exp.get("stopTime") else None
        yield SSPSystem(Cosimulation(components, wiring), start, stop, tree.get("name", "system"),
                        _oms_step(system, where))
    finally:
        if extraction is not None:
            extraction.close()


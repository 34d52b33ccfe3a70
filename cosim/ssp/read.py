"""An SSP 1.0 opened in the project's master (:func:`open_ssp`) and run in one call (:func:`run_ssp`);
what is read and what is refused: the user guide's page on third-party FMUs."""
from __future__ import annotations

import contextlib
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from fmu_models.errors import ConfigurationError, FMUError
from fmu_models.infra.checks import finite, positive

from ..components.conversion import Conversion
from ..core.master import Cosimulation
from ..fmi.archive import Extraction
from ..fmi.fmu_component import FMUComponent
from .export import ANNOTATION, OMS_ANNOTATION, OMS_NS, PC_NS
from .schema import NS, parse_xml, q
from .system import Element, FlatSystem, Link, _items

__all__ = ["SSPSystem", "open_ssp", "run_ssp"]

_INTERFACES = {"any": "auto", "CoSimulation": "cs", "ModelExchange": "me", "ScheduledExecution": "se"}


@dataclass
class SSPSystem:
    """An SSP opened by :func:`open_ssp`.

    Attributes
    ----------
    cosim, name : Cosimulation, str
        The system's FMUs, connections and parameters in the project's master; the system's name.
    start_time, stop_time, step_size : float or None
        [s] The SSD's ``DefaultExperiment``; the step of OMSimulator's ``oms:FixedStepMaster``, if any.
    names : dict of str to str
        Each FMU component's SSD path (element names joined by dots) -> its component name.
    """

    cosim: object
    start_time: float | None
    stop_time: float | None
    name: str
    step_size: float | None = None
    names: dict = field(default_factory=dict)

    def run(self, stop_time: float | None = None, **kw):
        """Run to ``stop_time`` (default the SSD's) from the SSD's start time; keywords go
        to :meth:`cosim.core.master.Cosimulation.run`. Returns the results DataFrame."""
        stop = stop_time if stop_time is not None else self.stop_time
        if stop is None:
            raise ConfigurationError(f"{self.name}: the SSD has no stop time; give stop_time")
        return self.cosim.run(stop, self.start_time or 0.0, **kw)


def _annotation(node, kind: str, tag: str):
    found = (a.find(f".//{tag}") for a in node.findall("ssd:Annotations/ssc:Annotation", NS) if a.get("type") == kind)
    return next((f for f in found if f is not None), None)


def _period(elem: Element, oms_step: float | None, step_size: float | None) -> float:
    label = ".".join(elem.path)
    t = _annotation(elem.node, ANNOTATION, f"{{{PC_NS}}}Timing")
    if t is not None and t.get("period"):
        return finite(t.get("period"), f"component {label!r}: the period of its {ANNOTATION} annotation")
    exp = elem.md.defaultExperiment
    if exp is not None and exp.stepSize:
        return finite(exp.stepSize, f"component {label!r}: its FMU's DefaultExperiment stepSize")
    for step in (oms_step, step_size):
        if step is not None:
            return step
    raise ConfigurationError(f"component {label!r}: no communication step (no {ANNOTATION} annotation, no "
                             "DefaultExperiment stepSize in its FMU, no FixedStepMaster step in the SSD); give one "
                             "(step_size, or --step-size on the command line)")


def _table_of(link: Link, variables) -> dict:
    """The mapping tables of ``link``'s steps composed into one table of the source's values."""
    table = None
    for s in link.steps:
        entries = dict(s.table)
        if s.kind == "enumeration":
            items = [_items(v) for v in variables]
            missing = [n for pair in entries.items() for n, known in zip(pair, items) if n not in known]
            if missing:
                raise ConfigurationError(f"connection {'.'.join(link.src)} -> {'.'.join(link.dst)}: the enumeration "
                                         f"mapping names {missing[0]!r}, not an item of the connected variables")
            entries = {items[0][a]: items[1][b] for a, b in entries.items()}
        else:
            entries = {int(a): int(b) for a, b in entries.items()}
        table = entries if table is None else {k: entries[v] for k, v in table.items() if v in entries}
    return table


def _conversion(link: Link, period: float, variables) -> Conversion:
    """The component that carries ``link``'s steps (unit conversions, transformations)."""
    types = {"input_type": variables[0].type, "output_type": variables[1].type}
    name = f"{link.dst[0]}_{''.join(ch if ch.isalnum() else '_' for ch in link.dst[1])}_conversion"
    kinds = {s.kind == "linear" for s in link.steps}
    if kinds == {True}:
        a, b = 1.0, 0.0
        for s in link.steps:
            a, b = s.factor * a, s.factor * b + s.offset
        return Conversion(name, period, a, b, **types)
    if kinds == {False}:
        return Conversion(name, period, table=_table_of(link, variables), **types)
    raise ConfigurationError(f"connection {'.'.join(link.src)} -> {'.'.join(link.dst)}: a linear transformation or "
                             "unit conversion and a mapping on one path cannot be combined")


def _components(flat: FlatSystem, communication_step, oms_step, step_size) -> tuple[list, list]:
    """The FMU components, the conversions and the wiring of the flattened system."""
    sources = {link.src for link in flat.links}
    fmus, elements = {}, {e.name: e for e in flat.elements.values()}
    for elem in elements.values():
        kind = elem.node.get("implementation", "any")
        if kind not in _INTERFACES:
            raise ConfigurationError(f"component {'.'.join(elem.path)!r}: implementation {kind!r} is not one of "
                                     f"{', '.join(_INTERFACES)}")
        outs = [c for c, k in elem.connectors.items() if k == "output" or (elem.name, c) in sources]
        fmus[elem.name] = FMUComponent(elem.name, elem.fmu, communication_step or _period(elem, oms_step, step_size),
                                       inputs=[c for c, k in elem.connectors.items() if k == "input"], outputs=outs,
                                       parameters=elem.parameters, interface=_INTERFACES[kind])
    components, wiring = list(fmus.values()), []
    for link in flat.links:
        if not link.steps:
            wiring.append((".".join(link.src), ".".join(link.dst)))
            continue
        variables = [elements[n].variable(port) for n, port in (link.src, link.dst)]
        conv = _conversion(link, fmus[link.dst[0]].period, variables)
        components.append(conv)
        wiring += [(".".join(link.src), f"{conv.name}.u"), (f"{conv.name}.y", ".".join(link.dst))]
    return components, wiring


def _apply_start(flat: FlatSystem, start: Mapping) -> None:
    """Values by hierarchical SSD name (or ``component.variable`` with the component's name
    in the master) over the SSP's own."""
    by_name = {e.name: e for e in flat.elements.values()}
    for key, value in start.items():
        target = flat.resolve(key)
        if target is None:
            comp, _, var = str(key).partition(".")
            target = (by_name[comp], var) if comp in by_name and by_name[comp].variable(var) is not None else None
        if target is None:
            raise ConfigurationError(f"start value {key!r}: no such variable in the SSP; write it "
                                     "component.variable (components: " + ", ".join(by_name) + ")")
        target[0].parameters[target[1]] = value


def _locate(path: Path) -> tuple[Path, Path, Extraction | None]:
    """The SSD file, the SSP's folder, and the extraction to remove (for an archive)."""
    if path.is_dir():
        return path / "SystemStructure.ssd", path, None
    if path.name.endswith(".ssd"):
        return path, path.parent, None
    extraction = Extraction(path, required="SystemStructure.ssd", label="SSP")
    root = Path(extraction.directory)
    return root / "SystemStructure.ssd", root, extraction


@contextlib.contextmanager
def open_ssp(path, communication_step: float | None = None, step_size: float | None = None,
             start: Mapping | None = None) -> Iterator[SSPSystem]:
    """Open the SSP at ``path`` as an :class:`.SSPSystem`; a context manager that removes
    what it unpacked.

    Parameters
    ----------
    path : str or Path
        A ``.ssp`` archive, its unpacked folder, or its ``.ssd`` file.
    communication_step : float, optional
        [s] One step for every FMU instead of its own period (as a single fixed-step master).
    step_size : float, optional
        [s] The step of the FMUs whose period the SSP does not give (its own annotation, the
        FMU's ``DefaultExperiment``, OMSimulator's ``FixedStepMaster``, first given first).
    start : mapping, optional
        Parameter and start values over the SSP's own, by hierarchical name
        (``Element.variable``, systems' names first) or ``component.variable``.

    Raises
    ------
    FMUError
        A missing, damaged or hostile archive or file.
    ConfigurationError
        What this reader does not support, or a name, unit or value it cannot resolve.
    """
    if communication_step is not None:
        communication_step = positive(communication_step, "open_ssp: communication_step [s]")
    if step_size is not None:
        step_size = positive(step_size, "open_ssp: step_size [s]")
    path = Path(path)
    if not path.exists():
        raise FMUError(f"no SSP file {path}")
    ssd_file, root, extraction = _locate(path)
    try:
        if not ssd_file.is_file():
            raise FMUError(f"{path} holds no SystemStructure.ssd")
        document = parse_xml(ssd_file, "a system structure description")
        where = ssd_file.name
        system = document.find("ssd:System", NS)
        if document.tag != q("ssd:SystemStructureDescription") or system is None:
            raise FMUError(f"{where}: not an SSP 1.0 system structure description")
        flat = FlatSystem(document, ssd_file.parent, root, where)
        _apply_start(flat, start or {})
        master = _annotation(system, OMS_ANNOTATION, f"{{{OMS_NS}}}FixedStepMaster")
        oms = (finite(master.get("stepSize"), f"{where}: the stepSize of its {OMS_ANNOTATION} annotation")
               if master is not None and master.get("stepSize") else None)
        components, wiring = _components(flat, communication_step, oms, step_size)
        exp = document.find("ssd:DefaultExperiment", NS)
        times = [finite(exp.get(a), f"{where}: DefaultExperiment {a}") if exp is not None and exp.get(a) else None
                 for a in ("startTime", "stopTime")]
        yield SSPSystem(Cosimulation(components, wiring), *times, document.get("name", "system"), oms, flat.names)
    finally:
        if extraction is not None:
            extraction.close()


def run_ssp(path, stop_time: float | None = None, *, step_size: float | None = None,
            communication_step: float | None = None, start: Mapping | None = None,
            outputs: Sequence[str] | None = None, output_interval: float | None = None):
    """Open the SSP at ``path``, run it and return the recorded signals (a DataFrame indexed
    by ``time`` [s], one column per signal).

    Parameters
    ----------
    path, step_size, communication_step, start
        As :func:`open_ssp` takes them.
    stop_time, output_interval : float, optional
        [s] Default: the SSD's ``DefaultExperiment`` stop time; record every this many seconds (a multiple
        of the base step).
    outputs : sequence of str, optional
        Glob patterns of the signals to record (``component.port``); default all.
    """
    with open_ssp(path, communication_step, step_size, start) as system:
        return system.run(stop_time, signals=outputs, output_interval=output_interval, progress=False)

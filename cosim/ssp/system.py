"""An SSP 1.0 system structure flattened for the master: nested systems dissolved into their FMU
components, each FMU input followed back to the FMU output that drives it, and the parameter bindings
resolved to component variables (the rules: the user guide's page on third-party FMUs)."""
from __future__ import annotations

import logging
import re
from dataclasses import dataclass, field
from pathlib import Path

from fmu_models.errors import ConfigurationError, FMUError

from ..fmi.archive import read_description
from .parameters import Value, binding_values
from .schema import BASE_UNITS, NS, Transformation, Unit, read_units, unit_factor

__all__ = ["Element", "FlatSystem", "Link"]

LOG = logging.getLogger("cosim.ssp")
FMU_TYPE = "application/x-fmu-sharedlibrary"
#: Connector kinds that may start a connection at an FMU component (its outputs).
SOURCE_KINDS = ("output", "local")


@dataclass
class Element:
    """An FMU component of the flattened system.

    Attributes
    ----------
    path, name : tuple of str, str
        Its SSD element names from the top system down; its component name in the master.
    fmu, node, md
        Its FMU file, its ``ssd:Component`` and the FMU's fmpy model description.
    connectors, parameters : dict
        Connector name -> kind; the resolved parameter and start values by variable name.
    """

    path: tuple
    name: str
    fmu: Path
    node: object
    md: object
    connectors: dict
    parameters: dict = field(default_factory=dict)

    def variable(self, name: str):
        """The FMU variable ``name`` or None."""
        return next((v for v in self.md.modelVariables if v.name == name), None)


@dataclass
class Link:
    """A connection of the flattened system: FMU output ``src`` to FMU input ``dst`` (each
    ``(component name, connector)``), through the ``steps`` met on the way, in order."""

    src: tuple
    dst: tuple
    steps: list


def _items(variable) -> dict[str, int]:
    """An FMU variable's enumeration items by name (none for other types)."""
    return {i.name: int(i.value) for i in getattr(variable.declaredType, "items", None) or []}


def _identifier(text: str) -> str:
    name = re.sub(r"\W", "_", text, flags=re.ASCII)
    return f"c_{name}" if not name or name[0].isdigit() else name


def _variable_unit(element: Element | None, connector: str) -> Unit | None:
    """The unit of an FMU variable, from the FMU's own unit definitions."""
    v = element.variable(connector) if element is not None else None
    name = v is not None and (v.unit or getattr(v.declaredType, "unit", None))
    if not name:
        return None
    for u in element.md.unitDefinitions or []:
        if u.name == name and u.baseUnit is not None:
            b = u.baseUnit
            return Unit(name, tuple(getattr(b, k) for k in BASE_UNITS), b.factor, b.offset)
    return Unit(name, ())


def _conversion(src: Unit | None, dst: Unit | None, where: str) -> Transformation | None:
    """The conversion of a value in unit ``src`` to unit ``dst`` (None: the same unit, or one of
    them unknown); units of different names must both be defined."""
    if src is None or dst is None or src.name == dst.name:
        return None
    undefined = [u.name for u in (src, dst) if not u.exponents]
    if undefined:
        raise ConfigurationError(f"{where}: unit {src.name!r} would be converted to {dst.name!r}, but "
                                 f"{undefined[0]!r} has no definition (no BaseUnit in the SSD or the FMU)")
    return Transformation("linear", *unit_factor(src, dst, where))


class FlatSystem:
    """The SSD's top system flattened (see the third-party FMUs page of the documentation).

    Parameters
    ----------
    document : Element
        The ``ssd:SystemStructureDescription``.
    base, root : Path
        The SSD's folder (relative sources are resolved against it); the SSP's (no source may leave it).
    where : str
        The SSD's name, for messages.

    Attributes
    ----------
    elements, names : dict
        The FMU components (:class:`Element`) by SSD path; SSD path (dotted) -> component name.
    links : list of Link
    """

    def __init__(self, document, base: Path, root: Path, where: str):
        self.base, self.root, self.where = base, root, where
        self.units = read_units(document.find("ssd:Units", NS), where)
        self.elements: dict[tuple, Element] = {}
        self.systems: dict[tuple, object] = {}
        self.connectors: dict[tuple, tuple[str, str | None]] = {}     # node -> (kind, SSD unit)
        self.edges: dict[tuple, tuple[tuple, list]] = {}               # node -> (source node, steps)
        self.names: dict[str, str] = {}
        self._walk(document.find("ssd:System", NS), ())
        inputs = [(path, c) for path, e in self.elements.items() for c, k in e.connectors.items()
                  if k == "input" and (path, c) in self.edges]
        self.links = [link for node in inputs if (link := self._link(node)) is not None]
        self._parameters()

    def _walk(self, system, path: tuple) -> None:
        self.systems[path] = system
        self._read_connectors(system, path)
        for child in system.findall("ssd:Elements/*", NS):
            tag = child.tag.rpartition("}")[2]
            name = child.get("name")
            if not name:
                raise ConfigurationError(f"{self.where}: a {tag} without a name in system "
                                         f"{'.'.join(path) or system.get('name')!r}")
            if tag == "System":
                self._walk(child, path + (name,))
            elif tag == "Component":
                self._component(child, path + (name,))
            else:
                raise ConfigurationError(f"{self.where}: element {name!r} is a {tag}, which is not read (only "
                                         "Components that are FMUs, and Systems)")
        for c in system.findall("ssd:Connections/ssd:Connection", NS):
            self._connection(c, path)

    def _read_connectors(self, node, path: tuple) -> None:
        for c in node.findall("ssd:Connectors/ssd:Connector", NS):
            real = next((e for e in c if e.tag in (f"{{{NS['ssc']}}}Real", f"{{{NS['ssc']}}}Float64")), None)
            unit = real.get("unit") if real is not None else None
            if unit is not None and unit not in self.units:
                raise ConfigurationError(f"{self.where}: connector {c.get('name')!r} of {'.'.join(path)!r} names the "
                                         f"unit {unit!r}, which the SSD's Units do not define")
            self.connectors[(path, c.get("name"))] = (c.get("kind", ""), unit)

    def _component(self, node, path: tuple) -> None:
        label = ".".join(path)
        source, kind = node.get("source"), node.get("type", FMU_TYPE)
        if kind != FMU_TYPE:
            raise ConfigurationError(f"component {label!r}: type {kind!r} is not an FMU (a Component that "
                                     "references another SSD or SSP is not read; give it as a nested System)")
        if not source:
            raise ConfigurationError(f"{self.where}: component {label!r} without a source (its FMU)")
        fmu = (self.base / source).resolve()
        if self.root.resolve() not in fmu.parents:
            raise FMUError(f"component {label!r}: source {source!r} points outside the SSP")
        name = base = _identifier("_".join(path))
        n = 1
        while name in self.names.values():
            n += 1
            name = f"{base}_{n}"
        self.names[label] = name
        self._read_connectors(node, path)
        conns = {c: k for (p, c), (k, _) in self.connectors.items() if p == path}
        self.elements[path] = Element(path, name, fmu, node, read_description(fmu), conns)

    def _connection(self, c, path: tuple) -> None:
        ends = []
        for side in ("start", "end"):
            elem, conn = c.get(f"{side}Element"), c.get(f"{side}Connector")
            node = (path + (elem,) if elem else path, conn)
            if conn is None or node not in self.connectors:
                raise ConfigurationError(f"{self.where}: connection {self._label(c)} names a connector that "
                                         f"{'.'.join(node[0]) or 'the system'!s} does not declare")
            ends.append(node)
        src, dst = ends
        for node, allowed, word in ((src, SOURCE_KINDS, "starts at an output"), (dst, ("input",), "ends at an input")):
            kind = self.connectors[node][0]
            if node[0] in self.elements and kind not in allowed:
                raise ConfigurationError(f"{self.where}: {'.'.join((*node[0], node[1]))} is an {kind or 'untyped'} "
                                         f"connector; a connection {word} of a component")
        if dst in self.edges:
            raise ConfigurationError(f"{self.where}: {'.'.join((*dst[0], dst[1]))} is connected twice")
        where = f"{self.where}: connection {self._label(c)}"
        steps = []                                  # each may be None: nothing to do
        if c.get("suppressUnitConversion", "false") not in ("true", "1"):
            steps.append(_conversion(self._unit(src), self._unit(dst), where))
        steps.append(Transformation.read(c, where))
        self.edges[dst] = (src, [step for step in steps if step is not None])

    @staticmethod
    def _label(c) -> str:
        return " -> ".join(".".join(filter(None, (c.get(f"{side}Element"), str(c.get(f"{side}Connector")))))
                           for side in ("start", "end"))

    def _unit(self, node) -> Unit | None:
        name = self.connectors[node][1]
        return self.units[name] if name is not None else _variable_unit(self.elements.get(node[0]), node[1])

    def _link(self, dst: tuple) -> Link | None:
        """The FMU output that drives the FMU input ``dst``, followed back through system
        connectors (None: it ends at an unconnected system connector)."""
        node, steps, seen = dst, [], {dst}
        while True:
            src, hop = self.edges[node]
            steps[:0] = hop
            if src in seen:
                raise ConfigurationError(f"{self.where}: the connections through {'.'.join((*src[0], src[1]))} "
                                         "form a cycle")
            seen.add(src)
            if src[0] in self.elements:
                break
            if src not in self.edges:
                return None
            node = src
        return Link((self.elements[src[0]].name, src[1]), (self.elements[dst[0]].name, dst[1]), steps)

    def _parameters(self) -> None:
        holders = [*self.systems.items(), *((path, e.node) for path, e in self.elements.items())]
        for path, node in sorted(holders, key=lambda h: -len(h[0])):      # the deepest first: higher levels win
            for i, b in enumerate(node.findall("ssd:ParameterBindings/ssd:ParameterBinding", NS)):
                where = f"{self.where}: parameter binding {i + 1} of {'.'.join(path) or 'the system'}"
                for value in binding_values(b, self.base, self.root, where):
                    self._apply(path, value)

    def _apply(self, path: tuple, value: Value) -> None:
        target = self._resolve(path, value.name)
        if target is None:
            LOG.warning("%s: parameter %r reaches no variable; ignored", value.where, value.name)
            return
        elem, var = target
        if isinstance(elem, tuple):                     # a system connector: the FMU variables it drives
            for dst, (src, steps) in self.edges.items():
                if src == (elem, var) and dst[0] in self.elements:
                    self._set(self.elements[dst[0]], dst[1], value, steps)
            return
        self._set(elem, var, value, [])

    def resolve(self, name: str) -> tuple[Element, str] | None:
        """The component variable that the hierarchical ``name`` (from the top system) reaches,
        or None."""
        target = self._resolve((), name)
        return target if target is not None and isinstance(target[0], Element) else None

    def _resolve(self, path: tuple, name: str):
        """``(Element, variable)`` or ``(system path, connector)`` that ``name`` reaches from
        the element at ``path``, or None."""
        if path in self.elements:
            return (self.elements[path], name) if self.elements[path].variable(name) is not None else None
        names = [k[-1] for k in list(self.elements) + list(self.systems) if len(k) == len(path) + 1 and k[:-1] == path]
        for e in sorted(names, key=len, reverse=True):
            if name.startswith(e + "."):
                return self._resolve(path + (e,), name[len(e) + 1:])
        return (path, name) if (path, name) in self.connectors else None

    def _set(self, elem: Element, var: str, value: Value, steps: list) -> None:
        v = elem.variable(var)
        x = value.value
        where = f"{value.where}: parameter {value.name!r}"
        if value.kind == "enumeration":
            items = _items(v)
            if x not in items:
                raise ConfigurationError(f"{where}: {x!r} is not an item of {var!r} ({', '.join(items)})")
            x = items[x]
        if value.kind == "real" and value.convert:
            conversion = _conversion(value.unit, _variable_unit(elem, var), where)
            steps = ([conversion] if conversion is not None else []) + steps
        for s in steps:
            x = s.apply(x, where)
        elem.parameters[var] = x

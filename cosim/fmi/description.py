"""What an FMU declares, read once (:class:`~cosim.fmi.description.FMUDescription`), and a component's choices
checked against it: the interface, clock intervals, parameter and start values, ports and their dependencies."""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from fractions import Fraction
from pathlib import Path

from fmu_models.errors import ConfigurationError, FMUError, TypeMismatchError, UnknownNameError
from fmu_models.export.pack import library_suffix, platform_dir
from fmu_models.infra.checks import finite

from ..core.component import CLOCK, PORT_TYPES, Port
from .archive import read_archive
from .clocks import FMIClocks
from .ports import ElementPort, array_shape, check_declared_range, check_integer, parse_start

__all__ = ["INTERFACES", "FMUDescription"]

#: The interfaces a component may ask for (``"auto"``, Co-Simulation, Model Exchange, Scheduled Execution).
INTERFACES = ("auto", "cs", "me", "se")
_WORDS = {"cs": "Co-Simulation", "me": "Model Exchange", "se": "Scheduled Execution"}


class FMUDescription:
    """An FMU file as its model description declares it.

    Parameters
    ----------
    path : str or Path
        The ``.fmu`` file (FMI 1.0, 2.0 or 3.0).
    owner : str
        The component's name (in messages).

    Attributes
    ----------
    version : int
        1, 2 or 3.
    prefix : str
        The prefix of the FMI functions in messages, ``fmi`` (FMI 1.0), ``fmi2`` or ``fmi3``.
    interfaces : dict
        The interfaces it has (fmpy's) by key, in the order ``"cs"``, ``"me"``, ``"se"``.
    variables : dict
        Its variables (fmpy's) by name.
    clocks : FMIClocks or None
        Its clocks (:mod:`cosim.fmi.clocks`), None if it declares none.
    dependencies : dict
        The ``ModelStructure``: the name of each output and derivative -> the variables it
        depends on directly (None: on every input).
    asynchronous : bool
        FMI 1.0 Co-Simulation: it declares ``canRunAsynchronuously`` (``fmiDoStep`` may
        return Pending).
    negated : frozenset of str
        FMI 1.0: the names of the ``negatedAlias`` variables.
    """

    def __init__(self, path, owner: str):
        self.path, self.owner = Path(path), owner
        archive = read_archive(self.path)
        md = self.md = archive.md
        self.version = {"1": 1, "3": 3}.get(str(md.fmiVersion)[:1], 2)
        self.prefix = "fmi" if self.version == 1 else f"fmi{self.version}"
        found = {"cs": md.coSimulation, "me": md.modelExchange, "se": getattr(md, "scheduledExecution", None)}
        self.interfaces = {k: v for k, v in found.items() if v is not None}
        for key, interface in self.interfaces.items():
            if not interface.modelIdentifier:
                raise FMUError(f"{owner}: {self.path.name} declares no modelIdentifier for its {_WORDS[key]} interface "
                               f"(FMI {self.version}.0)")
        self.variables = {v.name: v for v in md.modelVariables}
        self._members = archive.members
        clocked = self.version == 3 and any(v.type == "Clock" for v in md.modelVariables)
        self.clocks = FMIClocks(md, archive.root, owner) if clocked else None
        self.dependencies = {u.variable.name: u.dependencies for u in (*md.outputs, *getattr(md, "derivatives", []))
                             if u.variable is not None}
        root = archive.root if self.version == 1 else None
        self.negated = frozenset(el.get("name") for el in root.iter("ScalarVariable")
                                 if el.get("alias") == "negatedAlias") if root is not None else frozenset()
        capabilities = root.find("Implementation/*/Capabilities") if root is not None else None
        self.asynchronous = capabilities is not None and capabilities.get("canRunAsynchronuously") in ("true", "1")

    # ------------------------------------------------------------------ the interface
    def choose_interface(self, interface: str) -> str:
        """``interface`` (one of :data:`INTERFACES`; ``"auto"``: the first the FMU has) resolved
        and checked: the FMU has it, its clocks allow it, Scheduled Execution has clocks."""
        owner, file = self.owner, self.path.name
        if interface not in INTERFACES:
            raise UnknownNameError(f"{owner}: interface must be one of {INTERFACES}, got {interface!r}")
        if interface == "auto":
            interface = next(iter(self.interfaces), "")
            if not interface:
                raise FMUError(f"{owner}: {file} has no Co-Simulation, Model Exchange or Scheduled Execution "
                               "interface")
        elif interface not in self.interfaces:
            have = [_WORDS[k] for k in self.interfaces]
            raise ConfigurationError(f"{owner}: {file} has no {_WORDS[interface]} interface; it has: "
                                     f"{', '.join(have) or 'none'}")
        if self.clocks is not None:
            self.clocks.check_interface(interface)
        elif interface == "se":
            raise FMUError(f"{owner}: {file} is a Scheduled Execution FMU without clocks: it has no model "
                           "partition to activate")
        return interface

    def clock_overrides(self, intervals: Mapping[str, float] | None, isolate: object) -> dict[str, Fraction]:
        """The clock ``intervals`` [s] a component sets, by clock name, checked; refused without
        clocks, as ``isolate`` is with clocks."""
        if self.clocks is None:
            if intervals is not None:
                raise ConfigurationError(f"{self.owner}: clock_intervals given, but {self.path.name} has no clocks")
            return {}
        if isolate is True:
            raise ConfigurationError(f"{self.owner}: an FMU with clocks cannot be isolated (isolate = true): its "
                                     "Event Mode and callbacks run in the master's process")
        return self.clocks.check_overrides(intervals or {})

    def check_binary(self, interface: str) -> None:
        """Refuse an FMU without a binary of ``interface`` for this platform, naming the ones it has."""
        platform = platform_dir(3 if self.version == 3 else 2)      # FMI 1.0 names platforms as 2.0 does
        want = f"binaries/{platform}/{self.interfaces[interface].modelIdentifier}{library_suffix()}"
        names = self._members
        if want not in names:
            have = sorted({n.split("/")[1] for n in names if n.startswith("binaries/") and n.count("/") >= 2})
            hint = (" It ships its C sources: rebuild it for this platform (e.g. fmpy's "
                    "compile_platform_binary)." if any(n.startswith("sources/") for n in names) else "")
            raise FMUError(f"{self.owner}: {self.path.name} has no binary for this platform ({want}); it has "
                           f"binaries for: {', '.join(have) or 'none'}.{hint}")

    def _refuse_negated(self, name: str, what: str) -> None:
        """Refuse the FMI 1.0 ``negatedAlias`` variable ``name`` as ``what``."""
        if name in self.negated:
            raise ConfigurationError(f"{self.owner}: {name!r} cannot be {what}: it is an FMI 1.0 negated alias (its "
                                     "value is the negation of the variable with its value reference); use that "
                                     "variable instead")

    # ------------------------------------------------------------------ values
    def settings(self, parameters: Mapping, start: Mapping) -> tuple[dict, dict[str, int]]:
        """The ``parameters`` and ``start`` values (by variable name) checked: exact integers,
        finite reals, Booleans, within the declared ranges, lists for arrays. Returns them and
        the integer structural parameters' values (start values, or as set), both by name."""
        owner = self.owner
        if not isinstance(parameters, Mapping) or not isinstance(start, Mapping):
            raise TypeMismatchError(f"{owner}: parameters and start must be tables of name = value")
        structural = {v.name: int(parse_start(v, 1)[0]) for v in self.md.modelVariables
                      if v.causality == "structuralParameter" and v.type.startswith(("Int", "UInt"))}
        settings: dict = {}
        for kind, values in (("parameter", parameters), ("start", start)):
            for key, val in values.items():
                v = self.variables.get(key)
                if v is None:
                    raise UnknownNameError(f"{owner}: FMU {self.md.modelName} has no variable {key!r} (for {kind}); "
                                           f"valid names: {', '.join(self.variables)}")
                self._refuse_negated(key, f"a {kind} value")
                if v.type not in PORT_TYPES:
                    raise TypeMismatchError(f"{owner}: {key!r} is of type {v.type}; only numeric and Boolean "
                                            "variables can be set")
                if v.causality == "structuralParameter":
                    what = f"{owner}: {kind} {key}"
                    val = structural[key] = check_integer(val, v.type, self.version, what)
                    check_declared_range([val], v, what)
                settings[key] = val
        for key, val in settings.items():
            v = self.variables[key]
            if v.causality != "structuralParameter":
                settings[key] = self._value(v, val, array_shape(v, structural))
        return settings, structural

    def _value(self, v, val, shape: tuple[int, ...]):
        """The value ``val`` of the variable ``v`` of shape ``shape`` checked (a list for an array)."""
        count = math.prod(shape)
        items = list(val) if isinstance(val, (list, tuple)) else [val]
        if len(items) != count:
            raise ConfigurationError(f"{self.owner}: {v.name} takes {count} value(s) (shape {shape or 'scalar'}), "
                                     f"got {len(items)}")
        what, kind = f"{self.owner}: {v.name}", PORT_TYPES[v.type]
        if kind == "real":
            items = [finite(x, what) for x in items]
        elif kind == "boolean":
            if not all(isinstance(x, bool) or x in (0, 1) for x in items):
                raise TypeMismatchError(f"{what}: a Boolean takes true or false, got {val!r}")
            items = [bool(x) for x in items]
        else:
            items = [check_integer(x, v.type, self.version, what) for x in items]
        if kind != "boolean":
            check_declared_range(items, v, what)
        return items if shape else items[0]

    # ------------------------------------------------------------------ ports
    def ports(self, element_ports: Mapping[str, ElementPort], chosen: Sequence[str] | None,
              direction: str) -> list[Port]:
        """The ports ``chosen`` (element ports, or whole variables: all their elements) among
        the ``element_ports`` (by name) that are inputs (``direction`` "input") or outputs and
        locals ("output"); None: every input or output of a port type and the clock ports."""
        owner, clocks = self.owner, self.clocks
        causalities = ("input",) if direction == "input" else ("output", "local")
        available = {p.name: p for p in element_ports.values()
                     if p.variable.causality in causalities and p.variable.name not in self.negated}
        if chosen is None:
            chosen = [n for n, p in available.items() if p.variable.causality == causalities[0]
                      and p.type in PORT_TYPES]
            if clocks is not None:
                chosen += clocks.default_ports(direction)
        elif isinstance(chosen, str) or not all(isinstance(c, str) for c in chosen):
            raise TypeMismatchError(f"{owner}: {direction}s must be a list of variable names, got {chosen!r}")
        picked: dict[str, None] = {}            # the element ports in order, once each
        for p in chosen:
            names = [p] if p in available else [n for n, e in available.items() if e.variable.name == p and n != p]
            if not names:
                self._refuse_negated(p, f"a {direction}")
                raise UnknownNameError(f"{owner}: {p!r} is not an FMU {direction}; valid {direction}s: "
                                       f"{', '.join(available)}")
            picked.update(dict.fromkeys(names))
        ports = []
        for n in picked:
            e = available[n]
            if e.type == CLOCK and clocks is not None:
                ports.append(clocks.port(n, direction))
            elif e.type not in PORT_TYPES:
                raise TypeMismatchError(f"{owner}: {direction} {n!r} is of type {e.type}; ports can be "
                                        f"{', '.join(sorted(set(PORT_TYPES)))}")
            else:
                ports.append(Port(n, e.type, getattr(e.variable, "unit", None) or "", e.variable.description or ""))
        return ports

    def feedthrough(self, element_ports: Mapping[str, ElementPort], outs: Sequence[Port], ins: Sequence[Port],
                    interface: str) -> dict[str, list[str]]:
        """The direct dependencies of each output port on input ports as the ``ModelStructure``
        declares them (undeclared: every input), restricted by the clocks in ``interface``."""
        by_variable: dict[str, list[str]] = {}
        for p in ins:
            by_variable.setdefault(element_ports[p.name].variable.name, []).append(p.name)
        result = {}
        for p in outs:
            deps = self.dependencies.get(element_ports[p.name].variable.name)
            if deps is None:           # not declared: depends on every input (FMI default)
                result[p.name] = sorted(q.name for q in ins)
            else:
                result[p.name] = sorted(n for d in deps for n in by_variable.get(d.name, []))
        if self.clocks is not None:
            return self.clocks.feedthrough(result, outs, ins, element_ports, interface)
        return result

"""The FMI 3.0 clocks of an imported FMU (§2.2.8 Clocks), read from its model description
(also what fmpy leaves out) and checked: what the standard forbids is refused naming the
clock and the rule (listed on the clocks page of the documentation).
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from fractions import Fraction

from fmu_models.errors import ConfigurationError, FMUError, TypeMismatchError, UnknownNameError
from fmu_models.infra.checks import positive

from ..core.clocking import PERIODIC, VARIABILITIES, ClockInfo, time_fraction
from ..core.component import CLOCK, Port

__all__ = ["CHANGED", "NOT_YET_KNOWN", "QUALIFIERS", "UNCHANGED", "FMIClock", "FMIClocks"]

#: The values of ``fmi3IntervalQualifier``.
NOT_YET_KNOWN, UNCHANGED, CHANGED = 0, 1, 2
#: Their names.
QUALIFIERS = {0: "fmi3IntervalNotYetKnown", 1: "fmi3IntervalUnchanged", 2: "fmi3IntervalChanged"}
_ATTRS = ("intervalVariability", "intervalDecimal", "shiftDecimal", "supportsFraction", "resolution",
          "intervalCounter", "shiftCounter", "priority", "canBeDeactivated")


@dataclass(frozen=True)
class FMIClock:
    """One Clock variable of an FMU, as declared.

    Attributes
    ----------
    name : str
        The Clock variable's name (its port's, if it is a port).
    vr : int
        Value reference.
    causality : {"input", "output", "local"}
    variability : str
        ``intervalVariability``.
    interval : Fraction or None
        The declared interval [s] (``intervalCounter / resolution`` if given, else
        ``intervalDecimal``), or None.
    shift : Fraction
        The declared shift [s] (0 by default).
    has_decimal : bool
        ``intervalDecimal`` is declared (fixed and tunable clocks then get their interval
        from the importer).
    counter, resolution, shift_counter : int or None
        The counter form, if declared.
    supports_fraction, can_be_deactivated : bool
    priority : int or None
    index : int
        Declaration order among the clocks.
    description : str
    """

    name: str
    vr: int
    causality: str
    variability: str
    interval: Fraction | None
    shift: Fraction
    has_decimal: bool
    counter: int | None
    resolution: int | None
    shift_counter: int | None
    supports_fraction: bool
    priority: int | None
    can_be_deactivated: bool
    index: int
    description: str = ""

    @property
    def is_port(self) -> bool:
        """A triggered input clock or an output clock (a port of the component)."""
        return self.causality == "output" or (self.causality == "input" and self.variability == "triggered")

    @property
    def importer_sets_interval(self) -> bool:
        """A fixed or tunable clock with ``intervalDecimal``: the importer sets its interval."""
        return self.variability in ("fixed", "tunable") and self.has_decimal


def _bool(text, what: str) -> bool:
    if text not in (None, "true", "1", "false", "0"):
        raise FMUError(f"{what} must be true or false, got {text!r}")
    return text in ("true", "1")


def _number(text, what: str, conv, kind: str):
    """``conv(text)`` (None if not given); an FMUError naming ``what`` if ``text`` is not ``kind``."""
    if text is None:
        return None
    try:
        return conv(text)
    except ValueError:
        raise FMUError(f"{what} must be {kind}, got {text!r}") from None


def _uint(text, what: str) -> int | None:
    v = _number(text, what, int, "an unsigned integer")
    if v is not None and v < 0:
        raise FMUError(f"{what} must be >= 0, got {v}")
    return v


def _decimal(text, what: str) -> Fraction | None:
    f = _number(text, what, float, "a number")
    if f is None:
        return None
    if not math.isfinite(f):
        raise FMUError(f"{what} must be finite, got {text!r}")
    try:
        return time_fraction(text)
    except (ValueError, ZeroDivisionError):
        return time_fraction(f)


def _timing(where: str, var: str, a: dict) -> dict:
    """The timing attributes ``a`` of clock ``where`` (intervalVariability ``var``), parsed and checked."""
    decimal, shift_decimal = (_decimal(a[n], f"{where}: {n}") for n in ("intervalDecimal", "shiftDecimal"))
    counter, resolution, shift_counter = (_uint(a[n], f"{where}: {n}")
                                          for n in ("intervalCounter", "resolution", "shiftCounter"))
    fraction = _bool(a["supportsFraction"], f"{where}: supportsFraction")
    for attr, needs in (("shiftDecimal", "intervalDecimal"), ("intervalCounter", "resolution"),
                        ("shiftCounter", "intervalCounter")):
        if a[attr] is not None and a[needs] is None:
            raise FMUError(f"{where} declares {attr} without {needs} (the standard requires both)")
    for attr in ("intervalDecimal", "resolution"):
        if a[attr] is not None and var not in PERIODIC:
            raise FMUError(f"{where} ({var}) declares {attr}, which only periodic clocks (constant, fixed, tunable) "
                           "may have")
    if counter is not None and (var not in PERIODIC or not fraction):
        raise FMUError(f"{where} declares intervalCounter, which only a periodic clock with supportsFraction = true "
                       "may have")
    for attr, v in (("intervalDecimal", decimal), ("intervalCounter", counter), ("resolution", resolution)):
        if v is not None and v <= 0:
            raise FMUError(f"{where}: {attr} must be > 0, got {float(v):g}")
    if shift_decimal is not None and shift_decimal < 0:
        raise FMUError(f"{where}: shiftDecimal must be >= 0, got {float(shift_decimal):g}")
    if var == "constant" and decimal is None:
        raise FMUError(f"{where} is a constant clock without intervalDecimal (the standard requires it)")
    interval, shift = decimal, shift_decimal or Fraction(0)
    if counter is not None:
        exact = Fraction(counter, resolution)
        if decimal is not None and abs(exact - decimal) > 1e-12 * exact:
            raise FMUError(f"{where}: intervalDecimal {float(decimal):g} s disagrees with intervalCounter / "
                           f"resolution = {counter}/{resolution} s")
        interval = exact
        if shift_counter is not None:
            sc = Fraction(shift_counter, resolution)
            if shift_decimal is not None and abs(sc - shift_decimal) > 1e-12 * max(sc, Fraction(1)):
                raise FMUError(f"{where}: shiftDecimal {float(shift_decimal):g} s disagrees with shiftCounter / "
                               f"resolution = {shift_counter}/{resolution} s")
            shift = sc
    return dict(interval=interval, shift=shift, has_decimal=decimal is not None, counter=counter,
                resolution=resolution, shift_counter=shift_counter, supports_fraction=fraction)


def _by_name(root, section: str, tag: str) -> dict:
    """The ``tag`` elements of the XML ``section`` (under ``root``), by name."""
    return {el.get("name"): el for el in root.findall(f"{section}/{tag}") if el.get("name") is not None}


class FMIClocks:
    """The clocks of one FMI 3.0 FMU (see the clocks page of the documentation).

    Parameters
    ----------
    md : fmpy ModelDescription
    root : lxml Element
        The root of its ``modelDescription.xml`` (read for what fmpy leaves out).
    owner : str
        The component's name (for messages).

    Attributes
    ----------
    clocks : list of FMIClock
        In declaration order.
    by_name, by_vr : dict
    clocked : dict of str to tuple of int
        Clocked variable name -> the value references of its clocks.
    dependencies : dict of int to tuple of int
        Output clock value reference -> what its ``ModelStructure`` ``Output`` lists.
    """

    def __init__(self, md, root, owner: str):
        self.owner, self.md = owner, md
        types, elements = _by_name(root, "TypeDefinitions", "ClockType"), _by_name(root, "ModelVariables", "Clock")
        self.clocks: list[FMIClock] = []
        for v in md.modelVariables:
            if v.type != "Clock":
                continue
            el = elements.get(v.name)
            base = types.get(el.get("declaredType")) if el is not None and el.get("declaredType") else None
            attrs = {a: (el.get(a) if el is not None and el.get(a) is not None else
                         (base.get(a) if base is not None else None)) for a in _ATTRS}
            if el is not None and el.find("Dimension") is not None:
                raise FMUError(f"{owner}: clock {v.name!r} has a Dimension; clocks are scalar")
            self.clocks.append(self._clock(v, attrs, len(self.clocks)))
        self.by_name = {k.name: k for k in self.clocks}
        self.by_vr = {k.vr: k for k in self.clocks}
        self.clocked = {}
        for v in md.modelVariables:
            if not (refs := getattr(v, "clocks", None)):
                continue
            vrs = tuple(int(getattr(r, "valueReference", r)) for r in refs)
            for vr in vrs:
                if vr not in self.by_vr:
                    raise FMUError(f"{owner}: variable {v.name!r} is clocked by value reference {vr}, which is not a "
                                   "clock (the standard's clocks attribute lists clocks only)")
            if v.type != "Clock" and v.variability not in (None, "discrete", "tunable"):
                raise FMUError(f"{owner}: clocked variable {v.name!r} has variability {v.variability!r}; clocked "
                               "variables must be discrete or tunable")
            self.clocked[v.name] = vrs
        self.dependencies = {u.variable.valueReference: tuple(d.valueReference for d in u.dependencies or ())
                             for u in md.outputs if u.variable is not None and u.variable.type == "Clock"}

    def _clock(self, v, a: dict, index: int) -> FMIClock:
        where = f"{self.owner}: clock {v.name!r}"
        var = a["intervalVariability"] or getattr(v, "intervalVariability", None)
        if var not in VARIABILITIES:
            raise FMUError(f"{where} has intervalVariability {var!r}; it must be one of {', '.join(VARIABILITIES)}")
        causality = v.causality or "local"
        if causality not in ("input", "output", "local"):
            raise FMUError(f"{where} has causality {causality!r}; a clock must be an input, output or local")
        if v.variability not in (None, "discrete"):
            raise FMUError(f"{where} has variability {v.variability!r}; clocks must be discrete")
        if causality in ("output", "local") and var != "triggered":
            raise FMUError(f"{where} is an {causality} clock with intervalVariability {var!r}; {causality} clocks "
                           "must be triggered")
        priority = _uint(a["priority"], f"{where}: priority")
        if causality == "output" and priority is not None:
            raise FMUError(f"{where} is an output clock with a priority; output clocks must not have one")
        return FMIClock(v.name, int(v.valueReference), causality, var, **_timing(where, var, a), priority=priority,
                        can_be_deactivated=_bool(a["canBeDeactivated"], f"{where}: canBeDeactivated"), index=index,
                        description=v.description or "")

    # ------------------------------------------------------------------ interface rules
    def check_interface(self, interface: str) -> None:
        """Refuse what the standard forbids for ``interface`` ("cs", "me" or "se")."""
        if interface == "se":
            for k in self.clocks:
                if k.causality == "local":
                    raise FMUError(f"{self.owner}: clock {k.name!r} is a local clock, which Scheduled Execution does "
                                   "not allow")
                if k.causality == "input" and k.priority is None:
                    raise FMUError(f"{self.owner}: input clock {k.name!r} has no priority; Scheduled Execution "
                                   "requires one for every input clock")
        if interface == "cs" and not getattr(self.md.coSimulation, "hasEventMode", False):
            raise FMUError(f"{self.owner}: the FMU declares clocks but its Co-Simulation interface has no Event Mode "
                           "(hasEventMode is not true); clocks are activated only in Event Mode")

    # ------------------------------------------------------------------ ports
    def port(self, name: str, direction: str) -> Port:
        """The Clock port ``name`` (a triggered input clock or an output clock), or a named
        refusal of a clock that is no port."""
        k, owner = self.by_name[name], self.owner
        if direction == "input":
            if k.causality != "input":
                raise UnknownNameError(f"{owner}: {name!r} is an {k.causality} clock, not an input")
            if k.variability != "triggered":
                raise TypeMismatchError(f"{owner}: {name!r} is a {k.variability} clock: it ticks on its own timing, "
                                        "so it is no input port; only triggered input clocks take a source")
        elif k.causality != "output":
            raise UnknownNameError(f"{owner}: {name!r} is an {k.causality} clock, not an output")
        return Port(name, CLOCK, "", k.description or f"{k.variability} {k.causality} clock (counts its activations)")

    def default_ports(self, direction: str) -> list[str]:
        """The clock ports offered by default: every triggered input clock, every output clock."""
        want = "input" if direction == "input" else "output"
        return [k.name for k in self.clocks if k.is_port and k.causality == want]

    def clocks_of(self, variable: str) -> tuple[int, ...]:
        """The value references of the clocks of ``variable`` (empty: not clocked)."""
        return self.clocked.get(variable, ())

    def feedthrough(self, declared: Mapping[str, Sequence[str]], outs: list[Port], ins: list[Port], ports,
                    interface: str) -> dict:
        """The direct dependencies the master may assume (the rules: the clocks page of the
        documentation); ``declared``: those the ``ModelStructure`` lists (output port -> input ports)."""
        in_names = [p.name for p in ins]
        by_clock: dict[int, list[str]] = {}          # input clock -> the input ports it is or clocks
        for p in ins:
            for vr in (self.by_name[p.name].vr,) if p.type == CLOCK else self.clocks_of(ports[p.name].variable.name):
                by_clock.setdefault(vr, []).append(p.name)
        result = {}
        for p in outs:
            if p.type == CLOCK:
                vrs = self.dependencies.get(self.by_name[p.name].vr, ())
                deps = {n for n in in_names for vr in vrs
                        if n in by_clock.get(vr, ()) or (n in ports and ports[n].variable.valueReference == vr)}
            elif not (clocks := self.clocks_of(ports[p.name].variable.name)):
                result[p.name] = sorted(declared.get(p.name, ())) if interface == "me" else []
                continue
            else:
                deps = set(declared.get(p.name, ()))
                if interface == "cs":                   # discrete inputs without clock: set in the update
                    deps = {d for d in deps if d not in ports or ports[d].type == CLOCK or not ports[d].discrete
                            or self.clocks_of(ports[d].variable.name)}
                for vr in clocks:
                    deps.add(self.by_vr[vr].name)       # a clock no input port is: left out below
                    if interface == "se":
                        deps.update(by_clock.get(vr, ()))
            result[p.name] = sorted(d for d in deps if d in in_names)
        return result

    def infos(self, interface: str, overrides: Mapping[str, Fraction], ports: Sequence[str]) -> tuple[ClockInfo, ...]:
        """The clocks as the master's plan sees them (:class:`~cosim.core.clocking.ClockInfo`);
        ``ports``: the component's port names (a clock not among them is no port)."""
        ports = set(ports)
        out = []
        for k in self.clocks:
            # intervalDecimal is declared by periodic clocks only, by every constant one
            interval = overrides.get(k.name, k.interval) if k.has_decimal else None
            note = "activated by the FMU" if k.causality != "input" else ""
            if k.name in overrides:
                note = "interval set by the component (clock_intervals)"
            elif k.importer_sets_interval:
                note = "its declared interval, set by the master at initialisation"
            priority = k.priority if interface == "se" and k.causality == "input" else None
            out.append(ClockInfo(k.name, k.causality, k.variability, interval,
                                 k.shift if interval is not None else None,
                                 k.name if k.is_port and k.name in ports else None, note,
                                 priority))
        return tuple(out)

    def check_overrides(self, intervals: Mapping) -> dict[str, Fraction]:
        """``clock_intervals`` checked: only fixed and tunable clocks that declare
        ``intervalDecimal`` take an interval from the importer; positive, finite."""
        if not isinstance(intervals, Mapping):
            raise TypeMismatchError(f"{self.owner}: clock_intervals must be a table of clock name = interval [s]")
        out = {}
        for name, value in intervals.items():
            k = self.by_name.get(name)
            if k is None:
                raise UnknownNameError(f"{self.owner}: clock_intervals names {name!r}, not a clock; clocks: "
                                       f"{', '.join(self.by_name) or '(none)'}")
            if not k.importer_sets_interval:
                raise ConfigurationError(
                    f"{self.owner}: clock {name!r} ({k.causality}, {k.variability}"
                    f"{', no intervalDecimal' if k.variability in ('fixed', 'tunable') else ''}) takes no interval "
                    "from the importer; only fixed and tunable input clocks with an intervalDecimal do")
            out[name] = time_fraction(positive(value, f"{self.owner}: clock_intervals {name} [s]"))
        return out

"""FMI 3.0 clocks of an imported FMU: read and checked from its model description, and
driven in a run as the standard's call sequences say (Model Exchange, Co-Simulation with
Event Mode, Scheduled Execution).

What the master does with clocks in general (timing on the base grid, clock connections,
activations between instants) is in :mod:`cosim.core.clocking`; this module is the FMI
side, used by :class:`~cosim.fmi.fmu_component.FMUComponent` for any FMU that declares
clocks.

**Reading** (:class:`FMIClocks`). fmpy reads a Clock's ``intervalVariability`` and the
``clocks`` attribute of clocked variables; the other attributes (``intervalDecimal``,
``shiftDecimal``, ``supportsFraction``, ``resolution``, ``intervalCounter``,
``shiftCounter``, ``priority``, ``canBeDeactivated``, also through a ``ClockType``) are
read here from the XML. What the standard forbids is refused with the clock and the rule
named: an output or local clock that is not triggered, an output clock with a priority, a
constant clock without an interval, ``intervalDecimal``/``intervalCounter`` on a clock
that may not have them, a counter without ``resolution``, a ``shiftCounter`` without an
``intervalCounter``, an interval that disagrees with its counter form, a negative or
non-finite value, a Scheduled Execution input clock without a priority or a local clock in
Scheduled Execution, a Co-Simulation interface without Event Mode, a ``clocks`` attribute
naming a variable that is not a clock.

**Ports.** Triggered input clocks and output clocks are ports of type
:data:`~cosim.core.component.CLOCK` (their signals count the activations); other input
clocks tick on their own timing. Clocked variables are exchanged only while one of their
clocks is active: a clocked output keeps (the master holds) its value between the ticks.

**Initialisation Mode.** Fixed and tunable clocks that declare ``intervalDecimal`` get
their interval with ``fmi3SetIntervalDecimal`` (``fmi3SetIntervalFraction`` in their
counter form), the declared one or the component's ``clock_intervals``; those that do not
are asked ``fmi3GetInterval*`` and ``fmi3GetShift*``; changing and countdown clocks are
asked their first interval.

**Model Exchange and Co-Simulation** (``eventModeUsed = true``, ``earlyReturnAllowed =
true``). At an instant where clocks tick: Event Mode (``fmi3EnterEventMode``, or the Event
Mode after initialisation), ``fmi3SetClock`` of the ticking input clocks, their clocked
inputs set (those the outputs depend on directly; the others in the update, before the
state changes), their clocked outputs read, ``fmi3GetClock`` of the output (and local)
clocks and the outputs they clock read; in the update the event iteration
(``fmi3UpdateDiscreteStates`` until no more is needed, ``fmi3GetClock`` again in every
further super-dense instant), then the intervals of every countdown clock (in every Event
Mode) and of changing and tunable clocks that ticked; a clock due again at once (interval
0) or an activation that arrived meanwhile ticks in the same Event Mode; then
``fmi3EnterStepMode`` / ``fmi3EnterContinuousTimeMode``. Co-Simulation: ``fmi3DoStep``
ends at every activation between instants (a clock, the FMU's ``nextEventTime``), and an
early return with ``eventHandlingNeeded`` is handled in Event Mode at its
``lastSuccessfulTime`` before stepping on; outputs without clocks are read in Step Mode
without setting an input first (the standard forbids a get after a set), so they depend on
no input directly. Model Exchange: the activations between instants are time events of the
integrator (:mod:`cosim.fmi.model_exchange`), and every Event Mode it enters (state, time
and step events) reads the output clocks.

**Scheduled Execution.** ``fmi3InstantiateScheduledExecution`` with a ``clockUpdate``
callback, in which (Clock Update Mode) every output clock is read with ``fmi3GetClock``
and every countdown clock's interval with ``fmi3GetInterval*``; at each activation time
the partitions due are activated with ``fmi3ActivateModelPartition`` in priority order
(smaller first; a countdown clock that becomes due at the same time joins the queue), each
after its clocked inputs are set, its outputs (and those of the output clocks it
activated) read after it; a partition's inputs are treated as direct inputs of its
outputs (the partition computes both at once).
"""
from __future__ import annotations

import ctypes
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from fmu_models.errors import ConfigurationError, FMUError, TypeMismatchError, UnknownNameError
from fmu_models.infra.checks import positive

from ..core.clocking import APERIODIC, PERIODIC, VARIABILITIES, ClockBoard, ClockInfo, fraction_gcd, time_fraction
from ..core.component import CLOCK, Port, StopRequest
from .archive import _open_zip
from .exchange import Exchange, no_exchange
from .model_exchange import FMUModel

__all__ = ["FMIClock", "FMIClocks", "read_clocks"]

_CHANGED, _UNCHANGED, _NOT_YET_KNOWN = 2, 1, 0
_QUALIFIER = {0: "fmi3IntervalNotYetKnown", 1: "fmi3IntervalUnchanged", 2: "fmi3IntervalChanged"}
#: Most super-dense instants of one Event Mode.
MAX_SUPERDENSE = 1000
_ATTRS = ("intervalVariability", "intervalDecimal", "shiftDecimal", "supportsFraction", "resolution",
          "intervalCounter", "shiftCounter", "priority", "canBeDeactivated")


@dataclass(frozen=True)
class FMIClock:
    """One Clock variable of an FMU, as declared (see the module documentation).

    Attributes
    ----------
    name : str
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
    supports_fraction : bool
    priority : int or None
    can_be_deactivated : bool
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
    def periodic(self) -> bool:
        """Constant, fixed or tunable."""
        return self.variability in PERIODIC

    @property
    def aperiodic(self) -> bool:
        """Changing or countdown."""
        return self.variability in APERIODIC

    @property
    def is_port(self) -> bool:
        """A triggered input clock or an output clock (a port of the component)."""
        return self.causality == "output" or (self.causality == "input" and self.variability == "triggered")

    @property
    def importer_sets_interval(self) -> bool:
        """A fixed or tunable clock with ``intervalDecimal``: the importer sets its interval."""
        return self.variability in ("fixed", "tunable") and self.has_decimal


def _bool(text, what: str) -> bool:
    if text is None:
        return False
    if text in ("true", "1"):
        return True
    if text in ("false", "0"):
        return False
    raise FMUError(f"{what} must be true or false, got {text!r}")


def _uint(text, what: str) -> int | None:
    if text is None:
        return None
    try:
        v = int(text)
    except ValueError:
        raise FMUError(f"{what} must be an unsigned integer, got {text!r}") from None
    if v < 0:
        raise FMUError(f"{what} must be >= 0, got {v}")
    return v


def _decimal(text, what: str) -> Fraction | None:
    if text is None:
        return None
    try:
        f = float(text)
    except ValueError:
        raise FMUError(f"{what} must be a number, got {text!r}") from None
    if not math.isfinite(f):
        raise FMUError(f"{what} must be finite, got {text!r}")
    try:
        return time_fraction(text)
    except (ValueError, ZeroDivisionError):
        return time_fraction(f)


class FMIClocks:
    """The clocks of one FMI 3.0 FMU (see the module documentation).

    Parameters
    ----------
    md : fmpy ModelDescription
    path : Path
        The FMU file (its XML is read for what fmpy leaves out).
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

    def __init__(self, md, path, owner: str):
        self.owner, self.md = owner, md
        root = _xml(path)
        types = {}
        defs = root.find("TypeDefinitions")
        for el in defs if defs is not None else ():
            if el.tag == "ClockType" and el.get("name"):
                types[el.get("name")] = el
        elements = {}
        mv = root.find("ModelVariables")
        for el in mv if mv is not None else ():
            if el.tag == "Clock" and el.get("name") is not None:
                elements[el.get("name")] = el
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
            self.clocks.append(self._clock(v, attrs, len(self.clocks), el))
        self.by_name = {k.name: k for k in self.clocks}
        self.by_vr = {k.vr: k for k in self.clocks}
        self.clocked = {}
        for v in md.modelVariables:
            refs = getattr(v, "clocks", None) or []
            if not refs:
                continue
            vrs = []
            for r in refs:
                vr = getattr(r, "valueReference", r)
                if vr not in self.by_vr:
                    raise FMUError(f"{owner}: variable {v.name!r} is clocked by value reference {vr}, which is not a "
                                   "clock (the standard's clocks attribute lists clocks only)")
                vrs.append(int(vr))
            if v.type != "Clock" and v.variability not in (None, "discrete", "tunable"):
                raise FMUError(f"{owner}: clocked variable {v.name!r} has variability {v.variability!r}; clocked "
                               "variables must be discrete or tunable")
            self.clocked[v.name] = tuple(vrs)
        self.dependencies = {}
        for u in md.outputs:
            if u.variable is not None and u.variable.type == "Clock":
                self.dependencies[u.variable.valueReference] = tuple(d.valueReference for d in u.dependencies or ())

    def _clock(self, v, a: dict, index: int, el) -> FMIClock:
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
        decimal = _decimal(a["intervalDecimal"], f"{where}: intervalDecimal")
        shift_decimal = _decimal(a["shiftDecimal"], f"{where}: shiftDecimal")
        counter = _uint(a["intervalCounter"], f"{where}: intervalCounter")
        resolution = _uint(a["resolution"], f"{where}: resolution")
        shift_counter = _uint(a["shiftCounter"], f"{where}: shiftCounter")
        fraction = _bool(a["supportsFraction"], f"{where}: supportsFraction")
        if decimal is not None:
            if var not in PERIODIC:
                raise FMUError(f"{where} ({var}) declares intervalDecimal, which only periodic clocks (constant, "
                               "fixed, tunable) may have")
            if decimal <= 0:
                raise FMUError(f"{where}: intervalDecimal must be > 0, got {float(decimal):g}")
        if shift_decimal is not None:
            if decimal is None:
                raise FMUError(f"{where} declares shiftDecimal without intervalDecimal (the standard requires both)")
            if shift_decimal < 0:
                raise FMUError(f"{where}: shiftDecimal must be >= 0, got {float(shift_decimal):g}")
        if counter is not None:
            if var not in PERIODIC or not fraction:
                raise FMUError(f"{where} declares intervalCounter, which only a periodic clock with "
                               "supportsFraction = true may have")
            if counter == 0:
                raise FMUError(f"{where}: intervalCounter must be > 0")
            if resolution is None:
                raise FMUError(f"{where} declares intervalCounter without resolution (the standard requires both)")
        if resolution is not None:
            if var not in PERIODIC:
                raise FMUError(f"{where} ({var}) declares resolution, which only periodic clocks may have")
            if resolution == 0:
                raise FMUError(f"{where}: resolution must be > 0")
        if shift_counter is not None and counter is None:
            raise FMUError(f"{where} declares shiftCounter without intervalCounter (the standard requires both)")
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
        return FMIClock(v.name, int(v.valueReference), causality, var, interval, shift, decimal is not None, counter,
                        resolution, shift_counter, fraction, priority,
                        _bool(a["canBeDeactivated"], f"{where}: canBeDeactivated"), index, v.description or "")

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
    def port(self, name: str, direction: str, owner: str) -> Port:
        """The Clock port ``name`` (a triggered input clock or an output clock), or a named
        refusal of a clock that is no port."""
        k = self.by_name[name]
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
        """The direct dependencies the master may assume (see the module documentation):
        a clocked output on the inputs its ``ModelStructure`` lists and on its clocks'
        triggered input ports; in Scheduled Execution also on every input of its
        partitions; outputs without clocks as declared in Model Exchange, on no input in
        Co-Simulation and Scheduled Execution. ``declared``: the dependencies read from the
        ``ModelStructure`` (output port -> input ports)."""
        in_names = [p.name for p in ins]
        by_clock: dict[int, list[str]] = {}
        for p in ins:
            if p.type == CLOCK:
                by_clock.setdefault(self.by_name[p.name].vr, []).append(p.name)
            else:
                for vr in self.clocks_of(ports[p.name].variable.name):
                    by_clock.setdefault(vr, []).append(p.name)
        result = {}
        for p in outs:
            if p.type == CLOCK:
                k = self.by_name[p.name]
                deps = set()
                for vr in self.dependencies.get(k.vr, ()):
                    kk = self.by_vr.get(vr)
                    if kk is not None and kk.is_port and kk.causality == "input":
                        deps.add(kk.name)
                    deps.update(n for n in in_names if n in by_clock.get(vr, ()) or
                                (n in ports and ports[n].variable.valueReference == vr))
                result[p.name] = sorted(d for d in deps if d in in_names)
                continue
            clocks = self.clocks_of(ports[p.name].variable.name)
            if not clocks:
                result[p.name] = sorted(declared.get(p.name, ())) if interface == "me" else []
                continue
            deps = set(declared.get(p.name, ()))
            for vr in clocks:
                k = self.by_vr[vr]
                if k.is_port and k.causality == "input" and k.name in in_names:
                    deps.add(k.name)
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
            interval = overrides.get(k.name, k.interval) if k.periodic and (k.has_decimal or k.variability ==
                                                                            "constant") else None
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


def _xml(path):
    from lxml import etree

    with _open_zip(path) as z:
        return etree.fromstring(z.read("modelDescription.xml"),
                                etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=False))


def read_clocks(md, path, owner: str) -> FMIClocks | None:
    """The clocks of the FMU ``md`` (fmpy ModelDescription) at ``path`` (FMI 3.0), read and
    checked for the component ``owner`` (named in the errors), or None if it declares none."""
    if not str(md.fmiVersion).startswith("3") or not any(v.type == "Clock" for v in md.modelVariables):
        return None
    return FMIClocks(md, path, owner)


# ====================================================================== run time
_D, _B, _I = ctypes.c_double, ctypes.c_bool, ctypes.c_int


class _Schedule:
    """A run's timing of one FMU's clocks, from its initialisation on (times in s)."""

    def __init__(self, model: FMIClocks, t0: float, period: float, overrides: Mapping[str, Fraction]):
        self.t0, self.period = t0, period
        self.tol = 1e-9 * period
        self.periodic: list[list] = []               # [clock, interval in instants, next instant]
        self.next: dict[int, float | None] = {}      # aperiodic clock vr -> next activation time
        self.overrides = dict(overrides)
        self.model = model

    def add_periodic(self, k: FMIClock, interval: Fraction, shift: Fraction, owner: str) -> None:
        p = time_fraction(self.period)
        ratio, first = interval / p, shift / p
        for what, r, v in (("interval", ratio, interval), ("shift", first, shift)):
            if r.denominator != 1:
                g = fraction_gcd(p, interval, shift)
                raise ConfigurationError(
                    f"{owner}: clock {k.name!r} ({k.variability}) has the {what} {float(v):g} s (from the FMU at "
                    f"initialisation), not a multiple of {owner}'s period {float(p):g} s; a period of {float(g):g} s "
                    "would honour it")
        if ratio <= 0:
            raise FMUError(f"{owner}: clock {k.name!r} has the interval {float(interval):g} s; it must be > 0")
        self.periodic.append([k, int(ratio), int(first)])


def _interval(v: float, k: FMIClock, owner: str, periodic: bool) -> float:
    if not math.isfinite(v) or v < 0 or (periodic and v <= 0):
        raise FMUError(f"{owner}: fmi3GetInterval of clock {k.name!r} returned {v!r}; an interval must be finite and "
                       f"{'> 0' if periodic else '>= 0'}")
    return v


class ClockedRun:
    """One run of a clocked FMU: its bound output and update functions (see the module
    documentation). Built by :meth:`FMUComponent.bind` for an FMU with clocks.

    Parameters
    ----------
    comp : FMUComponent
        Reset (instantiated and initialised), with its schedule from the initialisation.
    board : ClockBoard
    values, integers : ndarray
        The master's signal arrays.
    inputs : slice or ndarray
        The connected inputs' signal indices.
    outputs : slice
        The outputs' signal indices.
    """

    def __init__(self, comp, board: ClockBoard, values, inputs, outputs, integers):
        self.comp, self.board, self.model = comp, board, comp.clock_model
        inst = comp.instance
        self.inst, self.name, self.interface = inst, comp.name, comp.interface
        self.sched: _Schedule = comp._clock_schedule
        self.P, self.t0, self.tol = comp.period, self.sched.t0, self.sched.tol
        self.c = ctypes.c_void_p(inst.handle)
        self.values, self.integers = values, integers
        self.idx_in = np.arange(len(values))[inputs] if isinstance(inputs, slice) else np.asarray(inputs, np.intp)
        self.out = outputs
        n_in, n_out = len(comp.connected_inputs), len(comp.output_names)
        self.own, self.own_i = np.zeros(n_out), np.zeros(n_out, dtype=np.int64)
        self.vin, self.iin = np.zeros(max(n_in, 1)), np.zeros(max(n_in, 1), dtype=np.int64)
        self.vin_base, self.iin_base = self.vin.copy(), self.iin.copy()
        self._raw = {}
        self._build_ports(comp)
        self._build_calls()
        self.in_event = comp.interface != "se"       # ME and CS: in Event Mode after initialisation
        self.started = False
        self.active: set[int] = set()                # input clocks active in the current Event Mode
        self.ticked: set[int] = set()                # clocks that ticked in the current Event Mode
        self.fmu_next: float | None = None           # the FMU's nextEventTime
        self.pending_event = False                   # the FMU asked for Event Mode at the next instant
        self.done_n = -1                             # the instant whose outputs were computed
        self.window_end = self.t0
        self.inbox = board.inbox(self.name)
        self._outbox: list = []                      # output clock activations to send
        self.in_callback = False                     # in the clockUpdate callback (Clock Update Mode)
        self._error: BaseException | None = None

    # ------------------------------------------------------------------ set-up
    def _build_ports(self, comp) -> None:
        model, ports = self.model, comp.element_ports
        names = comp.connected_inputs
        srcs = comp.input_sources or [(f"{comp.name}.{n}", (ports[n].type if n in ports else CLOCK)) for n in names]
        self.sources = self.board.sources(self.name, names)
        ft_names = set().union(*comp.feedthrough.values()) if comp.feedthrough else set()
        starts = comp._input_starts()
        data_in = [i for i, n in enumerate(names) if comp.element_ports.get(n) is not None
                   and n not in model.by_name]
        self.in_ft = np.array([i for i in data_in if names[i] in ft_names], dtype=np.intp)
        input_clock_vrs = [k.vr for k in model.clocks if k.causality == "input"]
        self.input_clocks = [model.by_vr[vr] for vr in input_clock_vrs]
        by_clock: dict[int, list[int]] = {vr: [] for vr in input_clock_vrs}
        unclocked = []
        for i in data_in:
            ks = model.clocks_of(ports[names[i]].variable.name)
            if not ks:
                unclocked.append(i)
            for vr in ks:
                by_clock.setdefault(vr, []).append(i)
        self.unclocked_in = unclocked

        def setter(positions, changes=False):
            if not positions:
                return no_exchange
            ex = Exchange(self.inst.dll, self.inst.handle, 3, [ports[names[i]] for i in positions], "set",
                          self._fail, self.name, [srcs[i] for i in positions])
            ex.preset({ports[names[i]].name: starts[i] for i in positions})
            return ex.bind(self.vin, np.asarray(positions, np.intp), self.iin, changes)

        def getter(positions):
            if not positions:
                return no_exchange
            outs = comp.output_names
            ex = Exchange(self.inst.dll, self.inst.handle, 3, [ports[outs[j]] for j in positions], "get",
                          self._fail, self.name)
            return ex.bind(self.own, np.asarray(positions, np.intp), self.own_i)

        ft = set(self.in_ft.tolist())
        self.set_ft = {vr: setter([i for i in pos if i in ft]) for vr, pos in by_clock.items()}
        self.set_rest = {vr: setter([i for i in pos if i not in ft]) for vr, pos in by_clock.items()}
        self.set_all = {vr: setter(pos) for vr, pos in by_clock.items()}
        if self.interface == "me":
            cont = [i for i in unclocked if not ports[names[i]].discrete]
            disc = [i for i in unclocked if ports[names[i]].discrete]
            self.set_cont = setter(cont, changes=True)
            self.set_disc = setter(disc, changes=True)
            self.set_cont_ft = setter([i for i in cont if i in ft], changes=True)
            self.set_disc_ft = setter([i for i in disc if i in ft], changes=True)
        self.set_u_all = setter(unclocked)
        self.set_u_ft = setter([i for i in unclocked if i in ft])
        outs = comp.output_names
        data_out = [j for j, n in enumerate(outs) if n not in model.by_name]
        get_by_clock: dict[int, list[int]] = {}
        unclocked_out = []
        for j in data_out:
            ks = model.clocks_of(ports[outs[j]].variable.name)
            if not ks:
                unclocked_out.append(j)
            for vr in ks:
                get_by_clock.setdefault(vr, []).append(j)
        self.get_u = getter(unclocked_out)
        self.get_k = {k.vr: getter(get_by_clock.get(k.vr, [])) for k in model.clocks}
        # output (and local) clocks: read with fmi3GetClock in every Event Mode
        self.out_clocks = [k for k in model.clocks if k.causality != "input"]
        self.out_clock_pos = [outs.index(k.name) if k.name in outs else -1 for k in self.out_clocks]
        self.out_counts = [0] * len(self.out_clocks)
        self.publishers = [self.board.publisher(self.name, k.name) if k.is_port else None for k in self.out_clocks]
        self.labels = {k.vr: self.board.label(self.name, k.name) for k in model.clocks}
        self.priority = {k.vr: ((k.priority if k.priority is not None else 0), k.index) for k in model.clocks}
        # the triggered input clock of each port name
        self.port_clock = {k.name: k.vr for k in model.clocks if k.is_port and k.causality == "input"}

    def _fn(self, name: str):
        f = self._raw.get(name)
        if f is None:
            f = self._raw[name] = self.inst.raw(name)
        return f

    def _fail(self, what: str, status: int):
        if self.interface == "se" and status == 2:      # Scheduled Execution: discard is an error
            self.inst.worst = max(self.inst.worst, 3)
        self.inst.fail(what, status)

    def _check(self, st: int, what: str) -> None:
        if st > 1:
            self._fail(what, st)

    def _build_calls(self) -> None:
        c = self.c
        n_out = len(self.out_clocks)
        self._out_vr = (ctypes.c_uint32 * max(n_out, 1))(*[k.vr for k in self.out_clocks])
        self._out_val = (_B * max(n_out, 1))()
        self._n_out = ctypes.c_size_t(n_out)
        self._get_clock = self._fn("fmi3GetClock")
        self._set_clock_cache: dict = {}
        self._set_clock = self._fn("fmi3SetClock")
        flags = [_B(False) for _ in range(5)]
        self._uds_flags = flags
        self._uds_next = _D(0.0)
        self._uds_args = (c, *[ctypes.byref(f) for f in flags], ctypes.byref(self._uds_next))
        self._uds = self._fn("fmi3UpdateDiscreteStates") if self.interface != "se" else None
        self._enter_event = self._fn("fmi3EnterEventMode") if self.interface != "se" else None
        if self.interface == "cs":
            self._enter_step = self._fn("fmi3EnterStepMode")
            self._do_step = self._fn("fmi3DoStep")
            self._ds_flags = [_B(False) for _ in range(3)]
            self._ds_last = _D(0.0)
            self._ds_refs = (*[ctypes.byref(f) for f in self._ds_flags], ctypes.byref(self._ds_last))
        if self.interface == "se":
            self._activate = self._fn("fmi3ActivateModelPartition")
        # intervals read at run time
        cd = [k for k in self.model.clocks if k.variability == "countdown" and k.causality == "input"]
        self.countdown = cd
        self._interval_calls = {}

    def _intervals(self, clocks: list[FMIClock]) -> list[tuple[FMIClock, float, int]]:
        """``fmi3GetInterval*`` of ``clocks`` (the fraction form where supported):
        ``(clock, interval [s], qualifier)`` each."""
        if not clocks:
            return []
        key = tuple(k.vr for k in clocks)
        call = self._interval_calls.get(key)
        n = len(clocks)
        if call is None:
            vrs = (ctypes.c_uint32 * n)(*key)
            frac = all(k.supports_fraction for k in clocks)
            q = (_I * n)()
            if frac:
                cnt, res = (ctypes.c_uint64 * n)(), (ctypes.c_uint64 * n)()
                fn, args = self._fn("fmi3GetIntervalFraction"), (self.c, vrs, ctypes.c_size_t(n), cnt, res, q)
                label = "GetIntervalFraction"

                def read():
                    return [(cnt[i] / res[i]) if res[i] else float("inf") for i in range(n)]
            else:
                vals = (_D * n)()
                fn, args = self._fn("fmi3GetIntervalDecimal"), (self.c, vrs, ctypes.c_size_t(n), vals, q)
                label = "GetIntervalDecimal"

                def read():
                    return [vals[i] for i in range(n)]
            call = self._interval_calls[key] = (fn, args, label, read, q)
        fn, args, label, read, q = call
        self._check(fn(*args), f"{label}({', '.join(k.name for k in clocks)})")
        return [(k, v, int(q[i])) for i, (k, v) in enumerate(zip(clocks, read()))]

    # ------------------------------------------------------------------ timing
    def instant(self, t: float) -> int:
        """The component's instant number of ``t`` [s]."""
        return round((t - self.t0) / self.P)

    def _due_periodic(self, n: int) -> list[int]:
        due = []
        for entry in self.sched.periodic:
            if entry[2] == n:
                due.append(entry[0].vr)
                entry[2] += entry[1]
            elif entry[2] < n:                      # cannot happen: every instant is visited
                raise FMUError(f"{self.name}: clock {entry[0].name!r} missed its instant {entry[2]}")
        return due

    def _due_at(self, t: float) -> list[int]:
        """Aperiodic clocks and received activations due at ``t`` (removed from the pending)."""
        tol = self.tol
        due = []
        nxt = self.sched.next
        for vr, tn in nxt.items():
            if tn is not None and abs(tn - t) <= tol:
                due.append(vr)
                nxt[vr] = None
            elif tn is not None and tn < t - tol:
                raise FMUError(f"{self.name}: clock {self.model.by_vr[vr].name!r} was due at {tn:g} s, before "
                               f"t = {t:g} s")
        return due

    def _received_at(self, t: float) -> tuple[list[int], dict | None]:
        """The triggered clocks activated at ``t`` by their sources, and the snapshot of the
        sources' outputs (merged)."""
        box = self.inbox
        if not box:
            return [], None
        tol = self.tol
        ks, snap, keep = [], None, []
        for entry in box:
            te, port, s = entry
            if abs(te - t) <= tol:
                ks.append(self.port_clock[port])
                snap = dict(s) if snap is None else {**snap, **s}
            elif te < t - tol:
                raise FMUError(f"{self.name}: activation of {port!r} at {te:g} s arrived after the component "
                               f"passed it (t = {t:g} s)")
            else:
                keep.append(entry)
        if ks:
            box[:] = keep
        return ks, snap

    def _next_point(self, after: float, before: float) -> float | None:
        """The earliest pending activation strictly between ``after`` and ``before`` [s]."""
        tol = self.tol
        best = None
        for tn in self.sched.next.values():
            if tn is not None and after + tol < tn < before - tol and (best is None or tn < best):
                best = tn
        for te, _, _ in self.inbox:
            if after + tol < te < before - tol and (best is None or te < best):
                best = te
        if self.fmu_next is not None and after + tol < self.fmu_next < before - tol \
                and (best is None or self.fmu_next < best):
            best = self.fmu_next
        return best

    # ------------------------------------------------------------------ inputs
    def _fill(self, positions=None) -> None:
        if positions is None:
            n = len(self.comp.connected_inputs)
            if n:
                np.take(self.values, self.idx_in, out=self.vin[:n])
                np.take(self.integers, self.idx_in, out=self.iin[:n])
        elif len(positions):
            self.vin[positions] = self.values[self.idx_in[positions]]
            self.iin[positions] = self.integers[self.idx_in[positions]]

    def _overlay(self, snap: dict | None) -> None:
        """Inputs from the components of ``snap`` take their values at the activation."""
        self.vin[:] = self.vin_base
        self.iin[:] = self.iin_base
        if not snap:
            return
        for i, src in enumerate(self.sources):
            if src is not None and src[0] in snap:
                fl, it = snap[src[0]]
                self.vin[i], self.iin[i] = fl[src[1]], it[src[1]]

    # ------------------------------------------------------------------ clocks (ME, CS)
    def _set_clocks(self, vrs: list[int]) -> None:
        key = tuple(vrs)
        args = self._set_clock_cache.get(key)
        if args is None:
            n = len(vrs)
            args = self._set_clock_cache[key] = (self.c, (ctypes.c_uint32 * n)(*vrs), ctypes.c_size_t(n),
                                                 (_B * n)(*([True] * n)))
        self._check(self._set_clock(*args), f"SetClock({', '.join(self.model.by_vr[v].name for v in vrs)})")

    def _activate(self, t: float, ks: list[int], phase: str, snap: dict | None) -> None:
        """Event Mode (ME, CS): activate the input clocks ``ks`` at ``t``, set their clocked
        inputs (``phase`` "output": only those outputs depend on), read their outputs and
        the output clocks."""
        if ks:
            for vr in ks:
                if vr in self.active and self.model.by_vr[vr].periodic:
                    raise FMUError(f"{self.name}: periodic clock {self.model.by_vr[vr].name!r} would be active "
                                   f"twice in one Event Mode at t = {t:g} s")
            self._set_clocks(ks)
            log, labels = self.board.log, self.labels
            for vr in ks:
                log(t, labels[vr])
            sets = self.set_ft if phase == "output" else self.set_all
            for vr in ks:
                sets[vr]()
            self.active.update(ks)
            self.ticked.update(ks)
            for vr in ks:
                self.get_k[vr]()
        self._read_output_clocks(t, snap, phase != "output")

    def _read_output_clocks(self, t: float, snap: dict | None, fresh: bool) -> None:
        n = len(self.out_clocks)
        if not n:
            return
        self._check(self._get_clock(self.c, self._out_vr, self._n_out, self._out_val), "GetClock")
        vals = self._out_val
        published = None
        for i in range(n):
            if not vals[i]:
                continue
            k = self.out_clocks[i]
            self.out_counts[i] += 1
            pos = self.out_clock_pos[i]
            if pos >= 0:
                self.own[pos] = self.out_counts[i]
                self.own_i[pos] = self.out_counts[i]
            self.board.log(t, self.labels[k.vr])
            self.ticked.add(k.vr)
            self.get_k[k.vr]()
            if self.publishers[i] is not None:
                published = published or []
                published.append(self.publishers[i])
        if published:
            self._outbox.append((t, snap, published))
            if fresh:                                 # CS: outputs without clocks are left limits
                self._publish(self.interface == "me")

    def _publish(self, read: bool) -> None:
        """Send the output clocks' activations read so far to their sinks, each with this
        component's outputs (the unclocked ones read again first if ``read``)."""
        if not self._outbox:
            return
        if read:
            self.get_u()
        for t, snap, published in self._outbox:
            out = dict(snap) if snap else {}
            out[self.name] = (self.own.copy(), self.own_i.copy())
            for pub in published:
                pub(t, out)
        self._outbox.clear()

    def _finish(self, t: float) -> bool:
        """The rest of an Event Mode at ``t`` (ME, CS): the event iteration, the intervals,
        activations due at once; returns whether the FMU asks to terminate."""
        f = self._uds_flags
        for _ in range(MAX_SUPERDENSE):
            self._check(self._uds(*self._uds_args), f"UpdateDiscreteStates(t = {t:g} s)")
            self.active.clear()
            if f[1].value:
                return True
            if f[0].value:
                self._read_output_clocks(t, None, True)
                continue
            self._read_intervals(t)
            ks = self._due_at(t)
            got, snap = self._received_at(t)
            if ks or got:
                if got:
                    self._overlay(snap)
                self._activate(t, ks + got, "late", snap)
                continue
            self.fmu_next = float(self._uds_next.value) if f[4].value else None
            self.ticked.clear()
            return False
        raise FMUError(f"{self.name}: the event iteration at t = {t:g} s did not end in {MAX_SUPERDENSE} "
                       "super-dense instants")

    def _read_intervals(self, t: float) -> None:
        want = list(self.countdown)
        for vr in self.ticked:
            k = self.model.by_vr[vr]
            if k.causality == "input" and (k.variability == "changing" or
                                           (k.variability == "tunable" and not k.has_decimal)):
                want.append(k)
        for k, v, q in self._intervals(want):
            self._apply_interval(k, v, q, t, k.vr in self.ticked)
            self.ticked.discard(k.vr)

    def _apply_interval(self, k: FMIClock, v: float, q: int, t: float, ticked: bool) -> None:
        if q not in _QUALIFIER:
            raise FMUError(f"{self.name}: fmi3GetInterval of clock {k.name!r} returned the qualifier {q}")
        if k.variability == "countdown":
            if q == _CHANGED:
                self.sched.next[k.vr] = t + _interval(v, k, self.name, False)
        elif k.variability == "changing":
            if ticked and q != _CHANGED:
                raise FMUError(f"{self.name}: changing clock {k.name!r} ticked at t = {t:g} s but fmi3GetInterval "
                               f"returned {_QUALIFIER[q]}; the standard requires its next interval (changed)")
            if q == _CHANGED:
                self.sched.next[k.vr] = t + _interval(v, k, self.name, False)
        elif q == _CHANGED:                             # tunable without intervalDecimal: from now on
            iv = _interval(v, k, self.name, True)
            ratio = iv / self.P
            if abs(ratio - round(ratio)) > 1e-9 * max(1.0, ratio):
                raise FMUError(f"{self.name}: tunable clock {k.name!r} changed its interval to {iv:g} s at "
                               f"t = {t:g} s, not a multiple of the period {self.P:g} s")
            for entry in self.sched.periodic:
                if entry[0].vr == k.vr:
                    entry[1] = round(ratio)
                    entry[2] = self.instant(t) + round(ratio)

    # ------------------------------------------------------------------ write
    def _write(self) -> None:
        self.values[self.out] = self.own
        self.integers[self.out] = self.own_i

    # ------------------------------------------------------------------ Co-Simulation
    def cs_functions(self):
        enter_step, do_step = self._enter_step, self._do_step
        c, flags, last, refs = self.c, self._ds_flags, self._ds_last, self._ds_refs
        can_vary = bool(getattr(self.comp.md.coSimulation, "canHandleVariableCommunicationStepSize", False))
        name = self.name

        def enter(t):
            if not self.in_event:
                self._check(self._enter_event(c), f"EnterEventMode(t = {t:g} s)")
                self.in_event = True

        def output_fn(t: float) -> None:
            n = self.instant(t)
            if n == self.done_n:                        # again at this instant (a split or a loop)
                if self.in_event:
                    for vr in self.active:
                        self.set_ft[vr]()
                        self.get_k[vr]()
                self._write()
                return
            self.done_n = n
            self._fill(self.in_ft)
            self.get_u()
            ks = self._due_periodic(n) + self._due_at(t)
            got, snap = self._received_at(t)
            if self.fmu_next is not None and abs(self.fmu_next - t) <= self.tol:
                self.pending_event, self.fmu_next = True, None
            if ks or got or self.pending_event or self.in_event:
                enter(t)
                self.pending_event = False
                if got:
                    self.vin_base[:] = self.vin
                    self.iin_base[:] = self.iin
                    self._overlay(snap)
                self._activate(t, ks + got, "output", snap)
                self.set_u_ft()
                self._publish(False)
            self._write()

        def event(t: float) -> None:
            if self._finish(t):
                raise StopRequest(name, t, "the FMU requested termination in its event update")
            self._check(enter_step(c), f"EnterStepMode(t = {t:g} s)")
            self.in_event = False

        def update_fn(t: float) -> None:
            self._fill()
            if self.in_event:
                for vr in list(self.active):
                    self.set_rest[vr]()
                self.set_u_all()
                event(t)
            else:
                self.set_u_all()
            self.vin_base[:] = self.vin
            self.iin_base[:] = self.iin
            end = t + self.P
            tc = t
            while True:
                p = self._next_point(tc, end)
                target = end if p is None else p
                if p is not None and not can_vary:
                    raise FMUError(f"{name}: an activation at t = {p:g} s falls between its communication points, "
                                   "but the FMU cannot vary its communication step "
                                   "(canHandleVariableCommunicationStepSize = false)")
                st = do_step(c, _D(tc), _D(target - tc), True, *refs)
                if st > 1:
                    self._fail(f"DoStep(t = {tc:g} s, h = {target - tc:g} s)", st)
                ehn, term, early = flags[0].value, flags[1].value, flags[2].value
                reached = last.value if early else target
                if term:
                    raise StopRequest(name, reached, "fmi3DoStep returned terminateSimulation")
                if ehn:
                    if reached >= end - self.tol:
                        self.pending_event = True
                        return
                    self.get_u()
                    enter(reached)
                    self._intra(reached)
                    event(reached)
                    tc = reached
                    continue
                if early and reached < target - self.tol:
                    tc = reached
                    continue
                if target >= end - self.tol:
                    return
                self.get_u()
                enter(target)
                self._intra(target)
                event(target)
                tc = target

        return output_fn, update_fn

    def _intra(self, t: float) -> None:
        """Between instants, in Event Mode at ``t``: the activations due (ME, CS)."""
        ks = self._due_at(t)
        got, snap = self._received_at(t)
        self._overlay(snap)
        if self.fmu_next is not None and abs(self.fmu_next - t) <= self.tol:
            self.fmu_next = None
        self._activate(t, ks + got, "intra", snap)

    # ------------------------------------------------------------------ Model Exchange
    def me_functions(self, integrator):
        me = integrator
        run = self

        class Model(FMUModel):                  # the integrator's events go through the clocks
            def event(self, t, set_inputs=None):
                return run._me_event(t, set_inputs)

            def initial_event(self, t):
                return run._me_event(t, run._pending_inputs)

        model = Model(self.inst)
        me.model = model
        self._me = me
        self._pending_inputs = None
        pending = [False]

        def output_fn(t: float) -> None:
            n = self.instant(t)
            if n == self.done_n:
                if self.in_event:
                    for vr in self.active:
                        self.set_ft[vr]()
                        self.get_k[vr]()
                    self.set_u_ft()
                self.get_u()
                self._write()
                return
            self.done_n = n
            self._fill(self.in_ft)
            ks = self._due_periodic(n) + self._due_at(t)
            got, snap = self._received_at(t)
            if ks or got or self.in_event or self.pending_event:
                if not self.in_event:
                    self._check(self._enter_event(self.c), f"EnterEventMode(t = {t:g} s)")
                    self.in_event = True
                self.pending_event = False
                if got:
                    self.vin_base[:] = self.vin
                    self.iin_base[:] = self.iin
                    self._overlay(snap)
                self._activate(t, ks + got, "output", snap)
                self.set_u_ft()
            else:
                pending[0] |= bool(self.set_cont_ft())
                if self.set_disc_ft.differs():
                    me.at_event(t, self.set_disc_ft)
            self.get_u()
            self._publish(False)
            self._write()

        def rest():
            for vr in list(self.active):
                self.set_rest[vr]()
            self.set_u_all()

        def update_fn(t: float) -> None:
            self._fill()
            self.window_end = t + self.P
            if not self.started:
                self._pending_inputs = rest
                self.started = True
                me.start(t)
            elif self.in_event:
                me.at_event(t, rest)
            else:
                pending[0] |= bool(self.set_cont())
                if self.set_disc.differs():
                    me.at_event(t, self.set_disc)
            self.vin_base[:] = self.vin
            self.iin_base[:] = self.iin
            me.next_event = self._me_next(t)
            me.advance(t, self.P, pending[0])
            pending[0] = False

        return output_fn, update_fn

    def _me_next(self, t: float) -> float | None:
        p = self._next_point(t, self.window_end)
        f = self.fmu_next
        if f is not None and f <= t + self.tol:
            f = None
        return p if f is None else (f if p is None else min(p, f))

    def _me_event(self, t: float, set_inputs) -> tuple[bool, float | None]:
        """An Event Mode of the ME FMU at ``t`` (entered here unless already in it). An event
        the integrator finds at the end of the step (within rounding) waits for that instant,
        whose Event Mode handles it with the instant's activations."""
        if not self.in_event and set_inputs is None and abs(t - self.window_end) <= self.tol:
            self.pending_event = True
            return False, None
        if not self.in_event:
            self._check(self._enter_event(self.c), f"EnterEventMode(t = {t:g} s)")
            self.in_event = True
            if set_inputs is not None:
                set_inputs()
            self._intra(t)
        elif set_inputs is not None:
            set_inputs()
        if self._finish(t):
            return True, None
        self._check(self._fn("fmi3EnterContinuousTimeMode")(self.c), f"EnterContinuousTimeMode(t = {t:g} s)")
        self.in_event = False
        return False, self._me_next(t)

    # ------------------------------------------------------------------ Scheduled Execution
    def se_functions(self):
        name = self.name
        by_vr = self.model.by_vr
        act = self._activate_fn = self._fn("fmi3ActivateModelPartition")
        self._se_cb_clocks: list[int] = []           # output clocks reported active in callbacks
        self._se_now: float | None = None
        self._se_queue: list[int] = []
        self._se_done: set[int] = set()

        def run_at(t: float, ks: list[int], snap: dict | None) -> None:
            if not ks:
                return
            self._se_now = t
            self._se_done = set()
            queue = self._se_queue
            queue[:] = sorted(set(ks), key=self.priority.get)
            self.set_u_all()
            while queue:
                vr = queue.pop(0)
                k = by_vr[vr]
                if vr in self._se_done:
                    raise FMUError(f"{name}: clock {k.name!r} would be activated twice at t = {t:g} s (Scheduled "
                                   "Execution activates a partition once per time)")
                self._se_done.add(vr)
                self.set_all[vr]()
                self._se_cb_clocks = []
                st = act(self.c, ctypes.c_uint32(vr), _D(t))
                err, self._error = self._error, None
                if err is not None:                 # what went wrong in the callback comes first
                    if st > 1:
                        self.inst.worst = max(self.inst.worst, 3 if st == 2 else st)
                    raise err
                if st > 1:
                    self._fail(f"ActivateModelPartition({k.name}, t = {t:g} s)", st)
                self.board.log(t, self.labels[vr])
                self.get_k[vr]()
                self.get_u()
                if k.variability == "changing" or (k.variability == "tunable" and not k.has_decimal):
                    for kk, v, q in self._intervals([k]):
                        self._apply_interval(kk, v, q, t, True)
                        if kk.variability == "changing" and abs(self.sched.next.get(kk.vr) or -1 - t) <= self.tol:
                            queue.append(kk.vr)
                    queue.sort(key=self.priority.get)
                self._se_outputs(t, snap)
            self._se_now = None

        def output_fn(t: float) -> None:
            n = self.instant(t)
            if n == self.done_n:
                self._write()
                return
            self.done_n = n
            self._fill(self.in_ft)
            ks = self._due_periodic(n) + self._due_at(t)
            got, snap = self._received_at(t)
            if got:
                self.vin_base[:] = self.vin
                self.iin_base[:] = self.iin
                self._overlay(snap)
            run_at(t, ks + got, snap)
            self._write()

        def update_fn(t: float) -> None:
            self._fill()
            self.vin_base[:] = self.vin
            self.iin_base[:] = self.iin
            end = t + self.P
            tc = t
            while True:
                p = self._next_point(tc, end)
                if p is None:
                    got, snap = self._received_at(t)        # arrived after this instant's outputs
                    if got:
                        self._overlay(snap)
                        run_at(t, got, snap)
                    return
                ks = self._due_at(p)
                got, snap = self._received_at(p)
                self._overlay(snap)
                run_at(p, ks + got, snap)
                tc = p

        return output_fn, update_fn

    def clock_update(self, env) -> None:
        """The ``clockUpdate`` callback (Clock Update Mode): every output clock read with
        ``fmi3GetClock``, every countdown clock's interval; an error is kept and raised
        after the activation returns (a callback cannot raise)."""
        try:
            self.in_callback = True
            n = len(self.out_clocks)
            if n:
                self._check(self._get_clock(self.c, self._out_vr, self._n_out, self._out_val), "GetClock")
                for i in range(n):
                    if self._out_val[i]:
                        self._se_cb_clocks.append(i)
            t = self._se_now
            for k, v, q in self._intervals(self.countdown):
                if q not in _QUALIFIER:
                    raise FMUError(f"{self.name}: fmi3GetInterval of clock {k.name!r} returned the qualifier {q}")
                if q == _CHANGED:
                    te = (t if t is not None else self.t0) + _interval(v, k, self.name, False)
                    self.sched.next[k.vr] = te
                    if t is not None and abs(te - t) <= self.tol:
                        self.sched.next[k.vr] = None
                        if k.vr not in self._se_queue:
                            self._se_queue.append(k.vr)
                            self._se_queue.sort(key=self.priority.get)
        except BaseException as e:  # noqa: BLE001 - kept, raised after the FMU returns
            if self._error is None:
                self._error = e
        finally:
            self.in_callback = False

    def _se_outputs(self, t: float, snap: dict | None) -> None:
        published = None
        for i in self._se_cb_clocks:
            k = self.out_clocks[i]
            self.out_counts[i] += 1
            pos = self.out_clock_pos[i]
            if pos >= 0:
                self.own[pos] = self.out_counts[i]
                self.own_i[pos] = self.out_counts[i]
            self.board.log(t, self.labels[k.vr])
            self.get_k[k.vr]()
            if self.publishers[i] is not None:
                published = published or []
                published.append(self.publishers[i])
        self._se_cb_clocks = []
        if published:
            out = dict(snap) if snap else {}
            out[self.name] = (self.own.copy(), self.own_i.copy())
            for pub in published:
                pub(t, out)


def initialise(comp, inst, t0: float) -> _Schedule:
    """In Initialization Mode: the clock intervals set or asked as the standard says (see
    the module documentation); returns the run's schedule."""
    model: FMIClocks = comp.clock_model
    sched = _Schedule(model, t0, comp.period, comp.clock_overrides)
    c = ctypes.c_void_p(inst.handle)

    def call(name, *args):
        st = inst.raw(name)(c, *args)
        if st > 1:
            inst.fail(f"{name[4:]}", st)

    for k in model.clocks:
        if k.causality != "input":
            continue
        vr = (ctypes.c_uint32 * 1)(k.vr)
        one = ctypes.c_size_t(1)
        if k.variability == "constant":
            sched.add_periodic(k, k.interval, k.shift, comp.name)
        elif k.importer_sets_interval:
            interval = sched.overrides.get(k.name, k.interval)
            if k.supports_fraction and k.counter is not None:
                counter = interval * k.resolution
                if counter.denominator != 1:
                    raise ConfigurationError(f"{comp.name}: the interval {float(interval):g} s of clock {k.name!r} is "
                                             f"not a whole number of its resolution 1/{k.resolution} s")
                call("fmi3SetIntervalFraction", vr, one, (ctypes.c_uint64 * 1)(counter.numerator),
                     (ctypes.c_uint64 * 1)(k.resolution))
            else:
                call("fmi3SetIntervalDecimal", vr, one, (_D * 1)(float(interval)))
            sched.add_periodic(k, interval, k.shift, comp.name)
        elif k.periodic:                                  # fixed/tunable without intervalDecimal: ask
            q = (_I * 1)()
            if k.supports_fraction:
                cnt, res = (ctypes.c_uint64 * 1)(), (ctypes.c_uint64 * 1)()
                call("fmi3GetIntervalFraction", vr, one, cnt, res, q)
                if not res[0]:
                    raise FMUError(f"{comp.name}: fmi3GetIntervalFraction of clock {k.name!r} returned resolution 0")
                interval = Fraction(cnt[0], res[0])
                sc, sr = (ctypes.c_uint64 * 1)(), (ctypes.c_uint64 * 1)()
                call("fmi3GetShiftFraction", vr, one, sc, sr)
                shift = Fraction(sc[0], sr[0]) if sr[0] else Fraction(0)
            else:
                iv = (_D * 1)()
                call("fmi3GetIntervalDecimal", vr, one, iv, q)
                interval = time_fraction(_interval(iv[0], k, comp.name, True))
                sh = (_D * 1)()
                call("fmi3GetShiftDecimal", vr, one, sh)
                if not math.isfinite(sh[0]) or sh[0] < 0:
                    raise FMUError(f"{comp.name}: fmi3GetShiftDecimal of clock {k.name!r} returned {sh[0]!r}")
                shift = time_fraction(sh[0])
            if q[0] == _NOT_YET_KNOWN:
                raise FMUError(f"{comp.name}: fmi3GetInterval of {k.variability} clock {k.name!r} returned "
                               "fmi3IntervalNotYetKnown, which only countdown clocks may return")
            sched.add_periodic(k, interval, shift, comp.name)
        elif k.aperiodic:
            iv, q = (_D * 1)(), (_I * 1)()
            if k.supports_fraction:
                cnt, res = (ctypes.c_uint64 * 1)(), (ctypes.c_uint64 * 1)()
                call("fmi3GetIntervalFraction", vr, one, cnt, res, q)
                iv[0] = cnt[0] / res[0] if res[0] else float("nan")
            else:
                call("fmi3GetIntervalDecimal", vr, one, iv, q)
            if q[0] not in _QUALIFIER:
                raise FMUError(f"{comp.name}: fmi3GetInterval of clock {k.name!r} returned the qualifier {q[0]}")
            if k.variability == "changing" and q[0] == _NOT_YET_KNOWN:
                raise FMUError(f"{comp.name}: fmi3GetInterval of changing clock {k.name!r} returned "
                               "fmi3IntervalNotYetKnown, which only countdown clocks may return")
            sched.next[k.vr] = t0 + _interval(iv[0], k, comp.name, False) if q[0] == _CHANGED else None
    for k in model.clocks:
        if k.aperiodic and k.causality == "input":
            sched.next.setdefault(k.vr, None)
    return sched

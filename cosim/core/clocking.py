"""Clocks in the master (FMI 3.0 clocks): what a clocked component declares
(:class:`~cosim.core.clocking.ClockInfo`), the plan checked before a run
(:class:`~cosim.core.clocking.ClockPlan`), a run's activations (:class:`~cosim.core.clocking.ClockBoard`)
and the clock source :class:`~cosim.core.clocking.ClockTicks`; see the clocks page of the documentation.
"""
from __future__ import annotations

import itertools
import math
from array import array
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import Protocol, runtime_checkable

import numpy as np
import pandas as pd

from fmu_models.errors import ConfigurationError, ResourceError, TypeMismatchError
from fmu_models.infra.checks import finite, positive

from .component import CLOCK, Component, Port

__all__ = ["APERIODIC", "MAX_TICKS", "PERIODIC", "VARIABILITIES", "ClockBoard", "ClockInfo", "ClockPlan", "ClockTicks",
           "ClockedComponent", "fraction_gcd", "time_fraction"]

#: Interval variabilities of periodic clocks (an interval and a shift known before the run).
PERIODIC = ("constant", "fixed", "tunable")
#: Interval variabilities of aperiodic clocks (the next activation known only at run time).
APERIODIC = ("changing", "countdown")
#: Every FMI 3.0 interval variability.
VARIABILITIES = PERIODIC + APERIODIC + ("triggered",)
#: The most activations one run logs; a run that would log more is refused (the log would not fit).
MAX_TICKS = 50_000_000


def time_fraction(x) -> Fraction:
    """A time [s] as an exact fraction: a decimal text exactly (``"0.1"`` is 1/10), a float
    to within 1e-9 of its value's denominator (as the base step, :mod:`cosim.core.schedule`)."""
    if isinstance(x, Fraction):
        return x
    if isinstance(x, str):
        return Fraction(x.strip())
    return Fraction(float(x)).limit_denominator(10**9)


def fraction_gcd(*values: Fraction) -> Fraction:
    """The greatest common divisor of positive fractions (zeros are skipped; 0 if all are)."""
    values = [v for v in values if v]                  # in lowest terms: gcd of numerators / lcm of denominators
    return Fraction(math.gcd(*(v.numerator for v in values)), math.lcm(*(v.denominator for v in values)))


@dataclass(frozen=True)
class ClockInfo:
    """One clock of a clocked component, as the master's plan sees it.

    Attributes
    ----------
    name : str
        The clock's name (the FMU variable's).
    causality : {"input", "output", "local"}
    variability : str
        One of :data:`VARIABILITIES`.
    interval, shift : Fraction or None
        A periodic clock's interval and shift [s] when known before the run (else None:
        given by the FMU at its initialisation).
    port : str or None
        The port the clock is (triggered input clocks and output clocks), else None.
    note : str
        Where its timing comes from, in words (for :meth:`~cosim.core.master.Cosimulation.describe`).
    priority : int or None
        Scheduled Execution priority (smaller first), if any.
    """

    name: str
    causality: str
    variability: str
    interval: Fraction | None = None
    shift: Fraction | None = None
    port: str | None = None
    note: str = ""
    priority: int | None = None

    def timing(self) -> str:
        """The clock's timing in words."""
        if self.causality != "input":
            return f"{self.causality} clock" + (f", {self.note}" if self.note else "")
        if self.variability == "triggered":
            what = "triggered"
        elif self.variability in APERIODIC:
            what = f"{self.variability}: when the FMU says (its intervals read at run time)"
        elif self.interval is None:
            what = f"{self.variability}, interval and shift from the FMU at initialisation"
        else:
            what = f"{self.variability}, every {float(self.interval):g} s from {float(self.shift or 0):g} s"
        return what + (f"; {self.note}" if self.note else "")


@runtime_checkable
class ClockedComponent(Protocol):
    """A component with clocks (a :class:`~cosim.core.clocking.ClockInfo` each); one whose
    ``clock_infos`` is empty takes no part in clocks."""

    clock_infos: tuple

    def attach_clocks(self, board: ClockBoard) -> None:
        """Called before each run (after ``reset``, before ``bind``) with the run's board."""


def clocked(component: Component) -> bool:
    """Whether ``component`` takes part in clocks."""
    # the attribute first: a Protocol isinstance check is slow, and most components have none
    return bool(getattr(component, "clock_infos", None)) and isinstance(component, ClockedComponent)


class ClockPlan:
    """The clocks of a co-simulation, checked before the run (what is refused: the clocks
    page of the documentation).

    Parameters
    ----------
    components : sequence of Component
        In the user's order.
    connections : mapping
        ``(dst component, input) -> (src component, output)`` (the master's, checked).
    ratios : mapping of str to int
        Each component's period in base steps.
    base : Fraction
        The base step [s].
    order : str
        The master's evaluation order option.

    Attributes
    ----------
    members : list of Component
        The clocked components, in list order.
    links : list of tuple
        The clock connections ``(src component, src port, dst component, dst port)``.
    update_order : list of Component
        Every component, in an order in which each clock source comes before its sinks
        (ties in list order).

    Raises
    ------
    ConfigurationError
        Any clock the run cannot honour, named.
    """

    def __init__(self, components: Sequence[Component], connections: Mapping, ratios: Mapping[str, int],
                 base: Fraction, order: str):
        self.components = list(components)
        self.by_name = {c.name: c for c in self.components}
        self.members = [c for c in self.components if clocked(c)]
        self.ratios, self.base = dict(ratios), base
        self.connections = dict(connections)
        self.links = [(sn, sp, dn, dp) for (dn, dp), (sn, sp) in connections.items()
                      if next(p.type for p in self.by_name[dn].input_ports if p.name == dp) == CLOCK]
        self._check_periodic()
        self._check_links(order)
        self.update_order = self._topological()

    @classmethod
    def build(cls, components, connections, ratios, base, order) -> ClockPlan | None:
        """The plan, or None if no component has clocks or clock ports (then nothing changes)."""
        if not any(clocked(c) for c in components) and not any(
                p.type == CLOCK for c in components for p in (*c.input_ports, *c.output_ports)):
            return None
        return cls(components, connections, ratios, base, order)

    # ------------------------------------------------------------------ checks
    def period(self, name: str) -> Fraction:
        """Component ``name``'s period [s], exact."""
        return self.ratios[name] * self.base

    def _check_periodic(self) -> None:
        for c in self.members:
            p = self.period(c.name)
            for k in c.clock_infos:
                if k.causality != "input" or k.variability not in PERIODIC or k.interval is None:
                    continue
                shift = k.shift or Fraction(0)
                for what, v in (("interval", k.interval), ("shift", shift)):
                    if (v / p).denominator != 1:
                        g = fraction_gcd(p, k.interval, shift)
                        raise ConfigurationError(
                            f"component {c.name!r}: clock {k.name!r} ({k.variability}) ticks every "
                            f"{float(k.interval):g} s from {float(shift):g} s, but its {what} {float(v):g} s is not a "
                            f"multiple of {c.name}'s period {float(p):g} s, so it would tick between the instants at "
                            f"which the master steps {c.name}. A period of {float(g):g} s (and a base step that "
                            "divides it) would honour it")

    def _check_links(self, order: str) -> None:
        members = {c.name for c in self.members}
        for c in self.components:
            for p in (*c.input_ports, *c.output_ports):
                if p.type == CLOCK and c.name not in members:
                    raise ConfigurationError(f"component {c.name!r} has the clock port {p.name!r} but declares no "
                                             "clocks (cosim.core.clocking.ClockedComponent)")
        for sn, sp, dn, dp in self.links:
            src = {k.port: k for k in self.by_name[sn].clock_infos if k.port}
            dst = {k.port: k for k in self.by_name[dn].clock_infos if k.port}
            if sp not in src or src[sp].causality == "input":
                raise ConfigurationError(f"clock connection {sn}.{sp} -> {dn}.{dp}: {sn}.{sp} is not an output clock")
            if dp not in dst or dst[dp].variability != "triggered" or dst[dp].causality != "input":
                raise ConfigurationError(f"clock connection {sn}.{sp} -> {dn}.{dp}: {dn}.{dp} is not a triggered "
                                         "input clock (only those take their activations from a connection)")
            if sn == dn:
                raise ConfigurationError(
                    f"clock connection {sn}.{sp} -> {dn}.{dp} connects {sn} to itself; the FMI way for an FMU to "
                    "activate one of its own partitions is a countdown clock inside it")
            if self.ratios[sn] % self.ratios[dn]:
                raise ConfigurationError(
                    f"clock connection {sn}.{sp} -> {dn}.{dp}: {dn} is stepped every {float(self.period(dn)):g} s, "
                    f"less often than its source {sn} (every {float(self.period(sn)):g} s), so an activation of "
                    f"{sn}.{sp} could come after {dn} has stepped past it. Give {dn} a period that divides "
                    f"{float(self.period(sn)):g} s")
        if self.links and order != "auto":
            raise ConfigurationError(f"clock connections need order = 'auto' (got {order!r}): a triggered clock is "
                                     "activated at the same instant as its source, after it")
        for c in self.members:
            for k in c.clock_infos:
                if k.causality == "input" and k.variability == "triggered" and (
                        k.port is None or (c.name, k.port) not in self.connections):
                    outs = [f"{m.name}.{q.port}" for m in self.members for q in m.clock_infos
                            if q.port and q.causality != "input" and m is not c]
                    where = "" if k.port is not None else f" (it is not among {c.name}'s inputs: list it there)"
                    raise ConfigurationError(
                        f"triggered input clock {c.name}.{k.name} has no source{where}: it is activated only through "
                        "a clock connection; connect an output clock to it (e.g. a clock_ticks component's 'tick')"
                        + (f"; output clocks: {', '.join(outs)}" if outs else ""))

    def _topological(self) -> list[Component]:
        """The components, each clock source before its sinks, ties in list order."""
        pending, out = list(self.components), []
        while pending:
            done = {c.name for c in out}
            c = next((c for c in pending if all(sn in done for sn, _, dn, _ in self.links if dn == c.name)), None)
            if c is None:
                cyc = {c.name for c in pending}
                hops = ", ".join(f"{sn}.{sp} -> {dn}.{dp}" for sn, sp, dn, dp in self.links if sn in cyc and dn in cyc)
                raise ConfigurationError(f"the clock connections form a cycle ({hops}): no component can be stepped "
                                         "before the others; break the cycle")
            pending.remove(c)
            out.append(c)
        return out

    # ------------------------------------------------------------------ description
    def describe_lines(self) -> list[str]:
        """The clocks in words, one line each (for :meth:`~cosim.core.master.Cosimulation.describe`)."""
        lines = ["clocks (a clock port's signal counts its activations):"]
        for c in self.members:
            p = self.period(c.name)
            for k in c.clock_infos:
                text = k.timing()
                if k.causality != "input":
                    drives = [f"{dn}.{dp}" for sn, sp, dn, dp in self.links if (sn, sp) == (c.name, k.port)]
                    text += f"; drives {', '.join(drives) or 'nothing'}"
                elif k.variability == "triggered":                # a source is checked to exist
                    text += f" by {'.'.join(self.connections[(c.name, k.port)])}"
                elif k.variability not in PERIODIC:
                    text += "; at its exact time, between instants if it falls there"
                elif k.interval is None:
                    text += f" (checked at initialisation to be multiples of {c.name}'s period)"
                else:
                    every, first = int(k.interval / p), int((k.shift or 0) / p)
                    text += (f": every instant of {c.name}" if every == 1 and first == 0 else
                             f": every {every} instant(s) of {c.name} from instant {first}")
                if k.priority is not None:
                    text += f"; priority {k.priority}"
                lines.append(f"  {c.name}.{k.name}: {text}")
        return lines

    def connection_text(self, src: str, dst: str) -> str:
        """What a clock connection does, in words."""
        return (f"clock connection: {dst.split('.')[0]}'s partition runs at each activation of {src}, at the same "
                "time (latency 0; between base instants if the activation falls there)")

    def clocked_text(self, dst: str, clocks: Sequence[str], direct: bool) -> str:
        """What a connection into an input of component ``dst`` clocked by ``clocks`` does,
        in words (``direct``: an output depends on the input directly)."""
        names = ", ".join(f"{dst}.{k}" for k in clocks)
        when = "at t after the source's output at t" if direct else "before the state changes at t"
        return (f"clocked by {names}: set only at its activations ({when}; between base instants the value of the "
                "component whose clock caused the activation at that time, else the value at the last instant)")

    # ------------------------------------------------------------------ the run
    def board(self, values: np.ndarray, integers: np.ndarray, slots: Mapping) -> ClockBoard:
        """A fresh :class:`ClockBoard` for one run over the master's signal arrays."""
        return ClockBoard(self, values, integers, slots)


class ClockBoard:
    """The activations of one run: who receives what, the inputs' sources, and the log.

    Parameters
    ----------
    plan : ClockPlan or None
        None: a component used outside a master (no clock connections).
    values, integers : ndarray
        The master's signal arrays (floats, exact integers).
    slots : mapping
        ``(component, output) -> index`` of every signal.
    """

    def __init__(self, plan: ClockPlan | None, values: np.ndarray, integers: np.ndarray, slots: Mapping):
        self.plan, self.values, self.integers, self.slots = plan, values, integers, dict(slots)
        self._inbox: dict = {}
        self._label_of: dict[str, int] = {}          # in the order of their numbers
        self._times, self._ids = array("d"), array("q")

    def inbox(self, component: str) -> list:
        """The list the activations for ``component``'s triggered clocks are appended to, as
        ``(time, port, snapshot)``; the component removes what it has handled."""
        return self._inbox.setdefault(component, [])

    def publisher(self, component: str, port: str) -> Callable[[float, dict], None] | None:
        """A function ``publish(time, snapshot)`` that activates every triggered clock connected
        to ``component.port`` at ``time`` [s] (``snapshot``: ``{component: (floats, ints)}``,
        outputs at that time); None if nothing is connected to it."""
        links = self.plan.links if self.plan is not None else ()
        boxes = [(self.inbox(dn), dp) for sn, sp, dn, dp in links if (sn, sp) == (component, port)]
        if not boxes:
            return None

        def publish(time: float, snapshot: dict) -> None:
            for box, dp in boxes:
                box.append((time, dp, snapshot))
        return publish

    def sources(self, component: str, inputs: Sequence[str]) -> list[tuple[str, int, int] | None]:
        """For each of ``component``'s ``inputs``: ``(source component, its output's index in
        that component's outputs, the signal's index)``, or None (not connected)."""
        plan = self.plan
        srcs = [plan.connections.get((component, p)) if plan is not None else None for p in inputs]
        return [None if s is None else (s[0], plan.by_name[s[0]].output_names.index(s[1]), self.slots[s])
                for s in srcs]

    def label(self, component: str, clock: str) -> int:
        """The log's number for ``component.clock``."""
        return self._label_of.setdefault(f"{component}.{clock}", len(self._label_of))

    def log_functions(self) -> tuple:
        """``(log_time, log_label, labels)``: the appends of :meth:`log` without its limit check
        and the logged labels, for a hot path (which calls :meth:`check_room` when their
        ``len`` is above the limit)."""
        return self._times.append, self._ids.append, self._ids

    def check_room(self) -> None:
        """Refuse (:class:`~fmu_models.errors.ResourceError`) a run that has logged more than
        :data:`MAX_TICKS` activations."""
        if len(self._ids) > MAX_TICKS:
            raise ResourceError(f"more than {MAX_TICKS} clock activations in one run: the log would not fit; "
                                "shorten the run")

    def log(self, time: float, label: int) -> None:
        """Log one activation of the clock numbered ``label`` at ``time`` [s]."""
        self.check_room()
        self._times.append(time)
        self._ids.append(label)

    def ticks(self) -> pd.DataFrame:
        """Every activation logged, in order: columns ``time`` [s] and ``clock``
        (``component.clock``)."""
        names = np.array([*self._label_of, ""], dtype=object)
        return pd.DataFrame({"time": np.frombuffer(self._times, dtype=float),
                             "clock": names[np.frombuffer(self._ids, dtype=np.int64)]})


class ClockTicks(Component, kind="clock_ticks"):
    """A clock source: its output clock ``tick`` is activated at the given ``times`` [s],
    or every ``interval`` [s] from ``shift`` [s] after the start (what drives a triggered
    input clock of an FMU; between its instants too, where a time falls there).

    Parameters
    ----------
    name : str
    period : float
        Sample period [s] (the activations need not fall on its instants).
    times : sequence of float, optional
        The activation times [s], distinct and finite.
    interval : float, optional
        Instead of ``times``: a periodic activation [s] ...
    shift : float
        ... from this delay [s] after the start time (default 0).

    Attributes
    ----------
    count : int
        Activations so far (the signal ``tick``).
    """

    reentrant = True

    def __init__(self, name: str, period: float, times: Sequence[float] | None = None,
                 interval: float | None = None, shift: float = 0.0):
        super().__init__(name, period, outputs=[Port("tick", CLOCK, description="activated at the given times")],
                         feedthrough=False)
        if (times is None) == (interval is None):
            raise ConfigurationError(f"{name}: give either times (a list of activation times) or interval")
        if times is not None:
            if isinstance(times, (str, bytes)) or not isinstance(times, Sequence | np.ndarray):
                raise TypeMismatchError(f"{name}: times must be a list of times [s], got {times!r}")
            ts = sorted(finite(x, f"{name}: times") for x in times)
            dup = [a for a, b in itertools.pairwise(ts) if a == b]
            if dup:
                raise ConfigurationError(f"{name}: the time {dup[0]:g} s is given twice (one activation per time)")
            self.times, self.interval, self.shift = ts, None, None
        else:
            self.times, self.interval = None, positive(interval, f"{name}: interval [s]")
            self.shift = finite(shift, f"{name}: shift [s]")
            if self.shift < 0:
                raise ConfigurationError(f"{name}: shift must be >= 0 s, got {self.shift:g}")
        note = (f"at {', '.join(f'{x:g}' for x in self.times[:6])}{' ...' if len(self.times) > 6 else ''} s"
                if self.times is not None else f"every {self.interval:g} s from {self.shift:g} s")
        self.clock_infos = (ClockInfo("tick", "output", "triggered", port="tick", note=f"activated {note}"),)
        self._publish = self._label = self._board = None
        self.reset(0.0)

    def attach_clocks(self, board: ClockBoard) -> None:
        self._board = board
        self._publish = board.publisher(self.name, "tick")
        self._label = board.label(self.name, "tick")

    def check_run(self, start_time: float, stop_time: float) -> None:
        """Refuse activation times before the start, and more than :data:`MAX_TICKS` activations."""
        if self.times and self.times[0] < start_time:
            raise ConfigurationError(f"{self.name}: activation time {self.times[0]:g} s is before the start time "
                                     f"{start_time:g} s")
        if self.interval is not None:
            n = (stop_time - start_time - self.shift) / self.interval + 1
            if n > MAX_TICKS:
                raise ResourceError(f"{self.name}: an activation every {self.interval:g} s from {start_time:g} s to "
                                    f"{stop_time:g} s makes {n:.3g} of them, more than {MAX_TICKS} (a run logs each)")

    def reset(self, t0: float) -> None:
        super().reset(t0)
        self.count, self._t0 = 0, float(t0)

    def _time(self, i: int) -> float | None:
        if self.times is not None:
            return self.times[i] if i < len(self.times) else None
        return self._t0 + self.shift + i * self.interval

    def _fire(self, until: float, inclusive: bool) -> None:
        tol = 1e-9 * self.period
        while True:
            ti = self._time(self.count)
            if ti is None or ti > until + tol or (not inclusive and ti >= until - tol):
                return
            self.count += 1
            if self._board is not None:
                self._board.log(ti, self._label)
            if self._publish is not None:
                self._publish(ti, {self.name: (np.array([float(self.count)]), np.array([self.count], np.int64))})

    def output(self, t: float, u) -> np.ndarray:
        """Activations at ``t`` [s] (and any before it not yet made); returns the count."""
        self._fire(t, True)
        return np.array([float(self.count)])

    def update(self, t: float, u) -> None:
        """The activations strictly between ``t`` and ``t + period`` [s]."""
        self._fire(t + self.period, False)

    def timing(self) -> str:
        return f"clock source: tick {self.clock_infos[0].note}"

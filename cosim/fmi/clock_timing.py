"""The timing of a clocked FMI 3.0 FMU's clocks, shared by the call sequences of
:mod:`cosim.fmi.clock_run`: set or asked in Initialization Mode (§2.3.3), then followed in
the run (the clocks page of the documentation).
"""
from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass, field
from fractions import Fraction

from fmu_models.errors import ConfigurationError, FMUError

from ..core.clocking import APERIODIC, PERIODIC, fraction_gcd, time_fraction
from .clock_ports import ClockPorts, Plan
from .clocks import CHANGED, NOT_YET_KNOWN, QUALIFIERS, FMIClock

__all__ = ["MAX_PATTERN", "ClockSchedule", "ClockedRun", "initialise"]

#: Longest pattern of periodic activations computed ahead (in instants).
MAX_PATTERN = 10_000
_D, _I, _U32, _U64, _SIZE = ctypes.c_double, ctypes.c_int, ctypes.c_uint32, ctypes.c_uint64, ctypes.c_size_t


def checked_interval(v: float, k: FMIClock, owner: str, periodic: bool) -> float:
    """An interval [s] ``fmi3GetInterval*`` returned for clock ``k`` of component ``owner``,
    refused unless finite and >= 0 (> 0 if ``periodic``)."""
    if not math.isfinite(v) or v < 0 or (periodic and v <= 0):
        raise FMUError(f"{owner}: fmi3GetInterval of clock {k.name!r} returned {v!r}; an interval must be finite and "
                       f"{'> 0' if periodic else '>= 0'}")
    return v


def _not_yet_known(k: FMIClock, owner: str) -> FMUError:
    return FMUError(f"{owner}: fmi3GetInterval of {k.variability} clock {k.name!r} returned fmi3IntervalNotYetKnown, "
                    "which only countdown clocks may return")


@dataclass
class ClockSchedule:
    """A run's timing of one FMU's clocks, from its initialisation on.

    Parameters
    ----------
    owner : str
        The component's name (for messages).
    t0 : float
        The start time [s].
    period : float
        The component's period [s].
    periodic : list of [FMIClock, int, int]
        Each periodic clock, its interval and its first activation in instants.
    next_at : dict of int to float
        The pending activation time [s] of each aperiodic clock that has one.
    """

    owner: str
    t0: float
    period: float
    periodic: list[list] = field(default_factory=list)
    next_at: dict[int, float] = field(default_factory=dict)

    def add_periodic(self, k: FMIClock, interval: Fraction, shift: Fraction) -> None:
        """Add periodic clock ``k``, its ``interval`` and ``shift`` [s] multiples of the period."""
        p, owner = time_fraction(self.period), self.owner
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

    def apply_interval(self, k: FMIClock, v: float, q: int, t: float, ticked: bool) -> bool:
        """Clock ``k``'s interval ``v`` [s] (qualifier ``q``) read at ``t`` [s] (``ticked``: it was
        active there): its next activation, or (tunable) its pattern from now on; whether the
        pattern changed."""
        owner = self.owner
        if q not in QUALIFIERS:
            raise FMUError(f"{owner}: fmi3GetInterval of clock {k.name!r} returned the qualifier {q}")
        if k.variability == "changing" and ticked and q != CHANGED:
            raise FMUError(f"{owner}: changing clock {k.name!r} ticked at t = {t:g} s but fmi3GetInterval "
                           f"returned {QUALIFIERS[q]}; the standard requires its next interval (changed)")
        if k.variability == "changing" and q == NOT_YET_KNOWN:
            raise _not_yet_known(k, owner)
        if q != CHANGED:
            return False
        if k.variability in ("countdown", "changing"):
            self.next_at[k.vr] = t + checked_interval(v, k, owner, False)
            return False
        iv = checked_interval(v, k, owner, True)          # tunable without intervalDecimal: from now on
        ratio = iv / self.period
        if abs(ratio - round(ratio)) > 1e-9 * max(1.0, ratio):
            raise FMUError(f"{owner}: tunable clock {k.name!r} changed its interval to {iv:g} s at "
                           f"t = {t:g} s, not a multiple of the period {self.period:g} s")
        for entry in self.periodic:
            if entry[0].vr == k.vr:
                entry[1:] = [round(ratio), round((t - self.t0) / self.period) + round(ratio)]
        return True


# ---------------------------------------------------------------------- Initialization Mode
def initialise(comp, inst, t0: float) -> ClockSchedule:
    """In Initialization Mode (§2.3.3): the input clocks' intervals set or asked (as the clocks
    page of the documentation says); returns the run's schedule.

    Parameters
    ----------
    comp : FMUComponent
        The component (its clocks, period and ``clock_intervals``).
    inst : FMUInstance
        Its instance, in Initialization Mode.
    t0 : float
        The start time [s].
    """
    sched = ClockSchedule(comp.name, t0, comp.period)
    c, owner = ctypes.c_void_p(inst.handle), comp.name

    def call(name: str, k: FMIClock, *args) -> list:
        """``name`` of clock ``k`` with the one-element arrays ``args``; their values after it."""
        st = inst.raw(name)(c, (_U32 * 1)(k.vr), _SIZE(1), *args)
        if st > 1:
            inst.fail(name[4:], st)
        return [a[0] for a in args]

    for k in comp.clock_model.clocks:
        if k.causality != "input":
            continue
        if k.variability == "constant":
            sched.add_periodic(k, k.interval, k.shift)
        elif k.importer_sets_interval:
            sched.add_periodic(k, _set_interval(call, k, comp.clock_overrides.get(k.name, k.interval), owner), k.shift)
        elif k.variability in PERIODIC:                   # fixed/tunable without intervalDecimal: ask
            sched.add_periodic(k, *_ask_periodic(call, k, owner))
        elif k.variability in APERIODIC:
            interval, q = _get_interval(call, k)
            if k.supports_fraction:
                interval = interval[0] / interval[1] if interval[1] else float("nan")
            sched.apply_interval(k, interval, q, t0, False)
    return sched


def _set_interval(call, k: FMIClock, interval: Fraction, owner: str) -> Fraction:
    """``fmi3SetInterval*`` of clock ``k`` (counter form: a whole number of its resolution)."""
    if k.supports_fraction and k.counter is not None:
        counter = interval * k.resolution
        if counter.denominator != 1:
            raise ConfigurationError(f"{owner}: the interval {float(interval):g} s of clock {k.name!r} is "
                                     f"not a whole number of its resolution 1/{k.resolution} s")
        call("fmi3SetIntervalFraction", k, (_U64 * 1)(counter.numerator), (_U64 * 1)(k.resolution))
    else:
        call("fmi3SetIntervalDecimal", k, (_D * 1)(float(interval)))
    return interval


def _get_interval(call, k: FMIClock) -> tuple:
    """``fmi3GetInterval*`` of clock ``k``: ``((counter, resolution) or interval [s], qualifier)``."""
    if k.supports_fraction:
        cnt, res, q = call("fmi3GetIntervalFraction", k, (_U64 * 1)(), (_U64 * 1)(), (_I * 1)())
        return (cnt, res), q
    return tuple(call("fmi3GetIntervalDecimal", k, (_D * 1)(), (_I * 1)()))


def _ask_periodic(call, k: FMIClock, owner: str) -> tuple[Fraction, Fraction]:
    """The interval and shift [s] of periodic clock ``k`` as the FMU gives them."""
    interval, q = _get_interval(call, k)
    if k.supports_fraction:
        if not interval[1]:
            raise FMUError(f"{owner}: fmi3GetIntervalFraction of clock {k.name!r} returned resolution 0")
        interval = Fraction(*interval)
        sc, sr = call("fmi3GetShiftFraction", k, (_U64 * 1)(), (_U64 * 1)())
        shift = Fraction(sc, sr) if sr else Fraction(0)
    else:
        interval = time_fraction(checked_interval(interval, k, owner, True))
        sh = call("fmi3GetShiftDecimal", k, (_D * 1)())[0]
        if not math.isfinite(sh) or sh < 0:
            raise FMUError(f"{owner}: fmi3GetShiftDecimal of clock {k.name!r} returned {sh!r}")
        shift = time_fraction(sh)
    if q == NOT_YET_KNOWN:
        raise _not_yet_known(k, owner)
    return interval, shift


# ---------------------------------------------------------------------- a run
class ClockedRun(ClockPorts):
    """One run of a clocked FMU: its ports and its clocks' timing; each interface's run
    adds its call sequence as the methods ``output(t)`` and ``update(t)``."""

    __slots__ = ("P", "_interval_calls", "countdown", "done_n", "first", "fmu_next", "inbox", "inv", "next_at",
                 "plan_len", "plans", "sched", "t0", "tol")
    #: Whether the periodic clocks due at one instant are activated in priority order.
    by_priority = False

    def _setup(self) -> None:
        super()._setup()
        self.sched: ClockSchedule = self.comp._clock_schedule
        self.next_at = self.sched.next_at
        self.P, self.t0, self.tol = self.comp.period, self.sched.t0, 1e-9 * self.comp.period
        self.inv = 1.0 / self.P
        self.inbox = self.board.inbox(self.name)
        self.countdown = [k for k in self.model.clocks if k.variability == "countdown" and k.causality == "input"]
        self.fmu_next: float | None = None           # the FMU's nextEventTime
        self.done_n = -1                             # the instant whose outputs were computed
        self._interval_calls: dict = {}
        self._patterns()

    # ------------------------------------------------------------------ periodic clocks
    def _patterns(self) -> None:
        """The periodic clocks' plans over their common period (``plans[n % plan_len]`` from instant ``first``)."""
        periodic = self.sched.periodic
        length = math.lcm(*(every for _, every, _ in periodic))
        first = max((f for _, _, f in periodic), default=0)
        if length > MAX_PATTERN or first > MAX_PATTERN:
            self.plans, self.plan_len, self.first = None, 1, 0
        else:                                        # plans[i]: the instant n from first on with n % length == i
            self.plans = [self._plan_at(first + (i - first) % length) for i in range(length)]
            self.plan_len, self.first = length, first

    def _plan_at(self, n: int) -> Plan | None:
        """The plan of the periodic clocks due at instant ``n`` (None: none)."""
        due = [k for k, every, first in self.sched.periodic if n >= first and (n - first) % every == 0]
        if self.by_priority:
            due.sort(key=lambda k: self.priority[k.vr])
        return self.plan([k.vr for k in due]) if due else None

    def periodic_at(self, n: int) -> Plan | None:
        """The periodic plan of instant ``n``."""
        if self.plans is not None and n >= self.first:
            return self.plans[n % self.plan_len]
        return self._plan_at(n)

    # ------------------------------------------------------------------ aperiodic and triggered clocks
    def _due_at(self, t: float) -> list[int]:
        """Aperiodic clocks due at ``t`` (removed from the pending)."""
        nxt, tol, due = self.next_at, self.tol, []
        for vr, tn in list(nxt.items()):
            if abs(tn - t) <= tol:
                due.append(vr)
                del nxt[vr]
            elif tn < t - tol:
                raise FMUError(f"{self.name}: clock {self.model.by_vr[vr].name!r} was due at {tn:g} s, before "
                               f"t = {t:g} s")
        return due

    def _received_at(self, t: float) -> tuple[list[int], dict | None]:
        """The triggered clocks activated at ``t`` by their sources, and the sources' outputs (merged)."""
        box, tol = self.inbox, self.tol
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
        times = [*self.next_at.values(), *(te for te, _, _ in self.inbox), self.fmu_next]
        return min((x for x in times if x is not None and after + self.tol < x < before - self.tol), default=None)

    # ------------------------------------------------------------------ intervals
    def _intervals(self, clocks: list[FMIClock]) -> list[tuple[FMIClock, float, int]]:
        """``fmi3GetInterval*`` of ``clocks`` (fraction form if supported): ``(clock, interval [s], qualifier)``s."""
        if not clocks:
            return []
        key = tuple(k.vr for k in clocks)
        call = self._interval_calls.get(key)
        if call is None:
            n = len(clocks)
            fraction = all(k.supports_fraction for k in clocks)
            bufs = ((_U64 * n)(), (_U64 * n)()) if fraction else ((_D * n)(),)
            label = "GetIntervalFraction" if fraction else "GetIntervalDecimal"
            q = (_I * n)()
            args = (self.c, (_U32 * n)(*key), _SIZE(n), *bufs, q)
            call = self._interval_calls[key] = (self.inst.raw(f"fmi3{label}"), args, label, bufs, q)
        fn, args, label, bufs, q = call
        st = fn(*args)
        if st > 1:
            self._fail(f"{label}({', '.join(k.name for k in clocks)})", st)
        values = [c / r if r else float("inf") for c, r in zip(*bufs)] if len(bufs) == 2 else bufs[0]
        return [(k, v, q[i]) for i, (k, v) in enumerate(zip(clocks, values))]

    def _apply_interval(self, k: FMIClock, v: float, q: int, t: float, ticked: bool) -> None:
        """:meth:`ClockSchedule.apply_interval`, the patterns again if they changed."""
        if self.sched.apply_interval(k, v, q, t, ticked):
            self._patterns()

"""A clocked FMI 3.0 FMU in a run: its output and update functions for the master, making
the standard's call sequences for clocks (the FMU's clocks as :mod:`cosim.fmi.clocks` reads
them; the master's side in :mod:`cosim.core.clocking`).

**Initialisation Mode** (:func:`initialise`). Fixed and tunable clocks that declare
``intervalDecimal`` get their interval with ``fmi3SetIntervalDecimal``
(``fmi3SetIntervalFraction`` in their counter form, in units of their resolution), the
declared one or the component's ``clock_intervals``; those that do not are asked
``fmi3GetInterval*`` and ``fmi3GetShift*`` (which must be multiples of the component's
period); changing and countdown clocks are asked their first interval.

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
``lastSuccessfulTime`` before stepping on (at the step's end: in the next instant's Event
Mode); outputs without clocks are read in Step Mode without setting an input first (the
standard forbids a get after a set), so they depend on no input directly. Model Exchange:
the activations between instants are time events of the integrator
(:mod:`cosim.fmi.model_exchange`), every Event Mode it enters (state, time and step events)
reads the output clocks, and an event found at the end of a step waits for that instant's
Event Mode.

**Scheduled Execution.** ``fmi3InstantiateScheduledExecution`` with a ``clockUpdate``
callback, in which (Clock Update Mode) every output clock is read with ``fmi3GetClock``
and every countdown clock's interval with ``fmi3GetInterval*``; at each activation time
the partitions due are activated with ``fmi3ActivateModelPartition`` in priority order
(smaller first, then declaration order; a countdown clock that becomes due at the same time
joins the queue), each after its inputs are set, its outputs (and those of the output
clocks it activated) read after it; a partition's inputs are direct inputs of its outputs
(the partition computes both at once); ``fmi3Discard`` counts as an error.

Every call's status is checked; a failing call raises
:class:`~fmu_models.errors.FMUError` naming the call, the time and the FMU's message. The
common instant (periodic clocks only, nothing pending) takes a short path: the activation
patterns of the periodic clocks are computed once per run.
"""
from __future__ import annotations

import ctypes
import itertools
import math
from collections.abc import Mapping
from fractions import Fraction

import numpy as np

from fmu_models.errors import ConfigurationError, FMUError

from ..core.clocking import MAX_TICKS, ClockBoard, fraction_gcd, time_fraction
from ..core.component import StopRequest
from .clocks import CHANGED, NOT_YET_KNOWN, QUALIFIERS, FMIClock, FMIClocks
from .exchange import Exchange, no_exchange
from .model_exchange import FMUModel

__all__ = ["MAX_PATTERN", "MAX_SUPERDENSE", "ClockedRun", "initialise"]

#: Most super-dense instants of one Event Mode.
MAX_SUPERDENSE = 1000
#: Longest pattern of periodic activations computed ahead (in instants).
MAX_PATTERN = 10_000
_D, _B, _I, _U32, _SIZE = ctypes.c_double, ctypes.c_bool, ctypes.c_int, ctypes.c_uint32, ctypes.c_size_t
#: FMI 3.0 type -> (ctypes type, function suffix, value kind) of the scalar fast path.
_SCALAR = {"Float64": (ctypes.c_double, "Float64", "f"), "Float32": (ctypes.c_float, "Float32", "f"),
           "Int8": (ctypes.c_int8, "Int8", "i"), "UInt8": (ctypes.c_uint8, "UInt8", "i"),
           "Int16": (ctypes.c_int16, "Int16", "i"), "UInt16": (ctypes.c_uint16, "UInt16", "i"),
           "Int32": (ctypes.c_int32, "Int32", "i"), "UInt32": (ctypes.c_uint32, "UInt32", "i"),
           "Int64": (ctypes.c_int64, "Int64", "i"), "UInt64": (ctypes.c_uint64, "UInt64", "u"),
           "Enumeration": (ctypes.c_int64, "Int64", "i"), "Boolean": (ctypes.c_bool, "Boolean", "b")}


class _Schedule:
    """A run's timing of one FMU's clocks, from its initialisation on.

    Attributes
    ----------
    periodic : list of [FMIClock, int, int]
        Each periodic clock, its interval and its first activation in instants.
    next_at : dict of int to float
        The pending activation time [s] of each aperiodic clock that has one.
    """

    def __init__(self, model: FMIClocks, t0: float, period: float, overrides: Mapping[str, Fraction]):
        self.t0, self.period = t0, period
        self.tol = 1e-9 * period
        self.periodic: list[list] = []
        self.next_at: dict[int, float] = {}
        self.overrides = dict(overrides)
        self.model = model

    def add_periodic(self, k: FMIClock, interval: Fraction, shift: Fraction, owner: str) -> None:
        """Add a periodic clock, its interval and shift [s] multiples of the period."""
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


class _Plan:
    """The calls of one set of input clocks activated together (ME, CS: one ``fmi3SetClock``;
    SE: the partitions in priority order)."""

    __slots__ = ("args", "fill", "fire", "get", "get_d", "intervals", "labels", "names", "set_all", "set_all_d",
                 "set_ft", "set_ft_d", "set_rest", "set_rest_d", "tick", "vrs")


def _calls(fns) -> tuple:
    return tuple(f for f in fns if f is not None and f is not no_exchange)


class ClockedRun:
    """One run of a clocked FMU: its bound output and update functions (see the module
    documentation). Built by ``FMUComponent.bind`` for an FMU with clocks.

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
        self.next_at = self.sched.next_at
        self.P, self.t0, self.tol = comp.period, self.sched.t0, self.sched.tol
        self.c = ctypes.c_void_p(inst.handle)
        self.values, self.integers = values, integers
        self.idx_in = np.arange(len(values))[inputs] if isinstance(inputs, slice) else np.asarray(inputs, np.intp)
        self.n_in = len(comp.connected_inputs)
        self.out = outputs
        n_out = len(comp.output_names)
        self.own, self.own_i = np.zeros(n_out), np.zeros(n_out, dtype=np.int64)
        self.vin, self.iin = np.zeros(max(self.n_in, 1)), np.zeros(max(self.n_in, 1), dtype=np.int64)
        self.vin_base, self.iin_base = self.vin.copy(), self.iin.copy()
        self._raw: dict = {}
        self._plans: dict = {}
        self.log_t, self.log_id = board.log_functions()
        self._build_ports(comp)
        self._build_calls()
        self._fillers()
        self._patterns()
        self.in_event = comp.interface != "se"       # ME and CS: in Event Mode after initialisation
        self.started = False
        self.active: set[int] = set()                # input clocks active in the current super-dense instant
        self.ticked: set[int] = set()                # clocks that ticked in the current Event Mode
        self.fmu_next: float | None = None           # the FMU's nextEventTime
        self.pending_event = False                   # the FMU asked for Event Mode at the next instant
        self.done_n = -1                             # the instant whose outputs were computed
        self.window_end = self.t0
        self.inbox = board.inbox(self.name)
        self._outbox: list = []                      # output clock activations to send
        self.in_callback = False                     # in the clockUpdate callback (Clock Update Mode)
        self.dirty = False                           # the own buffers hold outputs newer than the signals
        self._error: BaseException | None = None

    # ------------------------------------------------------------------ set-up
    def _fn(self, name: str):
        f = self._raw.get(name)
        if f is None:
            f = self._raw[name] = self.inst.raw(name)
        return f

    def _fail(self, what: str, status: int):
        if self.interface == "se" and status == 2:      # Scheduled Execution: discard is an error
            self.inst.worst = max(self.inst.worst, 3)
        self.inst.fail(what, status)

    def _getter(self, positions: list[int], direct: bool):
        """A call reading the output ports at ``positions`` (scalars: one FMI call per type;
        array elements: an :class:`Exchange`), into the master's signals (``direct``: at an
        instant) or into the component's own buffers (between instants)."""
        if not positions:
            return None
        comp = self.comp
        ports = [comp.element_ports[comp.output_names[j]] for j in positions]
        fail, c = self._fail, self.c
        if direct:
            own, own_i, base = self.values, self.integers, self.out.start
        else:
            own, own_i, base = self.own, self.own_i, 0
        if any(p.size != 1 or p.type not in _SCALAR for p in ports):
            ex = Exchange(self.inst.dll, self.inst.handle, 3, ports, "get", fail, self.name)
            return ex.bind(own, np.asarray(positions, np.intp) + base, own_i)
        groups: dict = {}
        calls = []
        items = sorted(zip([j + base for j in positions], ports), key=lambda x: x[0])
        if direct:                               # Float64 at consecutive signals: read in place
            runs, rest = [], []
            for j, p in items:
                if p.type == "Float64" and runs and runs[-1][-1][0] == j - 1 and \
                        all(q.variable.valueReference != p.variable.valueReference for _, q in runs[-1]):
                    runs[-1].append((j, p))
                elif p.type == "Float64":
                    runs.append([(j, p)])
                else:
                    rest.append((j, p))
            for run in runs:
                n = _SIZE(len(run))
                ptr = ctypes.cast(own.ctypes.data + 8 * run[0][0], ctypes.POINTER(_D))
                calls.append((self._fn("fmi3GetFloat64"), (c, (_U32 * len(run))(*[p.variable.valueReference
                                                                                   for _, p in run]), n, ptr, n),
                              None, "f", (), "GetFloat64"))
            items = rest
        for j, p in items:
            ctype, suffix, kind = _SCALAR[p.type]
            groups.setdefault(suffix, (ctype, kind, []))[2].append((j, p.variable.valueReference))
        for suffix, (ctype, kind, items) in groups.items():
            vrs = list(dict.fromkeys(vr for _, vr in items))
            n = _SIZE(len(vrs))
            buf = (ctype * len(vrs))()
            where = {vr: i for i, vr in enumerate(vrs)}
            calls.append((self._fn(f"fmi3Get{suffix}"), (c, (_U32 * len(vrs))(*vrs), n, buf, n), buf, kind,
                          tuple((j, where[vr]) for j, vr in items), f"Get{suffix}"))
        if len(calls) == 1 and calls[0][2] is None:
            fn, args, _, _, _, label = calls[0]

            def get_in_place() -> None:
                st = fn(*args)
                if st > 1:
                    fail(label, st)
            return get_in_place
        if len(calls) == 1 and calls[0][3] == "f" and len(calls[0][4]) == 1:
            fn, args, buf, _, ((j, _),), label = calls[0]

            def get_one() -> None:
                st = fn(*args)
                if st > 1:
                    fail(label, st)
                own[j] = buf[0]
            return get_one
        big = 1 << 63

        def get() -> None:
            for fn, args, buf, kind, pairs, label in calls:
                st = fn(*args)
                if st > 1:
                    fail(label, st)
                if kind == "f":
                    for j, i in pairs:
                        own[j] = buf[i]
                else:
                    for j, i in pairs:
                        v = buf[i]
                        if kind == "b":
                            v = 1 if v else 0
                        own[j] = v
                        own_i[j] = v - (big << 1) if kind == "u" and v >= big else v
        return get

    def _setter(self, positions: list[int], changes: bool = False, direct: bool = False):
        """A call setting the input ports at ``positions`` from the component's input buffer
        (scalar Float64 ports directly; others through an :class:`Exchange`, which checks
        integer ranges). ``direct``: scalar Float64 ports read from the master's signals
        (the short path, which fills no buffer); any other such setter has ``needs_fill``."""
        if not positions:
            return no_exchange
        comp = self.comp
        names = comp.connected_inputs
        ports = [comp.element_ports[names[i]] for i in positions]
        if not changes and all(p.size == 1 and p.type == "Float64" for p in ports) and \
                len({p.variable.valueReference for p in ports}) == len(ports):
            n = _SIZE(len(ports))
            vrs = (_U32 * len(ports))(*[p.variable.valueReference for p in ports])
            fn, fail = self._fn("fmi3SetFloat64"), self._fail
            slots = [int(self.idx_in[j]) for j in positions]
            if direct and all(b == a + 1 for a, b in itertools.pairwise(slots)):
                args = (self.c, vrs, n, ctypes.cast(self.values.ctypes.data + 8 * slots[0], ctypes.POINTER(_D)), n)

                def set_in_place() -> bool:      # the FMU reads the master's signals
                    st = fn(*args)
                    if st > 1:
                        fail("SetFloat64", st)
                    return False
                return set_in_place
            buf = (_D * len(ports))()
            args = (self.c, vrs, n, buf, n)
            src = self.values if direct else self.vin
            pairs = tuple((i, slots[i] if direct else j) for i, j in enumerate(positions))

            def set_reals() -> bool:
                for i, j in pairs:
                    buf[i] = src[j]
                st = fn(*args)
                if st > 1:
                    fail("SetFloat64", st)
                return False
            return set_reals
        if direct:
            f = self._setter(positions, changes)
            f.needs_fill = True
            return f
        srcs = comp.input_sources or [(f"{comp.name}.{n}", comp.element_ports[n].type) for n in names]
        starts = comp._input_starts()
        ex = Exchange(self.inst.dll, self.inst.handle, 3, ports, "set", self._fail, self.name,
                      [srcs[i] for i in positions])
        ex.preset({comp.element_ports[names[i]].name: starts[i] for i in positions})
        return ex.bind(self.vin, np.asarray(positions, np.intp), self.iin, changes)

    def _build_ports(self, comp) -> None:
        model, ports = self.model, comp.element_ports
        names = comp.connected_inputs
        self.sources = self.board.sources(self.name, names)
        ft_names = set().union(*comp.feedthrough.values()) if comp.feedthrough else set()
        data_in = [i for i, n in enumerate(names) if n in ports and n not in model.by_name]
        ft = {i for i in data_in if names[i] in ft_names}
        self.in_ft = np.array(sorted(ft), dtype=np.intp)
        by_clock: dict[int, list[int]] = {k.vr: [] for k in model.clocks if k.causality == "input"}
        unclocked = []
        for i in data_in:
            ks = model.clocks_of(ports[names[i]].variable.name)
            if not ks:
                unclocked.append(i)
            for vr in ks:
                by_clock.setdefault(vr, []).append(i)
        self.set_ft = {vr: self._setter([i for i in pos if i in ft]) for vr, pos in by_clock.items()}
        self.set_rest = {vr: self._setter([i for i in pos if i not in ft]) for vr, pos in by_clock.items()}
        self.set_all = {vr: self._setter(pos) for vr, pos in by_clock.items()}
        self.set_ft_d = {vr: self._setter([i for i in pos if i in ft], direct=True) for vr, pos in by_clock.items()}
        self.set_rest_d = {vr: self._setter([i for i in pos if i not in ft], direct=True)
                           for vr, pos in by_clock.items()}
        self.set_all_d = {vr: self._setter(pos, direct=True) for vr, pos in by_clock.items()}
        if self.interface == "me":
            cont = [i for i in unclocked if not ports[names[i]].discrete]
            disc = [i for i in unclocked if ports[names[i]].discrete]
            self.set_cont = self._setter(cont, changes=True)
            self.set_disc = self._setter(disc, changes=True)
            self.set_cont_ft = self._setter([i for i in cont if i in ft], changes=True)
            self.set_disc_ft = self._setter([i for i in disc if i in ft], changes=True)
        self.set_ud = no_exchange
        if self.interface == "cs":       # discrete inputs without clock: changed in Event Mode only
            disc = [i for i in unclocked if ports[names[i]].discrete]
            self.set_ud = self._setter(disc, changes=True)
            unclocked = [i for i in unclocked if i not in disc]
        self.set_u_all = self._setter(unclocked)
        self.set_u_ft = self._setter([i for i in unclocked if i in ft])
        self.set_u_all_d = self._setter(unclocked, direct=True)
        self.set_u_ft_d = self._setter([i for i in unclocked if i in ft], direct=True)
        self.set_u_rest = self._setter([i for i in unclocked if i not in ft])
        outs = comp.output_names
        get_by_clock: dict[int, list[int]] = {}
        unclocked_out = []
        for j, n in enumerate(outs):
            if n in model.by_name:
                continue
            ks = model.clocks_of(ports[n].variable.name)
            if not ks:
                unclocked_out.append(j)
            for vr in ks:
                get_by_clock.setdefault(vr, []).append(j)
        self.get_u = self._getter(unclocked_out, False)          # into the own buffers
        self.get_ud = self._getter(unclocked_out, True)          # into the signals
        self.get_k = {k.vr: self._getter(get_by_clock.get(k.vr, []), False) for k in model.clocks}
        self.get_kd = {k.vr: self._getter(get_by_clock.get(k.vr, []), True) for k in model.clocks}
        # output (and local) clocks: read with fmi3GetClock in every Event Mode
        self.out_clocks = [k for k in model.clocks if k.causality != "input"]
        self.out_clock_pos = [outs.index(k.name) if k.name in outs else -1 for k in self.out_clocks]
        self.out_counts = [0] * len(self.out_clocks)
        self.publishers = [self.board.publisher(self.name, k.name) if k.is_port else None for k in self.out_clocks]
        self.labels = {k.vr: self.board.label(self.name, k.name) for k in model.clocks}
        self.priority = {k.vr: ((k.priority if k.priority is not None else 0), k.index) for k in model.clocks}
        self.port_clock = {k.name: k.vr for k in model.clocks if k.is_port and k.causality == "input"}

    def _build_calls(self) -> None:
        c = self.c
        n_out = len(self.out_clocks)
        self._out_vr = (_U32 * max(n_out, 1))(*[k.vr for k in self.out_clocks])
        self._out_val = (_B * max(n_out, 1))()
        self._n_out = _SIZE(n_out)
        self._get_clock = self._fn("fmi3GetClock")
        self._set_clock = self._fn("fmi3SetClock")
        ub = self._uds_bytes = (ctypes.c_uint8 * 8)()        # the five flags side by side
        self._uds_flags = [_B.from_buffer(ub, i) for i in range(5)]
        self._uds_any = ctypes.c_uint64.from_buffer(ub)       # any of them set
        self._uds_next = _D(0.0)
        self._uds_args = (c, *[ctypes.byref(ub, i) for i in range(5)], ctypes.byref(self._uds_next))
        self._uds = self._fn("fmi3UpdateDiscreteStates") if self.interface != "se" else None
        self._enter_event = self._fn("fmi3EnterEventMode") if self.interface != "se" else None
        if self.interface == "cs":
            self._enter_step = self._fn("fmi3EnterStepMode")
            self._do_step = self._fn("fmi3DoStep")
            db = self._ds_bytes = (ctypes.c_uint8 * 4)()      # eventHandlingNeeded, terminate, earlyReturn
            self._ds_flags = [_B.from_buffer(db, i) for i in range(3)]
            self._ds_any = ctypes.c_uint32.from_buffer(db)
            self._ds_last = _D(0.0)
            self._ds_refs = (*[ctypes.byref(db, i) for i in range(3)], ctypes.byref(self._ds_last))
        if self.interface == "se":
            self._activate_fn = self._fn("fmi3ActivateModelPartition")
        self.countdown = [k for k in self.model.clocks if k.variability == "countdown" and k.causality == "input"]
        self._interval_calls: dict = {}

    def _plan(self, vrs) -> _Plan:
        """The calls for the input clocks ``vrs`` activated together (cached)."""
        key = tuple(vrs)
        plan = self._plans.get(key)
        if plan is None:
            by_vr = self.model.by_vr
            plan = self._plans[key] = _Plan()
            plan.vrs = key
            n = len(key)
            plan.args = (self.c, (_U32 * n)(*key), _SIZE(n), (_B * n)(*([True] * n)))
            plan.labels = tuple(self.labels[v] for v in key)
            plan.names = ", ".join(by_vr[v].name for v in key)
            plan.set_ft = _calls(self.set_ft.get(v) for v in key)
            plan.set_rest = _calls(self.set_rest.get(v) for v in key)
            plan.set_all = _calls(self.set_all.get(v) for v in key)
            plan.get = _calls(self.get_k.get(v) for v in key)
            plan.get_d = _calls(self.get_kd.get(v) for v in key)
            plan.intervals = [by_vr[v] for v in key if by_vr[v].variability == "changing" or
                              (by_vr[v].variability == "tunable" and not by_vr[v].has_decimal)]
            plan.set_ft_d = _calls(self.set_ft_d.get(v) for v in key)
            plan.set_rest_d = _calls(self.set_rest_d.get(v) for v in key)
            plan.set_all_d = _calls(self.set_all_d.get(v) for v in key)
            plan.fill = any(getattr(f, "needs_fill", False)
                            for f in (*plan.set_ft_d, *plan.set_rest_d, *plan.set_all_d))
            plan.tick = plan.fire = None                 # the short path's calls, made by the interface
        return plan

    def _patterns(self) -> None:
        """The periodic clocks' activations at each instant, as plans over their common
        period (``self.plans[n % len]`` for instants from ``self.first`` on)."""
        periodic = self.sched.periodic
        length = 1
        for _, every, _ in periodic:
            length = length * every // math.gcd(length, every)
            if length > MAX_PATTERN:
                break
        first = max((f for _, _, f in periodic), default=0)
        if length > MAX_PATTERN or first > MAX_PATTERN:
            self.plans, self.plan_len, self.first = None, 1, 0
            return
        plans: list = [None] * length
        for n in range(first, first + length):
            plans[n % length] = self._plan_at(n)
        self.plans, self.plan_len, self.first = plans, length, first

    def _plan_at(self, n: int) -> _Plan | None:
        """The plan of the periodic clocks due at instant ``n`` (None: none)."""
        due = [k for k, every, first in self.sched.periodic if n >= first and (n - first) % every == 0]
        if self.interface == "se":
            due.sort(key=lambda k: self.priority[k.vr])
        return self._plan([k.vr for k in due]) if due else None

    def periodic_at(self, n: int) -> _Plan | None:
        """The periodic plan of instant ``n``."""
        if self.plans is not None and n >= self.first:
            return self.plans[n % self.plan_len]
        return self._plan_at(n)

    def _intervals(self, clocks: list[FMIClock]) -> list[tuple[FMIClock, float, int]]:
        """``fmi3GetInterval*`` of ``clocks`` (the fraction form where supported):
        ``(clock, interval [s], qualifier)`` each."""
        if not clocks:
            return []
        key = tuple(k.vr for k in clocks)
        call = self._interval_calls.get(key)
        n = len(clocks)
        if call is None:
            vrs = (_U32 * n)(*key)
            q = (_I * n)()
            if all(k.supports_fraction for k in clocks):
                cnt, res = (ctypes.c_uint64 * n)(), (ctypes.c_uint64 * n)()
                fn, args = self._fn("fmi3GetIntervalFraction"), (self.c, vrs, _SIZE(n), cnt, res, q)
                label = "GetIntervalFraction"

                def read():
                    return [(cnt[i] / res[i]) if res[i] else float("inf") for i in range(n)]
            else:
                vals = (_D * n)()
                fn, args = self._fn("fmi3GetIntervalDecimal"), (self.c, vrs, _SIZE(n), vals, q)
                label = "GetIntervalDecimal"

                def read():
                    return [vals[i] for i in range(n)]
            call = self._interval_calls[key] = (fn, args, label, read, q)
        fn, args, label, read, q = call
        st = fn(*args)
        if st > 1:
            self._fail(f"{label}({', '.join(k.name for k in clocks)})", st)
        return [(k, v, int(q[i])) for i, (k, v) in enumerate(zip(clocks, read()))]

    # ------------------------------------------------------------------ timing
    def instant(self, t: float) -> int:
        """The component's instant number of ``t`` [s]."""
        return round((t - self.t0) / self.P)

    def _due_at(self, t: float) -> list[int]:
        """Aperiodic clocks due at ``t`` (removed from the pending)."""
        nxt = self.next_at
        if not nxt:
            return []
        tol, due = self.tol, []
        for vr, tn in list(nxt.items()):
            if abs(tn - t) <= tol:
                due.append(vr)
                del nxt[vr]
            elif tn < t - tol:
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
        for tn in self.next_at.values():
            if after + tol < tn < before - tol and (best is None or tn < best):
                best = tn
        for te, _, _ in self.inbox:
            if after + tol < te < before - tol and (best is None or te < best):
                best = te
        f = self.fmu_next
        if f is not None and after + tol < f < before - tol and (best is None or f < best):
            best = f
        return best

    # ------------------------------------------------------------------ inputs
    def _fillers(self) -> None:
        """``fill_all()`` (every connected input from the signals: what an update consumes)
        and ``fill_ft()`` (those the outputs depend on: at an instant), or None without any."""
        values, integers, vin, iin = self.values, self.integers, self.vin, self.iin
        n = self.n_in
        if n:
            idx, v_n, i_n = self.idx_in, vin[:n], iin[:n]
            take_v, take_i = values.take, integers.take

            def fill_all() -> None:
                take_v(idx, out=v_n)
                take_i(idx, out=i_n)
            self.fill_all = fill_all
        else:
            self.fill_all = None
        pairs = tuple((int(j), int(self.idx_in[j])) for j in self.in_ft)
        if not pairs:
            self.fill_ft = None
            return

        def fill_ft() -> None:
            for j, slot in pairs:
                vin[j] = values[slot]
                iin[j] = integers[slot]
        self.fill_ft = fill_ft

    def _fill(self, positions=None) -> None:
        """The inputs into the input buffer: all of them, or (``positions`` given) those the
        outputs depend on."""
        f = self.fill_all if positions is None else self.fill_ft
        if f is not None:
            f()

    def _keep_base(self) -> None:
        self.vin_base[:] = self.vin
        self.iin_base[:] = self.iin

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
    def _activate(self, t: float, ks: list[int], phase: str, snap: dict | None) -> None:
        """Event Mode (ME, CS): activate the input clocks ``ks`` at ``t``, set their clocked
        inputs (``phase`` "output": only those outputs depend on, the outputs read into the
        signals; else all, into the own buffers), read their outputs and the output clocks."""
        direct = phase == "output"
        if not direct:
            self._use_own()
        if ks:
            plan = self._plan(ks)
            st = self._set_clock(*plan.args)
            if st > 1:
                self._fail(f"SetClock({plan.names}, t = {t:g} s)", st)
            for lab in plan.labels:
                self.log_t(t)
                self.log_id(lab)
            for s in (plan.set_ft if direct else plan.set_all):
                s()
            self.active.update(ks)
            self.ticked.update(ks)
            for g in (plan.get_d if direct else plan.get):
                g()
        self._read_output_clocks(t, snap, not direct)

    def _count(self, i: int, direct: bool) -> None:
        """One more activation of output clock ``i``: its signal."""
        self.out_counts[i] += 1
        pos = self.out_clock_pos[i]
        if pos >= 0:
            if direct:
                self.values[self.out.start + pos] = self.integers[self.out.start + pos] = self.out_counts[i]
            else:
                self.own[pos] = self.own_i[pos] = self.out_counts[i]

    def _read_output_clocks(self, t: float, snap: dict | None, fresh: bool) -> None:
        """``fmi3GetClock`` of the output (and local) clocks; each active one counted, logged,
        the outputs it clocks read, its activation sent (``fresh``: between instants or after
        the outputs of the instant, sent at once; else with the instant's outputs)."""
        n = len(self.out_clocks)
        if not n:
            return
        st = self._get_clock(self.c, self._out_vr, self._n_out, self._out_val)
        if st > 1:
            self._fail(f"GetClock(t = {t:g} s)", st)
        vals = self._out_val
        published = None
        if fresh:
            self._use_own()
        for i in range(n):
            if not vals[i]:
                continue
            k = self.out_clocks[i]
            self._count(i, not fresh)
            self.log_t(t)
            self.log_id(self.labels[k.vr])
            self.ticked.add(k.vr)
            g = (self.get_k if fresh else self.get_kd)[k.vr]
            if g is not None:
                g()
            if self.publishers[i] is not None:
                published = published or []
                published.append(self.publishers[i])
        if published:
            self._outbox.append((t, snap, published))
            if fresh:                                 # CS: outputs without clocks are left limits
                self._publish(False, self.interface == "me")

    def _publish(self, direct: bool, read: bool = False) -> None:
        """Send the output clocks' activations read so far to their sinks, each with this
        component's outputs (``direct``: the signals of this instant; else the own buffers,
        the unclocked outputs read again first if ``read``)."""
        if not self._outbox:
            return
        if direct:
            mine = (self.values[self.out].copy(), self.integers[self.out].copy())
        else:
            self._use_own()
            if read and self.get_u is not None:
                self.get_u()
            mine = (self.own.copy(), self.own_i.copy())
        for t, snap, published in self._outbox:
            out = dict(snap) if snap else {}
            out[self.name] = mine
            for pub in published:
                pub(t, out)
        self._outbox.clear()

    def _finish(self, t: float) -> bool:
        """The rest of an Event Mode at ``t`` (ME, CS): the event iteration, the intervals,
        activations due at once; returns whether the FMU asks to terminate."""
        f = self._uds_flags
        uds, args = self._uds, self._uds_args
        for _ in range(MAX_SUPERDENSE):
            st = uds(*args)
            if st > 1:
                self._fail(f"UpdateDiscreteStates(t = {t:g} s)", st)
            self.active.clear()
            if f[1].value:
                return True
            if f[0].value:
                self._read_output_clocks(t, None, True)
                continue
            if self.countdown or self.ticked:
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
        if q not in QUALIFIERS:
            raise FMUError(f"{self.name}: fmi3GetInterval of clock {k.name!r} returned the qualifier {q}")
        if k.variability == "countdown":
            if q == CHANGED:
                self.next_at[k.vr] = t + _interval(v, k, self.name, False)
        elif k.variability == "changing":
            if ticked and q != CHANGED:
                raise FMUError(f"{self.name}: changing clock {k.name!r} ticked at t = {t:g} s but fmi3GetInterval "
                               f"returned {QUALIFIERS[q]}; the standard requires its next interval (changed)")
            if q == CHANGED:
                self.next_at[k.vr] = t + _interval(v, k, self.name, False)
        elif q == CHANGED:                              # tunable without intervalDecimal: from now on
            iv = _interval(v, k, self.name, True)
            ratio = iv / self.P
            if abs(ratio - round(ratio)) > 1e-9 * max(1.0, ratio):
                raise FMUError(f"{self.name}: tunable clock {k.name!r} changed its interval to {iv:g} s at "
                               f"t = {t:g} s, not a multiple of the period {self.P:g} s")
            for entry in self.sched.periodic:
                if entry[0].vr == k.vr:
                    entry[1] = round(ratio)
                    entry[2] = self.instant(t) + round(ratio)
            self._patterns()

    # ------------------------------------------------------------------ write
    def _use_own(self) -> None:
        """Before reading outputs between instants: the own buffers start from the signals
        of the last instant."""
        if not self.dirty:
            self.own[:] = self.values[self.out]
            self.own_i[:] = self.integers[self.out]
            self.dirty = True

    def _sync(self) -> None:
        """At an instant, before its outputs are read: what was read between instants goes
        to the signals (held until then)."""
        if self.dirty:
            self.values[self.out] = self.own
            self.integers[self.out] = self.own_i
            self.dirty = False

    def _again(self) -> None:
        """The outputs computed again at the same instant (a split evaluation or a loop)."""
        if self.in_event:
            self._fill(self.in_ft)
            vrs = set(self.active)
            plan = self.periodic_at(self.done_n)
            if plan is not None:
                vrs.update(plan.vrs)
            self.set_u_ft()
            for vr in vrs:
                self.set_ft[vr]()
                g = self.get_kd[vr]
                if g is not None:
                    g()
        if self.interface == "me" and self.get_ud is not None:
            self.get_ud()

    def _check_log(self) -> None:
        if self.board.count() > MAX_TICKS:
            self.board.log(0.0, 0)                      # raises ResourceError with the limit named

    # ------------------------------------------------------------------ Co-Simulation
    def cs_functions(self):
        """``(output_fn, update_fn)`` of a Co-Simulation FMU with Event Mode."""
        c, t0, inv = self.c, self.t0, 1.0 / self.P
        enter_ev, enter_step, do_step = self._enter_event, self._enter_step, self._do_step
        set_clock, uds, uds_args = self._set_clock, self._uds, self._uds_args
        fl = self._uds_flags
        need, term, next_def, next_t = fl[0], fl[1], fl[4], self._uds_next
        uds_any, ds_any = self._uds_any, self._ds_any
        flags, last, refs = self._ds_flags, self._ds_last, self._ds_refs
        ehn_f, term_f, early_f = flags
        can_vary = bool(getattr(self.comp.md.coSimulation, "canHandleVariableCommunicationStepSize", False))
        name, P, tol = self.name, self.P, self.tol
        inbox, next_at, outbox = self.inbox, self.next_at, self._outbox
        log_t, log_id, fail = self.log_t, self.log_id, self._fail
        get_ud = self.get_ud
        set_u_ft = None if self.set_u_ft is no_exchange else self.set_u_ft
        set_u_all = None if self.set_u_all is no_exchange else self.set_u_all
        set_u_ft_d = None if self.set_u_ft_d is no_exchange else self.set_u_ft_d
        set_u_all_d = None if self.set_u_all_d is no_exchange else self.set_u_all_d
        set_ud = None if self.set_ud is no_exchange else self.set_ud
        u_fill = set_ud is not None or any(getattr(f, "needs_fill", False) for f in (set_u_ft_d, set_u_all_d))
        has_out, countdown = bool(self.out_clocks), bool(self.countdown)
        ct, ch = _D(0.0), _D(P)
        ids = self.board._ids

        def enter(t):
            if not self.in_event:
                st = enter_ev(c)
                if st > 1:
                    fail(f"EnterEventMode(t = {t:g} s)", st)
                self.in_event = True

        quiet = [False]          # nothing pending, nothing held: the short path may run (set by each update)
        fast = [None]            # (event iteration, plan) of the short path's activation at this instant
        fill_ft, fill_all = self.fill_ft, self.fill_all

        def make(plan):
            """The short path of ``plan``: its activation at an instant (for the outputs) and
            its event iteration (in the update)."""
            args, vrs, labels = plan.args, plan.vrs, plan.labels
            set_ft, get_d, set_rest = plan.set_ft_d, plan.get_d, plan.set_rest_d
            one = labels[0] if len(labels) == 1 else None
            simple = not plan.intervals and not countdown
            fill = plan.fill or u_fill

            def tick(t: float) -> None:
                if fill and fill_ft is not None:
                    fill_ft()
                st = enter_ev(c)
                if st > 1:
                    fail(f"EnterEventMode(t = {t:g} s)", st)
                self.in_event = True
                if set_u_ft_d is not None:
                    set_u_ft_d()
                st = set_clock(*args)
                if st > 1:
                    fail(f"SetClock({plan.names}, t = {t:g} s)", st)
                if one is not None:
                    log_t(t)
                    log_id(one)
                else:
                    for lab in labels:
                        log_t(t)
                        log_id(lab)
                for f in set_ft:
                    f()
                for g in get_d:
                    g()
                if has_out:
                    self._read_output_clocks(t, None, False)
                    if outbox:
                        self._publish(True)
                if simple:
                    fast[0] = entry
                else:
                    self.active.update(vrs)
                    self.ticked.update(vrs)

            def tock(t: float) -> None:
                """The whole update of the short path: the event iteration, Step Mode, the step."""
                if fill and fill_all is not None:
                    fill_all()
                for f in set_rest:
                    f()
                if set_u_all_d is not None:
                    set_u_all_d()
                if set_ud is not None:
                    set_ud()
                st = uds(*uds_args)
                if st > 1:
                    fail(f"UpdateDiscreteStates(t = {t:g} s)", st)
                if uds_any.value:                       # a flag: the general way
                    if term.value:
                        raise StopRequest(name, t, "the FMU requested termination in its event update")
                    if need.value:
                        self._read_output_clocks(t, None, True)
                        event(t)
                    else:
                        self.fmu_next = next_t.value if next_def.value else None
                        step_mode(t)
                    step_general(t, False)
                    return
                if has_out and self.ticked:
                    self.ticked.clear()
                st = enter_step(c)
                if st > 1:
                    fail(f"EnterStepMode(t = {t:g} s)", st)
                self.in_event = False
                ct.value = t
                st = do_step(c, ct, ch, True, *refs)
                if st > 1:
                    fail(f"DoStep(t = {t:g} s, h = {P:g} s)", st)
                if ds_any.value:                        # an event, an early return, a stop
                    if fill_all is not None:
                        fill_all()
                    self._keep_base()
                    advance(t, step_done(t, t + P))
                    quiet[0] = now_quiet()
                else:
                    quiet[0] = True

            entry = (tock, plan)
            plan.tick = tick
            return tick

        def output_fn(t: float) -> None:
            n = round((t - t0) * inv)
            if n == self.done_n:
                self._again()
                return
            self.done_n = n
            if quiet[0] and not inbox:                  # the short path: periodic clocks only
                if get_ud is not None:                  # in Step Mode, before any set
                    get_ud()
                plans = self.plans
                plan = plans[n % self.plan_len] if plans is not None and n >= self.first else self._plan_at(n)
                if plan is not None:
                    (plan.tick or make(plan))(t)
                return
            if self.dirty:
                self._sync()
            if fill_ft is not None:
                fill_ft()
            if get_ud is not None:
                get_ud()
            plans = self.plans
            plan = plans[n % self.plan_len] if plans is not None and n >= self.first else self._plan_at(n)
            if inbox or next_at or self.pending_event or self.in_event or (
                    self.fmu_next is not None and abs(self.fmu_next - t) <= tol):
                slow_output(t, plan)
            elif plan is not None:
                (plan.tick or make(plan))(t)

        def slow_output(t, plan):
            ks = list(plan.vrs) if plan is not None else []
            ks += self._due_at(t)
            got, snap = self._received_at(t)
            if self.fmu_next is not None and abs(self.fmu_next - t) <= tol:
                self.pending_event, self.fmu_next = True, None
            if ks or got or self.pending_event or self.in_event:
                enter(t)
                self.pending_event = False
                if set_u_ft is not None:
                    set_u_ft()
                if got:
                    self._keep_base()
                    self._overlay(snap)
                self._activate(t, ks + got, "output", snap)
                self._publish(True)

        def step_mode(t: float) -> None:
            st = enter_step(c)
            if st > 1:
                fail(f"EnterStepMode(t = {t:g} s)", st)
            self.in_event = False

        def event(t: float) -> None:
            if self._finish(t):
                raise StopRequest(name, t, "the FMU requested termination in its event update")
            step_mode(t)

        def now_quiet() -> bool:
            return not (next_at or self.fmu_next is not None or self.pending_event or self.dirty or self.in_event)

        def update_fn(t: float) -> None:
            entry = fast[0]
            if entry is not None and not inbox and not next_at and self.fmu_next is None:
                fast[0] = None                          # the short path
                entry[0](t)
                return
            filled = False
            if entry is None and not self.in_event:     # no tick at this instant: Step Mode
                if u_fill and fill_all is not None:
                    fill_all()
                    filled = True
                if set_u_all_d is not None:
                    set_u_all_d()
                if set_ud is not None and set_ud.differs():
                    enter(t)                            # a discrete input changes: Event Mode
                    set_ud()
                    event(t)
            else:
                if fill_all is not None:
                    fill_all()
                filled = True
                fast[0] = None
                general_event(t, entry[1] if entry is not None else None)
            step_general(t, filled)
            if len(ids) > MAX_TICKS:
                self._check_log()

        def step_general(t: float, filled: bool) -> None:
            """The step from ``t`` (Step Mode), whatever may stop it; then whether the next
            instant may take the short path."""
            if not inbox and not next_at and self.fmu_next is None:
                ct.value = t
                st = do_step(c, ct, ch, True, *refs)
                if st > 1:
                    fail(f"DoStep(t = {t:g} s, h = {P:g} s)", st)
                if ds_any.value:
                    if not filled and fill_all is not None:
                        fill_all()
                    self._keep_base()
                    advance(t, step_done(t, t + P))
            else:
                if not filled and fill_all is not None:
                    fill_all()
                self._keep_base()
                advance(t, t)
            quiet[0] = now_quiet()

        def general_event(t, plan):
            if plan is not None:
                self.active.update(plan.vrs)
                self.ticked.update(plan.vrs)
            for vr in self.active:
                f = self.set_rest[vr]
                if f is not no_exchange:
                    f()
            if set_u_all is not None:
                set_u_all()
            if set_ud is not None:
                set_ud()
            event(t)

        def step_done(t, target):
            """After fmi3DoStep towards ``target``: the time to step on from, or None (the
            step reached its end)."""
            end = t + P
            ehn, stop, early = ehn_f.value, term_f.value, early_f.value
            reached = last.value if early else target
            if stop:
                raise StopRequest(name, reached, "fmi3DoStep returned terminateSimulation")
            if ehn:
                if reached >= end - tol:                # at the step's end: the next instant's Event Mode
                    self.pending_event = True
                    return None
                between(reached)
                return reached
            if early and reached < target - tol:        # an early return without event: step on
                return reached
            if target >= end - tol:
                return None
            between(target)                             # an activation between instants
            return target

        def between(te):
            """Event Mode between instants at ``te``: the outputs without clocks read first
            (in Step Mode), the activations due, the event iteration."""
            self._use_own()
            if self.get_u is not None:
                self.get_u()
            enter(te)
            self._intra(te)
            event(te)

        def advance(t, tc):
            """Step from ``tc`` to ``t + P``, stopping at every activation on the way."""
            end = t + P
            while tc is not None and tc < end - tol:
                p = self._next_point(tc, end)
                target = end if p is None else p
                if p is not None and not can_vary:
                    raise FMUError(f"{name}: an activation at t = {p:g} s falls between its communication points, "
                                   "but the FMU cannot vary its communication step "
                                   "(canHandleVariableCommunicationStepSize = false)")
                ct.value = tc
                st = do_step(c, ct, _D(target - tc), True, *refs)
                if st > 1:
                    fail(f"DoStep(t = {tc:g} s, h = {target - tc:g} s)", st)
                tc = step_done(t, target)

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
        """``(output_fn, update_fn)`` of a Model Exchange FMU (``integrator``: its
        :class:`~cosim.fmi.model_exchange.MEIntegrator`, whose events come here)."""
        me = integrator
        run = self

        class Model(FMUModel):                  # the integrator's events go through the clocks
            def event(self, t, set_inputs=None):
                return run._me_event(t, set_inputs)

            def initial_event(self, t):
                return run._me_event(t, run._pending_inputs)

        me.model = Model(self.inst)
        self._pending_inputs = None
        pending = [False]

        def output_fn(t: float) -> None:
            n = self.instant(t)
            if n == self.done_n:
                self._again()
                return
            self.done_n = n
            if self.dirty:
                self._sync()
            self._fill(self.in_ft)
            plan = self.periodic_at(n)
            ks = (list(plan.vrs) if plan is not None else []) + self._due_at(t)
            got, snap = self._received_at(t)
            if ks or got or self.in_event or self.pending_event:
                if not self.in_event:
                    st = self._enter_event(self.c)
                    if st > 1:
                        self._fail(f"EnterEventMode(t = {t:g} s)", st)
                    self.in_event = True
                self.pending_event = False
                self.set_u_ft()
                if got:
                    self._keep_base()
                    self._overlay(snap)
                self._activate(t, ks + got, "output", snap)
            else:
                pending[0] |= bool(self.set_cont_ft())
                if self.set_disc_ft.differs():
                    me.at_event(t, self.set_disc_ft)
                    self._sync()
            if self.get_ud is not None:
                self.get_ud()
            self._publish(True)

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
            self._check_log()
            self._keep_base()
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
            st = self._enter_event(self.c)
            if st > 1:
                self._fail(f"EnterEventMode(t = {t:g} s)", st)
            self.in_event = True
            if set_inputs is not None:
                set_inputs()
            self._intra(t)
        elif set_inputs is not None:
            set_inputs()
        if self._finish(t):
            return True, None
        st = self._fn("fmi3EnterContinuousTimeMode")(self.c)
        if st > 1:
            self._fail(f"EnterContinuousTimeMode(t = {t:g} s)", st)
        self.in_event = False
        return False, self._me_next(t)

    # ------------------------------------------------------------------ Scheduled Execution
    def se_functions(self):
        """``(output_fn, update_fn)`` of a Scheduled Execution FMU."""
        name, by_vr = self.name, self.model.by_vr
        act, c, t0, inv = self._activate_fn, self.c, self.t0, 1.0 / self.P
        self._se_cb_clocks: list[int] = []           # output clocks reported active in callbacks
        self._se_now: float | None = None
        self._se_queue: list[int] = []
        log_t, log_id, fail, labels = self.log_t, self.log_id, self._fail, self.labels
        set_u_all = None if self.set_u_all is no_exchange else self.set_u_all
        set_u_ft_d = None if self.set_u_ft_d is no_exchange else self.set_u_ft_d
        set_u_rest = None if self.set_u_rest is no_exchange else self.set_u_rest     # consumed at the update
        set_all = {vr: f for vr, f in self.set_all.items() if f is not no_exchange}
        inbox, next_at, ids = self.inbox, self.next_at, self.board._ids
        fill_ft, fill_all = self.fill_ft, self.fill_all
        cv, at = _U32(0), _D(0.0)

        def activate(t: float, vr: int, k: FMIClock, direct: bool) -> None:
            s = set_all.get(vr)
            if s is not None:
                s()
            self._se_cb_clocks.clear()
            cv.value, at.value = vr, t
            st = act(c, cv, at)
            if self._error is not None:                 # what went wrong in the callback comes first
                err, self._error = self._error, None
                if st > 1:
                    self.inst.worst = max(self.inst.worst, 3 if st == 2 else st)
                raise err
            if st > 1:
                fail(f"ActivateModelPartition({k.name}, t = {t:g} s)", st)
            log_t(t)
            log_id(labels[vr])
            g = (self.get_kd if direct else self.get_k)[vr]
            if g is not None:
                g()
            g = self.get_ud if direct else self.get_u
            if g is not None:
                g()

        def run_at(t: float, ks: list[int], snap: dict | None, direct: bool) -> None:
            """The partitions ``ks`` at ``t`` in priority order, and any that become due then
            (outputs into the signals if ``direct``, else into the own buffers)."""
            if not direct:
                self._use_own()
            self._se_now = t
            done = set()
            queue = self._se_queue
            queue[:] = sorted(set(ks), key=self.priority.get)
            if set_u_all is not None:
                set_u_all()
            while queue:
                vr = queue.pop(0)
                k = by_vr[vr]
                if vr in done:
                    raise FMUError(f"{name}: clock {k.name!r} would be activated twice at t = {t:g} s (Scheduled "
                                   "Execution activates a partition once per time)")
                done.add(vr)
                activate(t, vr, k, direct)
                if k.variability == "changing" or (k.variability == "tunable" and not k.has_decimal):
                    for kk, v, q in self._intervals([k]):
                        self._apply_interval(kk, v, q, t, True)
                    for v2 in self._due_at(t):
                        if v2 not in queue:
                            queue.append(v2)
                    queue.sort(key=self.priority.get)
                if self._se_cb_clocks:
                    self._se_outputs(t, snap, direct)
            self._se_now = None

        def make(plan):
            """The short path of ``plan``: one partition (not changing, not tunable without
            intervalDecimal) activated at an instant; others go through :func:`run_at`."""
            vr = plan.vrs[0]
            k = by_vr[vr]
            if len(plan.vrs) > 1 or plan.intervals:
                def fire_all(t: float) -> None:
                    self._fill(self.in_ft)
                    run_at(t, list(plan.vrs), None, True)
                plan.fire = fire_all
                return fire_all
            s_all = self.set_all_d[vr]
            s_all = None if s_all is no_exchange else s_all
            cvp, lab, g_k, g_u = _U32(vr), plan.labels[0], self.get_kd[vr], self.get_ud
            cb, queue = self._se_cb_clocks, self._se_queue
            fill = fill_ft is not None and (plan.fill or getattr(set_u_ft_d, "needs_fill", False))

            def fire(t: float) -> None:
                self._se_now = t
                if fill:
                    fill_ft()
                if set_u_ft_d is not None:
                    set_u_ft_d()
                if set_u_rest is not None:
                    set_u_rest()
                if s_all is not None:
                    s_all()
                at.value = t
                st = act(c, cvp, at)
                if self._error is not None:             # what went wrong in the callback comes first
                    err, self._error = self._error, None
                    if st > 1:
                        self.inst.worst = max(self.inst.worst, 3 if st == 2 else st)
                    raise err
                if st > 1:
                    fail(f"ActivateModelPartition({k.name}, t = {t:g} s)", st)
                log_t(t)
                log_id(lab)
                if g_k is not None:
                    g_k()
                if g_u is not None:
                    g_u()
                if cb:
                    self._se_outputs(t, None, True)
                self._se_now = None
                if queue:                               # a countdown due at once: after it, in order
                    run_at(t, list(queue), None, True)
            plan.fire = fire
            return fire

        def output_fn(t: float) -> None:
            n = round((t - t0) * inv)
            if n == self.done_n:
                return
            self.done_n = n
            if self.dirty:
                self._sync()
            plans = self.plans
            plan = plans[n % self.plan_len] if plans is not None and n >= self.first else self._plan_at(n)
            if not inbox and not next_at:               # the short path: periodic partitions only
                if plan is not None:
                    (plan.fire or make(plan))(t)
                return
            self._fill(self.in_ft)
            ks = (list(plan.vrs) if plan is not None else []) + self._due_at(t)
            got, snap = self._received_at(t)
            if got:
                self._keep_base()
                self._overlay(snap)
            if ks or got:
                run_at(t, ks + got, snap, True)

        def update_fn(t: float) -> None:
            if len(ids) > MAX_TICKS:
                self._check_log()
            if not inbox and not next_at:
                if set_u_rest is not None:              # the inputs consumed at t, for the next activation
                    fill_all()
                return
            if fill_all is not None:
                fill_all()
            self._keep_base()
            got, snap = self._received_at(t)        # arrived after this instant's outputs
            if got:
                self._overlay(snap)
                run_at(t, got, snap, False)
            end = t + self.P
            tc = t
            while True:
                p = self._next_point(tc, end)
                if p is None:
                    return
                ks = self._due_at(p)
                got, snap = self._received_at(p)
                self._overlay(snap)
                run_at(p, ks + got, snap, False)
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
                st = self._get_clock(self.c, self._out_vr, self._n_out, self._out_val)
                if st > 1:
                    self._fail("GetClock", st)
                for i in range(n):
                    if self._out_val[i]:
                        self._se_cb_clocks.append(i)
            t = self._se_now
            for k, v, q in self._intervals(self.countdown):
                if q not in QUALIFIERS:
                    raise FMUError(f"{self.name}: fmi3GetInterval of clock {k.name!r} returned the qualifier {q}")
                if q == CHANGED:
                    te = (t if t is not None else self.t0) + _interval(v, k, self.name, False)
                    if t is not None and abs(te - t) <= self.tol:
                        self.next_at.pop(k.vr, None)
                        if k.vr not in self._se_queue:
                            self._se_queue.append(k.vr)
                            self._se_queue.sort(key=self.priority.get)
                    else:
                        self.next_at[k.vr] = te
        except BaseException as e:  # noqa: BLE001 - kept, raised after the FMU returns
            if self._error is None:
                self._error = e
        finally:
            self.in_callback = False

    def _se_outputs(self, t: float, snap: dict | None, direct: bool) -> None:
        """Scheduled Execution, after an activation: the output clocks its callbacks reported
        counted, logged, their outputs read, their activations sent."""
        published = None
        for i in self._se_cb_clocks:
            k = self.out_clocks[i]
            self._count(i, direct)
            self.log_t(t)
            self.log_id(self.labels[k.vr])
            g = (self.get_kd if direct else self.get_k)[k.vr]
            if g is not None:
                g()
            if self.publishers[i] is not None:
                published = published or []
                published.append(self.publishers[i])
        self._se_cb_clocks.clear()
        if published:
            self._outbox.append((t, snap, published))
            self._publish(direct)


def initialise(comp, inst, t0: float) -> _Schedule:
    """In Initialization Mode: the clock intervals set or asked as the standard says (see
    the module documentation); returns the run's schedule.

    Parameters
    ----------
    comp : FMUComponent
        The component (its clocks, period and ``clock_intervals``).
    inst : FMUInstance
        Its instance, in Initialization Mode.
    t0 : float
        The start time [s].
    """
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
        vr = (_U32 * 1)(k.vr)
        one = _SIZE(1)
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
            if q[0] == NOT_YET_KNOWN:
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
            if q[0] not in QUALIFIERS:
                raise FMUError(f"{comp.name}: fmi3GetInterval of clock {k.name!r} returned the qualifier {q[0]}")
            if k.variability == "changing" and q[0] == NOT_YET_KNOWN:
                raise FMUError(f"{comp.name}: fmi3GetInterval of changing clock {k.name!r} returned "
                               "fmi3IntervalNotYetKnown, which only countdown clocks may return")
            if q[0] == CHANGED:
                sched.next_at[k.vr] = t0 + _interval(iv[0], k, comp.name, False)
    return sched

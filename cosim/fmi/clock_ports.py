"""The ports of a clocked FMI 3.0 FMU in a run: a clocked variable is set and got only while
one of its clocks is active (§2.2.8.3); each set of ports is one
:class:`~cosim.fmi.exchange.Exchange` (a call per type, §2.2.7.2).
"""
from __future__ import annotations

import ctypes
from typing import NamedTuple

import numpy as np

from ..core.clocking import ClockBoard
from .exchange import no_exchange
from .ports import parse_start

__all__ = ["ClockPorts", "InputSetters", "Plan"]

_B, _U32, _SIZE = ctypes.c_bool, ctypes.c_uint32, ctypes.c_size_t


def _index(positions) -> slice | np.ndarray:
    """``positions`` as a slice if they lie side by side (an Exchange of scalar Float64 ports
    then works in place, the FMU reading or writing the array itself), else an index array."""
    idx = np.asarray(positions, np.intp)
    if len(idx) and np.array_equal(idx, np.arange(idx[0], idx[0] + len(idx))):
        return slice(int(idx[0]), int(idx[0]) + len(idx))
    return idx


class InputSetters(NamedTuple):
    """The setters of one set of inputs: those some output depends on directly (``ft``),
    the others (``rest``), all of them; each from the component's input buffer and (``_d``)
    from the master's signals. A setter of no input is ``no_exchange``."""

    ft: object
    rest: object
    all: object
    ft_d: object
    rest_d: object
    all_d: object


class Plan:
    """The calls of one set of input clocks activated together (one ``fmi3SetClock``;
    Scheduled Execution: the partitions in priority order), made once per set.

    Parameters
    ----------
    ports : ClockPorts
        The run.
    vrs : tuple of int
        The clocks' value references.
    """

    __slots__ = ("args", "get", "get_d", "intervals", "labels", "names", "set_all", "set_ft", "set_ft_d", "set_rest_d",
                 "short", "vrs")

    def __init__(self, ports: ClockPorts, vrs: tuple[int, ...]):
        by_vr, n = ports.model.by_vr, len(vrs)
        ins = [ports.clock_in[v] for v in vrs]
        self.vrs = vrs
        self.args = (ports.c, (_U32 * n)(*vrs), _SIZE(n), (_B * n)(*([True] * n)))
        self.labels = tuple(ports.labels[v] for v in vrs)
        self.names = ", ".join(by_vr[v].name for v in vrs)
        self.set_ft, self.set_all = ports.calls(s.ft for s in ins), ports.calls(s.all for s in ins)
        self.set_ft_d, self.set_rest_d = ports.calls(s.ft_d for s in ins), ports.calls(s.rest_d for s in ins)
        self.get = ports.calls(ports.get_k.get(v) for v in vrs)
        self.get_d = ports.calls(ports.get_kd.get(v) for v in vrs)
        self.intervals = [by_vr[v] for v in vrs if ports.interval_read(by_vr[v])]
        self.short = None                # the short path's calls, made by the interface's run


class ClockPorts:
    """The ports of a clocked FMU in one run: its setters, getters, input and output buffers
    (outputs read between instants go to its own, the signals at the next instant), its
    output clocks' counts and sinks.

    Parameters
    ----------
    comp : FMUComponent
        Reset (instantiated and initialised), with its schedule from the initialisation.
    board : ClockBoard
        The run's activations.
    values, integers : ndarray
        The master's signal arrays.
    inputs : slice or ndarray
        The connected inputs' signal indices.
    outputs : slice
        The outputs' signal indices.

    Attributes
    ----------
    clock_in : dict of int to InputSetters
        Each input clock's clocked inputs.
    free_in : InputSetters
        The inputs without clock (in Co-Simulation: but the discrete ones); their positions
        are ``unclocked_in``.
    get_k, get_kd, get_u, get_ud : dict of int to callable, or callable
        The getters of each clock's outputs and of the outputs without clock (``_d``: into
        the signals, else into the own buffers); None for no output.
    """

    # a run's state, as slots: the hot paths' attribute and method look-ups stay fast
    __slots__ = ("_ft", "_get_clock", "_in_srcs", "_in_starts", "_logged", "_n_out", "_out_val", "_out_vr", "_outbox",
                 "_plans", "board", "c", "clock_in", "comp", "dirty", "fill_all", "fill_ft", "free_in", "get_k",
                 "get_kd", "get_u", "get_ud", "idx_in", "iin", "iin_base", "in_ft", "inst", "integers", "labels",
                 "log_id", "log_t", "model", "n_in", "name", "out", "out_clock_pos", "out_clocks", "out_counts", "own",
                 "own_i", "port_clock", "priority", "publishers", "sources", "unclocked_in", "values", "vin",
                 "vin_base")
    #: Whether discrete inputs without clock are set apart, in Event Mode only (Co-Simulation).
    discrete_apart = False

    def __init__(self, comp, board: ClockBoard, values, inputs, outputs, integers):
        self.comp, self.board, self.model = comp, board, comp.clock_model
        self.inst, self.name = comp.instance, comp.name
        self.c = ctypes.c_void_p(self.inst.handle)
        self.values, self.integers, self.out = values, integers, outputs
        self.idx_in = np.arange(len(values))[inputs] if isinstance(inputs, slice) else np.asarray(inputs, np.intp)
        self.n_in = len(comp.connected_inputs)
        n_out = len(comp.output_names)
        self.own, self.own_i = np.zeros(n_out), np.zeros(n_out, dtype=np.int64)
        self.vin, self.iin = np.zeros(max(self.n_in, 1)), np.zeros(max(self.n_in, 1), dtype=np.int64)
        self.vin_base, self.iin_base = self.vin.copy(), self.iin.copy()
        self.log_t, self.log_id, self._logged = board.log_functions()
        self.dirty = False                           # the own buffers hold outputs newer than the signals
        self._outbox: list = []                      # output clock activations to send
        self._plans: dict = {}
        self._in_starts = comp._input_starts()        # the connected inputs' start values and sources
        self._in_srcs = comp.connected_sources()
        self._build_clocks()
        self._build_inputs(comp)
        self._build_outputs(comp)
        self._fillers()
        self._setup()

    def _setup(self) -> None:
        """A subclass's set-up, after the ports'."""

    # ------------------------------------------------------------------ set-up
    def _fail(self, what: str, status: int):
        self.inst.fail(what, status)

    @staticmethod
    def calls(fns) -> tuple:
        """The calls among ``fns`` that do something (None and ``no_exchange`` left out)."""
        return tuple(f for f in fns if f is not None and f is not no_exchange)

    @staticmethod
    def _or_none(f):
        return None if f is no_exchange else f

    def _build_clocks(self) -> None:
        model = self.model
        self.labels = {k.vr: self.board.label(self.name, k.name) for k in model.clocks}
        self.priority = {k.vr: ((k.priority if k.priority is not None else 0), k.index) for k in model.clocks}
        self.port_clock = {k.name: k.vr for k in model.clocks if k.is_port and k.causality == "input"}
        # output (and local) clocks: read with fmi3GetClock
        outs = self.comp.output_names
        self.out_clocks = [k for k in model.clocks if k.causality != "input"]
        self.out_clock_pos = [outs.index(k.name) if k.name in outs else -1 for k in self.out_clocks]
        self.out_counts = [0] * len(self.out_clocks)
        self.publishers = [self.board.publisher(self.name, k.name) if k.is_port else None for k in self.out_clocks]
        n = len(self.out_clocks)
        self._out_vr = (_U32 * max(n, 1))(*[k.vr for k in self.out_clocks])
        self._out_val = (_B * max(n, 1))()
        self._n_out = _SIZE(n)
        self._get_clock = self.inst.raw("fmi3GetClock")

    def _by_clock(self, names: list[str], positions) -> tuple[dict[int, list[int]], list[int]]:
        """The ``positions`` of the variables ``names`` by the clocks that clock them, and the unclocked."""
        by_clock: dict[int, list[int]] = {}
        unclocked = []
        for i in positions:
            ks = self.model.clocks_of(self.comp.element_ports[names[i]].variable.name)
            if not ks:
                unclocked.append(i)
            for vr in ks:
                by_clock.setdefault(vr, []).append(i)
        return by_clock, unclocked

    def _build_inputs(self, comp) -> None:
        model, ports, names = self.model, comp.element_ports, comp.connected_inputs
        self.sources = self.board.sources(self.name, names)
        ft_names = set().union(*comp.feedthrough.values()) if comp.feedthrough else set()
        data_in = [i for i, n in enumerate(names) if n in ports and n not in model.by_name]
        self.in_ft = np.array([i for i in data_in if names[i] in ft_names], dtype=np.intp)
        self._ft = set(self.in_ft.tolist())
        by_clock, self.unclocked_in = self._by_clock(names, data_in)
        vrs = dict.fromkeys([*(k.vr for k in model.clocks if k.causality == "input"), *by_clock])
        self.clock_in = {vr: self.setters(by_clock.get(vr, [])) for vr in vrs}
        apart = self.discrete(self.unclocked_in) if self.discrete_apart else []
        self.free_in = self.setters([i for i in self.unclocked_in if i not in apart])

    def _build_outputs(self, comp) -> None:
        outs = comp.output_names
        by_clock, unclocked = self._by_clock(outs, [j for j, n in enumerate(outs) if n not in self.model.by_name])
        self.get_u = self._getter(unclocked, False)          # into the own buffers
        self.get_ud = self._getter(unclocked, True)          # into the signals
        self.get_k = {k.vr: self._getter(by_clock.get(k.vr, []), False) for k in self.model.clocks}
        self.get_kd = {k.vr: self._getter(by_clock.get(k.vr, []), True) for k in self.model.clocks}
        self._hold_starts(comp, sorted({j for positions in by_clock.values() for j in positions}))

    def _hold_starts(self, comp, positions: list[int]) -> None:
        """Clocked outputs hold their start values until their clock first ticks (read only while active)."""
        start = self.out.start
        for j in positions:
            p = comp.element_ports[comp.output_names[j]]
            v = parse_start(p.variable, p.size)[p.offset]
            exact = int(v) if p.type != "UInt64" or v < 2**63 else int(v) - 2**64
            self.values[start + j] = self.own[j] = float(v)
            self.integers[start + j] = self.own_i[j] = exact

    def discrete(self, positions: list[int]) -> list[int]:
        """Those of the input ``positions`` that are discrete variables."""
        names, ports = self.comp.connected_inputs, self.comp.element_ports
        return [i for i in positions if ports[names[i]].discrete]

    # ------------------------------------------------------------------ setters
    def setters(self, positions: list[int]) -> InputSetters:
        """The :class:`InputSetters` of the inputs at ``positions``."""
        parts = ([i for i in positions if i in self._ft], [i for i in positions if i not in self._ft], positions)
        return InputSetters(*(self._setter(p) for p in parts), *(self._setter(p, direct=True) for p in parts))

    def _setter(self, positions: list[int], changes: bool = False, direct: bool = False):
        """A call setting the input ports at ``positions`` from the input buffer (``direct``: from
        the master's signals); ``changes``: it returns whether a value changed."""
        if not positions:
            return no_exchange
        ports, names = self.comp.element_ports, self.comp.connected_inputs
        ex = self.inst.exchange([ports[names[i]] for i in positions], "set", [self._in_srcs[i] for i in positions])
        ex.preset({ports[names[i]].name: self._in_starts[i] for i in positions})
        if direct:
            return ex.bind(self.values, _index(self.idx_in[positions]), self.integers, changes)
        return ex.bind(self.vin, _index(positions), self.iin, changes)

    def _getter(self, positions: list[int], direct: bool):
        """A call reading the outputs at ``positions`` into the signals (``direct``) or own buffers; None: none."""
        if not positions:
            return None
        own, own_i, base = (self.values, self.integers, self.out.start) if direct else (self.own, self.own_i, 0)
        ports = [self.comp.element_ports[self.comp.output_names[j]] for j in positions]
        return self.inst.exchange(ports, "get").bind(own, _index(np.asarray(positions) + base), own_i)

    # ------------------------------------------------------------------ plans
    def interval_read(self, k) -> bool:
        """Whether input clock ``k``'s interval is read after each of its activations
        (changing clocks, tunable ones without ``intervalDecimal``)."""
        return k.variability == "changing" or (k.variability == "tunable" and not k.has_decimal)

    def plan(self, vrs) -> Plan:
        """The :class:`Plan` of the input clocks ``vrs`` activated together (cached)."""
        key = tuple(vrs)
        plan = self._plans.get(key)
        if plan is None:
            plan = self._plans[key] = Plan(self, key)
        return plan

    # ------------------------------------------------------------------ buffers
    def _fillers(self) -> None:
        """``fill_all()`` (the input buffer from the signals: what an update consumes) and
        ``fill_ft()`` (the inputs the outputs depend on: at an instant), or None."""
        values, integers, vin, iin = self.values, self.integers, self.vin, self.iin
        self.fill_all = self.fill_ft = None
        if self.n_in:
            idx, v_n, i_n = self.idx_in, vin[:self.n_in], iin[:self.n_in]
            take_v, take_i = values.take, integers.take

            def fill_all() -> None:
                take_v(idx, out=v_n)
                take_i(idx, out=i_n)
            self.fill_all = fill_all
        pairs = tuple((int(j), int(self.idx_in[j])) for j in self.in_ft)
        if pairs:
            def fill_ft() -> None:
                for j, slot in pairs:
                    vin[j] = values[slot]
                    iin[j] = integers[slot]
            self.fill_ft = fill_ft

    def _fill(self, positions=None) -> None:
        """The input buffer filled: all inputs, or (``positions`` given) ``fill_ft``."""
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

    def _use_own(self) -> None:
        """Before reading outputs between instants: the own buffers start from the signals."""
        if not self.dirty:
            self.own[:] = self.values[self.out]
            self.own_i[:] = self.integers[self.out]
            self.dirty = True

    def _sync(self) -> None:
        """At an instant: what was read between instants goes to the signals."""
        if self.dirty:
            self.values[self.out] = self.own
            self.integers[self.out] = self.own_i
            self.dirty = False

    # ------------------------------------------------------------------ output clocks
    def _active_out_clocks(self, what: str) -> list[int]:
        """``fmi3GetClock`` of the output (and local) clocks (the call ``what``): the active ones' indices."""
        st = self._get_clock(self.c, self._out_vr, self._n_out, self._out_val)
        if st > 1:
            self._fail(what, st)
        return [i for i in range(len(self.out_clocks)) if self._out_val[i]]

    def _clocks_ticked(self, t: float, indices, snap: dict | None, direct: bool) -> bool:
        """The output clocks at ``indices`` active at ``t``: each counted, logged, its outputs
        read (``direct``: into the signals), its activation queued; whether any has sinks."""
        get, floats, ints, base = ((self.get_kd, self.values, self.integers, self.out.start) if direct else
                                   (self.get_k, self.own, self.own_i, 0))
        for i in indices:
            vr = self.out_clocks[i].vr
            self.out_counts[i] += 1
            pos = self.out_clock_pos[i]
            if pos >= 0:
                floats[base + pos] = ints[base + pos] = self.out_counts[i]
            self.log_t(t)
            self.log_id(self.labels[vr])
            g = get[vr]
            if g is not None:
                g()
        published = [self.publishers[i] for i in indices if self.publishers[i] is not None]
        if published:
            self._outbox.append((t, snap, published))
        return bool(published)

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
            out = {**(snap or {}), self.name: mine}
            for pub in published:
                pub(t, out)
        self._outbox.clear()

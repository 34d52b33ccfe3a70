"""Event Mode with clocks (FMI 3.0 §2.3.5; the functions of §2.2.8.4 Clocks specific API),
shared by Model Exchange (:mod:`cosim.fmi.clock_me`) and Co-Simulation with Event Mode
(:mod:`cosim.fmi.clock_cs`), as the clocks page of the documentation describes.
"""
from __future__ import annotations

import ctypes

from fmu_models.errors import FMUError

from .clock_ports import Plan
from .clock_timing import ClockedRun

__all__ = ["MAX_SUPERDENSE", "EventModeRun"]

#: Most super-dense instants of one Event Mode.
MAX_SUPERDENSE = 1000


class EventModeRun(ClockedRun):
    """The Event Mode of a clocked Model Exchange or Co-Simulation FMU in one run."""

    __slots__ = ("_enter_event_mode", "_set_clock", "_uds_any", "_uds_args", "_uds_bytes", "_uds_flags", "_uds_next",
                 "_update_discrete_states", "active", "in_event", "pending_event", "ticked")
    #: Whether the outputs without clock are read again before an activation between
    #: instants is sent (Model Exchange; in Co-Simulation they are the step's left limits).
    read_unclocked_between = False

    def _setup(self) -> None:
        super()._setup()
        self._set_clock = self.inst.raw("fmi3SetClock")
        self._enter_event_mode = self.inst.raw("fmi3EnterEventMode")
        self._update_discrete_states = self.inst.raw("fmi3UpdateDiscreteStates")
        ub = self._uds_bytes = (ctypes.c_uint8 * 8)()        # the five flags side by side
        self._uds_flags = [ctypes.c_bool.from_buffer(ub, i) for i in range(5)]
        self._uds_any = ctypes.c_uint64.from_buffer(ub)       # any of them set
        self._uds_next = ctypes.c_double(0.0)
        self._uds_args = (self.c, *[ctypes.byref(ub, i) for i in range(5)], ctypes.byref(self._uds_next))
        self.in_event = True                         # in Event Mode after initialisation
        self.active: set[int] = set()                # input clocks active in the current super-dense instant
        self.ticked: set[int] = set()                # clocks that ticked in the current Event Mode
        self.pending_event = False                   # the FMU asked for Event Mode at the next instant

    def _event_mode(self, t: float) -> None:
        """``fmi3EnterEventMode`` at ``t`` [s] unless already in Event Mode."""
        if not self.in_event:
            st = self._enter_event_mode(self.c)
            if st > 1:
                self._fail(f"EnterEventMode(t = {t:g} s)", st)
            self.in_event = True

    # ------------------------------------------------------------------ at an instant
    def _instant_event(self, t: float, plan: Plan | None) -> bool:
        """Event Mode at instant ``t`` if anything happens there (``plan``, due, received, pending); whether it did."""
        ks = (list(plan.vrs) if plan is not None else []) + self._due_at(t)
        got, snap = self._received_at(t)
        if not (ks or got or self.pending_event or self.in_event):
            return False
        self._event_mode(t)
        self.pending_event = False
        self.free_in.ft()
        if got:
            self._keep_base()
            self._overlay(snap)
        self._activate(t, ks + got, True, snap)
        return True

    def _activate(self, t: float, ks: list[int], direct: bool, snap: dict | None) -> None:
        """``fmi3SetClock`` of the input clocks ``ks`` at ``t`` (§2.3.5), their clocked inputs set
        and outputs read (``direct``, at an instant: the inputs outputs depend on, the outputs
        into the signals; else all, into the own buffers), then the output clocks."""
        if not direct:
            self._use_own()
        if ks:
            plan = self.plan(ks)
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

    def _read_output_clocks(self, t: float, snap: dict | None, fresh: bool) -> None:
        """``fmi3GetClock`` of the output clocks, the active ones handled (``fresh``: sent at once)."""
        if not self.out_clocks:
            return
        active = self._active_out_clocks(f"GetClock(t = {t:g} s)")
        if fresh:
            self._use_own()
        self.ticked.update(self.out_clocks[i].vr for i in active)
        if self._clocks_ticked(t, active, snap, not fresh) and fresh:
            self._publish(False, self.read_unclocked_between)

    def _again(self) -> None:
        """The outputs computed again at the same instant (a split evaluation or a loop)."""
        if self.in_event:
            self._fill(self.in_ft)
            plan = self.periodic_at(self.done_n)
            vrs = self.active.union(plan.vrs if plan is not None else ())
            self.free_in.ft()
            for vr in vrs:
                self.clock_in[vr].ft()
                g = self.get_kd[vr]
                if g is not None:
                    g()

    def _intra(self, t: float) -> None:
        """Between instants, in Event Mode at ``t``: the activations due."""
        ks = self._due_at(t)
        got, snap = self._received_at(t)
        self._overlay(snap)
        if self.fmu_next is not None and abs(self.fmu_next - t) <= self.tol:
            self.fmu_next = None
        self._activate(t, ks + got, False, snap)

    # ------------------------------------------------------------------ the event iteration
    def _set_rest(self) -> None:
        """Before the state changes: the active clocks' other clocked inputs, the inputs without clock."""
        for vr in list(self.active):
            self.clock_in[vr].rest()
        self.free_in.all()

    def _finish(self, t: float, called: bool = False) -> bool:
        """The rest of an Event Mode at ``t``: the event iteration (``fmi3UpdateDiscreteStates``
        until ``discreteStatesNeedUpdate`` is false, §2.3.5; ``called``: its first call made),
        the intervals, the activations due at once; whether the FMU asks to terminate."""
        f = self._uds_flags
        uds, args = self._update_discrete_states, self._uds_args
        for _ in range(MAX_SUPERDENSE):
            st = 0 if called else uds(*args)
            if st > 1:
                self._fail(f"UpdateDiscreteStates(t = {t:g} s)", st)
            called = False
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
                self._activate(t, ks + got, False, snap)
                continue
            self.fmu_next = float(self._uds_next.value) if f[4].value else None
            self.ticked.clear()
            return False
        raise FMUError(f"{self.name}: the event iteration at t = {t:g} s did not end in {MAX_SUPERDENSE} "
                       "super-dense instants")

    def _read_intervals(self, t: float) -> None:
        """``fmi3GetInterval*`` after the iteration (§2.3.5): countdown clocks, ticked ones :meth:`interval_read`."""
        want = list(self.countdown)
        want += [k for k in map(self.model.by_vr.get, self.ticked) if k.causality == "input" and self.interval_read(k)]
        for k, v, q in self._intervals(want):
            self._apply_interval(k, v, q, t, k.vr in self.ticked)
            self.ticked.discard(k.vr)

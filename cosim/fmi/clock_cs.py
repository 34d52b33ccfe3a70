"""A clocked Co-Simulation FMU with Event Mode in a run, in the FMI 3.0 call sequence
(§4.2 State Machine for Co-Simulation, §4.1.3 Early Return; its Event Mode §2.3.5 in
:mod:`cosim.fmi.clock_event`), as the clocks page of the documentation describes.
"""
from __future__ import annotations

import ctypes

from fmu_models.errors import FMUError

from ..core.clocking import MAX_TICKS
from ..core.component import StopRequest
from .clock_event import EventModeRun
from .clock_ports import Plan

__all__ = ["CSClockedRun"]


class CSClockedRun(EventModeRun):
    """One run of a clocked Co-Simulation FMU."""

    __slots__ = ("_ch", "_ct", "_do_step", "_ds_any", "_ds_bytes", "_ds_flags", "_ds_last", "_ds_refs",
                 "_enter_step_mode", "_tick_calls", "_tock_calls", "can_vary", "fast", "quiet", "set_u_all_d",
                 "set_u_ft_d", "set_ud")
    discrete_apart = True

    def _setup(self) -> None:
        super()._setup()
        self._enter_step_mode = self.inst.raw("fmi3EnterStepMode")
        self._do_step = self.inst.raw("fmi3DoStep")
        db = self._ds_bytes = (ctypes.c_uint8 * 4)()      # eventHandlingNeeded, terminate, earlyReturn
        self._ds_flags = [ctypes.c_bool.from_buffer(db, i) for i in range(3)]
        self._ds_any = ctypes.c_uint32.from_buffer(db)
        self._ds_last = ctypes.c_double(0.0)
        self._ds_refs = (*[ctypes.byref(db, i) for i in range(3)], ctypes.byref(self._ds_last))
        self._ct, self._ch = ctypes.c_double(0.0), ctypes.c_double(self.P)
        self.can_vary = bool(getattr(self.comp.md.coSimulation, "canHandleVariableCommunicationStepSize", False))
        self.set_ud = self._or_none(self._setter(self.discrete(self.unclocked_in), changes=True))
        self.set_u_ft_d, self.set_u_all_d = self._or_none(self.free_in.ft_d), self._or_none(self.free_in.all_d)
        self.quiet = False       # nothing pending, nothing held: the short path may run (set by each update)
        self.fast: Plan | None = None    # the plan of the short path's activation at this instant
        # the short path's calls, unpacked into locals by _tick and _tock
        self._tick_calls = (self._enter_event_mode, self._set_clock, self.c, self.set_u_ft_d, self.log_t, self.log_id)
        self._tock_calls = (self._update_discrete_states, self._uds_args, self._uds_any, self._enter_step_mode,
                            self._do_step, self._ct, self._ch, self._ds_refs, self._ds_any)

    # ------------------------------------------------------------------ at an instant
    def output(self, t: float) -> None:
        """The outputs at instant ``t`` [s]."""
        n = round((t - self.t0) * self.inv)
        if n == self.done_n:
            self._again()
            return
        self.done_n = n
        if self.quiet and not self.inbox:            # the short path: periodic clocks only
            if self.get_ud is not None:              # in Step Mode, before any set
                self.get_ud()
            plans = self.plans
            plan = plans[n % self.plan_len] if plans is not None and n >= self.first else self._plan_at(n)
            if plan is not None:
                self._tick(plan, t)
            return
        self._sync()
        self._fill(self.in_ft)
        if self.get_ud is not None:
            self.get_ud()
        plan = self.periodic_at(n)
        fmu_now = self.fmu_next is not None and abs(self.fmu_next - t) <= self.tol
        if self.inbox or self.next_at or self.pending_event or self.in_event or fmu_now:
            if fmu_now:
                self.pending_event, self.fmu_next = True, None
            if self._instant_event(t, plan):
                self._publish(True)
        elif plan is not None:
            self._tick(plan, t)

    def _tick(self, plan: Plan, t: float) -> None:
        """The short path's Event Mode at instant ``t`` (§2.3.5): ``plan``'s clocks, their ports, the output clocks."""
        enter_event_mode, set_clock, c, set_u_ft, log_t, log_id = self._tick_calls
        simple = (plan.short or self._shorten(plan))[1]
        st = enter_event_mode(c)
        if st > 1:
            self._fail(f"EnterEventMode(t = {t:g} s)", st)
        self.in_event = True
        if set_u_ft is not None:
            set_u_ft()
        st = set_clock(*plan.args)
        if st > 1:
            self._fail(f"SetClock({plan.names}, t = {t:g} s)", st)
        for lab in plan.labels:
            log_t(t)
            log_id(lab)
        for f in plan.set_ft_d:
            f()
        for g in plan.get_d:
            g()
        if self.out_clocks:
            self._read_output_clocks(t, None, False)
            if self._outbox:
                self._publish(True)
        if simple:
            self.fast = plan
        else:
            self.active.update(plan.vrs)
            self.ticked.update(plan.vrs)

    def _shorten(self, plan: Plan) -> tuple:
        """``plan``'s short update ``(setters, simple)``; ``simple``: no interval to read after it."""
        sets = self.calls((self.fill_all if self.set_ud is not None else None, *plan.set_rest_d, self.set_u_all_d,
                           self.set_ud))
        plan.short = (sets, not plan.intervals and not self.countdown)
        return plan.short

    # ------------------------------------------------------------------ the update
    def update(self, t: float) -> None:
        """The update from instant ``t`` [s]: the event iteration, the step to the next instant."""
        plan = self.fast
        if plan is not None and not self.inbox and not self.next_at and self.fmu_next is None:
            self.fast = None                         # the short path
            self._tock(plan, t)
            return
        filled = False
        if plan is None and not self.in_event:       # no tick at this instant: Step Mode
            if self.set_ud is not None:
                self.fill_all()
                filled = True
            if self.set_u_all_d is not None:
                self.set_u_all_d()
            if self.set_ud is not None and self.set_ud.differs():
                self._event_mode(t)                  # a discrete input changes: Event Mode
                self.set_ud()
                self._event(t)
        else:
            self._fill()
            filled = True
            self.fast = None
            if plan is not None:
                self.active.update(plan.vrs)
                self.ticked.update(plan.vrs)
            self._set_rest()
            if self.set_ud is not None:
                self.set_ud()
            self._event(t)
        self._step(t, filled)
        if len(self._logged) > MAX_TICKS:
            self.board.check_room()

    def _tock(self, plan: Plan, t: float) -> None:
        """The short path's update: the other inputs, ``fmi3UpdateDiscreteStates``, Step Mode (§4.2.1), the step."""
        update_discrete_states, uds_args, uds_any, enter_step_mode, do_step, ct, ch, ds_refs, ds_any = self._tock_calls
        for f in plan.short[0]:
            f()
        st = update_discrete_states(*uds_args)
        if st > 1:
            self._fail(f"UpdateDiscreteStates(t = {t:g} s)", st)
        if uds_any.value:                            # a flag: the general way
            self._event(t, True)
            self._step(t, False)
            return
        if self.out_clocks and self.ticked:
            self.ticked.clear()
        c = self.c
        st = enter_step_mode(c)
        if st > 1:
            self._fail(f"EnterStepMode(t = {t:g} s)", st)
        self.in_event = False
        ct.value = t
        st = do_step(c, ct, ch, True, *ds_refs)
        if st > 1:
            self._fail(f"DoStep(t = {t:g} s, h = {self.P:g} s)", st)
        if ds_any.value:                             # an event, an early return, a stop
            self._step(t, False, True)
        else:
            self.quiet = True

    def _event(self, t: float, called: bool = False) -> None:
        """The event iteration at ``t`` (``called``: its first call made), then Step Mode."""
        if self._finish(t, called):
            raise StopRequest(self.name, t, "the FMU requested termination in its event update")
        st = self._enter_step_mode(self.c)
        if st > 1:
            self._fail(f"EnterStepMode(t = {t:g} s)", st)
        self.in_event = False

    # ------------------------------------------------------------------ the step
    def _step(self, t: float, filled: bool, stepped: bool = False) -> None:
        """The step from ``t`` (§4.2.1; ``stepped``: the whole step made), on from wherever it stopped;
        then whether the next instant may take the short path."""
        whole = stepped or not (self.inbox or self.next_at or self.fmu_next is not None)
        if whole and not stepped:
            self._do(t, self._ch)
        if not whole or self._ds_any.value:
            if not filled:
                self._fill()
            self._keep_base()
            self._advance(t, self._step_done(t, t + self.P) if whole else t)
        self.quiet = not (self.next_at or self.fmu_next is not None or self.pending_event or self.dirty
                          or self.in_event)

    def _advance(self, t: float, tc: float | None) -> None:
        """Step from ``tc`` to ``t + P``, stopping at every activation on the way."""
        end = t + self.P
        while tc is not None and tc < end - self.tol:
            p = self._next_point(tc, end)
            target = end if p is None else p
            if p is not None and not self.can_vary:
                raise FMUError(f"{self.name}: an activation at t = {p:g} s falls between its communication points, "
                               "but the FMU cannot vary its communication step "
                               "(canHandleVariableCommunicationStepSize = false)")
            self._do(tc, ctypes.c_double(target - tc))
            tc = self._step_done(t, target)

    def _do(self, tc: float, h: ctypes.c_double) -> None:
        """``fmi3DoStep`` from ``tc`` over ``h`` [s]."""
        self._ct.value = tc
        st = self._do_step(self.c, self._ct, h, True, *self._ds_refs)
        if st > 1:
            self._fail(f"DoStep(t = {tc:g} s, h = {h.value:g} s)", st)

    def _step_done(self, t: float, target: float) -> float | None:
        """After ``fmi3DoStep`` towards ``target`` (§4.1.3 Early Return): where to step on from (None: done)."""
        end = t + self.P
        ehn, stop, early = (f.value for f in self._ds_flags)
        reached = self._ds_last.value if early else target
        if stop:
            raise StopRequest(self.name, reached, "fmi3DoStep returned terminateSimulation")
        if ehn:
            if reached >= end - self.tol:            # at the step's end: the next instant's Event Mode
                self.pending_event = True
                return None
        elif early and reached < target - self.tol:  # an early return without event: step on
            return reached
        elif target >= end - self.tol:
            return None
        te = reached if ehn else target              # an event or an activation between instants
        self._between(te)
        return te

    def _between(self, te: float) -> None:
        """Event Mode between instants at ``te``: the outputs without clocks, the activations, the iteration."""
        self._use_own()
        if self.get_u is not None:
            self.get_u()
        self._event_mode(te)
        self._intra(te)
        self._event(te)

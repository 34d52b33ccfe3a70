"""A clocked Model Exchange FMU in a run, in the FMI 3.0 call sequence (§3.2 State Machine
for Model Exchange: Event Mode §2.3.5 in :mod:`cosim.fmi.clock_event`, Continuous-Time Mode
§3.2.1), as the clocks page of the documentation describes.
"""
from __future__ import annotations

from functools import partial

from ..core.clocking import ClockBoard
from .clock_event import EventModeRun
from .model_exchange import FMUModel, MEIntegrator

__all__ = ["MEClockedRun"]


class MEClockedRun(EventModeRun):
    """One run of a clocked Model Exchange FMU.

    Parameters
    ----------
    comp, board, values, inputs, outputs, integers
        As for :class:`~cosim.fmi.clock_ports.ClockPorts`.
    integrator : MEIntegrator
        The component's integrator, whose events come here.
    """

    __slots__ = ("_enter_ct_mode", "inputs_changed", "me", "set_cont", "set_cont_ft", "set_disc", "set_disc_ft",
                 "started", "window_end")
    read_unclocked_between = True

    def __init__(self, comp, board: ClockBoard, values, inputs, outputs, integers, integrator: MEIntegrator):
        super().__init__(comp, board, values, inputs, outputs, integers)
        disc = self.discrete(self.unclocked_in)
        cont = [i for i in self.unclocked_in if i not in disc]
        self.set_cont, self.set_disc = self._setter(cont, changes=True), self._setter(disc, changes=True)
        self.set_cont_ft = self._setter([i for i in cont if i in self._ft], changes=True)
        self.set_disc_ft = self._setter([i for i in disc if i in self._ft], changes=True)
        self.me = integrator
        self._enter_ct_mode = self.inst.raw("fmi3EnterContinuousTimeMode")
        model = integrator.model = FMUModel(self.inst)   # its events go through this run
        model.event, model.initial_event = self._event, partial(self._event, set_inputs=self._set_rest)
        self.started = False
        self.window_end = self.t0                    # the end of the current step [s]
        self.inputs_changed = False                  # an input without clock changed in Continuous-Time Mode

    def output(self, t: float) -> None:
        """The outputs at instant ``t`` [s]: Event Mode where clocks tick or an event is pending,
        else the inputs without clock the outputs depend on set."""
        n = round((t - self.t0) * self.inv)
        if n == self.done_n:
            self._again()
            return
        self.done_n = n
        self._sync()
        self._fill(self.in_ft)
        if not self._instant_event(t, self.periodic_at(n)):
            self.inputs_changed |= bool(self.set_cont_ft())
            if self.set_disc_ft.differs():
                self.me.at_event(t, self.set_disc_ft)
                self._sync()
        if self.get_ud is not None:
            self.get_ud()
        self._publish(True)

    def _again(self) -> None:
        super()._again()
        if self.get_ud is not None:
            self.get_ud()

    def update(self, t: float) -> None:
        """The update from instant ``t`` [s]: the instant's Event Mode ended (or the inputs
        set), the integrator through the activations on the way to the next instant."""
        self._fill()
        self.window_end = t + self.P
        if not self.started:
            self.started = True
            self.me.start(t)
        elif self.in_event:
            self.me.at_event(t, self._set_rest)
        else:
            self.inputs_changed |= bool(self.set_cont())
            if self.set_disc.differs():
                self.me.at_event(t, self.set_disc)
        self.board.check_room()
        self._keep_base()
        self.me.next_event = self._next_event(t)
        self.me.advance(t, self.P, self.inputs_changed)
        self.inputs_changed = False

    def _next_event(self, t: float) -> float | None:
        """The integrator's next time event after ``t`` [s] (an activation or ``nextEventTime``)."""
        f = self.fmu_next if self.fmu_next is not None and self.fmu_next > t + self.tol else None
        return min((x for x in (self._next_point(t, self.window_end), f) if x is not None), default=None)

    def _event(self, t: float, set_inputs=None) -> tuple[bool, float | None]:
        """An Event Mode at ``t`` (entered unless in it), the inputs set by ``set_inputs``, ended
        with ``fmi3EnterContinuousTimeMode`` (§3.2): ``(terminate, next time event)``."""
        if not self.in_event and set_inputs is None and abs(t - self.window_end) <= self.tol:
            self.pending_event = True
            return False, None
        if not self.in_event:
            self._event_mode(t)
            if set_inputs is not None:
                set_inputs()
            self._intra(t)
        elif set_inputs is not None:
            set_inputs()
        if self._finish(t):
            return True, None
        st = self._enter_ct_mode(self.c)
        if st > 1:
            self._fail(f"EnterContinuousTimeMode(t = {t:g} s)", st)
        self.in_event = False
        return False, self._next_event(t)

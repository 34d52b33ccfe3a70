"""A Scheduled Execution FMU in a run, in the FMI 3.0 call sequence (§5.1.1 Activating
Model Partitions, §5.2.1 Clock Activation Mode, §5.2.2 Clock Update Mode), as the clocks
page of the documentation describes.
"""
from __future__ import annotations

import ctypes

from fmu_models.errors import FMUError

from ..core.clocking import MAX_TICKS
from .clock_ports import Plan
from .clock_timing import ClockedRun
from .clocks import CHANGED, FMIClock
from .exchange import no_exchange

__all__ = ["SEClockedRun"]


class SEClockedRun(ClockedRun):
    """One run of a Scheduled Execution FMU."""

    __slots__ = ("_activate_model_partition", "_at", "_cv", "_error", "_fire_calls", "in_callback", "now", "queue",
                 "reported", "rest_later")
    by_priority = True

    def _setup(self) -> None:
        super()._setup()
        self._activate_model_partition = self.inst.raw("fmi3ActivateModelPartition")
        self.rest_later = self.free_in.rest is not no_exchange      # inputs consumed at the update
        self.reported: list[int] = []                # output clocks reported active in callbacks
        self.now: float | None = None                # the time of the activation under way
        self.queue: list[int] = []                   # the partitions still to activate at that time
        self.in_callback = False                     # in the clockUpdate callback (Clock Update Mode)
        self._error: BaseException | None = None     # what went wrong in the callback
        self._cv, self._at = ctypes.c_uint32(0), ctypes.c_double(0.0)
        self._fire_calls = (self._activate_model_partition, self.c, self._at, self.log_t, self.log_id)

    def _fail(self, what: str, status: int):
        if status == 2:                              # Scheduled Execution: discard is an error
            self.inst.worst = max(self.inst.worst, 3)
        self.inst.fail(what, status)

    # ------------------------------------------------------------------ at an instant
    def output(self, t: float) -> None:
        """The partitions due at instant ``t`` [s], their outputs into the signals."""
        n = round((t - self.t0) * self.inv)
        if n == self.done_n:
            return
        self.done_n = n
        if self.dirty:
            self._sync()
        plans = self.plans
        plan = plans[n % self.plan_len] if plans is not None and n >= self.first else self._plan_at(n)
        if not self.inbox and not self.next_at:      # the short path: periodic partitions only
            if plan is not None:
                self._fire(plan, t)
            return
        self._fill(self.in_ft)
        ks = (list(plan.vrs) if plan is not None else []) + self._due_at(t)
        got, snap = self._received_at(t)
        if got:
            self._keep_base()
            self._overlay(snap)
        if ks or got:
            self._run_at(t, ks + got, snap, True)

    def _fire(self, plan: Plan, t: float) -> None:
        """The short path of ``plan`` at ``t`` (one partition, no interval read): §5.2.1 activation."""
        sets, cv, name, label, gets = plan.short or self._shorten(plan)
        if cv is None:
            self._fill(self.in_ft)
            self._run_at(t, list(plan.vrs), None, True)
            return
        activate_model_partition, c, at, log_t, log_id = self._fire_calls
        self.now = t
        for f in sets:
            f()
        at.value = t
        st = activate_model_partition(c, cv, at)
        if st > 1 or self._error is not None:
            self._activation_failed(st, name, t)
        log_t(t)
        log_id(label)
        for g in gets:
            g()
        if self.reported:
            self._outputs(t, None, True)
        self.now = None
        if self.queue:                               # a countdown due at once: after it, in order
            self._run_at(t, list(self.queue), None, True)

    def _shorten(self, plan: Plan) -> tuple:
        """``plan``'s short path ``(setters, clock, name, label, getters)`` (clock None: not one partition)."""
        if len(plan.vrs) > 1 or plan.intervals:
            plan.short = ((), None, None, None, ())
            return plan.short
        vr = plan.vrs[0]
        plan.short = (self.calls((self.free_in.ft_d, self.free_in.rest, self.clock_in[vr].all_d)), ctypes.c_uint32(vr),
                      self.model.by_vr[vr].name, plan.labels[0], self.calls((self.get_kd[vr], self.get_ud)))
        return plan.short

    def _run_at(self, t: float, ks: list[int], snap: dict | None, direct: bool) -> None:
        """The partitions ``ks`` at ``t`` in priority order (§5.1.1), and those due then (``direct``: at an instant)."""
        if not direct:
            self._use_own()
        self.now = t
        done = set()
        queue = self.queue
        queue[:] = sorted(set(ks), key=self.priority.get)
        self.free_in.all()
        while queue:
            vr = queue.pop(0)
            k = self.model.by_vr[vr]
            if vr in done:
                raise FMUError(f"{self.name}: clock {k.name!r} would be activated twice at t = {t:g} s (Scheduled "
                               "Execution activates a partition once per time)")
            done.add(vr)
            self._activate(t, vr, k, direct)
            if self.interval_read(k):
                for kk, v, q in self._intervals([k]):
                    self._apply_interval(kk, v, q, t, True)
                self._enqueue(self._due_at(t))
            if self.reported:
                self._outputs(t, snap, direct)
        self.now = None

    def _enqueue(self, vrs: list[int]) -> None:
        """Add the partitions ``vrs`` due now to the queue, in priority order."""
        self.queue.extend(vr for vr in vrs if vr not in self.queue)
        self.queue.sort(key=self.priority.get)

    def _activate(self, t: float, vr: int, k: FMIClock, direct: bool) -> None:
        """Partition ``k`` at ``t``: its inputs set, activated, its outputs read (``direct``: into the signals)."""
        self.clock_in[vr].all()
        self.reported.clear()
        self._cv.value, self._at.value = vr, t
        st = self._activate_model_partition(self.c, self._cv, self._at)
        if st > 1 or self._error is not None:
            self._activation_failed(st, k.name, t)
        self.log_t(t)
        self.log_id(self.labels[vr])
        for g in self.calls([(self.get_kd if direct else self.get_k)[vr], self.get_ud if direct else self.get_u]):
            g()

    def _activation_failed(self, st: int, name: str, t: float) -> None:
        """Raise what went wrong in the callbacks of ``fmi3ActivateModelPartition``, else its failure ``st``."""
        if self._error is not None:
            err, self._error = self._error, None
            if st > 1:
                self.inst.worst = max(self.inst.worst, 3 if st == 2 else st)
            raise err
        self._fail(f"ActivateModelPartition({name}, t = {t:g} s)", st)

    # ------------------------------------------------------------------ Clock Update Mode
    def clock_update(self, env) -> None:
        """The ``clockUpdate`` callback (Clock Update Mode, §5.2.2): the output clocks and the
        countdown clocks' intervals read; an error is kept, raised after the activation returns.

        Parameters
        ----------
        env : object
            The instance environment the FMU passes (unused).
        """
        try:
            self.in_callback = True
            if self.out_clocks:
                self.reported += self._active_out_clocks("GetClock")
            t = self.now
            for k, v, q in self._intervals(self.countdown):
                self._apply_interval(k, v, q, t if t is not None else self.t0, False)
                if q == CHANGED and t is not None and abs(self.next_at[k.vr] - t) <= self.tol:
                    del self.next_at[k.vr]
                    self._enqueue([k.vr])
        except BaseException as e:  # noqa: BLE001 - kept, raised after the FMU returns
            if self._error is None:
                self._error = e
        finally:
            self.in_callback = False

    def _outputs(self, t: float, snap: dict | None, direct: bool) -> None:
        """After an activation: the output clocks its callbacks reported handled and sent."""
        if self._clocks_ticked(t, self.reported, snap, direct):
            self._publish(direct)
        self.reported.clear()

    # ------------------------------------------------------------------ the update
    def update(self, t: float) -> None:
        """The update from instant ``t`` [s]: the activations before the next instant, each at its time."""
        if len(self._logged) > MAX_TICKS:
            self.board.check_room()
        if not self.inbox and not self.next_at:
            if self.rest_later:                      # the inputs consumed at t, for the next activation
                self._fill()
            return
        self._fill()
        self._keep_base()
        got, snap = self._received_at(t)             # arrived after this instant's outputs
        if got:
            self._overlay(snap)
            self._run_at(t, got, snap, False)
        p = self._next_point(t, t + self.P)
        while p is not None:
            ks = self._due_at(p)
            got, snap = self._received_at(p)
            self._overlay(snap)
            self._run_at(p, ks + got, snap, False)
            p = self._next_point(p, t + self.P)

"""Model Exchange FMUs integrated between communication points (CVODE, Euler, RK4), with
their time, state and step events as the standard describes them; an FMU whose nominals
call returns Error is freed and integrated afresh with nominals of 1 (FMI 2.0 section
2.1.3, FMI 3.0 section 2.2.3; the co-simulation page of the documentation says more).
"""
from __future__ import annotations

import ctypes
import logging
import math
from collections.abc import Callable
from types import SimpleNamespace

import numpy as np

from fmu_models.errors import FMUError, UnknownNameError
from fmu_models.infra.checks import positive

from ..core.component import StopRequest

__all__ = ["SOLVERS", "ContinuousModel", "FMUModel", "MEIntegrator", "check_solver", "held_inputs",
           "unit_nominals_instead"]

#: The Model Exchange solvers (see the co-simulation page of the documentation).
SOLVERS = ("cvode", "euler", "rk4")
LOGGER = logging.getLogger("cosim.fmu")
_DP = ctypes.POINTER(ctypes.c_double)


def check_solver(owner: str, solver: str, solver_step: float | None, rtol: float) -> tuple[str, float | None, float]:
    """``(solver, solver_step, rtol)`` of the component ``owner`` checked: ``solver`` one of
    :data:`SOLVERS`, ``solver_step`` [s] None or positive, ``rtol`` positive."""
    if solver not in SOLVERS:
        raise UnknownNameError(f"{owner}: solver must be one of {SOLVERS}, got {solver!r}")
    rtol = positive(rtol, f"{owner}: rtol")
    return solver, None if solver_step is None else positive(solver_step, f"{owner}: solver_step"), rtol


class ContinuousModel:
    """The interface :class:`MEIntegrator` integrates; defaults for what a model may leave out.

    A model also has ``set_time(t)`` [s], ``get_states(x)``, ``set_states(x)``,
    ``derivatives(dx)`` (arrays of nx values), ``indicators(z)`` (nz values),
    ``enter_event_mode()`` and ``settle(t)`` (the event iteration, then Continuous-Time Mode
    unless the model terminates: ``(terminate, next event time or None)``).

    Attributes
    ----------
    nx, nz : int
        Numbers of continuous states and event indicators.
    name : str
        For messages.
    needs_completed_step : bool
        ``CompletedIntegratorStep`` must be called after every integrator step.
    stop_reason : str
        Why the model asked to terminate in its last event (for the stop notice).
    dirty : bool
        An input changed since the outputs' values were brought up to date (:meth:`refresh`).
    """

    nx = 0
    nz = 0
    name = ""
    needs_completed_step = False
    stop_reason = "the FMU requested termination in its event update"
    dirty = False

    def refresh(self) -> None:
        """Bring the values the outputs are read from up to date (nothing to do for one FMU)."""

    def nominals(self, out: np.ndarray) -> None:
        """Write the states' nominal values into ``out``."""
        out[:] = 1.0

    def completed_step(self) -> tuple[bool, bool]:
        """After an integrator step: ``(enter_event_mode, terminate)``."""
        return False, False

    def event(self, t: float, set_inputs: Callable[[], None] | None = None) -> tuple[bool, float | None]:
        """Event Mode at ``t`` [s], ``set_inputs()``, then ``settle(t)``."""
        self.enter_event_mode()
        if set_inputs is not None:
            set_inputs()
        return self.settle(t)

    def initial_event(self, t: float) -> tuple[bool, float | None]:
        """``settle(t)`` after ``ExitInitializationMode``."""
        return self.settle(t)


class FMUModel(ContinuousModel):
    """One Model Exchange FMU instance (after ``ExitInitializationMode``; FMI 1.0: after
    ``fmiInitialize``) as a :class:`ContinuousModel` over its raw FMI functions.

    Parameters
    ----------
    instance : FMUInstance
    unit_nominals : bool
        The states' nominal values are 1, the FMU is not asked (see the co-simulation page of the
        documentation).

    Attributes
    ----------
    nominals_refused : bool
        ``GetNominalsOfContinuousStates`` returned Error.
    """

    def __init__(self, instance, unit_nominals: bool = False):
        md = instance.md
        self.inst, self.name, self.version = instance, instance.owner, instance.version
        self.nominals_refused = False
        self.nx = int(md.numberOfContinuousStates)
        self.nz = int(md.numberOfEventIndicators)
        self.needs_completed_step = self.version == 1 or bool(getattr(md.modelExchange, "needsCompletedIntegratorStep",
                                                                      True))
        p = f"fmi{self.version}"
        c, fail = ctypes.c_void_p(instance.handle), instance.fail

        def check(st, what):
            if st > 1:
                fail(what, st)

        def vector(function: str, n: int, what: str, checked=check):
            fn, size = instance.raw(f"{p}{function}"), ctypes.c_size_t(n)
            return (lambda x: checked(fn(c, x.ctypes.data_as(_DP), size), what)) if n else (lambda x: None)

        self.get_states = vector("GetContinuousStates", self.nx, "GetContinuousStates")
        self.set_states = vector("SetContinuousStates", self.nx, "SetContinuousStates")
        self.derivatives = vector("GetContinuousStateDerivatives" if self.version == 3 else "GetDerivatives", self.nx,
                                  "GetDerivatives")
        self.indicators = vector("GetEventIndicators", self.nz, "GetEventIndicators")

        def check_nominals(st, what):
            self.nominals_refused = st == 3             # Error
            check(st, what)
        if not unit_nominals:                           # else ContinuousModel's: 1 for every state
            nominals = "GetNominalContinuousStates" if self.version == 1 else "GetNominalsOfContinuousStates"
            self.nominals = vector(nominals, self.nx, nominals, check_nominals)
        set_time, completed = instance.raw(f"{p}SetTime"), instance.raw(f"{p}CompletedIntegratorStep")
        self.set_time = lambda t: check(set_time(c, ctypes.c_double(t)), "SetTime")
        flag = {1: ctypes.c_int8, 2: ctypes.c_int}.get(self.version, ctypes.c_bool)       # fmiBoolean is a char
        self._enter, self._term = flag(0), flag(0)
        args = ((c, ctypes.byref(self._enter)) if self.version == 1 else       # FMI 1.0: callEventUpdate only
                (c, 1, ctypes.byref(self._enter), ctypes.byref(self._term)))
        self._completed = lambda: check(completed(*args), "CompletedIntegratorStep")

    def completed_step(self):
        """``CompletedIntegratorStep`` (FMI 1.0: ``callEventUpdate``, never terminates)."""
        self._completed()
        return bool(self._enter.value), bool(self._term.value)

    def enter_event_mode(self) -> None:
        """``EnterEventMode`` (FMI 1.0 has none)."""
        if self.version > 1:
            self.inst.call("EnterEventMode", self.inst.fmu.enterEventMode)

    def enter_continuous_time_mode(self) -> None:
        """``EnterContinuousTimeMode`` (FMI 1.0 has none)."""
        if self.version > 1:
            self.inst.call("EnterContinuousTimeMode", self.inst.fmu.enterContinuousTimeMode)

    def initial_event(self, t):
        """FMI 1.0: what ``fmiInitialize`` said (its initial event iteration is its own)."""
        if self.version == 1:
            return self.inst.initial_events
        return self.settle(t)

    def settle(self, t: float) -> tuple[bool, float | None]:
        """:meth:`iterate`, then Continuous-Time Mode unless the model terminates."""
        terminate, nxt = self.iterate(t)
        if not terminate:
            self.enter_continuous_time_mode()
        return terminate, nxt

    def iterate(self, t: float) -> tuple[bool, float | None]:
        """In Event Mode: update the discrete states until no more update is needed (at most
        1000 rounds); returns ``(terminate, next event time or None)``."""
        name = {1: "EventUpdate", 2: "NewDiscreteStates", 3: "UpdateDiscreteStates"}[self.version]
        update = getattr(self.inst.fmu, name[0].lower() + name[1:])
        for _ in range(1000):
            info = self.inst.call(name, update)
            if self.version == 1:   # (converged, two "changed" flags, terminate, upcomingTimeEvent, nextEventTime)
                need, term, defined, nxt = not info[0], info[3], info[4], info[5]
            else:                   # (update needed, terminate, two "changed" flags, next time defined, next time)
                need, term, defined, nxt = info[0], info[1], info[4], info[5]
            if term:
                return True, None
            if not need:
                return False, (float(nxt) if defined else None)
        raise FMUError(f"{self.name}: the event iteration at t = {t:g} s did not converge in 1000 rounds")


def _cvode(model: ContinuousModel, t0: float, max_step: float, rtol: float):
    """fmpy's CVodeSolver for ``model``: an exception inside a callback is kept in its ``pending`` and
    raised after CVODE returns (a ctypes callback cannot raise), and no model call follows it (after
    an Error only FreeInstance may); a destructor that cannot fail (fmpy's reads ``cvode_mem``, never
    set by a constructor that failed); SUNDIALS' error messages kept for the FMUError, not printed."""
    from fmpy.sundials import CVodeSolver, SUNContext_PushErrHandler
    from fmpy.sundials.libraries import sundials_core

    n = max(model.nx, 1)
    x = np.zeros(n)

    def out(fill, buf: np.ndarray):
        def copy(ptr, size: int) -> None:
            fill(buf)
            ctypes.memmove(ptr, buf.ctypes.data, 8 * size)
        return copy

    class _Solver(CVodeSolver):
        pending: BaseException | None = None

        def __init__(self):
            super().__init__(nx=model.nx, nz=model.nz, get_x=out(model.get_states, x), set_x=self._set_x,
                             get_dx=out(model.derivatives, np.zeros(n)), get_nominals=out(model.nominals, np.ones(n)),
                             get_z=out(model.indicators, np.zeros(max(model.nz, 1))), set_time=model.set_time,
                             input=SimpleNamespace(apply=lambda t: None),     # the master holds the inputs
                             startTime=t0, maxStep=max_step, relativeTolerance=rtol, maxNumSteps=1_000_000)

        def _set_x(self, ptr, size: int) -> None:
            if self.pending is None:        # fmpy sets the states after a failed CVode call too
                ctypes.memmove(x.ctypes.data, ptr, 8 * size)
                model.set_states(x)

        def _guarded(self, call, *args) -> int:
            if self.pending is not None:
                return -1
            try:
                return call(*args)
            except BaseException as e:  # noqa: BLE001 - kept, raised after CVODE returns
                self.pending = e
                return -1

        def f(self, *args):
            return self._guarded(super().f, *args)

        def g(self, *args):
            return self._guarded(super().g, *args)

        def __del__(self):
            if "cvode_mem" in vars(self):       # made: freed (a constructor that failed before made none)
                super().__del__()

    try:
        solver = _Solver()
    except FMUError:
        raise
    except Exception as e:  # noqa: BLE001 - fmpy's binding raises a plain Exception when a CVODE call fails
        raise FMUError(f"{model.name}: CVODE could not be set up at t = {t0:g} s: {e}") from None
    sundials_core.SUNContext_ClearErrHandlers(solver.sunctx)         # only fmpy's handler, which keeps them
    SUNContext_PushErrHandler(solver.sunctx, solver.ehfun_, None)
    return solver


class MEIntegrator:
    """Advance a :class:`.ContinuousModel` between communication points (see the co-simulation
    page of the documentation).

    Parameters
    ----------
    model : ContinuousModel
    solver : {"cvode", "euler", "rk4"}
    solver_step : float, optional
        The fixed step [s] of Euler and RK4 (default: the communication step), or CVODE's
        largest step (default: none).
    rtol : float
        CVODE's relative tolerance.
    """

    #: Most integration steps plus events within one communication step.
    MAX_ROUNDS = 10_000_000

    def __init__(self, model: ContinuousModel, solver: str, solver_step: float | None, rtol: float):
        self.model = model
        self.solver, self.h_int, self.rtol = check_solver(model.name, solver, solver_step, rtol)
        n = max(model.nx, 1)
        self.x, self.dx, self.scratch = np.zeros(n), np.zeros(n), np.zeros(n)
        self.z, self.z_new = np.zeros(max(model.nz, 1)), np.zeros(max(model.nz, 1))
        self.next_event: float | None = None
        self.cvode = None

    # ------------------------------------------------------------------ events
    def _after_event(self, t: float, terminate: bool, nxt: float | None) -> None:
        if terminate:
            raise StopRequest(self.model.name, t, self.model.stop_reason)
        self.next_event = nxt
        self.model.get_states(self.x)
        self.model.indicators(self.z)
        self.reset(t)

    def start(self, t0: float) -> None:
        """After ``ExitInitializationMode``: the initial event iteration, Continuous-Time
        Mode, the solver created."""
        settled = self.model.initial_event(t0)
        if self.solver == "cvode":
            self.cvode = _cvode(self.model, t0, self.h_int or math.inf, self.rtol)
        self._after_event(t0, *settled)

    def reset(self, t: float) -> None:
        """Reinitialise the solver at ``t`` (after an event, or an input that changed)."""
        if self.cvode is not None:
            self.cvode.reset(t)

    def at_event(self, t: float, set_inputs: Callable[[], None]) -> None:
        """An event at ``t`` [s] whose Event Mode sets discrete inputs (``set_inputs()``)."""
        self._after_event(t, *self.model.event(t, set_inputs))

    # ------------------------------------------------------------------ stepping
    def _fixed_step(self, t: float, h: float) -> None:
        """One Euler or RK4 step of length h from (t, self.x); leaves the model at t + h."""
        m, x, dx, s = self.model, self.x, self.dx, self.scratch
        m.derivatives(dx)
        if self.solver == "euler":
            x += h * dx
        else:
            k = [dx.copy()]
            for stage, c in enumerate((h / 2, h / 2, h)):
                s[:] = x + c * k[-1]
                if stage != 1:                   # the second stage is at the first's time
                    m.set_time(t + c)
                m.set_states(s)
                m.derivatives(dx)
                k.append(dx.copy())
            x += h / 6 * (k[0] + 2 * k[1] + 2 * k[2] + k[3])
        m.set_time(t + h)
        m.set_states(x)

    def _cvode_step(self, t: float, t_next: float) -> tuple[float, bool]:
        cvode = self.cvode
        try:
            root, _, t_reached = cvode.step(t, t_next)
        except RuntimeError as e:
            if cvode.pending is None:
                raise FMUError(f"{self.model.name}: CVODE failed between t = {t:g} s and {t_next:g} s: {e}") from None
        if cvode.pending is not None:
            err, cvode.pending = cvode.pending, None
            raise err from None
        self.model.set_time(t_reached)
        self.model.get_states(self.x)
        return t_reached, bool(root)

    def advance(self, t: float, h: float, inputs_changed: bool = False) -> None:
        """Integrate from ``t`` to ``t + h`` [s] with the inputs held, handling every event
        on the way; ``inputs_changed``: a continuous input jumped at ``t`` (the solver is
        reinitialised there).

        Raises
        ------
        StopRequest
            The model asked to terminate (its time is where it asked).
        FMUError
            An FMU call failed, CVODE failed, or more than :data:`MAX_ROUNDS` steps and
            events were needed (chattering events?).
        """
        m = self.model
        t_end = t + h
        tiny = 1e-12 * max(1.0, abs(t_end))
        if inputs_changed:
            self.reset(t)
        h_fix = self.h_int or h
        rounds = 0
        while t < t_end - tiny:
            rounds += 1
            if rounds > self.MAX_ROUNDS:
                raise FMUError(f"{m.name}: more than {self.MAX_ROUNDS} integration steps or events between "
                               f"t = {t_end - h:g} s and {t_end:g} s (chattering events?)")
            t_next = t_end if self.cvode is not None else min(t_end, t + h_fix)
            if t_end - t_next < tiny:
                t_next = t_end
            time_event = self.next_event is not None and self.next_event <= t_next + tiny
            if time_event:
                t_next = max(self.next_event, t)
            if self.cvode is not None:
                t_reached, state_event = self._cvode_step(t, t_next)
                if state_event:
                    t_next, time_event = t_reached, False
            else:
                if t_next > t:
                    self._fixed_step(t, t_next - t)
                state_event = False
                if m.nz:
                    m.indicators(self.z_new)
                    state_event = bool(np.any(np.sign(self.z_new) != np.sign(self.z)))
                    self.z[:] = self.z_new
            step_event = False
            if m.needs_completed_step:
                step_event, terminate = m.completed_step()
                if terminate:
                    raise StopRequest(m.name, t_next, "the FMU requested termination after an integrator step")
            if time_event or state_event or step_event:
                self._after_event(t_next, *m.event(t_next))
            t = t_next


def unit_nominals_instead(models: list[FMUModel], components: list) -> bool:
    """After an integrator failed to start: the component (``components``, in the order of
    ``models``) of each model whose nominals call returned Error gets ``unit_nominals = True``,
    with a warning. Returns whether there was one (the caller then starts afresh)."""
    refused = False
    for model, comp in zip(models, components):
        if model.nominals_refused:
            refused = comp.unit_nominals = True
            call = ("fmiGetNominalContinuousStates" if comp.version == 1 else
                    f"fmi{comp.version}GetNominalsOfContinuousStates")
            LOGGER.warning("%s: %s returned Error from %s when the integrator started; the FMI rules allow only "
                           "FreeInstance after an Error, so that instance was freed and a new one integrates with "
                           "nominal values of 1 for its states", comp.name, comp.path.name, call)
    return refused


def held_inputs(me: MEIntegrator, h: float, setters: tuple[list, list], feedthrough: tuple[list, list],
                getters: list) -> tuple[Callable[[float], None], Callable[[float], None]]:
    """The output and update functions of the model ``me`` integrates, its inputs held over
    each step: continuous ones set in Continuous-Time Mode (the solver reinitialised where one
    jumped), discrete ones in Event Mode (an event where one changed).

    Parameters
    ----------
    me : MEIntegrator
    h : float
        The communication step [s]: the update advances over ``[t, t + h]``.
    setters, feedthrough : (list, list)
        The calls that set the continuous and the discrete inputs, and those of the feed-through ones,
        set at ``t`` before the outputs are read (each returns whether a value changed; ``differs()``:
        whether one would).
    getters : list
        The calls that read the outputs.
    """
    model = me.model
    pending = [False]                        # a continuous input jumped since the last advance

    def set_inputs(t: float, cont: list, disc: list) -> None:
        if cont and any([s() for s in cont]):          # a list: every setter called
            pending[0] = True
            model.dirty = True
        if disc and any(s.differs() for s in disc):
            me.at_event(t, lambda: [s() for s in disc])

    def output_fn(t: float) -> None:
        set_inputs(t, *feedthrough)
        model.refresh()
        for g in getters:
            g()

    def update_fn(t: float) -> None:
        set_inputs(t, *setters)
        me.advance(t, h, pending[0])
        pending[0] = False
    return output_fn, update_fn

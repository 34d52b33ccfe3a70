"""Integrating Model Exchange FMUs between communication points, with their events.

A :class:`ContinuousModel` is what the integrator needs: continuous states, derivatives,
event indicators and the FMI event machinery. :class:`FMUModel` is one ME FMU;
:class:`cosim.fmi.me_system.MESystem` is several connected ones integrated as one.

:class:`MEIntegrator` advances a model over ``[t, t + h]`` with one of three solvers:

* ``"cvode"``: SUNDIALS CVODE (BDF, variable step, relative tolerance ``rtol``, absolute
  tolerance ``rtol`` times the states' nominal values) through fmpy's binding, with root
  finding on the event indicators. The solver integrates **across** communication points:
  its step-size and order history is kept, and it is reinitialised only at events and
  where an input of the model actually changed (a continuous input's jump is a
  discontinuity of the right-hand side). Its largest step is ``max_step`` (default none).
* ``"euler"``, ``"rk4"``: fixed steps of ``solver_step`` (a last partial step ends on the
  communication point); a state event is handled at the end of the step in which an
  indicator changed sign (no localisation).

Events follow the standard: time events (``nextEventTime``) end an integration step
exactly; state events (CVODE's roots of the event indicators) and step events
(``CompletedIntegratorStep`` asking for Event Mode) are handled where they occur: Event
Mode, the event iteration (``NewDiscreteStates``/``UpdateDiscreteStates`` until no more is
needed), Continuous-Time Mode, the states read again (they may jump), the solver
reinitialised. Discrete-time inputs change only in Event Mode (:meth:`MEIntegrator.at_event`).
A model that asks to terminate ends the run at that time
(:class:`~cosim.core.component.StopRequest`).
"""
from __future__ import annotations

import ctypes
import math
from collections.abc import Callable

import numpy as np

from fmu_models.errors import ConfigurationError, FMUError, UnknownNameError
from fmu_models.infra.checks import positive

from ..core.component import StopRequest

__all__ = ["SOLVERS", "ContinuousModel", "FMUModel", "MEIntegrator", "check_solver", "held_inputs"]

#: The Model Exchange solvers (see the module documentation).
SOLVERS = ("cvode", "euler", "rk4")
_DP = ctypes.POINTER(ctypes.c_double)


def check_solver(owner: str, solver: str, solver_step: float | None, rtol: float) -> tuple[str, float | None, float]:
    """``(solver, solver_step, rtol)`` of the component ``owner`` checked: ``solver`` one of
    :data:`SOLVERS`, ``solver_step`` [s] None or positive, ``rtol`` positive."""
    if solver not in SOLVERS:
        raise UnknownNameError(f"{owner}: solver must be one of {SOLVERS}, got {solver!r}")
    rtol = positive(rtol, f"{owner}: rtol")
    return solver, None if solver_step is None else positive(solver_step, f"{owner}: solver_step"), rtol


class ContinuousModel:
    """The interface :class:`MEIntegrator` integrates (see the module documentation).

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
        An input changed since the values the outputs are read from were brought up to
        date (:meth:`refresh`).
    """

    nx = 0
    nz = 0
    name = ""
    needs_completed_step = False
    stop_reason = "the FMU requested termination in its event update"
    dirty = False

    def refresh(self) -> None:
        """Bring the values the outputs are read from up to date (nothing to do for one FMU)."""

    def set_time(self, t: float) -> None:
        """Set the time [s]."""
        raise NotImplementedError

    def get_states(self, x: np.ndarray) -> None:
        """Write the continuous states into ``x`` (nx)."""
        raise NotImplementedError

    def set_states(self, x: np.ndarray) -> None:
        """Set the continuous states from ``x`` (nx)."""
        raise NotImplementedError

    def derivatives(self, dx: np.ndarray) -> None:
        """Write the state derivatives at the current time and states into ``dx`` (nx)."""
        raise NotImplementedError

    def indicators(self, z: np.ndarray) -> None:
        """Write the event indicators into ``z`` (nz)."""
        raise NotImplementedError

    def nominals(self, out: np.ndarray) -> None:
        """Write the states' nominal values into ``out`` (nx)."""
        out[:] = 1.0

    def completed_step(self) -> tuple[bool, bool]:
        """After an integrator step: ``(enter_event_mode, terminate)``."""
        return False, False

    def event(self, t: float, set_inputs: Callable[[], None] | None = None) -> tuple[bool, float | None]:
        """Event Mode at ``t`` [s]: ``set_inputs()`` (discrete inputs), the event iteration,
        Continuous-Time Mode. Returns ``(terminate, next event time or None)``."""
        raise NotImplementedError

    def initial_event(self, t: float) -> tuple[bool, float | None]:
        """After ``ExitInitializationMode`` (already in Event Mode): the event iteration and
        Continuous-Time Mode. Returns ``(terminate, next event time or None)``."""
        raise NotImplementedError


class FMUModel(ContinuousModel):
    """One Model Exchange FMU instance (after ``ExitInitializationMode``) as a
    :class:`ContinuousModel`: its states, derivatives, indicators and nominals are calls of
    the FMU's raw FMI functions, bound when it is made.

    Parameters
    ----------
    instance : FMUInstance
        The instance (:mod:`cosim.fmi.instance`).
    """

    def __init__(self, instance):
        md = instance.md
        self.inst, self.name = instance, instance.owner
        self.v3 = instance.version == 3
        self.nx = int(md.numberOfContinuousStates)
        self.nz = int(md.numberOfEventIndicators)
        self.needs_completed_step = bool(getattr(md.modelExchange, "needsCompletedIntegratorStep", True))
        p = "fmi3" if self.v3 else "fmi2"
        c, fail = ctypes.c_void_p(instance.handle), instance.fail

        def check(st, what):
            if st > 1:
                fail(what, st)

        def vector(function: str, n: int, what: str):
            """``function`` on an array of ``n`` values (nothing to do for none)."""
            fn, size = instance.raw(f"{p}{function}"), ctypes.c_size_t(n)
            return (lambda x: check(fn(c, x.ctypes.data_as(_DP), size), what)) if n else (lambda x: None)

        self.get_states = vector("GetContinuousStates", self.nx, "GetContinuousStates")
        self.set_states = vector("SetContinuousStates", self.nx, "SetContinuousStates")
        self.derivatives = vector("GetContinuousStateDerivatives" if self.v3 else "GetDerivatives", self.nx,
                                  "GetDerivatives")
        self.indicators = vector("GetEventIndicators", self.nz, "GetEventIndicators")
        self.nominals = vector("GetNominalsOfContinuousStates", self.nx, "GetNominalsOfContinuousStates")
        set_time, completed = instance.raw(f"{p}SetTime"), instance.raw(f"{p}CompletedIntegratorStep")
        self.set_time = lambda t: check(set_time(c, ctypes.c_double(t)), "SetTime")
        flag = ctypes.c_bool if self.v3 else ctypes.c_int
        self._enter, self._term = flag(0), flag(0)
        args = (c, 1, ctypes.byref(self._enter), ctypes.byref(self._term))
        self._completed = lambda: check(completed(*args), "CompletedIntegratorStep")

    def completed_step(self):
        """``CompletedIntegratorStep``: ``(enter_event_mode, terminate)``."""
        self._completed()
        return bool(self._enter.value), bool(self._term.value)

    def event(self, t, set_inputs=None):
        """Event Mode, ``set_inputs()``, the event iteration, Continuous-Time Mode."""
        self.inst.call("EnterEventMode", self.inst.fmu.enterEventMode)
        if set_inputs is not None:
            set_inputs()
        return self.initial_event(t)

    def initial_event(self, t):
        """The event iteration after initialisation, then Continuous-Time Mode."""
        terminate, nxt = self.iterate(t)
        if not terminate:
            self.inst.call("EnterContinuousTimeMode", self.inst.fmu.enterContinuousTimeMode)
        return terminate, nxt

    def iterate(self, t: float) -> tuple[bool, float | None]:
        """In Event Mode: update the discrete states until no more update is needed
        (at most 1000 rounds); returns ``(terminate, next event time or None)``."""
        fmu, inst = self.inst.fmu, self.inst
        update = fmu.updateDiscreteStates if self.v3 else fmu.newDiscreteStates
        name = "UpdateDiscreteStates" if self.v3 else "NewDiscreteStates"
        for _ in range(1000):
            need, term, _nominals, _values, defined, nxt = inst.call(name, update)
            if term:
                return True, None
            if not need:
                return False, (float(nxt) if defined else None)
        raise FMUError(f"{self.name}: the event iteration at t = {t:g} s did not converge in 1000 rounds")


class _Callbacks:
    """The functions fmpy's CVODE binding calls, for a :class:`ContinuousModel`; an exception
    inside one (a failing FMU call) is kept and raised after CVODE returns (a ctypes
    callback cannot raise)."""

    def __init__(self, model: ContinuousModel):
        self.m = model
        self.pending: BaseException | None = None
        n = max(model.nx, 1)
        self.x, self.dx = np.zeros(n), np.zeros(n)
        self.z = np.zeros(max(model.nz, 1))

    def _guard(self, fn):
        try:
            fn()
            return 0
        except BaseException as e:  # noqa: BLE001 - kept, raised after CVODE returns
            self.pending = e
            return -1

    def get_x(self, ptr, n):
        self.m.get_states(self.x)
        ctypes.memmove(ptr, self.x.ctypes.data, 8 * n)

    def set_x(self, ptr, n):
        ctypes.memmove(self.x.ctypes.data, ptr, 8 * n)
        self.m.set_states(self.x)

    def get_dx(self, ptr, n):
        self.m.derivatives(self.dx)
        ctypes.memmove(ptr, self.dx.ctypes.data, 8 * n)

    def get_z(self, ptr, n):
        self.m.indicators(self.z)
        ctypes.memmove(ptr, self.z.ctypes.data, 8 * n)

    def get_nominals(self, ptr, n):
        nom = np.ones(max(self.m.nx, 1))
        self.m.nominals(nom)
        ctypes.memmove(ptr, nom.ctypes.data, 8 * n)


class _NoInput:
    """fmpy's CVODE binding applies inputs at each root evaluation; the master holds ours."""

    @staticmethod
    def apply(t, **kw):
        return None


def _cvode(model: ContinuousModel, t0: float, max_step: float, rtol: float):
    """fmpy's CVodeSolver for ``model``, with its callbacks guarded (see :class:`_Callbacks`)."""
    from fmpy.sundials import NV_DATA_S, CVodeSolver

    cb = _Callbacks(model)

    class _Solver(CVodeSolver):
        def f(self, t, y, ydot, user_data):
            def run():
                model.set_time(t)
                if model.nx:
                    cb.set_x(NV_DATA_S(y), self.nx)
                    cb.get_dx(NV_DATA_S(ydot), self.nx)
                else:
                    np.ctypeslib.as_array(NV_DATA_S(ydot), (self.nx,))[:] = 0.0
            return cb._guard(run)

        def g(self, t, y, gout, user_data):
            def run():
                model.set_time(t)
                if model.nx:
                    cb.set_x(NV_DATA_S(y), self.nx)
                cb.get_z(gout, self.nz)
            return cb._guard(run)

    solver = _Solver(nx=model.nx, nz=model.nz, get_x=cb.get_x, set_x=cb.set_x, get_dx=cb.get_dx,
                     get_z=cb.get_z, get_nominals=cb.get_nominals, set_time=model.set_time, input=_NoInput(),
                     startTime=t0, maxStep=max_step, relativeTolerance=rtol, maxNumSteps=1_000_000)
    return solver, cb


class MEIntegrator:
    """Advance a :class:`.ContinuousModel` between communication points (see the module
    documentation).

    Parameters
    ----------
    model : ContinuousModel
    solver : {"cvode", "euler", "rk4"}
    solver_step : float, optional
        The fixed step [s] of Euler and RK4 (default: the communication step given to
        :meth:`advance`), or CVODE's largest step (default: none).
    rtol : float
        CVODE's relative tolerance.
    """

    #: Most integration steps plus events within one communication step.
    MAX_ROUNDS = 10_000_000

    def __init__(self, model: ContinuousModel, solver: str, solver_step: float | None, rtol: float):
        if solver not in SOLVERS:
            raise ConfigurationError(f"unknown solver {solver!r}; valid: {', '.join(SOLVERS)}")
        self.model, self.solver, self.h_int, self.rtol = model, solver, solver_step, rtol
        n = max(model.nx, 1)
        self.x, self.dx, self.scratch = np.zeros(n), np.zeros(n), np.zeros(n)
        self.z, self.z_new = np.zeros(max(model.nz, 1)), np.zeros(max(model.nz, 1))
        self.next_event: float | None = None
        self.cvode = None
        self._cb = None
        self.resets = 0
        self.t = float("nan")

    # ------------------------------------------------------------------ events
    def _after_event(self, t: float, terminate: bool, nxt: float | None) -> None:
        if terminate:
            raise StopRequest(self.model.name, t, self.model.stop_reason)
        self.next_event = nxt
        m = self.model
        m.get_states(self.x)
        m.indicators(self.z)
        self.reset(t)

    def start(self, t0: float) -> None:
        """After ``ExitInitializationMode`` (the model in Event Mode): the initial event
        iteration, Continuous-Time Mode, the solver created."""
        terminate, nxt = self.model.initial_event(t0)
        self.t = t0
        if self.solver == "cvode":
            self.cvode, self._cb = _cvode(self.model, t0, self.h_int or math.inf, self.rtol)
        self._after_event(t0, terminate, nxt)

    def reset(self, t: float) -> None:
        """Reinitialise the solver at ``t`` (after an event, or an input that changed)."""
        if self.cvode is not None:
            self.cvode.reset(t)
            self.resets += 1

    def at_event(self, t: float, set_inputs: Callable[[], None]) -> None:
        """An event at ``t`` [s] whose Event Mode sets discrete inputs (``set_inputs()``)."""
        terminate, nxt = self.model.event(t, set_inputs)
        self._after_event(t, terminate, nxt)

    # ------------------------------------------------------------------ stepping
    def _fixed_step(self, t: float, h: float) -> None:
        """One Euler or RK4 step of length h from (t, self.x); leaves the model at t + h."""
        m, x, dx, s = self.model, self.x, self.dx, self.scratch
        m.derivatives(dx)
        if self.solver == "euler":
            x += h * dx
        else:
            k1 = dx.copy()
            s[:] = x + h / 2 * k1
            m.set_time(t + h / 2)
            m.set_states(s)
            m.derivatives(dx)
            k2 = dx.copy()
            s[:] = x + h / 2 * k2
            m.set_states(s)
            m.derivatives(dx)
            k3 = dx.copy()
            s[:] = x + h * k3
            m.set_time(t + h)
            m.set_states(s)
            m.derivatives(dx)
            x += h / 6 * (k1 + 2 * k2 + 2 * k3 + dx)
        m.set_time(t + h)
        m.set_states(x)

    def _cvode_step(self, t: float, t_next: float) -> tuple[float, bool]:
        cb = self._cb
        try:
            root, _, t_reached = self.cvode.step(t, t_next)
        except RuntimeError as e:
            if cb.pending is not None:
                err, cb.pending = cb.pending, None
                raise err from None
            raise FMUError(f"{self.model.name}: CVODE failed between t = {t:g} s and {t_next:g} s: {e}") from None
        if cb.pending is not None:
            err, cb.pending = cb.pending, None
            raise err
        m = self.model
        m.set_time(t_reached)
        m.get_states(self.x)
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
                terminate, nxt = m.event(t_next)
                self._after_event(t_next, terminate, nxt)
            t = t_next
        self.t = t_end


def held_inputs(me: MEIntegrator, h: float, setters: tuple[list, list], feedthrough: tuple[list, list],
                getters: list) -> tuple[Callable[[float], None], Callable[[float], None]]:
    """The output and update functions of the model ``me`` integrates, its inputs held over
    each communication step: continuous inputs set in Continuous-Time Mode (the solver
    reinitialised where one jumped), discrete ones only in Event Mode (an event at the
    communication point where one changed).

    Parameters
    ----------
    me : MEIntegrator
    h : float
        The communication step [s]: the update advances over ``[t, t + h]``.
    setters : (list, list)
        The calls that set the continuous and the discrete inputs (each returns whether a
        value changed; its ``differs()`` whether one would).
    feedthrough : (list, list)
        The same for the inputs that feed through, set at ``t`` before the outputs are read.
    getters : list
        The calls that read the outputs.
    """
    model = me.model
    pending = [False]                        # a continuous input jumped since the last advance

    def apply(calls) -> bool:
        changed = False
        for s in calls:
            changed |= bool(s())
        return changed

    def set_inputs(t: float, cont: list, disc: list) -> None:
        if cont and apply(cont):
            pending[0] = True
            model.dirty = True
        if disc and any(s.differs() for s in disc):
            me.at_event(t, lambda: apply(disc))

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

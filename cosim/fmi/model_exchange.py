"""Integrating a Model Exchange FMU between communication points, with its events.

The master holds the FMU's inputs constant over ``[t, t + h]`` (as for Co-Simulation) and
:class:`MEIntegrator` advances the FMU's continuous states over that interval with one of
three solvers:

* ``"euler"``: explicit Euler with step ``solver_step`` (a last partial step ends on the
  communication point);
* ``"rk4"``: classical Runge-Kutta, same stepping;
* ``"cvode"``: SUNDIALS CVODE (BDF, variable step, relative tolerance ``rtol``) through
  fmpy's binding, with root finding on the event indicators.

Events: time events (``nextEventTime``) end an integration step exactly; step events
(``completedIntegratorStep``) and state events (a sign change of an event indicator)
trigger the FMI event iteration (``enterEventMode``, ``newDiscreteStates`` /
``updateDiscreteStates`` until done, ``enterContinuousTimeMode``). CVODE locates state
events by root finding; the fixed-step solvers handle a state event at the end of the
step in which the sign changed (no localisation, documented). An FMU that requests
termination raises :class:`~fmu_models.errors.FMUError`.
"""
from __future__ import annotations

import ctypes

import numpy as np

from fmu_models.errors import ConfigurationError, FMUError

from .exchange import raw_function

__all__ = ["SOLVERS", "MEIntegrator"]

SOLVERS = ("cvode", "euler", "rk4")


class _NoInput:
    """fmpy's CVodeSolver re-applies inputs at each root evaluation; ours are held."""

    @staticmethod
    def apply(t, **kw):
        return None


class MEIntegrator:
    """Advance an instantiated, initialised Model Exchange FMU.

    Parameters
    ----------
    fmu : fmpy FMU2Model or FMU3Model
        The instance (after ``exitInitializationMode``).
    md : fmpy ModelDescription
    solver : {"cvode", "euler", "rk4"}
    solver_step : float
        Step [s] of the fixed-step solvers; the largest step of CVODE.
    rtol : float
        Relative tolerance of CVODE.
    fail : callable
        ``fail(what, status)`` raises the component's FMUError.
    """

    #: Most integration steps plus events within one communication step.
    MAX_ROUNDS = 10_000_000

    def __init__(self, fmu, md, solver: str, solver_step: float, rtol: float, fail):
        if solver not in SOLVERS:
            raise ConfigurationError(f"unknown solver {solver!r}; valid: {', '.join(SOLVERS)}")
        self.fmu, self.md, self.solver, self.h_int, self.rtol = fmu, md, solver, solver_step, rtol
        self.v3 = md.fmiVersion.startswith("3")
        self.nx, self.nz = md.numberOfContinuousStates, md.numberOfEventIndicators
        self.needs_completed = bool(getattr(md.modelExchange, "needsCompletedIntegratorStep", True))
        self._fail = fail
        p = "fmi3" if self.v3 else "fmi2"
        dll, c = fmu.dll, ctypes.c_void_p(fmu.component)
        self._c = c
        n = max(self.nx, 1)
        self.x, self.dx = np.zeros(n), np.zeros(n)
        self.z, self.z_new = np.zeros(max(self.nz, 1)), np.zeros(max(self.nz, 1))
        D, ptr = ctypes.c_double, lambda a: a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
        nxs, nzs = ctypes.c_size_t(self.nx), ctypes.c_size_t(self.nz)
        set_time = raw_function(dll, f"{p}SetTime")
        set_x = raw_function(dll, f"{p}SetContinuousStates")
        get_dx = raw_function(dll, f"{p}GetContinuousStateDerivatives" if self.v3 else f"{p}GetDerivatives")
        get_z = raw_function(dll, f"{p}GetEventIndicators")
        get_x = raw_function(dll, f"{p}GetContinuousStates")
        completed = raw_function(dll, f"{p}CompletedIntegratorStep")
        flag_t = ctypes.c_bool if self.v3 else ctypes.c_int
        self._enter, self._term = flag_t(0), flag_t(0)
        self._scratch = np.zeros(n)
        xp, dxp, sp = ptr(self.x), ptr(self.dx), ptr(self._scratch)

        def check(st, what):
            if st > 1:
                fail(what, st)

        self.set_time = lambda t: check(set_time(c, D(t)), "SetTime")
        self.set_x = lambda: check(set_x(c, xp, nxs), "SetContinuousStates") if self.nx else None
        self.set_scratch = lambda: check(set_x(c, sp, nxs), "SetContinuousStates") if self.nx else None
        self.get_x = lambda: check(get_x(c, xp, nxs), "GetContinuousStates") if self.nx else None
        self.get_dx = lambda: check(get_dx(c, dxp, nxs), "GetDerivatives") if self.nx else None
        self._zp = {id(a): ptr(a) for a in (self.z, self.z_new)}
        self.get_z = lambda a: check(get_z(c, self._zp[id(a)], nzs), "GetEventIndicators") if self.nz else None
        enter, term = ctypes.byref(self._enter), ctypes.byref(self._term)
        self.completed = lambda: check(completed(c, 1, enter, term), "CompletedIntegratorStep")
        self.next_event = None
        self.cvode = None

    # ------------------------------------------------------------------ events
    def event_iteration(self, t: float) -> None:
        """In event mode: iterate the discrete states, then enter continuous-time mode."""
        fmu = self.fmu
        for _ in range(1000):
            if self.v3:
                need, term, _, _changed, defined, nxt = fmu.updateDiscreteStates()
            else:
                need, term, _, _changed, defined, nxt = fmu.newDiscreteStates()
            if term:
                raise FMUError(f"the FMU requested termination at t = {t:g} s")
            if not need:
                break
        else:
            raise FMUError(f"the FMU's event iteration at t = {t:g} s did not converge in 1000 rounds")
        self.next_event = nxt if defined else None
        fmu.enterContinuousTimeMode()
        self.get_x()
        self.get_z(self.z)
        if self.cvode is not None:
            self.cvode.reset(t)

    def start(self, t0: float) -> None:
        """After ``exitInitializationMode``: the initial event iteration."""
        self.event_iteration(t0)
        if self.solver == "cvode":
            from fmpy.sundials import CVodeSolver

            fmu = self.fmu
            self.cvode = CVodeSolver(
                nx=self.nx, nz=self.nz, get_x=fmu.getContinuousStates, set_x=fmu.setContinuousStates,
                get_dx=fmu.getContinuousStateDerivatives if self.v3 else fmu.getDerivatives,
                get_z=fmu.getEventIndicators, get_nominals=fmu.getNominalsOfContinuousStates,
                set_time=fmu.setTime, input=_NoInput(), startTime=t0, maxStep=self.h_int,
                relativeTolerance=self.rtol, maxNumSteps=100000)

    def _event(self, t: float) -> None:
        self.fmu.enterEventMode()
        self.event_iteration(t)

    # ------------------------------------------------------------------ stepping
    def _fixed_step(self, t: float, h: float) -> None:
        """One Euler or RK4 step of length h from (t, self.x); leaves the FMU at t + h."""
        x, dx, s = self.x, self.dx, self._scratch
        self.get_dx()
        if self.solver == "euler":
            x += h * dx
        else:
            k1 = dx.copy()
            s[:] = x + h / 2 * k1
            self.set_time(t + h / 2)
            self.set_scratch()
            self.get_dx()
            k2 = dx.copy()
            s[:] = x + h / 2 * k2
            self.set_scratch()
            self.get_dx()
            k3 = dx.copy()
            s[:] = x + h * k3
            self.set_time(t + h)
            self.set_scratch()
            self.get_dx()
            x += h / 6 * (k1 + 2 * k2 + 2 * k3 + dx)
        self.set_time(t + h)
        self.set_x()

    def advance(self, t: float, h: float) -> None:
        """Integrate from ``t`` to ``t + h`` [s] with the inputs held, handling events."""
        t_end = t + h
        tiny = 1e-12 * max(1.0, abs(t_end))
        rounds = 0
        if self.cvode is not None:
            # the inputs may have jumped at t: CVODE's multistep history must not span it
            self.cvode.reset(t)
        while t < t_end - tiny:
            rounds += 1
            if rounds > self.MAX_ROUNDS:
                raise FMUError(f"more than {self.MAX_ROUNDS} integration steps or events between "
                               f"t = {t_end - h:g} s and {t_end:g} s (chattering events?)")
            t_next = min(t_end, t + self.h_int) if self.cvode is None else t_end
            if t_end - t_next < tiny:
                t_next = t_end
            time_event = self.next_event is not None and self.next_event <= t_next + tiny
            if time_event:
                t_next = max(self.next_event, t)
            if self.cvode is not None:
                state_event, _, t_reached = self.cvode.step(t, t_next)
                if state_event:
                    t_next, time_event = t_reached, False
                self.set_time(t_next)
                self.get_x()
            else:
                if t_next > t:
                    self._fixed_step(t, t_next - t)
                state_event = False
                if self.nz:
                    self.get_z(self.z_new)
                    state_event = bool(np.any(np.sign(self.z_new) != np.sign(self.z)))
                    self.z[:] = self.z_new
            step_event = False
            if self.needs_completed:
                self.completed()
                if self._term.value:
                    raise FMUError(f"the FMU requested termination at t = {t_next:g} s")
                step_event = bool(self._enter.value)
            if time_event or state_event or step_event:
                self._event(t_next)
            t = t_next

"""One FMU instance (FMI 1.0, 2.0, 3.0) and the standard's rules of its life (the co-simulation page of
the documentation: the FMI call sequence); a failure is an :class:`~fmu_models.errors.FMUError`
naming the component, the call, the status and the FMU's last messages."""
from __future__ import annotations

import ctypes
import functools
import logging
import os
import time
from collections import deque

from fmu_models.errors import FMUError

from ..core import crash_guard
from .exchange import Exchange, raw_function

__all__ = ["STATUS", "FMUInstance", "unload_library"]

LOGGER = logging.getLogger("cosim.fmu")
_LEVELS = {0: logging.INFO, 1: logging.WARNING, 2: logging.WARNING, 3: logging.ERROR, 4: logging.CRITICAL}
#: FMI status codes by name.
STATUS = {0: "ok", 1: "warning", 2: "discard", 3: "error", 4: "fatal", 5: "pending"}
_ERROR, _FATAL, _PENDING = 3, 4, 5
#: FMI 1.0 and 2.0 loggers by instance key: fmpy's addLoggerProxy (one callback) formats a
#: printf-style message, this table sends it to its instance: FMI 2.0 by its
#: componentEnvironment (an int), FMI 1.0 (no environment) by its instance name (bytes; of
#: two live instances of one name, the newer).
_LOGS: dict[int | bytes, object] = {}
_KEYS = iter(range(1, 2**62))


@functools.cache
def _shared_logger():
    """The ctypes logger every FMI 1.0 and 2.0 instance shares (created once, kept alive)."""
    from fmpy import fmi2

    def dispatch(env, inst, status, category, message):
        log = _LOGS.get(env or 0) or _LOGS.get(inst)
        if log is not None:
            log(status, message)

    return fmi2.fmi2CallbackLoggerTYPE(dispatch)


class _Symbols:
    """An FMI 1.0 library's functions by fmpy's names (``fmi1DoStep``: ``<modelIdentifier>_fmiDoStep``)."""

    def __init__(self, dll, identifier: str):
        self._dll, self._prefix = dll, f"{identifier}_fmi"

    def __getattr__(self, name: str):
        if not name.startswith("fmi1"):
            raise AttributeError(name)
        return getattr(self._dll, self._prefix + name[4:])


def unload_library(fmu) -> None:
    """Unload the library of the fmpy FMU object ``fmu`` (its instance freed) and forget it in the crash guard."""
    try:
        fmu.freeLibrary()
    except Exception:
        LOGGER.debug("freeLibrary failed", exc_info=True)
    crash_guard.forget_library(getattr(fmu, "pendulum_guard_entry", -1))


class FMUInstance:
    """An instantiated FMU (see the FMI call sequence on the co-simulation page of the documentation).

    Parameters
    ----------
    owner : str
        The component's name (the instance name and the messages').
    description : FMUDescription
        The FMU's description (:mod:`cosim.fmi.description`).
    directory : str
        Where the FMU is unpacked.
    interface : {"cs", "me", "se"}
        The interface (FMI 1.0: the FMU's one).
    logging_on : bool
        Ask the FMU for debug messages and log them at INFO level (warnings and errors always
        are, on the ``cosim.fmu`` logger).
    event_mode : bool
        FMI 3.0 Co-Simulation: instantiate with ``eventModeUsed`` (what clocks need).
    early_return : bool
        FMI 3.0 Co-Simulation: instantiate with ``earlyReturnAllowed``.
    clock_update : callable, optional
        Scheduled Execution: the ``clockUpdate`` callback (it must not raise).
    library : fmpy FMU object, optional
        The library of an earlier, freed instance of the same FMU and interface
        (``keep_library``), instantiated again without loading it again.

    Attributes
    ----------
    fmu : fmpy FMU object (``FMU2Slave``, ``FMU3Model``, ...)
    dll : ctypes.CDLL
        The library (FMI 1.0: its functions by fmpy's names, ``fmi1DoStep``).
    handle : int
        The instance pointer.
    initial_events : tuple of (bool, float or None)
        FMI 1.0 Model Exchange: what ``fmiInitialize`` said (terminate, the next time event).
    worst : int
        The worst status a call returned (0 ok ... 4 fatal).
    initialized : bool
        Initialisation mode was left.
    messages : collections.deque of (int, str)
        The last 200 log messages (status, text).
    keep_library : bool
        Free only the instance at the end, not the library (its owner reuses or frees it).
    """

    def __init__(self, owner: str, description, directory: str, interface: str, logging_on: bool = False, *,
                 event_mode: bool = False, early_return: bool = False, clock_update=None, library=None):
        self.owner, self.md, self.interface, self.description = owner, description.md, interface, description
        self.version, self.prefix = description.version, description.prefix
        self.initial_events: tuple[bool, float | None] = (False, None)
        self.messages: deque = deque(maxlen=200)
        self.worst, self.initialized, self.logging_on = 0, False, bool(logging_on)
        self._guard_entry = -1
        self._freed = self.keep_library = False
        self.fmu = None
        ident = self._identifier = description.interfaces[interface].modelIdentifier
        args = dict(guid=self.md.guid, unzipDirectory=directory, modelIdentifier=ident, instanceName=owner)
        cwd = os.getcwd()
        try:
            if self.version < 3:
                self._instantiate12(args, library)
            else:
                self._instantiate3(args, directory, event_mode, early_return, clock_update, library)
        except Exception as e:  # noqa: BLE001 - ctypes, fmpy and OSError: all become one FMUError
            self._forget_log()
            if getattr(self.fmu, "dll", None) is not None:      # a reused library too: not again
                unload_library(self.fmu)
            else:
                crash_guard.forget_library(self._guard_entry)
            raise FMUError(f"{owner}: cannot load or instantiate {ident}: {e}" + self._last(" (", ")")) from None
        finally:
            if os.getcwd() != cwd:              # fmpy changes directory to load the library
                os.chdir(cwd)
        fmu = self.fmu
        if not fmu.component:
            self._forget_log()
            unload_library(fmu)
            what = {"cs": "Slave", "me": "Model"}[interface] if self.version == 1 else ""
            raise FMUError(f"{owner}: {self.prefix}Instantiate{what} returned no instance" + self._last(" (", ")"))
        self.dll, self.handle = (_Symbols(fmu.dll, ident) if self.version == 1 else fmu.dll), fmu.component
        if self.logging_on:
            try:
                fmu.setDebugLogging(*((True,) if self.version == 1 else (True, [])))
            except Exception:  # noqa: BLE001 - optional: an FMU may refuse debug logging
                LOGGER.debug("%s: setDebugLogging refused", owner)

    def _instantiate12(self, args: dict, library) -> None:
        """FMI 1.0 and 2.0: instantiate with the shared logger (FMI 1.0: no ``stepFinished``)."""
        from fmpy import fmi1, fmi2
        from fmpy.logging import addLoggerProxy

        fmi, p = (fmi1, "fmi1") if self.version == 1 else (fmi2, "fmi2")
        kind = getattr(fmi, f"FMU{self.version}{'Slave' if self.interface == 'cs' else 'Model'}")
        fmu = self._guarded(library or kind(**args))
        self._log_key = self.owner.encode() if self.version == 1 else next(_KEYS)
        _LOGS[self._log_key] = self._logger = self._log
        cb = getattr(fmi, f"{p}CallbackFunctions")()
        cb.logger = _shared_logger()
        cb.allocateMemory = getattr(fmi, f"{p}CallbackAllocateMemoryTYPE")(fmi1.calloc)
        cb.freeMemory = getattr(fmi, f"{p}CallbackFreeMemoryTYPE")(fmi1.free)
        if self.version == 2:
            cb.componentEnvironment = self._log_key
        addLoggerProxy(ctypes.byref(cb))     # printf-style messages formatted with their arguments
        self._callbacks = cb
        fmu.instantiate(**{"functions" if self.version == 1 else "callbacks": cb}, loggingOn=self.logging_on)

    def _instantiate3(self, args: dict, directory: str, event_mode: bool, early_return: bool, clock_update,
                      library) -> None:
        """FMI 3.0: instantiate with this instance's logger always on (an FMU logs even its errors
        only with loggingOn); Scheduled Execution with ``clockUpdate`` (fmpy's passes a no-op) and
        no-op preemption locks (partitions run one after the other here)."""
        from fmpy import fmi3

        def log3(env, status, category, message):
            self._log(status, message)

        def noop(*args):
            return None

        if self.interface == "cs":
            self._guarded(library or fmi3.FMU3Slave(**args)).instantiate(
                loggingOn=True, logMessage=log3, eventModeUsed=bool(event_mode), earlyReturnAllowed=bool(early_return))
        elif self.interface == "me":
            self._guarded(fmi3.FMU3Model(**args)).instantiate(loggingOn=True, logMessage=log3)
        else:
            fmu = self._guarded(fmi3.FMU3ScheduledExecution(**args))
            fmu.logMessage = fmi3.fmi3LogMessageCallback(log3)
            fmu.clockUpdate = fmi3.fmi3ClockUpdateCallback(clock_update or noop)
            fmu.lockPreemption = fmi3.fmi3LockPreemptionCallback(noop)
            fmu.unlockPreemption = fmi3.fmi3UnlockPreemptionCallback(noop)
            resources = os.path.join(directory, "resources") + os.path.sep
            fmu.component = fmu.fmi3InstantiateScheduledExecution(
                fmu.instanceName.encode("utf-8"), fmu.guid.encode("utf-8"), resources.encode("utf-8"), fmi3.fmi3False,
                fmi3.fmi3Boolean(True), fmi3.fmi3InstanceEnvironment(), fmu.logMessage, fmu.clockUpdate,
                fmu.lockPreemption, fmu.unlockPreemption)

    def _guarded(self, fmu):
        """``fmu`` registered with the crash guard (:mod:`cosim.core.crash_guard`): its crash names this component."""
        name = f"{self._identifier}_fmiGetVersion" if self.version == 1 else f"fmi{self.version}GetVersion"
        version = getattr(fmu.dll, name, None)
        address = ctypes.cast(version, ctypes.c_void_p).value if version is not None else None
        self._guard_entry = crash_guard.register_library(address, self.owner)
        fmu.pendulum_guard_entry = self._guard_entry       # forgotten when its library is unloaded
        self.fmu = fmu
        return fmu

    # ------------------------------------------------------------------ status
    def _log(self, status, message) -> None:
        text = message.decode(errors="replace") if isinstance(message, bytes) else str(message)
        self.messages.append((int(status), text))
        if status >= 1 or self.logging_on:
            LOGGER.log(_LEVELS.get(int(status), logging.ERROR), "[%s] %s", self.owner, text)

    def _last(self, before: str = "", after: str = "", n: int = 3) -> str:
        log = "; ".join(m for s, m in list(self.messages)[-n:])
        return f"{before}{log}{after}" if log else ""

    def fail(self, what: str, status: int):
        """Remember ``status`` and raise the FMUError of the call ``what`` (the FMI function's
        name without its prefix, e.g. ``"DoStep(t = 1 s, h = 0.1 s)"``)."""
        status = int(status)
        self.worst = max(self.worst, status)
        label = STATUS.get(status, f"status {status}")
        raise FMUError(f"{self.owner}: {self.prefix}{what} returned {label}: "
                       + (self._last() or "no message from the FMU"))

    def call(self, what: str, fn, *args):
        """``fn(*args)`` (an fmpy method), its failure an FMUError naming ``what``."""
        from fmpy.fmi1 import FMICallException

        try:
            return fn(*args)
        except FMICallException as e:
            self.fail(what, e.status)

    def raw(self, name: str):
        """A fresh pointer to the FMI function ``name`` (no argtypes; see :func:`raw_function`)."""
        return raw_function(self.dll, name)

    def exchange(self, ports, direction: str, sources=None) -> Exchange:
        """The :class:`~cosim.fmi.exchange.Exchange` of ``ports`` in ``direction`` with this instance."""
        return Exchange(self, ports, direction, sources)

    # ------------------------------------------------------------------ initialisation
    def setup(self, t0: float) -> None:
        """Before the parameters and start values are set: FMI 2.0 ``SetupExperiment`` at
        ``t0`` [s] (no tolerance, no stop time), FMI 1.0 Model Exchange ``fmiSetTime(t0)``."""
        if self.version == 2:
            self.call("SetupExperiment", self.fmu.setupExperiment, None, t0)
        elif self.version == 1 and self.interface == "me":
            self.call("SetTime", self.fmu.setTime, t0)

    def enter_initialization(self, t0: float) -> None:
        """After the parameters and start values: ``EnterInitializationMode`` (FMI 3.0 at ``t0``
        [s]); FMI 1.0 initialises at once: ``fmiInitializeSlave(t0, no stop time)`` or
        ``fmiInitialize`` (no tolerance control; its event information in ``initial_events``)."""
        fmu = self.fmu
        if self.version > 1:
            args = (None, t0) if self.version == 3 else ()      # FMI 3.0: no tolerance, at t0
            self.call("EnterInitializationMode", fmu.enterInitializationMode, *args)
        elif self.interface == "cs":        # fmpy's wrapper reads the status as a string: the raw call
            st = self.raw("fmi1InitializeSlave")(ctypes.c_void_p(self.handle), ctypes.c_double(t0), ctypes.c_char(0),
                                                 ctypes.c_double(0.0))
            if st > 1:
                self.fail(f"InitializeSlave(t = {t0:g} s)", st)
        else:
            _, _, _, terminate, defined, nxt = self.call("Initialize", fmu.initialize)
            self.initial_events = (bool(terminate), float(nxt) if defined else None)

    def exit_initialization(self) -> None:
        """``ExitInitializationMode`` (nothing to do in FMI 1.0)."""
        if self.version > 1:
            self.call("ExitInitializationMode", self.fmu.exitInitializationMode)

    # ------------------------------------------------------------------ FMI 1.0 steps
    def step_failed(self, status: int, t: float, h: float) -> None:
        """After an FMI 1.0 ``fmiDoStep(t, h)`` [s] returned ``status`` above Warning: Pending
        waited for with ``fmiGetStatus(fmiDoStepStatus)`` (returns if the step then ended well;
        Ctrl-C, or no ``canRunAsynchronuously``, cancels it), else the FMUError (a Discard names
        ``fmiLastSuccessfulTime``)."""
        what = f"DoStep(t = {t:g} s, h = {h:g} s)"
        if status == _PENDING:
            if not self.description.asynchronous:
                self._cancel_step()
                raise FMUError(f"{self.owner}: {self.prefix}{what} returned pending, but {self.description.path.name} "
                               "does not declare canRunAsynchronuously (FMI 1.0): the step was cancelled "
                               "(fmiCancelStep)")
            get_status = self.raw("fmi1GetStatus")
            c, value, delay = ctypes.c_void_p(self.handle), ctypes.c_int(0), 1e-4
            try:
                while status == _PENDING:
                    st = get_status(c, 0, ctypes.byref(value))          # fmiDoStepStatus
                    if st > 1:
                        self.fail("GetStatus(fmiDoStepStatus)", st)
                    status = value.value
                    if status == _PENDING:
                        time.sleep(delay)
                        delay = min(2 * delay, 0.05)
            except KeyboardInterrupt:
                self._cancel_step()
                raise
            if status <= 1:
                return
        if status == 2:
            last = ctypes.c_double(float("nan"))
            st = self.raw("fmi1GetRealStatus")(ctypes.c_void_p(self.handle), 2, ctypes.byref(last))   # LastSuccessful
            known = f"; it computed up to t = {last.value:g} s (fmiLastSuccessfulTime)" if st <= 1 else ""
            what = f"DoStep(t = {t:g} s, h = {h:g} s{known}; FMI 1.0 has no stop request)"
        self.fail(what, status)

    def _cancel_step(self) -> None:
        """``fmiCancelStep`` (then only ``fmiFreeSlaveInstance``: the instance counts as failed)."""
        self.worst = max(self.worst, _ERROR)
        self.raw("fmi1CancelStep")(ctypes.c_void_p(self.handle))

    # ------------------------------------------------------------------ stop requests
    def discard_reason(self) -> float | None:
        """After an FMI 2.0 ``DoStep`` returned Discard: ``fmi2LastSuccessfulTime`` if ``fmi2Terminated``, or None."""
        from fmpy.fmi2 import fmi2LastSuccessfulTime, fmi2Terminated

        try:
            terminated = self.fmu.getBooleanStatus(fmi2Terminated)
        except Exception:  # noqa: BLE001 - an FMU may not implement the status functions
            return None
        if not terminated:
            return None
        try:
            return float(self.fmu.getRealStatus(fmi2LastSuccessfulTime))
        except Exception:  # noqa: BLE001
            return float("nan")

    # ------------------------------------------------------------------ the end
    def finish(self) -> None:
        """End the instance as the standard allows (the FMI call sequence on the co-simulation
        page of the documentation); safe twice."""
        if self._freed:
            return
        self._freed = True
        try:
            if self.worst >= _FATAL:
                LOGGER.debug("%s: fatal: the instance is abandoned (no further FMI call)", self.owner)
                return
            if self.worst < _ERROR and self.initialized:
                try:
                    self.fmu.terminate()
                except Exception:  # noqa: BLE001 - a refusal changes nothing: free it anyway
                    LOGGER.debug("%s: terminate refused", self.owner)
            try:
                if self.keep_library:       # fmpy's freeInstance would unload the library too
                    free = {1: "fmi1FreeSlaveInstance", 2: "fmi2FreeInstance", 3: "fmi3FreeInstance"}[self.version]
                    getattr(self.fmu, free)(self.fmu.component)
                else:
                    self.fmu.freeInstance()
            except Exception:  # noqa: BLE001
                LOGGER.debug("%s: freeInstance failed", self.owner)
            if not self.keep_library:
                crash_guard.forget_library(self._guard_entry)
        finally:
            self._forget_log()

    def _forget_log(self) -> None:
        """No more messages to this instance (an FMI 1.0 name now used by a newer one stays)."""
        key = getattr(self, "_log_key", 0)
        if _LOGS.get(key) is getattr(self, "_logger", None):
            _LOGS.pop(key, None)

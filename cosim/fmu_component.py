"""An FMI 2.0 or 3.0 Co-Simulation FMU as a co-simulation component (through fmpy)."""
from __future__ import annotations

import ctypes
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException, calloc, free

from .component import check_name, check_period

REAL_TYPES = ("Real", "Float64", "Float32")


class FMUError(RuntimeError):
    """An FMU call returned discard, error or fatal; the message holds the FMU's log."""


class FMUComponent:
    """A Co-Simulation FMU stepped by the master.

    Parameters
    ----------
    name : str
        Component name.
    path : str or Path
        The ``.fmu`` file (FMI 2.0 or 3.0 with a Co-Simulation interface).
    period : float
        Communication step [s].
    inputs : sequence of str, optional
        FMU variables (causality input) offered as input ports; default: all Real inputs.
        Unconnected ones keep their start values. A non-Real variable is refused.
    outputs : sequence of str, optional
        FMU variables offered as output ports; default: all Real outputs. Local variables
        such as ``der(alpha_dot)`` may be listed too (an accelerometer needs them).
    parameters : mapping, optional
        Parameter values by name, set before initialisation.
    start : mapping, optional
        Start values by name (e.g. initial states), set before initialisation.

    Attributes
    ----------
    kind : str
        ``"fmu"``.
    messages : list of (int, str)
        Log messages the FMU sent (status, text).
    """

    kind = "fmu"

    def __init__(self, name: str, path, period: float, inputs: Sequence[str] | None = None,
                 outputs: Sequence[str] | None = None, parameters: Mapping[str, float] | None = None,
                 start: Mapping[str, float] | None = None):
        self.name = check_name(name)
        self.period = check_period(period, name)
        self.path = Path(path)
        if not self.path.is_file():
            raise FileNotFoundError(f"{name}: no FMU file at {self.path}")
        md = read_model_description(str(self.path))
        if md.coSimulation is None:
            raise ValueError(f"{name}: {self.path.name} has no Co-Simulation interface")
        self.md, self.version = md, 3 if md.fmiVersion.startswith("3") else 2
        self.variables = {v.name: v for v in md.modelVariables}
        all_in = [v.name for v in md.modelVariables if v.causality == "input"]
        all_out = [v.name for v in md.modelVariables if v.causality == "output"]
        # local variables (e.g. der(x)) may be read as outputs when asked for by name
        readable = all_out + [v.name for v in md.modelVariables if v.causality == "local"]
        real = lambda names: [n for n in names if self.variables[n].type in REAL_TYPES]  # noqa: E731
        self.input_names = self._ports(real(all_in) if inputs is None else inputs, all_in, "input")
        self.output_names = self._ports(real(all_out) if outputs is None else outputs, readable, "output")
        self.settings = {}
        for kind, values in (("parameter", parameters or {}), ("start", start or {})):
            for key, val in values.items():
                if key not in self.variables:
                    raise KeyError(f"{name}: FMU {md.modelName} has no variable {key!r} "
                                   f"(for {kind}); valid names: {', '.join(self.variables)}")
                self.settings[key] = val
        self.fmu = None
        self.messages: list[tuple[int, str]] = []
        self._unzipped = None
        self.connected_inputs = list(self.input_names)

    def use_inputs(self, names: Sequence[str]) -> None:
        """Set, at each step, only these input ports (the connected ones); the others keep
        their start values. Called by the master."""
        unknown = [n for n in names if n not in self.input_names]
        if unknown:
            raise KeyError(f"{self.name}: not input ports: {unknown}")
        self.connected_inputs = list(names)

    def _ports(self, chosen, available, what):
        for p in chosen:
            if p not in available:
                raise KeyError(f"{self.name}: {p!r} is not an FMU {what}; valid {what}s: "
                               f"{', '.join(available)}")
            if self.variables[p].type not in REAL_TYPES:
                raise TypeError(f"{self.name}: {what} {p!r} is of type {self.variables[p].type}; "
                                "only Real/Float64 ports can be connected")
        return list(chosen)

    def __repr__(self):
        return f"FMUComponent({self.name!r}, {self.path.name}, FMI {self.version}.0, period={self.period})"

    # ---------------------------------------------------------------- lifecycle
    def _instantiate(self):
        if self._unzipped is None:
            self._unzipped = extract(str(self.path))
        args = dict(guid=self.md.guid, unzipDirectory=self._unzipped,
                    modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=self.name)
        if self.version == 2:
            from fmpy import fmi2
            self.fmu = fmi2.FMU2Slave(**args)

            def logger(env, inst, status, category, message):
                self.messages.append((status, message.decode(errors="replace")))

            cb = fmi2.fmi2CallbackFunctions()
            cb.logger = fmi2.fmi2CallbackLoggerTYPE(logger)
            cb.allocateMemory = fmi2.fmi2CallbackAllocateMemoryTYPE(calloc)
            cb.freeMemory = fmi2.fmi2CallbackFreeMemoryTYPE(free)
            self._callbacks = cb
            self.fmu.instantiate(callbacks=cb)
        else:
            from fmpy import fmi3
            self.fmu = fmi3.FMU3Slave(**args)

            def log3(env, status, category, message):
                self.messages.append((status, message.decode(errors="replace")))

            self.fmu.instantiate(logMessage=log3)

    def _set(self, name, value):
        v = self.variables[name]
        vr = [v.valueReference]
        if v.type in REAL_TYPES:
            (self.fmu.setReal if self.version == 2 else self.fmu.setFloat64)(vr, [float(value)])
        elif v.type == "Boolean":
            self.fmu.setBoolean(vr, [bool(value)])
        elif self.version == 2:
            self.fmu.setInteger(vr, [int(value)])
        else:
            {"Int32": self.fmu.setInt32, "Int64": self.fmu.setInt64,
             "Enumeration": self.fmu.setInt64}.get(v.type, self.fmu.setInt32)(vr, [int(value)])

    def _bind_calls(self):
        """Preallocated ctypes buffers and a stepping closure over the raw FMI functions.

        The functions are fresh pointers from the library with no ``argtypes`` (ctypes'
        per-call argument conversion costs 1.5 us a call); every argument is prebuilt.
        """
        n_in, n_out = len(self.connected_inputs), len(self.output_names)
        vr_t = ctypes.c_uint32
        in_vr = (vr_t * max(n_in, 1))(*[self.variables[p].valueReference for p in self.connected_inputs])
        out_vr = (vr_t * max(n_out, 1))(*[self.variables[p].valueReference for p in self.output_names])
        in_buf, out_buf = (ctypes.c_double * max(n_in, 1))(), (ctypes.c_double * max(n_out, 1))()
        self.in_view = np.ctypeslib.as_array(in_buf)[:n_in]
        self.out_view = np.ctypeslib.as_array(out_buf)[:n_out]
        self._keep = (in_vr, out_vr, in_buf, out_buf)
        dll, c = self.fmu.dll, ctypes.c_void_p(self.fmu.component)
        names = (("fmi2SetReal", "fmi2DoStep", "fmi2GetReal") if self.version == 2
                 else ("fmi3SetFloat64", "fmi3DoStep", "fmi3GetFloat64"))
        set_real, do_step, get_real = (dll[n] for n in names)
        for f in (set_real, do_step, get_real):
            f.restype = ctypes.c_int
        ni, no, D, fail = ctypes.c_size_t(n_in), ctypes.c_size_t(n_out), ctypes.c_double, self._fail
        if self.version == 2:
            set_args, get_args = (c, in_vr, ni, in_buf), (c, out_vr, no, out_buf)

            def step_call(t, h):
                return do_step(c, D(t), D(h), 1)
        else:
            set_args, get_args = (c, in_vr, ni, in_buf, ni), (c, out_vr, no, out_buf, no)
            flags = [ctypes.c_int(0) for _ in range(3)] + [ctypes.c_double(0)]
            refs = [ctypes.byref(x) for x in flags]

            def step_call(t, h):
                return do_step(c, D(t), D(h), 1, *refs)

        def read():
            if n_out:
                st = get_real(*get_args)
                if st > 1:
                    fail("GetReal", st)
            return self.out_view

        def advance(t: float, h: float):
            if n_in:
                st = set_real(*set_args)
                if st > 1:
                    fail("SetReal", st)
            st = step_call(t, h)
            if st > 1:
                fail(f"DoStep(t = {t:g} s, h = {h:g} s)", st)
            return read()

        self._read, self.advance = read, advance

    def _fail(self, what: str, status: int):
        label = {1: "warning", 2: "discard", 3: "error", 4: "fatal"}.get(status, str(status))
        log = "; ".join(m for s, m in self.messages[-3:]) or "no message from the FMU"
        raise FMUError(f"{self.name}: {what} returned {label}: {log}")

    def reset(self, t0: float) -> np.ndarray:
        """Instantiate, apply parameters and start values, initialise at ``t0``; return the
        outputs at ``t0``."""
        self.close()
        self.messages.clear()
        try:
            self._instantiate()
            if self.version == 2:
                self.fmu.setupExperiment(startTime=t0)
            for key, val in self.settings.items():
                self._set(key, val)
            if self.version == 2:
                self.fmu.enterInitializationMode()
            else:
                self.fmu.enterInitializationMode(startTime=t0)
            self.fmu.exitInitializationMode()
        except FMICallException as e:
            self._fail(str(e).split(" failed")[0] if " failed" in str(e) else "initialisation", 3)
        self._bind_calls()
        return self._read()

    def advance(self, t: float, h: float) -> np.ndarray:
        """Inputs from :attr:`in_view` held over ``[t, t + h]``; returns outputs at ``t + h``.

        (Replaced after :meth:`reset` by a closure over the FMU's functions.)
        """
        raise RuntimeError(f"{self.name}: reset() must be called before advance()")

    def close(self) -> None:
        """Terminate and free the FMU instance (safe to call twice)."""
        if self.fmu is None:
            return
        fmu, self.fmu = self.fmu, None
        self.__dict__.pop("advance", None)
        self.__dict__.pop("_read", None)
        try:
            fmu.terminate()
        except Exception:
            pass
        try:
            fmu.freeInstance()
        except Exception:
            pass

"""An FMI 2.0 or 3.0 FMU (Co-Simulation or Model Exchange) as a co-simulation component.

Timing (see :mod:`cosim.core.component`): at an instant ``t`` the component's outputs are the
FMU's outputs at ``t``. With ``feedthrough="model"`` (default) the inputs the
``ModelStructure`` lists as direct dependencies of an output are set to their values at
``t`` before the outputs are read, so a feed-through FMU passes its input on at the same
instant; with ``feedthrough="none"`` the outputs are read before any input changes (the
left limit at ``t``: computed with the inputs held over the previous step), which breaks
algebraic loops through the FMU at the price of one step of latency, as a sensor that
samples just before the actuator updates. Then ``update`` sets all connected inputs and
advances the FMU over ``[t, t + period]`` with the inputs held: ``doStep`` in
Co-Simulation, the solver of :mod:`cosim.fmi.model_exchange` in Model Exchange.

Ports may be of any FMI numeric type (Float64/Real, Float32, the integer types,
Enumeration, Boolean); values travel as floats in the master and are converted exactly at
the FMU boundary (:mod:`cosim.fmi.exchange`). FMU log messages go to the Python logger
``cosim.fmu`` (warnings and errors always; everything with ``logging=True``), and the
last ones are kept in :attr:`FMUComponent.messages` and quoted in errors.
"""
from __future__ import annotations

import ctypes
import logging as _logging
from collections import deque
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from fmu_models.errors import (
    ConfigurationError,
    FMUError,
    TypeMismatchError,
    UnknownNameError,
)

from ..core.component import PORT_TYPES, Component, ExportedFMU, Port
from .archive import Extraction, read_description
from .exchange import Exchange, raw_function
from .model_exchange import SOLVERS, MEIntegrator

__all__ = ["FEEDTHROUGH_MODES", "INTERFACES", "FMUComponent", "FMUError"]

INTERFACES = ("auto", "cs", "me")
FEEDTHROUGH_MODES = ("model", "none")
LOGGER = _logging.getLogger("cosim.fmu")
_LEVELS = {0: _logging.INFO, 1: _logging.WARNING, 2: _logging.WARNING, 3: _logging.ERROR, 4: _logging.CRITICAL}
_STATUS = {1: "warning", 2: "discard", 3: "error", 4: "fatal", 5: "pending"}


class FMUComponent(Component, kind="fmu"):
    """An FMU stepped by the master.

    Parameters
    ----------
    name : str
        Component name.
    path : str or Path
        The ``.fmu`` file (FMI 2.0 or 3.0).
    period : float
        Communication step [s].
    inputs : sequence of str, optional
        FMU variables (causality input) offered as input ports; default: all inputs of a
        numeric type. Unconnected ones keep their start values.
    outputs : sequence of str, optional
        FMU variables offered as output ports; default: all outputs of a numeric type.
        Local variables such as ``der(alpha_dot)`` may be listed too.
    parameters : mapping, optional
        Parameter values by name, set before initialisation.
    start : mapping, optional
        Start values by name (e.g. initial states), set before initialisation.
    interface : {"auto", "cs", "me"}
        Co-Simulation or Model Exchange; ``"auto"`` takes Co-Simulation if the FMU has it.
    solver : {"cvode", "euler", "rk4"}
        Model Exchange solver (see :mod:`cosim.fmi.model_exchange`; default CVODE).
    solver_step : float, optional
        Model Exchange: fixed step [s] of Euler/RK4, largest step of CVODE (default: the
        period).
    rtol : float
        Model Exchange: CVODE's relative tolerance (default 1e-6).
    feedthrough : {"model", "none"}
        Direct dependencies of outputs on inputs: from the FMU's ``ModelStructure``
        (default; an output without declared dependencies depends on every input), or
        none (outputs are the left limits at each instant; see the module documentation).
    logging : bool
        Ask the FMU for debug messages (``SetDebugLogging``) and log them at INFO level;
        warnings and errors are always logged (default False).

    Attributes
    ----------
    md : fmpy ModelDescription
    version : int
        2 or 3.
    interface : str
        ``"cs"`` or ``"me"``, as resolved.
    messages : collections.deque of (int, str)
        The last 200 log messages of the FMU (status, text).
    """

    reentrant = True
    holds_inputs = True

    def __init__(self, name: str, path, period: float, inputs: Sequence[str] | None = None,
                 outputs: Sequence[str] | None = None, parameters: Mapping[str, float] | None = None,
                 start: Mapping[str, float] | None = None, interface: str = "auto",
                 solver: str = "cvode", solver_step: float | None = None, rtol: float = 1e-6,
                 feedthrough: str = "model", logging: bool = False):
        self.path = Path(path)
        md = read_description(self.path)
        self.md, self.version = md, 3 if str(md.fmiVersion).startswith("3") else 2
        if interface not in INTERFACES:
            raise UnknownNameError(f"{name}: interface must be one of {INTERFACES}, got {interface!r}")
        has = {"cs": md.coSimulation is not None, "me": md.modelExchange is not None}
        if interface == "auto":
            interface = "cs" if has["cs"] else "me" if has["me"] else ""
            if not interface:
                raise FMUError(f"{name}: {self.path.name} has neither a Co-Simulation nor a Model "
                               "Exchange interface")
        elif not has[interface]:
            have = [k for k, v in has.items() if v]
            raise ConfigurationError(f"{name}: {self.path.name} has no "
                                     f"{'Co-Simulation' if interface == 'cs' else 'Model Exchange'} "
                                     f"interface; it has: {', '.join(have) or 'none'}")
        self.interface = interface
        if solver not in SOLVERS:
            raise UnknownNameError(f"{name}: solver must be one of {SOLVERS}, got {solver!r}")
        if feedthrough not in FEEDTHROUGH_MODES:
            raise UnknownNameError(f"{name}: feedthrough must be one of {FEEDTHROUGH_MODES}, got {feedthrough!r}")
        from fmu_models.checks import positive

        self.solver, self.rtol = solver, positive(rtol, f"{name}: rtol")
        self.solver_step = positive(solver_step if solver_step is not None else period, f"{name}: solver_step")
        self.feedthrough_mode, self.logging = feedthrough, bool(logging)
        self.variables = {v.name: v for v in md.modelVariables}
        ident = (md.coSimulation if interface == "cs" else md.modelExchange).modelIdentifier
        self.model_identifier = ident
        self._check_binary(name)
        all_in = [v.name for v in md.modelVariables if v.causality == "input"]
        all_out = [v.name for v in md.modelVariables if v.causality == "output"]
        readable = all_out + [v.name for v in md.modelVariables if v.causality == "local"]
        numeric = lambda names: [n for n in names if self.variables[n].type in PORT_TYPES]  # noqa: E731
        ins = self._ports(name, numeric(all_in) if inputs is None else inputs, all_in, "input")
        outs = self._ports(name, numeric(all_out) if outputs is None else outputs, readable, "output")
        ft = self._model_feedthrough(outs, ins) if feedthrough == "model" else False
        super().__init__(name, period, ins, outs, feedthrough=ft, port_names_are_identifiers=False)
        self.settings = {}
        for kind, values in (("parameter", parameters or {}), ("start", start or {})):
            for key, val in values.items():
                if key not in self.variables:
                    raise UnknownNameError(f"{name}: FMU {md.modelName} has no variable {key!r} (for {kind}); "
                                           f"valid names: {', '.join(self.variables)}")
                if self.variables[key].type not in PORT_TYPES:
                    raise TypeMismatchError(f"{name}: {key!r} is of type {self.variables[key].type}; only "
                                            "numeric and Boolean variables can be set")
                self.settings[key] = val
        self.fmu = None
        self.messages: deque = deque(maxlen=200)
        self._extraction: Extraction | None = None
        self.connected_inputs = list(self.input_names)
        self._private, self._me, self._initialized = None, None, False

    @classmethod
    def from_scenario(cls, name, table, context):
        """Either ``model`` (this project's plant, built into the scenario's FMU folder as FMI
        ``fmi_version``, with ``model_parameters``) or ``path`` (an FMU file); the other keys
        as the constructor's."""
        table = dict(table)
        if ("model" in table) == ("path" in table):
            raise ConfigurationError(f"component {name!r}: give either model (this project's plant, built on "
                                     "the fly) or path (an .fmu file)")
        if "model" in table:
            from fmu_models.export.pack import FMI_VERSIONS
            from fmu_models.export.plant import build_fmu

            version = table.pop("fmi_version", 2)
            if isinstance(version, bool) or version not in FMI_VERSIONS:
                raise ConfigurationError(f"component {name!r}: fmi_version must be one of {FMI_VERSIONS}, "
                                         f"got {version!r}")
            model = context.model(table.pop("model"), table.pop("model_parameters", None))
            path = build_fmu(model, context.fmu_dir / f"fmi{version}", fmi_version=version)
        else:
            for key in ("fmi_version", "model_parameters"):
                if key in table:
                    raise ConfigurationError(f"component {name!r}: {key} applies to a built model, not to an FMU "
                                             "file")
            path = context.path(table.pop("path"), f"component {name!r}: path")
        return context.construct(cls, name, table, path=path)

    # ------------------------------------------------------------------ description
    def _check_binary(self, name: str) -> None:
        import zipfile

        from fmu_models.export.pack import library_suffix, platform_dir

        want = f"binaries/{platform_dir(self.version)}/{self.model_identifier}{library_suffix()}"
        with zipfile.ZipFile(self.path) as z:
            names = z.namelist()
        if want not in names:
            have = sorted({n.split("/")[1] for n in names if n.startswith("binaries/") and n.count("/") >= 2})
            hint = (" It ships its C sources: rebuild it for this platform (e.g. fmpy's "
                    "compile_platform_binary)." if any(n.startswith("sources/") for n in names) else "")
            raise FMUError(f"{name}: {self.path.name} has no binary for this platform ({want}); it has "
                           f"binaries for: {', '.join(have) or 'none'}.{hint}")

    def _ports(self, name, chosen, available, what) -> list[Port]:
        ports = []
        for p in chosen:
            if p not in available:
                raise UnknownNameError(f"{name}: {p!r} is not an FMU {what}; valid {what}s: "
                                       f"{', '.join(available)}")
            v = self.variables[p]
            if v.type not in PORT_TYPES:
                raise TypeMismatchError(f"{name}: {what} {p!r} is of type {v.type}; ports can be "
                                        f"{', '.join(sorted(set(PORT_TYPES)))}")
            ports.append(Port(p, v.type, getattr(v, "unit", None) or "", v.description or ""))
        return ports

    def _model_feedthrough(self, outs: list[Port], ins: list[Port]) -> dict:
        """Direct dependencies of each output port on input ports, from the ModelStructure."""
        declared = {}
        for unknown in list(self.md.outputs) + list(getattr(self.md, "derivatives", [])):
            if unknown.variable is not None:
                declared[unknown.variable.name] = unknown.dependencies
        in_names = {p.name for p in ins}
        result = {}
        for p in outs:
            deps = declared.get(p.name)
            if deps is None:           # not declared: depends on every input (FMI default)
                result[p.name] = sorted(in_names)
            else:
                result[p.name] = sorted(d.name for d in deps if d.name in in_names)
        return result

    def __repr__(self):
        return (f"FMUComponent({self.name!r}, {self.path.name}, FMI {self.version}.0 "
                f"{self.interface.upper()}, period={self.period})")

    def export_fmu(self, folder: Path, fmi_version: int = 2) -> ExportedFMU:
        """A copy of the FMU file as ``<folder>/<name>.fmu``, with this component's
        parameters and start values (``fmi_version`` does not apply: the file is kept)."""
        from fmu_models.export.pack import atomic_copy

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        dst = folder / f"{self.name}.fmu"
        atomic_copy(self.path, dst)
        note = ""
        if self.interface == "me":
            note = (f"{self.name}: the master ran this FMU through Model Exchange ({self.solver}); an SSP "
                    "importer may use its Co-Simulation interface")
        return ExportedFMU(dst, dict(self.settings), note)

    def timing(self) -> str:
        kind = ("Co-Simulation doStep" if self.interface == "cs"
                else f"Model Exchange, {self.solver} solver (step {self.solver_step:g} s)")
        lim = " (left limits: feedthrough='none')" if self.feedthrough_mode == "none" else ""
        return f"FMI {self.version}.0 {kind}: outputs at t{lim}; inputs held over [t, t + {self.period:g}]"

    def required_inputs(self) -> list[str]:
        """None: unconnected FMU inputs keep their start values."""
        return []

    def use_inputs(self, names: Sequence[str]) -> None:
        """Set, at each step, only these input ports (the connected ones), in this order."""
        unknown = [n for n in names if n not in self.input_names]
        if unknown:
            raise UnknownNameError(f"{self.name}: not input ports: {unknown}")
        self.connected_inputs = list(names)

    # ------------------------------------------------------------------ lifecycle
    def _log(self, status: int, category, message) -> None:
        text = message.decode(errors="replace") if isinstance(message, bytes) else str(message)
        self.messages.append((int(status), text))
        if status >= 1 or self.logging:
            LOGGER.log(_LEVELS.get(int(status), _logging.ERROR), "[%s] %s", self.name, text)

    def _fail(self, what: str, status: int):
        label = _STATUS.get(status, f"status {status}")
        log = "; ".join(m for s, m in list(self.messages)[-3:]) or "no message from the FMU"
        raise FMUError(f"{self.name}: {what} returned {label}: {log}")

    def _instantiate(self, t0: float) -> None:
        from fmpy import fmi2, fmi3
        from fmpy.fmi1 import calloc, free

        if self._extraction is None or self._extraction.closed:   # unpacked once, reused by every run
            self._extraction = Extraction(self.path)
        args = dict(guid=self.md.guid, unzipDirectory=self._extraction.directory,
                    modelIdentifier=self.model_identifier, instanceName=self.name)
        cs = self.interface == "cs"
        try:
            if self.version == 2:
                self.fmu = (fmi2.FMU2Slave if cs else fmi2.FMU2Model)(**args)

                def logger(env, inst, status, category, message):
                    self._log(status, category, message)

                cb = fmi2.fmi2CallbackFunctions()
                cb.logger = fmi2.fmi2CallbackLoggerTYPE(logger)
                cb.allocateMemory = fmi2.fmi2CallbackAllocateMemoryTYPE(calloc)
                cb.freeMemory = fmi2.fmi2CallbackFreeMemoryTYPE(free)
                self._callbacks = cb
                self.fmu.instantiate(callbacks=cb, loggingOn=self.logging)
            else:
                self.fmu = (fmi3.FMU3Slave if cs else fmi3.FMU3Model)(**args)

                def log3(env, status, category, message):
                    self._log(status, category, message)

                self.fmu.instantiate(loggingOn=self.logging, logMessage=log3)
        except Exception as e:  # noqa: BLE001 - ctypes, fmpy and OSError: all become one FMUError
            fmu, self.fmu = self.fmu, None
            if fmu is not None and getattr(fmu, "dll", None) is not None:
                try:
                    fmu.freeLibrary()
                except Exception:
                    LOGGER.debug("freeLibrary failed", exc_info=True)
            log = "; ".join(m for s, m in list(self.messages)[-3:])
            raise FMUError(f"{self.name}: cannot load or instantiate {self.path.name}: {e}"
                           + (f" ({log})" if log else "")) from None
        if self.logging:
            try:
                self.fmu.setDebugLogging(True, [])
            except Exception:  # noqa: BLE001 - optional: an FMU may refuse debug logging
                LOGGER.debug("%s: setDebugLogging refused", self.name)

    def _set_setting(self, name, value):
        v = self.variables[name]
        vr = [v.valueReference]
        kind = PORT_TYPES[v.type]
        if kind == "boolean":
            self.fmu.setBoolean(vr, [bool(value)])
        elif kind == "integer":
            if float(value) != int(value):
                raise ConfigurationError(f"{self.name}: {name} is an integer variable, got {value!r}")
            if self.version == 2:
                setter = self.fmu.setInteger
            else:
                setter = getattr(self.fmu, "setInt64" if v.type == "Enumeration" else f"set{v.type}")
            setter(vr, [int(value)])
        else:
            (self.fmu.setReal if self.version == 2 else getattr(self.fmu, f"set{v.type}"))(vr, [float(value)])

    def reset(self, t0: float) -> None:
        """Unpack and instantiate the FMU, apply parameters and start values and initialise
        it at ``t0``."""
        from fmpy.fmi1 import FMICallException

        self.close()
        super().reset(t0)
        self.messages.clear()
        self._instantiate(t0)
        try:
            if self.version == 2:
                self.fmu.setupExperiment(startTime=t0)
            for key, val in self.settings.items():
                self._set_setting(key, val)
            if self.version == 2:
                self.fmu.enterInitializationMode()
            else:
                self.fmu.enterInitializationMode(startTime=t0)
            self.fmu.exitInitializationMode()
            self._initialized = True
            self._me = None
            if self.interface == "me":
                self._me = MEIntegrator(self.fmu, self.md, self.solver, self.solver_step, self.rtol, self._fail)
                self._me.start(t0)
        except FMICallException as e:
            what = str(e).split(" failed")[0] if " failed" in str(e) else "initialisation"
            self._fail(what, 3)
        except (TypeError, ValueError, OverflowError) as e:
            raise ConfigurationError(f"{self.name}: bad parameter or start value: {e}") from None
        self._private = None

    def bind(self, values, inputs, outputs):
        """Output and update closures over the raw FMI functions, exchanging values with
        ``values`` in place (see :meth:`Component.bind`)."""
        if self.fmu is None:
            raise FMUError(f"{self.name}: reset() must be called before bind()")
        inst, dll = self.fmu.component, self.fmu.dll
        var = self.variables
        in_vars = [var[n] for n in self.connected_inputs]
        idx = np.arange(len(values))[inputs] if isinstance(inputs, slice) else np.asarray(inputs, np.intp)
        set_all = Exchange(dll, inst, self.version, in_vars, "set", self._fail).bind(values, inputs)
        ft_names = sorted(set().union(*self.feedthrough.values()) & set(self.connected_inputs)) \
            if self.feedthrough else []
        pos = [self.connected_inputs.index(n) for n in sorted(ft_names, key=self.connected_inputs.index)]
        set_ft = (Exchange(dll, inst, self.version, [in_vars[i] for i in pos], "set", self._fail)
                  .bind(values, idx[pos]) if pos else None)
        get_out = Exchange(dll, inst, self.version, [var[n] for n in self.output_names], "get",
                           self._fail).bind(values, outputs)
        h, fail = self.period, self._fail

        if set_ft is None:
            output_fn = lambda t: get_out()  # noqa: E731 - the hot path: one FMI call
        else:
            def output_fn(t: float) -> None:
                set_ft()
                get_out()

        if self.interface == "me":
            me = self._me

            def update_fn(t: float) -> None:
                set_all()
                me.advance(t, h)
            return output_fn, update_fn

        do_step, D = raw_function(dll, f"fmi{self.version}DoStep"), ctypes.c_double
        c, Dh = ctypes.c_void_p(inst), ctypes.c_double(h)
        if self.version == 2:
            def update_fn(t: float) -> None:
                set_all()
                st = do_step(c, D(t), Dh, 1)
                if st > 1:
                    fail(f"DoStep(t = {t:g} s, h = {h:g} s)", st)
        else:
            flags = [ctypes.c_bool(False) for _ in range(3)] + [ctypes.c_double(0)]
            refs = [ctypes.byref(x) for x in flags]
            term = flags[1]

            def update_fn(t: float) -> None:
                set_all()
                st = do_step(c, D(t), Dh, True, *refs)
                if st > 1:
                    fail(f"DoStep(t = {t:g} s, h = {h:g} s)", st)
                if term.value:
                    raise FMUError(f"{self.name}: the FMU requested termination at t = {t + h:g} s")
        return output_fn, update_fn

    def _private_binding(self):
        if self._private is None:
            n_in, n_out = len(self.connected_inputs), len(self.output_names)
            buf = np.zeros(n_in + n_out)
            self._private = (buf, *self.bind(buf, slice(0, n_in), slice(n_in, n_in + n_out)))
        return self._private

    def output(self, t: float, u: np.ndarray) -> np.ndarray:
        """Outputs at ``t`` with the connected inputs ``u`` (see the module documentation)."""
        buf, out_fn, _ = self._private_binding()
        n_in = len(self.connected_inputs)
        buf[:n_in] = u
        out_fn(t)
        return buf[n_in:].copy()

    def update(self, t: float, u: np.ndarray) -> None:
        """Set the connected inputs ``u`` and advance over ``[t, t + period]``."""
        buf, _, upd_fn = self._private_binding()
        buf[: len(self.connected_inputs)] = u
        upd_fn(t)

    def close(self) -> None:
        """Terminate and free the FMU instance and remove its unpacked files (safe twice)."""
        fmu, self.fmu = self.fmu, None
        self._private, self._me = None, None
        initialized, self._initialized = self._initialized, False
        if fmu is not None:
            if initialized:
                try:
                    fmu.terminate()
                except Exception:  # noqa: BLE001 - an FMU in error state may refuse; free it anyway
                    LOGGER.debug("%s: terminate refused", self.name)
            try:
                fmu.freeInstance()
            except Exception:  # noqa: BLE001
                LOGGER.debug("%s: freeInstance failed", self.name)

    def release(self) -> None:
        """:meth:`close`, and remove the unpacked FMU (kept between runs otherwise; removed
        anyway when the component is garbage-collected or at interpreter exit)."""
        self.close()
        if self._extraction is not None:
            self._extraction.close()
            self._extraction = None

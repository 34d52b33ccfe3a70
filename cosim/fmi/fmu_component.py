"""An FMI 1.0, 2.0 or 3.0 FMU (Co-Simulation, Model Exchange or Scheduled Execution) as a
co-simulation component (the co-simulation page of the documentation: FMUs in the master)."""
from __future__ import annotations

import ctypes
import weakref
from collections import deque
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from fmu_models.errors import ConfigurationError, FMUError, ResourceError, TypeMismatchError, UnknownNameError
from fmu_models.export.clocked import check_clocked
from fmu_models.export.pack import FMI_VERSIONS
from fmu_models.export.plant_fmu import build_fmu
from fmu_models.infra.files import atomic_copy, private_tempdir

from ..core.clocking import ClockBoard
from ..core.component import BoundCalls, Component, ExportedFMU, StopRequest, port_kind
from ..core.native import OP_STEP1, OP_STEP2, OP_STEP3, Op, native_ops
from .archive import Extraction
from .clock_run import clocked_run
from .clock_timing import initialise
from .description import FMUDescription
from .exchange import FMI_TYPES, no_exchange
from .instance import _ERROR, _FATAL, FMUInstance, unload_library
from .isolated import RemoteFMU
from .model_exchange import FMUModel, MEIntegrator, check_solver, held_inputs, unit_nominals_instead
from .ports import element_ports, parse_start

__all__ = ["FEEDTHROUGH_MODES", "MAX_INTERNAL_STEPS", "FMUComponent", "FMUError", "HeldInputs"]

FEEDTHROUGH_MODES = ("model", "none")
#: The most fixed internal steps (``fixedInternalStepSize``, or Euler/RK4's ``solver_step``) a run may
#: take; beyond it the run is refused, not left running for days inside one uninterruptible call.
MAX_INTERNAL_STEPS = 10**9


def _unload_box(box: list) -> None:
    """Unload the library a component keeps in ``box[0]`` (if any)."""
    fmu, box[0] = box[0], None
    if fmu is not None:
        unload_library(fmu)


class HeldInputs:
    """The inputs of :class:`FMUComponent` and :class:`~cosim.fmi.me_system.MESystem` (a mixin): the master
    sets only the connected ones (:meth:`use_inputs`), the others keep their start values."""

    reentrant = True
    holds_inputs = True
    _sources: list | None = None

    def required_inputs(self) -> list[str]:
        return []

    def use_inputs(self, names: Sequence[str], sources: Sequence[tuple[str, str]] | None = None) -> None:
        """Set, at each step, only these input ports (the connected ones), in this order;
        ``sources``: each one's source signal and FMI type (for the integer range checks)."""
        unknown = [n for n in names if n not in self.input_names]
        if unknown:
            raise UnknownNameError(f"{self.name}: not input ports: {unknown}")
        self.connected_inputs = list(names)
        self._sources = list(sources) if sources is not None else None


class FMUComponent(BoundCalls, HeldInputs, Component, kind="fmu"):
    """An FMU stepped by the master.

    Parameters
    ----------
    name : str
    path : str or Path
        The ``.fmu`` file (FMI 1.0, 2.0 or 3.0).
    period : float
        Communication step [s].
    inputs : sequence of str, optional
        FMU inputs offered as ports (an array's name means all its elements, ``u[2]`` one);
        default: all inputs of a numeric type. Unconnected ones keep their start values.
    outputs : sequence of str, optional
        As ``inputs``, for outputs; locals such as ``der(alpha_dot)`` may be listed too.
    parameters, start : mapping, optional
        Parameter and start values by name (lists for arrays), set before initialisation;
        structural parameters in Configuration Mode (FMI 3.0), deciding the arrays' sizes.
    interface : {"auto", "cs", "me", "se"}
        Co-Simulation, Model Exchange or Scheduled Execution; ``"auto"``: the first the FMU has.
    solver : {"cvode", "euler", "rk4"}
        Model Exchange solver (:mod:`cosim.fmi.model_exchange`).
    solver_step : float, optional
        Model Exchange: the fixed step [s] of Euler/RK4 (default: the period), or CVODE's
        largest step (default: none).
    rtol : float
        Model Exchange: CVODE's relative tolerance.
    feedthrough : {"model", "none"}
        Direct dependencies of outputs on inputs: from the ``ModelStructure`` (default; an
        output without declared ones depends on every input), or none (left limits).
    logging : bool
        Ask the FMU for debug messages and log them at INFO level on the ``cosim.fmu``
        logger (warnings and errors always are; default False).
    isolate : bool
        Run the FMU in a process of its own: a crash of its code ends the run with a named
        error, not the process (default False).
    clock_intervals : mapping, optional
        Intervals [s] of the fixed or tunable input clocks that declare ``intervalDecimal``,
        by clock name (default: the declared ones); multiples of ``period``.

    Attributes
    ----------
    description : FMUDescription
        What the FMU declares (:mod:`cosim.fmi.description`); ``path``, ``md``, ``version`` and
        ``clock_model`` (its clocks, :mod:`cosim.fmi.clocks`) are its.
    interface : str
        ``"cs"``, ``"me"`` or ``"se"``, as resolved.
    messages : collections.deque of (int, str)
        The last 200 log messages of the FMU (status, text), quoted in errors.
    integrator : MEIntegrator or None
        The Model Exchange integrator of the current run.
    unit_nominals : bool
        Model Exchange: the states' nominal values are 1 (:mod:`cosim.fmi.model_exchange`).
    arguments : dict
        The constructor's arguments but ``isolate`` (an isolating child process builds its copy from them).
    plant_model : object or None
        The project's plant model this FMU was built from (a scenario's ``model``).
    """

    def __init__(self, name: str, path, period: float, inputs: Sequence[str] | None = None,
                 outputs: Sequence[str] | None = None, parameters: Mapping[str, object] | None = None,
                 start: Mapping[str, object] | None = None, interface: str = "auto",
                 solver: str = "cvode", solver_step: float | None = None, rtol: float = 1e-6,
                 feedthrough: str = "model", logging: bool = False, isolate: bool = False,
                 clock_intervals: Mapping[str, float] | None = None):
        self.arguments = dict(name=name, path=str(path), period=period, inputs=inputs, outputs=outputs,
                              parameters=parameters, start=start, interface=interface, solver=solver,
                              solver_step=solver_step, rtol=rtol, feedthrough=feedthrough, logging=logging,
                              clock_intervals=clock_intervals)
        d = self.description = FMUDescription(path, name)
        self.path, self.md, self.version, self.clock_model = d.path, d.md, d.version, d.clocks
        self.interface = d.choose_interface(interface)
        self.clock_overrides = d.clock_overrides(clock_intervals, isolate)
        self.solver, self.solver_step, self.rtol = check_solver(name, solver, solver_step, rtol)
        if feedthrough not in FEEDTHROUGH_MODES:
            raise UnknownNameError(f"{name}: feedthrough must be one of {FEEDTHROUGH_MODES}, got {feedthrough!r}")
        if not isinstance(isolate, bool):
            raise TypeMismatchError(f"{name}: isolate must be true or false, got {isolate!r}")
        self.feedthrough_mode, self.logging, self.isolate = feedthrough, bool(logging), isolate
        d.check_binary(self.interface)
        self.plant_model = None
        self.settings, structural = d.settings(parameters or {}, start or {})
        self.element_ports = element_ports(d.md, structural)
        ins = d.ports(self.element_ports, inputs, "input")
        outs = d.ports(self.element_ports, outputs, "output")
        ft = d.feedthrough(self.element_ports, outs, ins, self.interface) if feedthrough == "model" else False
        super().__init__(name, period, ins, outs, feedthrough=ft, port_names_are_identifiers=False)
        self.reentrant = self.interface != "se"         # a partition is activated once per time
        self._board = self._run = self._clock_schedule = self._remote = self._extraction = None
        self.instance: FMUInstance | None = None
        self.integrator: MEIntegrator | None = None
        self.messages: deque = deque(maxlen=200)
        self._library_box: list = [None]        # the last Co-Simulation instance's library, reused by the next
        weakref.finalize(self, _unload_box, self._library_box)
        self.connected_inputs = list(self.input_names)
        self.unit_nominals = False

    @classmethod
    def from_scenario(cls, name, table, context):
        """Either ``model`` (this project's plant, built as FMI ``fmi_version`` with
        ``model_parameters``) or ``path`` (an FMU file); the other keys as the constructor's."""
        table = dict(table)
        if ("model" in table) == ("path" in table):
            raise ConfigurationError(f"component {name!r}: give either model (this project's plant, built on "
                                     "the fly) or path (an .fmu file)")
        if "model" in table:
            version = table.pop("fmi_version", 2)
            if isinstance(version, bool) or version not in FMI_VERSIONS:
                raise ConfigurationError(f"component {name!r}: fmi_version must be one of {FMI_VERSIONS}, "
                                         f"got {version!r}")
            model = context.model(table.pop("model"), table.pop("model_parameters", None))
            path = build_fmu(model, context.fmu_dir / f"fmi{version}", fmi_version=version)
            comp = context.construct(cls, name, table, path=path)
            comp.plant_model = model
            return comp
        for key in ("fmi_version", "model_parameters"):
            if key in table:
                raise ConfigurationError(f"component {name!r}: {key} applies to a built model, not to an FMU file")
        path = context.path(table.pop("path"), f"component {name!r}: path")
        return context.construct(cls, name, table, path=path)

    def __repr__(self):
        return (f"FMUComponent({self.name!r}, {self.path.name}, FMI {self.version}.0 "
                f"{self.interface.upper()}, period={self.period})")

    def export_fmu(self, folder: Path, fmi_version: int = 2, clocked: bool = False) -> ExportedFMU:
        """A plant built from the project's model in ``fmi_version``; an FMU file copied as it is
        (not converted, nor clocked: the note says so)."""
        if fmi_version not in FMI_VERSIONS:
            raise ConfigurationError(f"fmi_version must be one of {FMI_VERSIONS}, got {fmi_version!r}")
        check_clocked(clocked, fmi_version, self.name)
        if self.clock_model is not None:
            raise ConfigurationError(f"{self.name}: an FMU with clocks has no SSP form here (the SSP 1.0 files "
                                     "written have no clock connections)")
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        dst = folder / f"{self.name}.fmu"
        notes = []
        if fmi_version != self.version and self.plant_model is not None:
            with private_tempdir(f"pendulum_cosim_export_{self.name}_") as tmp:
                atomic_copy(build_fmu(self.plant_model, tmp, fmi_version=fmi_version), dst)
            notes.append(f"built as FMI {fmi_version}.0 from its model {self.plant_model.name!r} (the run used the "
                         f"FMI {self.version}.0 FMU of the same model)")
        else:
            atomic_copy(self.path, dst)
            if fmi_version != self.version:
                notes.append(f"copied as the FMI {self.version}.0 FMU it is (an FMU file is not converted; for FMI "
                             f"{fmi_version}.0 give its scenario table fmi_version = {fmi_version})")
            elif self.interface == "me":
                notes.append(f"the master ran this FMU through Model Exchange ({self.solver}); an SSP importer may "
                             "use its Co-Simulation interface")
        if clocked:
            notes.append("an FMU component has no clocked form; written unclocked")
        return ExportedFMU(dst, dict(self.settings), "; ".join(f"{self.name}: {n}" for n in notes))

    def timing(self) -> str:
        if self.clock_model is not None:
            kind = {"cs": "Co-Simulation with Event Mode", "se": "Scheduled Execution",
                    "me": f"Model Exchange, {self.solver} solver"}[self.interface]
            n_in = sum(k.causality == "input" for k in self.clock_model.clocks)
            n_out = len(self.clock_model.clocks) - n_in
            held = "" if self.interface == "se" else f"; inputs held over [t, t + {self.period:g}]"
            return (f"FMI 3.0 {kind}, {n_in} input and {n_out} output/local clock(s): clocked outputs at their "
                    f"clocks' activations, held in between{held}")
        if self.interface == "cs":
            kind = "Co-Simulation doStep"
        else:
            step = self.solver_step if self.solver_step is not None or self.solver == "cvode" else self.period
            kind = f"Model Exchange, {self.solver} solver ({'variable step' if step is None else f'step {step:g} s'})"
        lim = " (left limits: feedthrough='none')" if self.feedthrough_mode == "none" else ""
        return f"FMI {self.version}.0 {kind}: outputs at t{lim}; inputs held over [t, t + {self.period:g}]"

    @property
    def input_sources(self) -> list[tuple[str, str]] | None:
        """Each connected input's source signal name and FMI type (given to :meth:`use_inputs`), or None."""
        return list(self._sources) if self._sources is not None else None

    def connected_sources(self) -> list[tuple[str, str]]:
        """:attr:`input_sources` if given, else each connected input as its own source (its
        signal name and FMI type)."""
        return self._sources or [(f"{self.name}.{n}", self.element_ports[n].type) for n in self.connected_inputs]

    # ------------------------------------------------------------------ clocks
    @property
    def clock_infos(self) -> tuple:
        """The FMU's clocks as the master's plan (:mod:`cosim.core.clocking`) sees them."""
        if self.clock_model is None:
            return ()
        return self.clock_model.infos(self.interface, self.clock_overrides, self.input_names + self.output_names)

    def port_clocks(self, port: str) -> list[str]:
        """The clocks of the data port ``port`` (exchanged only at their activations)."""
        clocks = self.clock_model
        if clocks is None or port not in self.element_ports or port in clocks.by_name:
            return []
        return [clocks.by_vr[vr].name for vr in clocks.clocks_of(self.element_ports[port].variable.name)]

    def attach_clocks(self, board: ClockBoard) -> None:
        """Take the run's clock board (before :meth:`bind`)."""
        self._board = board

    def _clock_update(self, env) -> None:
        """The Scheduled Execution ``clockUpdate`` callback, passed on to the run (an exception
        is kept by the run and raised when the FMU returns: a ctypes callback cannot raise)."""
        run = self._run
        try:
            if run is not None:
                run.clock_update(env)
        except BaseException as e:  # noqa: BLE001 - kept for the run
            if run._error is None:
                run._error = e

    # ------------------------------------------------------------------ lifecycle
    def check_run(self, start_time: float, stop_time: float) -> None:
        """Refuse a run whose fixed internal steps would exceed :data:`MAX_INTERNAL_STEPS`."""
        if self.interface == "cs":
            h, what = self.md.coSimulation.fixedInternalStepSize, "its fixedInternalStepSize"
            hint = "; its Model Exchange interface (interface = 'me') integrates with CVODE" if \
                "me" in self.description.interfaces else ""
        elif self.interface == "me" and self.solver != "cvode":
            h, what, hint = self.solver_step or self.period, f"solver_step ({self.solver})", "; use solver = 'cvode'"
        else:
            return
        try:
            h = float(h) if h is not None else 0.0
        except ValueError:
            return                               # an unreadable attribute: nothing to go by
        if h > 0 and (stop_time - start_time) / h > MAX_INTERNAL_STEPS:
            raise ResourceError(f"{self.name}: {self.path.name} takes internal steps of {h:g} s ({what}): "
                                f"{(stop_time - start_time) / h:.3g} of them from {start_time:g} s to "
                                f"{stop_time:g} s, more than {MAX_INTERNAL_STEPS:.0e}{hint}")

    def use_unpacked(self, directory: str) -> None:
        """Instantiate from the FMU unpacked in ``directory`` (the caller's, which removes it)."""
        self.close()
        self._extraction = Extraction.existing(directory)

    @property
    def unpacked(self) -> str:
        """The folder the FMU is unpacked in (unpacked on first use, kept between runs)."""
        if self._extraction is None or self._extraction.closed:
            self._extraction = Extraction(self.path)
        return self._extraction.directory

    def reset(self, t0: float) -> None:
        """Unpack (once), instantiate and initialise the FMU at ``t0`` [s]; Model Exchange: start its integrator."""
        self.close()
        super().reset(t0)
        if self.isolate:
            self._remote = RemoteFMU(self, t0)
            return
        self.instantiate(t0)
        if self.interface == "me":
            self._start_integrator(t0)

    def _start_integrator(self, t0: float) -> None:
        """Model Exchange: the integrator started at ``t0`` [s] (a clocked FMU's in its first update)."""
        model = FMUModel(self.instance, self.unit_nominals)
        self.integrator = MEIntegrator(model, self.solver, self.solver_step, self.rtol)
        if self.clock_model is not None:
            return
        try:
            self.integrator.start(t0)
        except FMUError:
            if not unit_nominals_instead([model], [self]):
                raise
            self.instantiate(t0)
            self._start_integrator(t0)

    def instantiate(self, t0: float) -> FMUInstance:
        """A new instance of the FMU (closing any previous one), initialised at ``t0`` [s] with
        the structural parameters (in Configuration Mode), parameters and start values; left
        after ``ExitInitializationMode`` (FMI 1.0: ``fmiInitializeSlave`` or ``fmiInitialize``)."""
        self.close()
        options = {}
        if self.clock_model is not None:
            options = dict(event_mode=True, early_return=True, clock_update=self._clock_update)
        library, self._library_box[0] = self._library_box[0], None     # kept only by an unclocked CS instance
        inst = FMUInstance(self.name, self.description, self.unpacked, self.interface, self.logging, **options,
                           library=library)
        inst.keep_library = not options and self.interface == "cs"      # reused by the next run
        self.instance = inst
        self.messages = inst.messages
        fmu = inst.fmu
        try:
            inst.setup(t0)
            structural = {k: v for k, v in self.settings.items()
                          if self.description.variables[k].causality == "structuralParameter"}
            if structural:
                inst.call("EnterConfigurationMode", fmu.enterConfigurationMode)
                for key, val in structural.items():
                    self._set_setting(key, val)
                inst.call("ExitConfigurationMode", fmu.exitConfigurationMode)
            for key, val in self.settings.items():
                if key not in structural:
                    self._set_setting(key, val)
            inst.enter_initialization(t0)
            if self.clock_model is not None:
                self._clock_schedule = initialise(self, inst, t0)
            inst.exit_initialization()
            inst.initialized = True
        except (TypeError, ValueError, OverflowError) as e:
            raise ConfigurationError(f"{self.name}: bad parameter or start value: {e}") from None
        self._private = None
        return inst

    def _set_setting(self, name: str, value) -> None:
        v, inst = self.description.variables[name], self.instance
        suffix = FMI_TYPES[self.version][v.type][1]
        items = value if isinstance(value, list) else [value]
        inst.call(f"Set{suffix}({name} = {value!r})", getattr(inst.fmu, f"set{suffix}"), [v.valueReference], items)

    def bind(self, values, inputs, outputs, integers=None):
        """Output and update closures over the raw FMI functions (:class:`~cosim.core.component.FastBinding`)."""
        if self._remote is not None:
            return self._remote.bind(values, inputs, outputs, integers)
        if self.instance is None:
            raise FMUError(f"{self.name}: reset() must be called before bind()")
        if integers is None:
            integers = np.zeros(len(values), dtype=np.int64)
        if self.clock_model is not None:
            board = self._board if self._board is not None else ClockBoard(None, values, integers, {})
            run = self._run = clocked_run(self, board, values, inputs, outputs, integers, self.integrator)
            return run.output, run.update
        inst, idx = self.instance, np.arange(len(values))[inputs]
        ports = [self.element_ports[n] for n in self.connected_inputs]
        sources = self.connected_sources()

        def setter(positions, changes=False):
            if not positions:
                return no_exchange
            ex = inst.exchange([ports[i] for i in positions], "set", [sources[i] for i in positions])
            ex.preset({p.name: s for p, s in zip(ports, self._input_starts())})
            return ex.bind(values, idx[positions], integers, changes)

        all_pos = list(range(len(ports)))
        ft_names = set().union(*self.feedthrough.values()) if self.feedthrough else set()
        ft_pos = [i for i, n in enumerate(self.connected_inputs) if n in ft_names]
        get_out = inst.exchange([self.element_ports[n] for n in self.output_names], "get").bind(values, outputs,
                                                                                                integers)
        if self.interface == "me":            # continuous inputs and discrete ones (set in Event Mode) apart
            def setters(positions: list[int]) -> tuple[list, list]:
                kinds = ([i for i in positions if not ports[i].discrete], [i for i in positions if ports[i].discrete])
                return tuple([setter(sel, changes=True)] if sel else [] for sel in kinds)
            return held_inputs(self.integrator, self.period, setters(all_pos), setters(ft_pos), [get_out])
        return self._output_fn(setter(ft_pos), get_out), self._cs_update(setter(all_pos))

    def _input_starts(self) -> list:
        """The start value of every connected input (what an array's unconnected elements send)."""
        ports = [self.element_ports[n] for n in self.connected_inputs]
        return [parse_start(p.variable, p.size)[p.offset] for p in ports]

    @staticmethod
    def _output_fn(set_ft, get_out):
        if set_ft is no_exchange:
            def output_fn(t: float) -> None:
                get_out()
        else:
            def output_fn(t: float) -> None:
                set_ft()
                get_out()
        parts = [native_ops(set_ft), native_ops(get_out)]
        if None not in parts:
            output_fn.native = parts[0] + parts[1]
        return output_fn

    def native_reason(self) -> str | None:
        """Why this FMU's calls run in Python (None: in the native kernel, :mod:`cosim.core.native`)."""
        if self.isolate:
            return "isolated in a process of its own"
        if self.interface != "cs":
            return {"me": "Model Exchange", "se": "Scheduled Execution"}[self.interface]
        if self.clock_model is not None:
            return "clocked"
        if self.description.asynchronous:
            return "FMI 1.0 asynchronous doStep (canRunAsynchronuously: a Pending step is waited for)"
        ports = [self.element_ports[n] for n in (*self.connected_inputs, *self.output_names)]
        other = sorted({p.type for p in ports if p.type not in ("Real", "Float64")})
        return f"{', '.join(other)} ports" if other else None

    def _cs_update(self, set_all):
        """``update_fn(t)``: set the inputs and ``doStep`` (with its native operations if it can have them)."""
        inst, h, name, v = self.instance, self.period, self.name, self.version
        do_step, D = inst.raw(f"fmi{v}DoStep"), ctypes.c_double
        c, Dh = ctypes.c_void_p(inst.handle), ctypes.c_double(h)

        def ended(st: int, t: float, terminate: bool = False, last_time: float = 0.0) -> None:
            """``doStep`` at ``t`` [s] returned ``st`` above Warning or asked to terminate."""
            if v == 1:                       # Pending waited for, Discard without a stop request
                inst.step_failed(st, t, h)
                return
            when = inst.discard_reason() if v == 2 and st == 2 else None
            if when is not None:
                raise StopRequest(name, when, "fmi2DoStep returned discard, fmi2Terminated is true")
            if st > 1 and not (st == 2 and terminate):
                inst.fail(f"DoStep(t = {t:g} s, h = {h:g} s)", st)
            if terminate:
                when = last_time if st == 2 or last_time > t else t + h
                raise StopRequest(name, when, "fmi3DoStep returned terminateSimulation")

        if v < 3:
            new_step = ctypes.c_char(1) if v == 1 else 1

            def update_fn(t: float) -> None:
                set_all()
                st = do_step(c, D(t), Dh, new_step)
                if st > 1:
                    ended(st, t)
        else:
            flags = [ctypes.c_bool(False) for _ in range(3)] + [ctypes.c_double(0)]
            refs, term, last = [ctypes.byref(x) for x in flags], flags[1], flags[3]

            def update_fn(t: float) -> None:
                set_all()
                st = do_step(c, D(t), Dh, True, *refs)
                if st > 1 or term.value:
                    ended(st, t, term.value, last.value)
        ops = native_ops(set_all)
        if ops is not None and self.native_reason() is None:
            step = Op((OP_STEP1, OP_STEP2, OP_STEP3)[v - 1],
                      dict(fn=ctypes.cast(do_step, ctypes.c_void_p).value, inst=inst.handle, a=float(h)), (do_step,),
                      lambda op, t: ended(op.status, t, bool(op.flag), op.d))
            update_fn.native = [*ops, step]
        return update_fn

    def _set_private_inputs(self, buf, ints, u) -> None:
        n_in = len(self.connected_inputs)
        buf[:n_in] = u
        for i, n in enumerate(self.connected_inputs):
            if port_kind(self.element_ports[n].type) != "real":
                ints[i] = int(u[i])

    def close(self) -> None:
        """End and free the FMU instance as the FMI rules allow (:mod:`cosim.fmi.instance`); safe twice."""
        remote, self._remote = self._remote, None
        if remote is not None:
            remote.close()
        inst, self.instance = self.instance, None
        self._private, self.integrator, self._run = None, None, None
        if inst is not None:
            inst.finish()
            if inst.keep_library and inst.worst < _ERROR:   # the library stays loaded for the next instance
                self._library_box[0] = inst.fmu
            elif inst.keep_library and inst.worst < _FATAL:
                unload_library(inst.fmu)

    def release(self) -> None:
        """:meth:`close`, unload the FMU's library and remove the unpacked FMU (otherwise kept between runs)."""
        self.close()
        _unload_box(self._library_box)
        if self._extraction is not None:
            self._extraction.close()
            self._extraction = None

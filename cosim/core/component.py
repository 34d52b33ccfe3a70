"""The component protocol: what the co-simulation master needs from every component.

Every component, FMU or Python, is a :class:`Component`. The master depends on this
class only. A component has a ``name``, a sample ``period`` [s], typed input and output
ports (:class:`Port`), and declares which outputs depend *directly* on which inputs
(its ``feedthrough`` attribute). At each of its sample instants ``t`` (every ``period``
seconds from the start time) the master calls, for all components due at ``t``:

1. :meth:`Component.output` ``(t, u) -> y`` in an order that respects the direct
   dependencies (a component's feedthrough inputs are computed before it reads them):
   the outputs at ``t``. ``u`` holds every input's current value; only the feedthrough
   inputs are guaranteed to be the values at ``t`` (the others may still be the
   values before ``t``, and must not change the outputs).
2. the row of all signals at ``t`` is recorded;
3. :meth:`Component.update` ``(t, u)`` once, with every input at its value at ``t``: the
   component consumes its inputs and advances its state to its next instant. An FMU
   sets its inputs and steps over ``[t, t + period]`` here; its outputs at
   ``t + period`` are then read by the next ``output``.

Between its instants a component's outputs are held (zero-order hold). A component
whose output at ``t`` must not depend on its input at ``t`` (a filter's input ``u``
predicts the *next* state; a unit delay; an encoder counting over the last period)
declares no feedthrough for that input and reads it in :meth:`Component.update`. That
declaration is what makes results independent of the order in which components are
listed, and what lets the master find algebraic loops before a run.

To write a component: subclass :class:`Component`, pass the ports to ``__init__``, and
implement :meth:`~Component.output` (and :meth:`~Component.update`,
:meth:`~Component.reset`, :meth:`~Component.close` when needed). Set ``feedthrough``
when some output does not depend on every input, and ``reentrant = True`` if
``output`` may be called several times at one instant with improving inputs (needed to
iterate an algebraic loop through it; ``output`` must then not change the state). Give
the class a ``kind`` keyword (``class Thermometer(Component, kind="thermometer")``) to use
it from scenario files (:data:`COMPONENTS`); :meth:`~Component.from_scenario` builds it
from its table (default: the constructor, with the table's keys checked against its
signature).

Optional capabilities, declared by implementing a protocol (the master and the exporters
test ``isinstance(component, Protocol)``, never the class):

* :class:`FastBinding`: ``bind(values, inputs, outputs)``, a fast path for the master's
  inner loop (the FMU components exchange values with the FMU without copies);
* :class:`ExportsFMU`: ``export_fmu(folder, fmi_version)``, the component as an FMU (what
  :func:`cosim.ssp.export_ssp` and ``pendulum-cosim export-fmu`` need);
* :class:`StateEstimator`: ``estimated_states``, the names of the states whose estimates
  the component outputs (the command line compares them with the plant's).

``holds_inputs = True`` declares that the inputs :meth:`~Component.update` consumes are
held over ``[t, t + period]`` (a plant integrating them) rather than used at the next
instant. The master counts every component's instants itself (``Component.n_samples``).

Signals: the master keeps every signal as a float and every integer or Boolean signal
also as an exact int64 (a UInt64 as its bit pattern), so 64-bit integers travel exactly
between components that exchange them (:class:`FastBinding` receives both arrays).

A component that wants the run to end (an FMU asking to terminate) raises
:class:`StopRequest` from :meth:`~Component.update`: the run then ends normally, its last
row at the time the component asked for.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np

from fmu_models.errors import ConfigurationError, TypeMismatchError
from fmu_models.infra.checks import positive
from fmu_models.infra.registry import Registry

__all__ = ["CLOCK", "COMPONENTS", "PORT_TYPES", "BoundCalls", "Component", "ExportedFMU", "ExportsFMU", "FastBinding",
           "Port", "StateEstimator", "StopRequest", "bind_protocol", "check_name", "check_period", "port_kind",
           "ports_compatible", "split_port"]

#: FMI type names a port may have, by kind (real, integer incl. enumerations, boolean).
PORT_TYPES = {
    "Float64": "real", "Float32": "real", "Real": "real",
    "Int8": "integer", "UInt8": "integer", "Int16": "integer", "UInt16": "integer",
    "Int32": "integer", "UInt32": "integer", "Int64": "integer", "UInt64": "integer",
    "Integer": "integer", "Enumeration": "integer",
    "Boolean": "boolean",
}


#: The type of a clock port, an FMI 3.0 Clock. A clock connection carries its activations and
#: its signal counts them (see :mod:`cosim.core.clocking`).
CLOCK = "Clock"


def port_kind(type_name: str) -> str:
    """``"real"``, ``"integer"`` or ``"boolean"`` for the FMI type name ``type_name`` (see
    :data:`PORT_TYPES`), ``"clock"`` for :data:`CLOCK`."""
    if type_name == CLOCK:
        return "clock"
    try:
        return PORT_TYPES[type_name]
    except KeyError:
        raise TypeMismatchError(f"port type {type_name!r} is not supported; supported types: "
                                f"{', '.join(PORT_TYPES)}") from None


def ports_compatible(src_type: str, dst_type: str) -> bool:
    """True if an output of type ``src_type`` may drive an input of type ``dst_type``.

    Same kind always; integer and boolean outputs may also drive real inputs (exact).
    A real output never drives an integer or boolean input (that would round silently). A
    clock drives only a clock, and only a clock drives a clock.
    """
    s, d = port_kind(src_type), port_kind(dst_type)
    return s == d or (d == "real" and s != "clock")


@dataclass(frozen=True)
class Port:
    """A scalar port: ``name`` (an identifier, or an FMU variable name), ``type`` (an FMI
    type name, default ``"Float64"``), optional ``unit`` and ``description``."""

    name: str
    type: str = "Float64"
    unit: str = ""
    description: str = ""

    @property
    def kind(self) -> str:
        """``"real"``, ``"integer"`` or ``"boolean"``."""
        return port_kind(self.type)


@dataclass(frozen=True)
class ExportedFMU:
    """A component written as an FMU by :meth:`ExportsFMU.export_fmu`.

    Attributes
    ----------
    path : Path
        The ``.fmu`` file.
    parameters : dict
        Parameter and start values (by FMU variable name) that make the FMU behave as the
        component: they go into the SSP's parameter bindings.
    note : str
        What differs from the component, if anything (empty: nothing).
    """

    path: Path
    parameters: dict
    note: str = ""


def check_name(name: str, what: str = "component name") -> str:
    """``name`` if it is an ASCII identifier, else :class:`ConfigurationError` naming ``what`` it is
    (FMU, SSP and C names must be ASCII)."""
    if not isinstance(name, str) or not name.isidentifier() or not name.isascii():
        raise ConfigurationError(f"{what} {name!r} must be an ASCII identifier (letters, digits, _)")
    return name


def check_period(period, owner: str) -> float:
    """A component's sample period [s] as a positive finite float, else
    :class:`ConfigurationError` naming the ``owner`` component."""
    return positive(period, f"{owner}: sample period")


def _as_ports(ports, owner: str, direction: str, check_names: bool) -> tuple[Port, ...]:
    out = []
    for p in ports:
        port = p if isinstance(p, Port) else Port(p)
        if check_names:
            check_name(port.name, f"{owner}: {direction} port")
        port_kind(port.type)
        out.append(port)
    names = [p.name for p in out]
    if len(set(names)) != len(names):
        raise ConfigurationError(f"{owner}: duplicate {direction} port names in {names}")
    return tuple(out)


class StopRequest(Exception):           # a request, not an error: the run ends normally
    """Raised by a component's ``update`` to end the run normally at ``time`` (see the module
    documentation).

    Parameters
    ----------
    component : str
        Who asks.
    time : float
        When [s] (within the component's step).
    reason : str
        Why, in words.
    """

    def __init__(self, component: str, time: float, reason: str = ""):
        super().__init__(f"{component} asked to stop at t = {time:g} s" + (f" ({reason})" if reason else ""))
        self.component, self.time, self.reason = component, float(time), reason


#: The component types usable in scenario files, by their ``kind``.
COMPONENTS: Registry = Registry("component type")


@runtime_checkable
class FastBinding(Protocol):
    """A component with a fast path for the master's inner loop (see :meth:`~.FastBinding.bind`)."""

    def bind(self, values: np.ndarray, inputs, outputs: slice, integers: np.ndarray | None = None
             ) -> tuple[Callable[[float], None], Callable[[float], None]]:
        """Return ``(output_fn, update_fn)``, each taking ``t``: ``output_fn(t)`` writes the
        outputs at ``t`` into ``values[outputs]`` (and the exact ones of integer and Boolean
        ports into ``integers[outputs]``); ``update_fn(t)`` consumes ``values[inputs]`` (a
        slice or an int index array of the connected inputs) and ``integers[inputs]``."""


def split_port(ref, what: str, owner: str = "component") -> tuple[str, str]:
    """``(owner, port)`` of the connection end ``ref``, written ``"<owner>.<port>"``;
    ``what`` names it in the error (ConfigurationError) for anything else, ``owner`` is
    the word for its first part in that message ("component", "member")."""
    if not isinstance(ref, str) or "." not in ref or ref.startswith(".") or ref.endswith("."):
        raise ConfigurationError(f"{what} {ref!r} must be written '{owner}.port'")
    first, port = ref.split(".", 1)
    return first, port


class BoundCalls:
    """``output`` and ``update`` of a :class:`FastBinding` component through its own
    :meth:`~FastBinding.bind` on a private buffer (the path of calls from outside the
    master's loop). A mixin: the class sets ``self._private = None`` and drops it again
    whenever its binding becomes stale (new instance, closed); it may override
    ``_set_private_inputs`` for ports that need their exact integer value."""

    _private = None

    def _private_binding(self):
        if self._private is None:
            n_in, n_out = len(self.connected_inputs), len(self.output_names)
            buf, ints = np.zeros(n_in + n_out), np.zeros(n_in + n_out, dtype=np.int64)
            self._private = (buf, ints, *self.bind(buf, slice(0, n_in), slice(n_in, n_in + n_out), ints))
        return self._private

    def _set_private_inputs(self, buf: np.ndarray, ints: np.ndarray, u) -> None:
        n_in = len(self.connected_inputs)
        buf[:n_in] = u
        ints[:n_in] = np.asarray(u, dtype=float).astype(np.int64)

    def output(self, t: float, u: np.ndarray) -> np.ndarray:
        """Outputs at ``t`` [s] with the connected inputs ``u`` (one value per connected
        input, in order); returns a new array, one value per output."""
        buf, ints, out_fn, _ = self._private_binding()
        self._set_private_inputs(buf, ints, u)
        out_fn(t)
        return buf[len(self.connected_inputs):].copy()

    def update(self, t: float, u: np.ndarray) -> None:
        """Set the connected inputs ``u`` and advance over ``[t, t + period]`` (``t`` in s)."""
        buf, ints, _, upd_fn = self._private_binding()
        self._set_private_inputs(buf, ints, u)
        upd_fn(t)


@runtime_checkable
class ExportsFMU(Protocol):
    """A component that can be written as a Co-Simulation FMU."""

    def export_fmu(self, folder: Path, fmi_version: int = 2, clocked: bool = False) -> ExportedFMU:
        """Write the component as ``<folder>/<name>.fmu`` with the component's port names
        (FMI ``fmi_version`` 2 or 3); ``clocked``: its clocked form where it has one (FMI 3.0,
        :mod:`fmu_models.export.clocked`; without one, the unclocked form and a note); raises
        ConfigurationError (saying why) for a configuration without an FMU form."""


@runtime_checkable
class StateEstimator(Protocol):
    """A component whose outputs include state estimates (named as the plant's states)."""

    estimated_states: list


class Component(ABC):
    """A block of the co-simulation (see the module documentation for the protocol).

    Parameters
    ----------
    name : str
        Unique identifier of the component in a co-simulation.
    period : float
        Sample period [s].
    inputs : sequence of str or Port
        Input ports (strings are Float64 ports).
    outputs : sequence of str or Port
        Output ports.
    feedthrough : mapping or bool, optional
        Which inputs each output depends on directly: ``{output: [inputs]}`` (outputs not
        listed depend on no input), ``True`` (every output on every input; the default)
        or ``False`` (no output on any input).
    port_names_are_identifiers : bool
        Check that port names are identifiers (default True; FMU variables such as
        ``der(x)`` are not).

    Attributes
    ----------
    name : str
    period : float
    input_ports, output_ports : tuple of Port
    input_names, output_names : list of str
    feedthrough : dict of str to frozenset of str
        Output name -> the input names it depends on directly.
    reentrant : bool
        ``output`` may be called several times at one instant (class attribute, default
        False).
    holds_inputs : bool
        The inputs consumed by ``update`` are held over ``[t, t + period]`` (class
        attribute, default False).
    n_samples : int
        Instants of the last run at which the component computed its outputs (counted by
        the master, or by :meth:`sample`).
    """

    reentrant: bool = False
    holds_inputs: bool = False

    def __init_subclass__(cls, kind: str | None = None, **kwargs):
        super().__init_subclass__(**kwargs)
        if kind is not None:
            COMPONENTS.register(kind, cls)
            cls.kind = kind

    @classmethod
    def from_scenario(cls, name: str, table: dict, context) -> Component:
        """Build the component ``name`` from its scenario table (the keys besides ``name`` and
        ``type``); ``context`` is the :class:`~cosim.scenario.ScenarioContext` (paths relative to
        the scenario, models by name, the checked constructor call). Default:
        ``context.construct(cls, name, table)``, the constructor with the keys as keyword
        arguments, refused with the valid keys named if one is unknown or missing."""
        return context.construct(cls, name, table)

    def __init__(self, name: str, period: float, inputs: Sequence = (), outputs: Sequence = (),
                 feedthrough: Mapping[str, Sequence[str]] | bool = True,
                 port_names_are_identifiers: bool = True):
        self.name = check_name(name)
        self.period = check_period(period, name)
        self.input_ports = _as_ports(inputs, name, "input", port_names_are_identifiers)
        self.output_ports = _as_ports(outputs, name, "output", port_names_are_identifiers)
        self.feedthrough = self._feedthrough(feedthrough)
        self.n_samples = 0

    def _feedthrough(self, spec) -> dict[str, frozenset[str]]:
        ins, outs = set(self.input_names), self.output_names
        if spec is True:
            return {o: frozenset(ins) for o in outs}
        if spec is False or spec is None:
            return {o: frozenset() for o in outs}
        result = {o: frozenset() for o in outs}
        for o, deps in spec.items():
            if o not in result:
                raise ConfigurationError(f"{self.name}: feedthrough names {o!r}, not an output; "
                                         f"outputs: {', '.join(outs)}")
            unknown = set(deps) - ins
            if unknown:
                raise ConfigurationError(f"{self.name}: feedthrough of {o!r} names {sorted(unknown)}, "
                                         f"not inputs; inputs: {', '.join(sorted(ins))}")
            result[o] = frozenset(deps)
        return result

    input_names = property(lambda self: [p.name for p in self.input_ports],
                           doc="Input port names, in order.")
    output_names = property(lambda self: [p.name for p in self.output_ports],
                            doc="Output port names, in order.")

    def required_inputs(self) -> list[str]:
        """Inputs that must be connected (default: all). FMUs return none: their
        unconnected inputs keep their start values."""
        return self.input_names

    def use_inputs(self, names: Sequence[str], sources: Sequence[tuple[str, str]] | None = None) -> None:
        """Called by the master before a run with the names of the connected inputs, in
        the order their values appear in ``u`` (default: every input, in port order), and
        each one's source signal and its FMI type (``sources``, for range checks)."""
        if list(names) != self.input_names:
            raise ConfigurationError(f"{self.name}: every input must be connected")

    def __repr__(self):
        return (f"{type(self).__name__}({self.name!r}, period={self.period}, "
                f"inputs={self.input_names}, outputs={self.output_names})")

    def timing(self) -> str:
        """One line on what an output at ``t`` means (for :meth:`~cosim.core.master.Cosimulation.describe`)."""
        return "sampled: outputs at t from the inputs at t"

    # ------------------------------------------------------------------ the protocol
    def check_run(self, start_time: float, stop_time: float) -> None:  # noqa: B027 - optional
        """Refuse, before anything starts, a run from ``start_time`` to ``stop_time`` [s]
        this component cannot do (raise a :class:`~fmu_models.errors.CosimError` subclass that
        says why). Default: every run is possible."""

    def reset(self, t0: float) -> None:
        """Prepare a run starting at ``t0`` [s] (instantiate, clear state)."""
        self.n_samples = 0

    @abstractmethod
    def output(self, t: float, u: np.ndarray) -> np.ndarray:
        """Outputs at instant ``t`` [s], shape ``(n_outputs,)``, from the inputs ``u``
        (shape ``(n_connected_inputs,)``; only feedthrough inputs are current)."""

    def update(self, t: float, u: np.ndarray) -> None:  # noqa: B027 - optional, default does nothing
        """Consume the inputs ``u`` at instant ``t`` [s] (all current) and advance the state
        to the next instant. Default: nothing."""

    def close(self) -> None:  # noqa: B027 - optional, default does nothing
        """Release resources (called by the master at the end of every run, also after a
        failure; must be safe to call twice)."""

    def _fmu_identifier(self) -> str:
        """A model identifier for this component's FMU (``pc_<name>``)."""
        return f"pc_{self.name}"

    def sample(self, t: float, u) -> np.ndarray:
        """One whole instant outside a master: :meth:`output` then :meth:`update` with the
        same inputs ``u``; returns the outputs at ``t`` [s]. Call :meth:`reset` first."""
        u = np.asarray(u if u is not None else [], dtype=float)
        y = np.asarray(self.output(t, u), dtype=float)
        self.update(t, u)
        self.n_samples += 1
        return y


def _exact(value, type_name: str, owner: str, port: str) -> int:
    """An integer or Boolean output's exact value (a Python int stays exact at any size)."""
    if isinstance(value, (bool, int, np.integer)):
        v = int(value)
    else:
        v = float(value)
        if not np.isfinite(v) or v != int(v):
            raise TypeMismatchError(f"{owner}.{port} ({type_name}) output {value!r}, not an integer")
        v = int(v)
    if type_name == "UInt64" and v >= 2**63:       # kept as its bit pattern in int64
        v -= 2**64
    return v


def bind_protocol(comp: Component, values: np.ndarray, source: np.ndarray, inputs, outputs: slice,
                  integers: np.ndarray | None = None) -> tuple[Callable[[float], None], Callable[[float], None]]:
    """``(output_fn, update_fn)`` calling ``comp``'s :meth:`~Component.output` and
    :meth:`~Component.update` with its inputs read from ``source[inputs]`` and its outputs
    written to ``values[outputs]`` (the number checked): the binding of a component without
    :class:`FastBinding` (``source is values``), and the Jacobi order's binding of any
    component (``source``: the values before the instant). The exact values of integer and
    Boolean output ports also go to ``integers[outputs]``."""
    n_out = outputs.stop - outputs.start
    output, update = comp.output, comp.update
    exact = [(j, outputs.start + j, p.type) for j, p in enumerate(comp.output_ports) if p.kind != "real"]
    if integers is None:
        exact = []

    def output_fn(t: float) -> None:
        y = output(t, source[inputs])
        try:
            ok = len(y) == n_out
        except TypeError:
            ok = False
        if not ok:
            raise ConfigurationError(f"output returned {y!r}, expected {n_out} value(s)")
        values[outputs] = y
        for j, at, type_name in exact:           # integer and Boolean ports: their exact values too
            integers[at] = _exact(y[j], type_name, comp.name, comp.output_names[j])

    def update_fn(t: float) -> None:
        update(t, source[inputs])

    return output_fn, update_fn

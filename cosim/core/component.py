"""The component protocol (:class:`~cosim.core.component.Component`), the one class the master depends on.

At each instant the master calls ``output(t, u)`` (in an order that respects the direct
``feedthrough``), records the row, then ``update(t, u)``; ``reset`` comes before a run, ``close``
after it; a ``reentrant`` component may evaluate ``output`` twice at an instant. Optional
capabilities (``bind``, ``export_fmu``, state estimates) are protocols tested with ``isinstance``.
The whole protocol is on the extending page of the documentation.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np

from fmu_models.errors import ConfigurationError, TypeMismatchError
from fmu_models.infra.checks import check_unique, positive
from fmu_models.infra.registry import Registry

__all__ = ["CLOCK", "COMPONENTS", "PORT_TYPES", "BoundCalls", "Component", "ExportedFMU", "ExportsFMU", "FastBinding",
           "Port", "StateEstimator", "StopRequest", "bind_protocol", "check_name", "port_kind", "ports_compatible",
           "split_port"]

#: FMI type names a port may have, by kind (real, integer incl. enumerations, boolean).
PORT_TYPES = {
    **dict.fromkeys(("Float64", "Float32", "Real"), "real"),
    **dict.fromkeys(("Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64", "Integer",
                     "Enumeration"), "integer"),
    "Boolean": "boolean",
}

#: The type of a clock port, an FMI 3.0 Clock. A clock connection carries its activations and
#: its signal counts them (see :mod:`cosim.core.clocking`).
CLOCK = "Clock"

#: The component types usable in scenario files, by their ``kind``.
COMPONENTS: Registry = Registry("component type")


def port_kind(type_name: str) -> str:
    """``"real"``, ``"integer"`` or ``"boolean"`` for the FMI type name ``type_name`` (see
    :data:`PORT_TYPES`), ``"clock"`` for :data:`CLOCK`."""
    if type_name == CLOCK:
        return "clock"
    if type_name not in PORT_TYPES:
        raise TypeMismatchError(f"port type {type_name!r} is not supported; supported types: "
                                f"{', '.join(PORT_TYPES)}")
    return PORT_TYPES[type_name]


def ports_compatible(src_type: str, dst_type: str) -> bool:
    """True if an output of type ``src_type`` may drive an input of type ``dst_type``: the same
    kind, or an integer or Boolean output into a real input (exact); never a real output into
    an integer or Boolean input (it would round), and a clock only to a clock."""
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
    """A component written as an FMU by :meth:`ExportsFMU.export_fmu`: the ``.fmu`` file ``path``, the
    ``parameters`` (parameter and start values by FMU variable name) that make it behave as the
    component (the SSP's parameter bindings), and a ``note`` of what differs (empty: nothing)."""

    path: Path
    parameters: dict
    note: str = ""


def check_name(name: str, what: str = "component name") -> str:
    """``name`` if it is an ASCII identifier, else :class:`ConfigurationError` naming ``what`` it is
    (FMU, SSP and C names must be ASCII)."""
    if not isinstance(name, str) or not name.isidentifier() or not name.isascii():
        raise ConfigurationError(f"{what} {name!r} must be an ASCII identifier (letters, digits, _)")
    return name


def _as_ports(ports, owner: str, direction: str, check_names: bool) -> tuple[Port, ...]:
    out = tuple(p if isinstance(p, Port) else Port(p) for p in ports)
    for port in out:
        if check_names:
            check_name(port.name, f"{owner}: {direction} port")
        port_kind(port.type)
    check_unique((p.name for p in out), f"{owner}: duplicate {direction} port names:")
    return out


class StopRequest(Exception):           # a request, not an error: the run ends normally
    """Raised by the ``update`` of ``component`` (its name) to end the run normally at ``time`` [s]
    (within its step), for the ``reason`` in words."""

    def __init__(self, component: str, time: float, reason: str = ""):
        super().__init__(f"{component} asked to stop at t = {time:g} s" + (f" ({reason})" if reason else ""))
        self.component, self.time, self.reason = component, float(time), reason


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
    return tuple(ref.split(".", 1))


class BoundCalls:
    """``output`` and ``update`` of a :class:`FastBinding` component through its own
    :meth:`~FastBinding.bind` on a private buffer (calls from outside the master's loop). A
    mixin: the class drops ``self._private`` (sets None) whenever its binding becomes stale, and
    may override ``_set_private_inputs`` for ports that need their exact integer value."""

    _private = None

    def _bound(self, u) -> tuple:
        """``(buf, output_fn, update_fn)`` of the private binding, its inputs set to ``u``."""
        if self._private is None:
            n_in, n_out = len(self.connected_inputs), len(self.output_names)
            buf, ints = np.zeros(n_in + n_out), np.zeros(n_in + n_out, dtype=np.int64)
            self._private = (buf, ints, *self.bind(buf, slice(0, n_in), slice(n_in, n_in + n_out), ints))
        buf, ints, out_fn, upd_fn = self._private
        self._set_private_inputs(buf, ints, u)
        return buf, out_fn, upd_fn

    def _set_private_inputs(self, buf: np.ndarray, ints: np.ndarray, u) -> None:
        n_in = len(self.connected_inputs)
        buf[:n_in] = u
        kinds = {p.name: port_kind(p.type) for p in self.input_ports}
        for i, n in enumerate(self.connected_inputs):
            if kinds[n] != "real":          # a real input may be NaN (a missing measurement)
                ints[i] = int(u[i])

    def output(self, t: float, u: np.ndarray) -> np.ndarray:
        """Outputs at ``t`` [s] from the connected inputs ``u`` (in order); a new array."""
        buf, out_fn, _ = self._bound(u)
        out_fn(t)
        return buf[len(self.connected_inputs):].copy()

    def update(self, t: float, u: np.ndarray) -> None:
        """Set the connected inputs ``u`` and advance over ``[t, t + period]`` (``t`` in s)."""
        _, _, update_fn = self._bound(u)
        update_fn(t)


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
    """A block of the co-simulation (the protocol: see the module documentation).

    Parameters
    ----------
    name : str
        Unique identifier of the component in a co-simulation.
    period : float
        Sample period [s].
    inputs, outputs : sequence of str or Port
        Input and output ports (strings are Float64 ports), kept as ``input_ports`` and
        ``output_ports`` (tuples of Port).
    feedthrough : mapping or bool, optional
        Which inputs each output depends on directly: ``{output: [inputs]}`` (outputs not
        listed depend on no input), ``True`` (every output on every input; the default)
        or ``False``; kept as a dict of output name -> frozenset of input names.
    port_names_are_identifiers : bool
        Check that port names are identifiers (default True; FMU variables such as
        ``der(x)`` are not).

    Attributes
    ----------
    reentrant, holds_inputs : bool
        Class attributes (default False): ``output`` may be called several times at one instant;
        the inputs ``update`` consumes are held over ``[t, t + period]``.
    n_samples : int
        Instants of the last run at which the component computed its outputs.
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
        ``type``); ``context`` is the :class:`~cosim.scenario.ScenarioContext`. Default:
        ``context.construct(cls, name, table)``, the constructor with the keys checked."""
        return context.construct(cls, name, table)

    def __init__(self, name: str, period: float, inputs: Sequence = (), outputs: Sequence = (),
                 feedthrough: Mapping[str, Sequence[str]] | bool = True,
                 port_names_are_identifiers: bool = True):
        self.name = check_name(name)
        self.period = positive(period, f"{name}: sample period")
        self.input_ports = _as_ports(inputs, name, "input", port_names_are_identifiers)
        self.output_ports = _as_ports(outputs, name, "output", port_names_are_identifiers)
        self.feedthrough = self._feedthrough(feedthrough)
        self.n_samples = 0

    def _feedthrough(self, spec) -> dict[str, frozenset[str]]:
        ins, outs = set(self.input_names), self.output_names
        result = {o: frozenset(ins if spec is True else ()) for o in outs}
        if spec is True or spec is False or spec is None:
            return result
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
        """Inputs that must be connected (default: all; FMUs: none, their unconnected inputs
        keep their start values)."""
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

    def check_run(self, start_time: float, stop_time: float) -> None:  # noqa: B027 - optional
        """Refuse, before anything starts, a run from ``start_time`` to ``stop_time`` [s]
        this component cannot do (a :class:`~fmu_models.errors.CosimError` subclass that says
        why). Default: every run is possible."""

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
        """Release resources (called at the end of every run, also after a failure; safe to
        call twice)."""

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
    """The :meth:`FastBinding.bind` of ``comp`` through its :meth:`~Component.output` (the number of
    outputs checked) and :meth:`~Component.update`: outputs to ``values[outputs]`` (and ``integers``),
    inputs from ``source[inputs]`` (``values``; for the Jacobi order, the values before the instant)."""
    n_out = outputs.stop - outputs.start
    output, update = comp.output, comp.update
    exact = [] if integers is None else [(j, outputs.start + j, p.type) for j, p in enumerate(comp.output_ports)
                                         if p.kind != "real"]

    def output_fn(t: float) -> None:
        y = output(t, source[inputs])
        try:
            ok = len(y) == n_out
        except TypeError:
            ok = False
        if not ok:
            raise ConfigurationError(f"output returned {y!r}, expected {n_out} value(s)")
        values[outputs] = y
        for j, at, type_name in exact:
            integers[at] = _exact(y[j], type_name, comp.name, comp.output_names[j])

    def update_fn(t: float) -> None:
        update(t, source[inputs])

    return output_fn, update_fn

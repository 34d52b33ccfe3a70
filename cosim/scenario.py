"""Scenario files (TOML): components, connections and settings of a co-simulation; every
table and key is listed in the co-simulation page of the documentation. Unknown tables and
keys are refused with the valid ones named.
"""
from __future__ import annotations

import inspect
from collections.abc import Callable
from pathlib import Path

from estimators.fmu_model import FMUProcessModel
from fmu_models import get_model
from fmu_models.errors import ConfigurationError, PendulumCosimError, TypeMismatchError, UnknownNameError
from fmu_models.infra.checks import finite
from fmu_models.infra.registry import load_plugin

from . import components as _library  # noqa: F401 - the library's components register themselves
from . import tomlfile
from .core.component import COMPONENTS, Component
from .core.master import Cosimulation
from .fmi import fmu_component as _fmu  # noqa: F401 - registers the fmu component type

__all__ = ["RECORDING_KEYS", "SIMULATION_KEYS", "TABLES", "Scenario", "ScenarioContext", "component_types"]

TABLES = ("title", "plugins", "simulation", "recording", "component", "connections", "plot")
SIMULATION_KEYS = ("stop_time", "start_time", "step_size", "order", "loops", "loop_tolerance",
                   "loop_max_iter", "loop_solver", "engine", "threads")
RECORDING_KEYS = ("signals", "output_interval", "stream")
PLOT_KEYS = ("truth", "estimate", "measured")


def _known(table, valid, where: str) -> None:
    if not isinstance(table, dict):
        raise ConfigurationError(f"{where} must be a table, got {type(table).__name__}")
    unknown = sorted(set(table) - set(valid))
    if unknown:
        raise UnknownNameError(f"{where} has unknown keys {unknown}; valid: {', '.join(valid)}")


def _strings(value, what: str, allow_empty: bool = False) -> list[str]:
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value) or (not value and not allow_empty):
        raise TypeMismatchError(f"{what} must be a list of strings, got {value!r}")
    return list(value)


class ScenarioContext:
    """What a component needs to build itself from a scenario table
    (:meth:`~cosim.core.component.Component.from_scenario`).

    Parameters
    ----------
    base_dir, fmu_dir : path
        As :class:`Scenario` (``fmu_dir`` given, not defaulted).
    """

    def __init__(self, base_dir, fmu_dir):
        self.base_dir, self.fmu_dir = Path(base_dir), Path(fmu_dir)

    def path(self, p, what: str = "path") -> Path:
        """``p`` as a path, relative to the scenario file's folder unless absolute."""
        if not isinstance(p, str) or not p:
            raise TypeMismatchError(f"{what} must be a file name (a string), got {p!r}")
        return self.base_dir / p

    def model(self, name, parameters=None):
        """The registered plant model ``name`` with ``parameters`` (a table) overridden."""
        if not isinstance(parameters, dict | None):
            raise TypeMismatchError(f"model_parameters must be a table, got {parameters!r}")
        return get_model(name, **(parameters or {}))

    @staticmethod
    def check_keys(target: Callable, table: dict, where: str, skip: tuple[str, ...] = ()) -> dict:
        """``table`` if its keys are keyword arguments of ``target`` (a class or a function)
        and every required one (besides ``skip``) is there; else UnknownNameError /
        ConfigurationError naming the keys (``where`` says whose)."""
        params = [p for p in inspect.signature(target).parameters.values() if p.name not in skip]
        if any(p.kind == p.VAR_KEYWORD for p in params):
            return dict(table)
        params = [p for p in params if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
        names = [p.name for p in params]
        unknown = sorted(set(table) - set(names))
        if unknown:
            raise UnknownNameError(f"{where} has the unknown key{'s' if len(unknown) > 1 else ''} "
                                   f"{', '.join(map(repr, unknown))}; valid keys: {', '.join(names)}")
        missing = [p.name for p in params if p.default is p.empty and p.name not in table]
        if missing:
            raise ConfigurationError(f"{where} needs the key{'s' if len(missing) > 1 else ''} "
                                     f"{', '.join(map(repr, missing))}")
        return dict(table)

    def fmu_process_model(self, path, period: float, table: dict, where: str):
        """The process model of the Model Exchange FMU at ``path`` (relative to the scenario
        file) with the sample period ``period`` [s] (:class:`estimators.FMUProcessModel`), from
        the keys of ``table`` it takes out: ``measurements`` (required: FMU outputs or states),
        ``inputs``, ``model_parameters`` (the FMU's parameters by name), ``method`` (default
        ``"rk4"``), ``substeps``, ``jacobian``, ``tolerance``; ``where`` names the component
        in messages."""
        if "measurements" not in table:
            raise ConfigurationError(f"{where}: a model from an FMU needs the key 'measurements' (the FMU outputs or "
                                     "states the filter measures)")
        keys = {k: table.pop(k) for k in ("inputs", "method", "substeps", "jacobian", "tolerance") if k in table}
        return FMUProcessModel(self.path(path, f"{where}: model"), period, table.pop("measurements"),
                               parameters=table.pop("model_parameters", None), **keys)

    def construct_with_model(self, cls: type, name: str, table: dict) -> Component:
        """:meth:`construct` with the table's ``model`` (a registered model's name) and
        ``model_parameters`` turned into the constructor's ``model`` argument."""
        t = dict(table)
        if "model" not in t:        # else model_parameters would be named an unknown key
            raise ConfigurationError(f"component {name!r} ({getattr(cls, 'kind', cls.__name__)}) needs the key "
                                     "'model'")
        t["model"] = self.model(t["model"], t.pop("model_parameters", None))
        return self.construct(cls, name, t)

    def construct(self, cls: type, name: str, table: dict, **extra) -> Component:
        """``cls(name, **table, **extra)`` with the keys checked (:meth:`check_keys`); an
        error of the constructor that is not the package's own is named with the component."""
        where = f"component {name!r} ({getattr(cls, 'kind', cls.__name__)})"
        kwargs = self.check_keys(cls, {**table, **extra}, where, skip=("name",))
        try:
            return cls(name, **kwargs)
        except PendulumCosimError:
            raise
        except (TypeError, ValueError, KeyError, IndexError, AttributeError) as e:
            raise ConfigurationError(f"{where}: {type(e).__name__}: {e}") from None


class Scenario:
    """A parsed scenario: ``cosim`` (the :class:`Cosimulation`), ``start_time`` and
    ``stop_time`` [s], ``title``, and the checked ``recording`` and ``plot`` (or None) tables.

    Parameters
    ----------
    spec : dict
        The scenario as loaded from TOML.
    base_dir : path
        Directory that relative paths in the scenario refer to.
    fmu_dir : path, optional
        Where to build this project's FMUs (default ``<base_dir>/.fmus``), each FMI
        version in its own subfolder.
    """

    def __init__(self, spec: dict, base_dir, fmu_dir=None):
        if not isinstance(spec, dict):
            raise ConfigurationError("a scenario must be a TOML table")
        self.spec, self.base_dir = spec, Path(base_dir)
        self.fmu_dir = Path(fmu_dir) if fmu_dir else self.base_dir / ".fmus"
        _known(spec, TABLES, "the scenario")
        for plugin in _strings(spec.get("plugins", []), "plugins", allow_empty=True):
            load_plugin(plugin, self.base_dir)
        sim = spec.get("simulation")
        if sim is None:
            raise ConfigurationError("the scenario has no [simulation] table (it needs stop_time)")
        _known(sim, SIMULATION_KEYS, "[simulation]")
        if "stop_time" not in sim:
            raise ConfigurationError("[simulation] needs stop_time")
        self.stop_time = finite(sim["stop_time"], "[simulation] stop_time [s]")
        self.start_time = finite(sim.get("start_time", 0.0), "[simulation] start_time [s]")
        self.recording = self._recording(spec.get("recording", {}))
        comps = spec.get("component", [])
        if not isinstance(comps, list) or not comps:
            raise ConfigurationError("the scenario needs at least one [[component]]")
        context = ScenarioContext(self.base_dir, self.fmu_dir)
        components = [self._component(c, context) for c in comps]
        options = {k: v for k, v in sim.items() if k not in ("stop_time", "start_time", "step_size")}
        connections = spec.get("connections", {})
        if not isinstance(connections, dict):
            raise ConfigurationError("[connections] must be a table of \"input\" = \"output\"")
        self.cosim = Cosimulation(components, connections, step_size=sim.get("step_size"), **options)
        self.plot = self._plot(spec.get("plot"))
        self.title = spec.get("title", "")
        if not isinstance(self.title, str):
            raise TypeMismatchError(f"title must be a string, got {self.title!r}")

    @staticmethod
    def _recording(table) -> dict:
        _known(table, RECORDING_KEYS, "[recording]")
        rec = dict(table)
        if "signals" in rec:
            rec["signals"] = _strings(rec["signals"], "[recording] signals")
        if "output_interval" in rec:
            rec["output_interval"] = finite(rec["output_interval"], "[recording] output_interval [s]")
        if "stream" in rec and not isinstance(rec["stream"], bool):
            raise TypeMismatchError(f"[recording] stream must be true or false, got {rec['stream']!r}")
        return rec

    def _plot(self, table) -> dict | None:
        if table is None:
            return None
        _known(table, PLOT_KEYS, "[plot]")
        for key in ("truth", "estimate"):
            if key not in table:
                raise ConfigurationError(f"[plot] needs {key} (a list of signals)")
        plot = {k: _strings(table[k], f"[plot] {k}", allow_empty=(k == "measured")) for k in table}
        if len(plot["truth"]) != len(plot["estimate"]):
            raise ConfigurationError(f"[plot] truth and estimate must name as many signals ({len(plot['truth'])} "
                                     f"and {len(plot['estimate'])})")
        if plot.get("measured") and len(plot["measured"]) != len(plot["truth"]):
            raise ConfigurationError("[plot] measured must name one signal (or \"\") per truth signal")
        known = set(self.cosim.signal_names)
        for key, names in plot.items():
            bad = [n for n in names if n and n not in known]
            if bad:
                raise UnknownNameError(f"[plot] {key} names {bad}, not signals; signals: "
                                       f"{', '.join(self.cosim.signal_names)}")
        return plot

    @classmethod
    def load(cls, path, fmu_dir=None) -> Scenario:
        """Read a TOML scenario file at ``path``; ``fmu_dir`` as in the constructor; a missing
        file, a folder, not TOML or any problem of the scenario is a ConfigurationError."""
        return cls(tomlfile.read(path, "scenario file"), Path(path).parent, fmu_dir)

    def run(self):
        """Run the co-simulation in memory with the scenario's recording settings; returns
        the results DataFrame."""
        rec = {k: v for k, v in self.recording.items() if k != "stream"}
        return self.cosim.run(self.stop_time, self.start_time, **rec)

    @staticmethod
    def _component(c, context: ScenarioContext) -> Component:
        if not isinstance(c, dict):
            raise ConfigurationError(f"a [[component]] must be a table, got {c!r}")
        c = dict(c)
        for key in ("name", "type"):
            if key not in c:
                raise ConfigurationError(f"a [[component]] lacks {key!r}: {c}")
        name, kind = c.pop("name"), c.pop("type")
        if not isinstance(name, str):
            raise TypeMismatchError(f"a component name must be a string, got {name!r}")
        if not isinstance(kind, str) or kind not in COMPONENTS:
            raise UnknownNameError(f"component {name!r}: unknown type {kind!r}; valid types: "
                                   f"{', '.join(component_types())}")
        return COMPONENTS.get(kind).from_scenario(name, c, context)


def component_types() -> list[str]:
    """Names of the component types a scenario file may use (the registered kinds)."""
    return COMPONENTS.names()

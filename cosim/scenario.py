"""Scenario files (TOML): components, connections and settings of a co-simulation.

Example (``cosim/scenarios/seed000_cartpole.toml`` is a complete one)::

    title = "what this scenario shows"

    [simulation]
    stop_time = 5.0
    order = "auto"                  # or "given" (list order), "jacobi"
    loops = "refuse"                # or "iterate" (then loop_solver, loop_tolerance, loop_max_iter)

    [recording]                     # optional
    signals = ["plant.*", "ekf.*"]  # glob patterns (default: all)
    output_interval = 0.01          # s (default: every base step)
    stream = false                  # true: rows go to results.parquet in chunks (long runs)

    [[component]]
    name = "plant"
    type = "fmu"
    model = "cartpole"              # build this project's FMU; or path = "other.fmu"
    fmi_version = 2                 # of the built FMU
    interface = "auto"              # or "cs", "me" (then solver, solver_step, rtol)
    feedthrough = "model"           # or "none": outputs as left limits
    logging = false                 # FMU debug messages to the console
    period = 0.01
    start = { x = 0.5, theta = 1.8 }

    [[component]]
    name = "ekf"
    type = "estimator"
    filter = "EKF"                  # KF, EKF, UKF, IAE, MFIAE
    model = "cartpole"
    period = 0.01
    x0 = [0.5, 0, 1.8, 0.5]
    P0 = 1.0
    Q = 0.2
    R = 0.1

    [connections]                   # input = output
    "ekf.y_x" = "sensor.y_x"

    [plot]                          # optional: truth/estimate figure
    truth = ["plant.x"]
    estimate = ["ekf.x"]

Component types: ``fmu``, ``estimator``, ``lqr``, ``sensor``, ``process_noise``,
``constant``, ``step``, ``sine``, ``prbs``, ``table``. Relative paths are relative to
the scenario file. Unknown tables and keys are refused with the valid ones named.
"""
from __future__ import annotations

import re
import tomllib
from pathlib import Path

from cosim.components.estimation import EstimatorComponent, LQRController
from cosim.components.sensors import ProcessNoise, Sensor
from cosim.components.sources import PRBS, Constant, Sine, Step, Table
from cosim.core.component import Component
from cosim.core.master import Cosimulation
from cosim.fmi.component import FMUComponent
from fmu_models.checks import finite
from fmu_models.errors import ConfigurationError, TypeMismatchError, UnknownNameError

SIMPLE = {"constant": Constant, "step": Step, "sine": Sine, "prbs": PRBS}
TABLES = ("title", "simulation", "recording", "component", "connections", "plot")
SIMULATION_KEYS = ("stop_time", "start_time", "step_size", "order", "loops", "loop_tolerance",
                   "loop_max_iter", "loop_solver")
RECORDING_KEYS = ("signals", "output_interval", "stream")
FILTERS = ("KF", "EKF", "UKF", "IAE", "MFIAE")


def _known(table: dict, valid, where: str) -> None:
    if not isinstance(table, dict):
        raise ConfigurationError(f"{where} must be a table")
    unknown = sorted(set(table) - set(valid))
    if unknown:
        raise UnknownNameError(f"{where} has unknown keys {unknown}; valid: {', '.join(valid)}")


class Scenario:
    """A parsed scenario: ``cosim`` (the :class:`Cosimulation`), ``stop_time``, ``plot``.

    Parameters
    ----------
    spec : dict
        The scenario as loaded from TOML.
    base_dir : path
        Directory that relative paths in the scenario refer to.
    fmu_dir : path, optional
        Where to build this project's FMUs (default ``<base_dir>/.fmus``); each FMI
        version in its own subfolder, so FMI 2.0 and 3.0 builds of one model coexist.

    Attributes
    ----------
    recording : dict
        The ``[recording]`` table (``signals``, ``output_interval``, ``stream``).
    """

    def __init__(self, spec: dict, base_dir, fmu_dir=None):
        self.spec, self.base_dir = spec, Path(base_dir)
        self.fmu_dir = Path(fmu_dir) if fmu_dir else self.base_dir / ".fmus"
        _known(spec, TABLES, "the scenario")
        sim = spec.get("simulation")
        if sim is None:
            raise ConfigurationError("the scenario has no [simulation] table (it needs stop_time)")
        _known(sim, SIMULATION_KEYS, "[simulation]")
        if "stop_time" not in sim:
            raise ConfigurationError("[simulation] needs stop_time")
        self.stop_time = finite(sim["stop_time"], "[simulation] stop_time [s]")
        self.start_time = finite(sim.get("start_time", 0.0), "[simulation] start_time [s]")
        self.recording = dict(spec.get("recording", {}))
        _known(self.recording, RECORDING_KEYS, "[recording]")
        comps = spec.get("component", [])
        if not isinstance(comps, list) or not comps:
            raise ConfigurationError("the scenario needs at least one [[component]]")
        components = [self._component(c) for c in comps]
        options = {k: sim[k] for k in ("order", "loops", "loop_tolerance", "loop_max_iter", "loop_solver")
                   if k in sim}
        self.cosim = Cosimulation(components, spec.get("connections", {}), step_size=sim.get("step_size"),
                                  **options)
        self.plot = spec.get("plot")
        self.title = str(spec.get("title", ""))

    @classmethod
    def load(cls, path, fmu_dir=None) -> Scenario:
        """Read a TOML scenario file at ``path``; ``fmu_dir`` as in the constructor.

        Raises
        ------
        ConfigurationError
            Missing file, a folder, not TOML, or any problem of the scenario itself.
        """
        path = Path(path)
        if path.is_dir():
            raise ConfigurationError(f"{path} is a folder, not a scenario file (.toml)")
        try:
            with open(path, "rb") as f:
                spec = tomllib.load(f)
        except FileNotFoundError:
            raise ConfigurationError(f"no scenario file {path}") from None
        except tomllib.TOMLDecodeError as e:
            raise ConfigurationError(f"{path}: not valid TOML: {e}") from None
        except (OSError, UnicodeDecodeError) as e:
            raise ConfigurationError(f"cannot read {path}: {e}") from None
        return cls(spec, path.parent, fmu_dir)

    def run(self):
        """Run the co-simulation in memory with the scenario's recording settings; returns
        the results DataFrame."""
        rec = {k: v for k, v in self.recording.items() if k != "stream"}
        return self.cosim.run(self.stop_time, self.start_time, **rec)

    # ---------------------------------------------------------------- builders
    def _component(self, c: dict) -> Component:
        if not isinstance(c, dict):
            raise ConfigurationError(f"a [[component]] must be a table, got {c!r}")
        c = dict(c)
        try:
            name, kind = c.pop("name"), c.pop("type")
        except KeyError as e:
            raise ConfigurationError(f"a [[component]] lacks {e.args[0]!r}: {c}") from None
        builders = {"fmu": self._fmu, "estimator": self._estimator, "lqr": self._lqr,
                    "sensor": lambda n, c: Sensor(n, **c),
                    "process_noise": lambda n, c: ProcessNoise(n, **c),
                    "table": self._table,
                    **{k: (lambda n, c, cls=v: cls(n, **c)) for k, v in SIMPLE.items()}}
        if kind not in builders:
            raise UnknownNameError(f"component {name!r}: unknown type {kind!r}; valid types: "
                                   f"{', '.join(builders)}")
        try:
            return builders[kind](name, c)
        except TypeError as e:
            if isinstance(e, TypeMismatchError):
                raise
            text = str(e)
            missing = re.search(r"missing \d+ required (?:positional |keyword-only )?arguments?: (.*)", text)
            unexpected = re.search(r"unexpected keyword argument '(\w+)'", text)
            if missing:
                text = f"needs the key{'s' if ',' in missing.group(1) else ''} {missing.group(1)}"
            elif unexpected:
                text = f"has the unknown key {unexpected.group(1)!r}"
            raise ConfigurationError(f"component {name!r} ({kind}) {text}") from None
        except KeyError as e:
            if isinstance(e, UnknownNameError):
                raise
            raise ConfigurationError(f"component {name!r} ({kind}) needs the key {e.args[0]!r}") from None

    def _path(self, p):
        p = Path(p)
        return p if p.is_absolute() else self.base_dir / p

    def _table(self, name, c):
        return Table(name, c.pop("period"), self._path(c.pop("data")), **c)

    def _fmu(self, name, c):
        if ("model" in c) == ("path" in c):
            raise ConfigurationError(f"component {name!r}: give either model (this project's "
                                     "plant, built on the fly) or path (an .fmu file)")
        if "model" in c:
            from fmu_models import build_fmu, get_model

            version = c.pop("fmi_version", 2)
            model = get_model(c.pop("model"))
            path = build_fmu(model, self.fmu_dir / f"fmi{version}", fmi_version=version)
        else:
            if "fmi_version" in c:
                raise ConfigurationError(f"component {name!r}: fmi_version applies to a built model, "
                                         "not to an FMU file")
            path = self._path(c.pop("path"))
        return FMUComponent(name, path, c.pop("period"), c.pop("inputs", None), c.pop("outputs", None),
                            c.pop("parameters", None), c.pop("start", None), **c)

    def _estimator(self, name, c):
        import estimators
        from fmu_models import get_model

        filt = c.pop("filter")
        if filt not in FILTERS:
            raise UnknownNameError(f"component {name!r}: unknown filter {filt!r}; valid: {', '.join(FILTERS)}")
        model = get_model(c.pop("model"), **c.pop("model_parameters", {}))
        period = c.pop("period")
        system = estimators.discretize(model, period, c.pop("method", "euler"), c.pop("substeps", 1))
        bias = c.pop("bias_on", None)
        if bias:
            system = estimators.augment_rate_bias(system, bias)
        covariance = c.pop("covariance", "diagonal")
        cls = getattr(estimators, filt)
        return EstimatorComponent(name, lambda: cls(system, **c), period, covariance=covariance)

    def _lqr(self, name, c):
        from fmu_models import get_model

        model = get_model(c.pop("model"), **c.pop("model_parameters", {}))
        return LQRController(name, model, **c)


def component_types() -> list[str]:
    """Names of the component types a scenario file may use."""
    return ["fmu", "estimator", "lqr", "sensor", "process_noise", "table", *SIMPLE]


__all__ = ["Component", "Scenario", "component_types"]

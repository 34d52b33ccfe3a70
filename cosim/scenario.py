"""Scenario files (TOML): components, connections and settings of a co-simulation.

Example (``cosim/scenarios/seed000_cartpole.toml`` is a complete one)::

    [simulation]
    stop_time = 5.0
    order = "gauss-seidel"          # or "jacobi"

    [[component]]
    name = "plant"
    type = "fmu"
    model = "cartpole"              # build this project's FMU; or path = "other.fmu"
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
the scenario file.
"""
from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np

from .component import Component
from .estimation import EstimatorComponent, LQRController
from .fmu_component import FMUComponent
from .master import ConfigurationError, Cosimulation
from .sensors import ProcessNoise, Sensor
from .sources import PRBS, Constant, Sine, Step, Table

SIMPLE = {"constant": Constant, "step": Step, "sine": Sine, "prbs": PRBS}


class Scenario:
    """A parsed scenario: ``cosim`` (the :class:`Cosimulation`), ``stop_time``, ``plot``.

    Parameters
    ----------
    spec : dict
        The scenario as loaded from TOML.
    base_dir : path
        Directory that relative paths in the scenario refer to.
    fmu_dir : path, optional
        Where to build this project's FMUs (default ``<base_dir>/.fmus``).
    """

    def __init__(self, spec: dict, base_dir, fmu_dir=None):
        self.spec, self.base_dir = spec, Path(base_dir)
        self.fmu_dir = Path(fmu_dir) if fmu_dir else self.base_dir / ".fmus"
        sim = spec.get("simulation", {})
        unknown = set(sim) - {"stop_time", "start_time", "step_size", "order"}
        if unknown:
            raise ConfigurationError(f"[simulation] has unknown keys {sorted(unknown)}; valid: "
                                     "stop_time, start_time, step_size, order")
        if "stop_time" not in sim:
            raise ConfigurationError("[simulation] needs stop_time")
        self.stop_time, self.start_time = float(sim["stop_time"]), float(sim.get("start_time", 0.0))
        comps = [self._component(c) for c in spec.get("component", [])]
        self.cosim = Cosimulation(comps, spec.get("connections", {}),
                                  step_size=sim.get("step_size"), order=sim.get("order", "auto"))
        self.plot = spec.get("plot")
        self.title = spec.get("title", "")

    @classmethod
    def load(cls, path, fmu_dir=None) -> "Scenario":
        """Read a TOML scenario file."""
        path = Path(path)
        with open(path, "rb") as f:
            try:
                spec = tomllib.load(f)
            except tomllib.TOMLDecodeError as e:
                raise ConfigurationError(f"{path}: not valid TOML: {e}") from None
        return cls(spec, path.parent, fmu_dir)

    def run(self):
        """Run the co-simulation; returns the results DataFrame."""
        return self.cosim.run(self.stop_time, self.start_time)

    # ---------------------------------------------------------------- builders
    def _component(self, c: dict):
        c = dict(c)
        try:
            name, kind = c.pop("name"), c.pop("type")
        except KeyError as e:
            raise ConfigurationError(f"a [[component]] lacks {e.args[0]!r}: {c}") from None
        builders = {"fmu": self._fmu, "estimator": self._estimator, "lqr": self._lqr,
                    "sensor": lambda n, c: Sensor(n, **c),
                    "process_noise": lambda n, c: ProcessNoise(n, **c),
                    "table": lambda n, c: Table(n, c.pop("period"), self._path(c.pop("data")), **c),
                    **{k: (lambda n, c, cls=v: cls(n, **c)) for k, v in SIMPLE.items()}}
        if kind not in builders:
            raise ConfigurationError(f"component {name!r}: unknown type {kind!r}; valid types: "
                                     f"{', '.join(builders)}")
        try:
            return builders[kind](name, c)
        except TypeError as e:
            raise ConfigurationError(f"component {name!r} ({kind}): {e}") from None

    def _path(self, p):
        p = Path(p)
        return p if p.is_absolute() else self.base_dir / p

    def _fmu(self, name, c):
        if ("model" in c) == ("path" in c):
            raise ConfigurationError(f"component {name!r}: give either model (this project's "
                                     "plant, built on the fly) or path (an .fmu file)")
        if "model" in c:
            from fmu_models import get_model
            from fmu_models.build import build_fmu

            model = c.pop("model")
            path = build_fmu(get_model(model), self.fmu_dir, fmi_version=int(c.pop("fmi_version", 2)))
        else:
            path = self._path(c.pop("path"))
        return FMUComponent(name, path, c.pop("period"), c.pop("inputs", None), c.pop("outputs", None),
                            c.pop("parameters", None), c.pop("start", None), **c)

    def _estimator(self, name, c):
        import estimators
        from fmu_models import get_model

        filt = c.pop("filter")
        if filt not in ("KF", "EKF", "UKF", "IAE", "MFIAE"):
            raise ConfigurationError(f"component {name!r}: unknown filter {filt!r}; valid: "
                                     "KF, EKF, UKF, IAE, MFIAE")
        model = get_model(c.pop("model"), **c.pop("model_parameters", {}))
        period = float(c.pop("period"))
        system = estimators.discretize(model, period, c.pop("method", "euler"), c.pop("substeps", 1))
        bias = c.pop("bias_on", None)
        if bias:
            system = estimators.augment_rate_bias(system, bias)
        cls = getattr(estimators, filt)
        kwargs = {k: (np.asarray(v, float) if isinstance(v, list) else v) for k, v in c.items()}
        try:                           # builds one filter now: bad settings fail here
            return EstimatorComponent(name, lambda: cls(system, **kwargs), period)
        except TypeError as e:
            raise ConfigurationError(f"component {name!r} ({filt}): {e}") from None

    def _lqr(self, name, c):
        from fmu_models import get_model

        model = get_model(c.pop("model"), **c.pop("model_parameters", {}))
        return LQRController(name, model, **c)


def component_types() -> list[str]:
    """Names of the component types a scenario file may use."""
    return ["fmu", "estimator", "lqr", "sensor", "process_noise", "table", *SIMPLE]


__all__ = ["Scenario", "component_types", "Component"]

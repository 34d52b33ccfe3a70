"""The experiment protocol: what ``pendulum-cosim experiment NAME`` needs from an experiment.

An experiment is a subclass of :class:`Experiment` registered by name with a class keyword,
``class MyStudy(Experiment, register="my-study")`` (docs/guide/extending.md).
"""
from __future__ import annotations

from pathlib import Path
from typing import ClassVar

from fmu_models.errors import ConfigurationError
from fmu_models.infra.registry import Registry

from .settings import apply_overrides, load_settings

__all__ = ["EXPERIMENTS", "PATHS", "Experiment"]

#: The experiments by name (``pendulum-cosim experiment NAME``).
EXPERIMENTS: Registry = Registry("experiment")
#: The ways a realisation can be run (the vectorised fast path, or the co-simulation master with the plant FMU).
PATHS = ("fast", "master")


class Experiment:
    """An experiment runnable from the command line (docs/guide/extending.md): its ``name``
    (set by the ``register`` class keyword), a one-line ``description`` for ``--help``, its
    named settings ``configs`` (``default_config`` without ``--config``) and the ``paths`` it
    supports (see :data:`PATHS`)."""

    name = ""
    description = ""
    configs: ClassVar[dict] = {}
    default_config = "default"
    paths: tuple[str, ...] = PATHS

    def __init_subclass__(cls, register: str | None = None, **kwargs):
        super().__init_subclass__(**kwargs)
        if register is not None:
            cls.name = register
            EXPERIMENTS.register(register, cls)

    def settings(self, config: str | None = None, settings_file=None, overrides=(), runs: int | None = None,
                 seed: int | None = None):
        """The settings of configuration ``config`` (default ``default_config``) with the
        values of the TOML ``settings_file``, then ``runs``, ``seed`` and every ``name=value``
        of ``overrides`` applied, in that order; ConfigurationError for an unknown
        configuration or setting, or a value of the wrong type."""
        config = config or self.default_config
        if config not in self.configs:
            raise ConfigurationError(f"{self.name}: unknown --config {config!r}; valid: {', '.join(self.configs)}")
        s = self.configs[config]
        if settings_file:
            s = load_settings(s, settings_file)
        quick = [f"{name}={v}" for name, v in (("runs", runs), ("seed", seed)) if v is not None]
        return apply_overrides(s, quick + list(overrides or ()))

    def check_path(self, path: str) -> str:
        """``path`` if this experiment supports it, else ConfigurationError."""
        if path not in self.paths:
            raise ConfigurationError(f"{self.name} runs on the paths {', '.join(self.paths)}, not {path!r}")
        return path

    def run(self, settings, path: str = "fast", backend: str = "processes", n_jobs: int | None = None,
            progress: bool = True):
        """Run the experiment with ``settings`` on ``path`` (``backend``, ``n_jobs`` and
        ``progress`` as :func:`~cosim.experiments.campaign.run_tasks`); returns its result.
        Interrupted, it raises :class:`~fmu_models.errors.Interrupted` with the result of
        what finished as ``partial``."""
        raise NotImplementedError

    def write_report(self, result, settings, out_dir: Path, path: str = "fast", config: str = "custom",
                     partial: bool = False) -> Path:
        """Write the report of ``result`` (from ``settings`` on ``path``, configuration
        ``config``; ``partial``: an interrupted run) into ``out_dir``; returns ``summary.md``."""
        raise NotImplementedError

    def summary(self, result, settings, path: str = "fast", config: str = "custom") -> str:
        """What the command line prints after a run (``result`` of ``settings`` on ``path``,
        configuration ``config``)."""
        return ""

"""The papers' experiments as Monte Carlo campaigns: ``pendulum-cosim experiment NAME``.

Each is an :class:`~cosim.experiments.experiment.Experiment` registered in :data:`EXPERIMENTS`,
over the shared :mod:`.campaign`, :mod:`.settings`, :mod:`.metrics` and :mod:`.common`.
"""
from . import seed000, seed000_sweep, seed001, seed002  # noqa: F401 - each registers its experiment
from .experiment import EXPERIMENTS, PATHS, Experiment

__all__ = ["EXPERIMENTS", "PATHS", "Experiment"]

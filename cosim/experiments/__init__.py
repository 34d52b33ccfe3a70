"""The papers' experiments as Monte Carlo campaigns: ``pendulum-cosim experiment NAME``.

Each experiment is one module with an :class:`~cosim.experiments.experiment.Experiment` subclass
registered by name (:data:`EXPERIMENTS`): :mod:`.seed000` (Table 3), :mod:`.seed000_sweep`
(the robustness map), :mod:`.seed001`, :mod:`.seed002`. Shared machinery: the parallel
campaign runner (:mod:`.campaign`), settings from the command line and files
(:mod:`.settings`), metrics (:mod:`.metrics`) and the pieces the experiments share
(:mod:`.common`).
"""
from . import seed000, seed000_sweep, seed001, seed002  # noqa: F401 - each registers its experiment
from .experiment import EXPERIMENTS, PATHS, Experiment

__all__ = ["EXPERIMENTS", "PATHS", "Experiment"]

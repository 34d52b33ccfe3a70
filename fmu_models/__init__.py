"""Exact symbolic plant models of two benchmark pendulums, and the FMUs of the project.

>>> from fmu_models import get_model
>>> cp = get_model("cartpole", Bc=0.3)
>>> A, B = cp.linearize([0, 0, 0, 0], [0])

A plant model is registered by name where it is defined (:func:`register_model`); the
exceptions of the whole project are in :mod:`fmu_models.errors`.
"""
from __future__ import annotations

from . import errors
from .catalog import MODELS, get_model, model_names, register_model
from .infra.registry import load_plugin
from .infra.version import VERSION as __version__
from .plant import METHODS, PlantModel
from .variables import Variable

__all__ = ["METHODS", "MODELS", "PlantModel", "Variable", "__version__", "build_fmu", "build_fmus", "errors",
           "get_model", "load_plugin", "model_names", "register_model"]


from . import cartpole, iwp  # noqa: F401 - the built-in models register themselves
from .export.plant_fmu import build_fmu, build_fmus

"""Exact symbolic plant models of two benchmark pendulums, and the FMUs of the project.

>>> from fmu_models import get_model
>>> cp = get_model("cartpole", Bc=0.3)
>>> A, B = cp.linearize([0, 0, 0, 0], [0])

A plant model is registered by name where it is defined (:func:`register_model`), so a new
one is one file: :func:`get_model` and every entry point (scenario files, the command
line, the FMU builder) find it. The exceptions of the whole project are in
:mod:`fmu_models.errors`.
"""
from __future__ import annotations

from collections.abc import Callable

from . import errors
from .errors import ConfigurationError
from .plant import METHODS, PlantModel
from .registry import Registry, load_plugin
from .variables import Variable

__all__ = ["METHODS", "MODELS", "PlantModel", "Variable", "build_fmu", "build_fmus", "errors", "get_model",
           "load_plugin", "model_names", "register_model"]

#: The plant models by name: each a function returning the model with its default parameters.
MODELS: Registry[Callable[[], PlantModel]] = Registry("model")
_BASE: dict[str, PlantModel] = {}


def register_model(name: str) -> Callable:
    """Decorator registering a function ``build() -> PlantModel`` as the model ``name``.

    >>> @register_model("double_integrator")      # doctest: +SKIP
    ... def build():
    ...     return PlantModel(...)
    """
    def decorate(build: Callable[[], PlantModel]) -> Callable[[], PlantModel]:
        MODELS.register(name, build)
        _BASE.pop(name, None)
        return build
    return decorate


def model_names() -> list[str]:
    """The names of the registered plant models."""
    return MODELS.names()


def get_model(name: str, **params: float) -> PlantModel:
    """Return the plant model ``name`` (e.g. "cartpole" or "iwp") with parameters overridden by name.

    Raises
    ------
    UnknownNameError
        Unknown model name or parameter name (the message lists the valid ones).
    ConfigurationError
        A parameter value outside its domain, or a registered build function that does not
        return a PlantModel.
    """
    build = MODELS.get(name)
    if name not in _BASE:
        model = build()
        if not isinstance(model, PlantModel):
            raise ConfigurationError(f"model {name!r}: its build function returned {type(model).__name__}, "
                                     "not a PlantModel")
        _BASE[name] = model
    model = _BASE[name]
    return model.with_params(**params) if params else model.with_params()


def build_fmu(model, out_dir=".", fmi_version: int = 2):
    """Build a plant FMU; see :func:`fmu_models.export.plant.build_fmu` (parameters
    ``model``, ``out_dir``, ``fmi_version``)."""
    from .export.plant import build_fmu as build

    return build(model, out_dir, fmi_version)


def build_fmus(out_dir=".", fmi_version: int = 2, models=None):
    """Build the plant FMUs; see :func:`fmu_models.export.plant.build_fmus` (parameters
    ``out_dir``, ``fmi_version``, ``models``)."""
    from .export.plant import build_fmus as build

    return build(out_dir, fmi_version, models)


from . import cartpole, iwp  # noqa: E402,F401 - the built-in models register themselves

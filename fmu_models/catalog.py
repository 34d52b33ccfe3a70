"""The plant models by name: :data:`MODELS`, filled by :func:`register_model` where each
model is defined, and read by :func:`get_model` (parameters overridden by name)."""
from __future__ import annotations

from collections.abc import Callable
from functools import cache

from .errors import ConfigurationError
from .infra.registry import Registry
from .plant import PlantModel

__all__ = ["MODELS", "get_model", "model_names", "register_model"]

#: The plant models by name, each a function returning the model with its default parameters.
MODELS: Registry[Callable[[], PlantModel]] = Registry("model")


def register_model(name: str) -> Callable:
    """Decorator registering a function ``build() -> PlantModel`` as the model ``name``.

    >>> @register_model("double_integrator")      # doctest: +SKIP
    ... def build():
    ...     return PlantModel(...)
    """
    return MODELS.register(name)


def model_names() -> list[str]:
    """The names of the registered plant models."""
    return MODELS.names()


def get_model(name: str, **params: float) -> PlantModel:
    """Return the plant model ``name`` (e.g. "cartpole" or "iwp") with ``params`` overridden by name.

    Raises
    ------
    UnknownNameError
        Unknown model name or parameter name (the message lists the valid ones).
    ConfigurationError
        A parameter value outside its domain, or a build function that does not return a PlantModel.
    """
    return _built(name, MODELS.get(name)).with_params(**params)


@cache
def _built(name: str, build: Callable[[], PlantModel]) -> PlantModel:
    """The model ``build()`` returns, built once per registered function."""
    model = build()
    if not isinstance(model, PlantModel):
        raise ConfigurationError(f"model {name!r}: its build function returned {type(model).__name__}, "
                                 "not a PlantModel")
    return model

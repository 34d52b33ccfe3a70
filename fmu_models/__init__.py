"""Exact symbolic plant models of two benchmark pendulums, and their FMUs.

>>> from fmu_models import get_model
>>> cp = get_model("cartpole", Bc=0.3)
>>> A, B = cp.linearize([0, 0, 0, 0], [0])
"""
from __future__ import annotations

from functools import cache

from . import cartpole, iwp
from .errors import UnknownNameError
from .plant import METHODS, PlantModel
from .variables import Variable

_BUILDERS = {"cartpole": cartpole.build, "iwp": iwp.build}
MODEL_NAMES = tuple(_BUILDERS)

__all__ = ["METHODS", "MODEL_NAMES", "PlantModel", "Variable", "get_model"]


@cache
def _base(name: str) -> PlantModel:
    return _BUILDERS[name]()


def get_model(name: str, **params: float) -> PlantModel:
    """Return the plant model ``name`` ("cartpole" or "iwp") with parameters overridden by name.

    Raises
    ------
    UnknownNameError
        Unknown model name or parameter name (the message lists the valid ones).
    ConfigurationError
        A parameter value outside its domain.
    """
    if not isinstance(name, str) or name not in _BUILDERS:
        raise UnknownNameError(f"unknown model {name!r}; valid models: {', '.join(MODEL_NAMES)}")
    model = _base(name)
    return model.with_params(**params) if params else model.with_params()

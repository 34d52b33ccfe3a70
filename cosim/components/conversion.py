"""A conversion on a connection: ``y = factor * u + offset``, or a table of values (an SSP's
connection transformations and unit conversions)."""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from fmu_models.errors import ConfigurationError, CosimError
from fmu_models.infra.checks import finite

from ..core.component import Component, Port, port_kind

__all__ = ["Conversion"]


class Conversion(Component, kind="conversion"):
    """``y = factor * u + offset`` (reals), or ``y = table[u]`` (integers, Booleans), ``y`` at
    ``t`` from ``u`` at ``t``.

    Parameters
    ----------
    name : str
    period : float
        Sample period [s] (that of the input it drives).
    factor, offset : float
        The linear map (default the identity).
    table : mapping, optional
        Input value -> output value (integers or Booleans), instead of ``factor`` and
        ``offset``; an input value it lacks stops the run.
    input_type, output_type : str
        FMI types of ``u`` and ``y`` (default ``"Float64"``).
    """

    def __init__(self, name: str, period: float, factor: float = 1.0, offset: float = 0.0,
                 table: Mapping | None = None, input_type: str = "Float64", output_type: str = "Float64"):
        super().__init__(name, period, inputs=[Port("u", input_type)], outputs=[Port("y", output_type)])
        self.factor, self.offset = finite(factor, f"{name}: factor"), finite(offset, f"{name}: offset")
        if table is not None and (self.factor != 1.0 or self.offset != 0.0):
            raise ConfigurationError(f"{name}: give a table or factor and offset, not both")
        if table is None and port_kind(output_type) != "real":
            raise ConfigurationError(f"{name}: a linear map gives reals; an output of type {output_type} needs a "
                                     "table")
        self.table = None if table is None else {int(float(k) if isinstance(k, str) else k): v
                                                  for k, v in dict(table).items()}

    def timing(self) -> str:
        if self.table is None:
            return f"y = {self.factor:g} * u + {self.offset:g}, at t from u at t"
        return "y = table[u], at t from u at t"

    def output(self, t: float, u: np.ndarray) -> np.ndarray:
        if self.table is None:
            return np.array([self.factor * u[0] + self.offset])
        key = int(u[0])
        if key not in self.table:
            raise CosimError(f"{self.name}: no table entry for the input value {key} at t = {t:g} s", self.name, t)
        return np.array([float(self.table[key])])

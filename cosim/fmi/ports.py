"""The ports of an FMU: its variables as element ports (an FMI 3.0 array is one port per
element, ``y[1]``, ``A[1,2]``: 1-based, row-major) with exact integer types."""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from fmu_models.errors import ConfigurationError, TypeMismatchError

__all__ = ["INTEGER_RANGES", "REAL_TYPES", "ElementPort", "array_shape", "check_declared_range", "check_integer",
           "element_ports", "integer_range", "parse_start"]

#: The FMI real types.
REAL_TYPES = ("Real", "Float64", "Float32")
#: The value range of every FMI integer type (FMI 1.0's and 2.0's Integer and Enumeration are
#: 32-bit; FMI 3.0's Enumeration is 64-bit).
INTEGER_RANGES = {
    "Int8": (-2**7, 2**7 - 1), "UInt8": (0, 2**8 - 1), "Int16": (-2**15, 2**15 - 1), "UInt16": (0, 2**16 - 1),
    "Int32": (-2**31, 2**31 - 1), "UInt32": (0, 2**32 - 1), "Int64": (-2**63, 2**63 - 1), "UInt64": (0, 2**64 - 1),
    "Integer": (-2**31, 2**31 - 1), "Boolean": (0, 1),
}


def integer_range(type_name: str, version: int) -> tuple[int, int]:
    """The value range of the FMI integer, Enumeration or Boolean ``type_name`` in FMI ``version``."""
    if type_name == "Enumeration":
        return INTEGER_RANGES["Int32" if version < 3 else "Int64"]
    return INTEGER_RANGES[type_name]


def check_integer(value, type_name: str, version: int, what: str) -> int:
    """``value`` as an exact Python int within the range of ``type_name`` (in FMI ``version``);
    else TypeMismatchError (not an integer; a float beyond 2**53 is not exact) or
    ConfigurationError (out of range) naming ``what``, the value and the range."""
    if isinstance(value, (bool, np.bool_)):
        raise TypeMismatchError(f"{what}: {value!r} is a Boolean, not an integer (the variable is {type_name})")
    if isinstance(value, (int, np.integer)):
        v = int(value)
    else:
        try:
            f = float(value)
        except (TypeError, ValueError):
            f = math.nan
        if not (math.isfinite(f) and f == int(f)):
            raise TypeMismatchError(f"{what}: {value!r} is not an integer (the variable is {type_name})")
        if abs(f) > 2**53:
            raise TypeMismatchError(f"{what}: {value!r} is a float beyond 2**53, not an exact integer; give it as "
                                    "an integer")
        v = int(f)
    lo, hi = integer_range(type_name, version)
    if not lo <= v <= hi:
        raise ConfigurationError(f"{what}: {v} is outside the range of {type_name} [{lo}, {hi}]")
    return v


def check_declared_range(values: list, variable, what: str) -> None:
    """Refuse ``values`` outside the ``variable``'s declared ``min``/``max`` (an error by the
    standard), naming ``what``, the value and the range."""
    conv = float if variable.type in REAL_TYPES else int
    try:
        lo = -math.inf if variable.min is None else conv(variable.min)
        hi = math.inf if variable.max is None else conv(variable.max)
    except (TypeError, ValueError):
        return                                   # an unreadable bound: nothing to go by
    for x in values:
        if not lo <= x <= hi:
            raise ConfigurationError(f"{what}: {x!r} is outside the range the FMU declares for "
                                     f"{variable.name!r} [{lo}, {hi}]")


def parse_start(variable, count: int) -> list:
    """The start value(s) of ``variable`` as Python numbers, ``count`` of them (one value may
    stand for all elements); zeros if it has none."""
    if variable.start is None:
        return [0] * count
    cast = float if variable.type in REAL_TYPES else int
    conv = [int(p in ("true", "1")) if variable.type == "Boolean" else cast(p) for p in str(variable.start).split()]
    if len(conv) == 1 and count > 1:
        conv = conv * count
    if len(conv) != count:
        raise ConfigurationError(f"variable {variable.name!r}: {len(conv)} start values for {count} elements")
    return conv


def array_shape(variable, structural: Mapping[str, int]) -> tuple[int, ...]:
    """The shape of ``variable`` (``()`` for a scalar) from its dimensions: fixed sizes, or
    structural parameters whose values are in ``structural`` (by name)."""
    shape = []
    for d in getattr(variable, "dimensions", []) or []:
        if d.start is not None:
            shape.append(int(d.start))
        elif d.variable is not None:
            if d.variable.name not in structural:
                raise ConfigurationError(f"variable {variable.name!r}: its dimension {d.variable.name!r} has no value")
            shape.append(int(structural[d.variable.name]))
        else:
            raise ConfigurationError(f"variable {variable.name!r}: a dimension without a size")
    if any(n < 0 for n in shape):
        raise ConfigurationError(f"variable {variable.name!r}: negative dimension {shape}")
    return tuple(shape)


@dataclass(frozen=True)
class ElementPort:
    """One port of an FMU: an element of a variable.

    Attributes
    ----------
    name : str
        The port name (the variable's, or ``name[i,j]`` for an array element).
    variable : fmpy ModelVariable
    offset : int
        The element's position in the variable's values (0 for a scalar).
    size : int
        The number of the variable's values (1 for a scalar).
    type : str
        The FMI type name.
    discrete : bool
        The variable is not continuous-time (an ME FMU takes it only in Event Mode).
    """

    name: str
    variable: object
    offset: int
    size: int
    type: str
    discrete: bool


def element_ports(md, structural: Mapping[str, int]) -> dict[str, ElementPort]:
    """Every element port of the FMU ``md`` (fmpy's), by name, for the ``structural`` parameters' values."""
    ports = {}
    for v in md.modelVariables:
        if v.causality in ("parameter", "structuralParameter", "calculatedParameter", "independent"):
            continue
        shape = array_shape(v, structural)
        size = math.prod(shape)
        discrete = v.variability not in ("continuous", None) or v.type not in REAL_TYPES
        names = [f"{v.name}[{','.join(str(i + 1) for i in idx)}]" for idx in np.ndindex(*shape)] if shape else [v.name]
        for k, n in enumerate(names):
            ports[n] = ElementPort(n, v, k, size, v.type, discrete)
    return ports

"""The ports of an FMU: its variables, scalar or array, as element ports with exact types.

An FMI 3.0 array variable (``<Dimension start=.../>`` or ``valueReference=...``, a
structural parameter) becomes one port per element, named as the standard's structured
naming does (1-based): ``y[1]``, ``y[2]``; ``A[1,2]`` for a matrix (row-major, the order
of the FMI values). Its shape comes from the dimensions' start values, or from the
structural parameters' values (their start values, or what the component sets).

Integer types keep their exact range (:data:`INTEGER_RANGES`): a value is checked against
the destination's type before it is set (:func:`check_integer`), never wrapped.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from fmu_models.errors import ConfigurationError, TypeMismatchError

__all__ = ["INTEGER_RANGES", "ElementPort", "array_shape", "check_integer", "element_ports", "integer_range",
           "parse_start"]

#: The value range of every FMI integer type (FMI 1.0's and 2.0's Integer and Enumeration are
#: 32-bit; FMI 3.0's Enumeration is 64-bit).
INTEGER_RANGES = {
    "Int8": (-2**7, 2**7 - 1), "UInt8": (0, 2**8 - 1), "Int16": (-2**15, 2**15 - 1), "UInt16": (0, 2**16 - 1),
    "Int32": (-2**31, 2**31 - 1), "UInt32": (0, 2**32 - 1), "Int64": (-2**63, 2**63 - 1), "UInt64": (0, 2**64 - 1),
    "Integer": (-2**31, 2**31 - 1), "Boolean": (0, 1),
}


def integer_range(type_name: str, version: int) -> tuple[int, int]:
    """The value range of the FMI ``type_name`` (an integer, Enumeration or Boolean type) in FMI
    ``version``."""
    if type_name == "Enumeration":
        return INTEGER_RANGES["Int32" if version < 3 else "Int64"]
    return INTEGER_RANGES[type_name]


def check_integer(value, type_name: str, version: int, what: str) -> int:
    """``value`` as an exact Python int within the range of ``type_name`` (in FMI ``version``);
    else TypeMismatchError (not an integer) or ConfigurationError (out of range) naming
    ``what``, the value and the range. Python ints (from TOML) are exact at any size; a
    float must be integral and below 2**53 (beyond, it is not exact)."""
    if isinstance(value, (bool, np.bool_)):
        raise TypeMismatchError(f"{what}: {value!r} is a Boolean, not an integer (the variable is {type_name})")
    if isinstance(value, (int, np.integer)):
        v = int(value)
    else:
        try:
            f = float(value)
        except (TypeError, ValueError):
            raise TypeMismatchError(f"{what}: {value!r} is not an integer (the variable is {type_name})") from None
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
    """Refuse values outside the variable's declared ``min``/``max`` (the standard makes
    them an error), naming ``what``, the value and the range."""
    real = variable.type in ("Real", "Float64", "Float32")
    conv = float if real else int
    try:
        lo = conv(variable.min) if variable.min is not None else None
        hi = conv(variable.max) if variable.max is not None else None
    except (TypeError, ValueError):
        return                                   # an unreadable bound: nothing to go by
    if lo is None and hi is None:
        return
    for x in values:
        if (lo is not None and x < lo) or (hi is not None and x > hi):
            raise ConfigurationError(f"{what}: {x!r} is outside the range the FMU declares for "
                                     f"{variable.name!r} [{'-inf' if lo is None else lo}, "
                                     f"{'inf' if hi is None else hi}]")


def parse_start(variable, count: int) -> list:
    """The start value(s) of ``variable`` as Python numbers, ``count`` of them (an array's
    start may hold one value for all elements); zeros if it has none."""
    text = variable.start
    if text is None:
        return [0] * count
    parts = str(text).split()
    real = variable.type in ("Real", "Float64", "Float32")
    conv = []
    for p in parts:
        if variable.type == "Boolean":
            conv.append(1 if p in ("true", "1") else 0)
        elif real:
            conv.append(float(p))
        else:
            conv.append(int(p))
    if len(conv) == 1 and count > 1:
        conv = conv * count
    if len(conv) != count:
        raise ConfigurationError(f"variable {variable.name!r}: {len(conv)} start values for {count} elements")
    return conv


def array_shape(variable, structural: Mapping[str, int]) -> tuple[int, ...]:
    """The shape of ``variable`` (``()`` for a scalar) from its dimensions: fixed ``start``
    sizes or structural parameters, whose values are in ``structural`` (by name)."""
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


def _element_names(name: str, shape: tuple[int, ...]) -> list[str]:
    if not shape:
        return [name]
    return [f"{name}[{','.join(str(i + 1) for i in idx)}]" for idx in np.ndindex(*shape)]


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
    """Every element port of the FMU ``md`` (fmpy ModelDescription), by name, for the
    structural-parameter values ``structural``."""
    ports = {}
    for v in md.modelVariables:
        if v.causality in ("parameter", "structuralParameter", "calculatedParameter", "independent"):
            continue
        shape = array_shape(v, structural)
        size = int(np.prod(shape)) if shape else 1
        discrete = v.variability not in ("continuous", None) or v.type not in ("Real", "Float64", "Float32")
        for k, n in enumerate(_element_names(v.name, shape)):
            ports[n] = ElementPort(n, v, k, size, v.type, discrete)
    return ports

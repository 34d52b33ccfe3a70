"""Named, unit-carrying descriptors for a plant's states, inputs, outputs and parameters."""
from __future__ import annotations

import math
from dataclasses import dataclass

from .errors import ConfigurationError, TypeMismatchError
from .infra.checks import finite

#: Admissible value sets for a parameter; checked in Python and in the generated FMU.
DOMAINS = ("real", "positive", "nonnegative", "unit", "sign")


def check_declaration(kind: str, name: str, domain: str) -> None:
    """Refuse (ConfigurationError) a declared ``kind`` of thing (``"variable"``, ``"parameter"``)
    whose ``name`` is not a legal identifier or whose ``domain`` is not one of :data:`DOMAINS`."""
    if not name.isidentifier():
        raise ConfigurationError(f"{kind} name {name!r} is not a legal identifier")
    if domain not in DOMAINS:
        raise ConfigurationError(f"{kind} {name!r}: domain {domain!r} not in {DOMAINS}")


@dataclass(frozen=True)
class Variable:
    """One named scalar of a plant model.

    Parameters
    ----------
    name, unit, description : str
        Identifier, also the FMI variable name (a legal C identifier); SI unit string (``"m"``,
        ``"N.s/m"``; ``"1"`` if dimensionless); one line shown to users and in ``modelDescription.xml``.
    start : float
        Default value (parameter value, state start value, input start value).
    domain : str
        For parameters: one of :data:`DOMAINS`. ``"unit"`` is (0, 1], ``"sign"`` admits only -1 and +1.
    """

    name: str
    unit: str
    description: str
    start: float = 0.0
    domain: str = "real"

    def __post_init__(self):
        check_declaration("variable", self.name, self.domain)

    def measured(self, description: str) -> Variable:
        """The output ``y_<name>`` measuring this variable, in its unit, described by ``description``."""
        return Variable(f"y_{self.name}", self.unit, description)

    def check(self, value: float) -> float:
        """``value`` as float if it lies in this variable's domain, else ConfigurationError
        (TypeMismatchError for a non-number)."""
        if isinstance(value, (str, bytes)):
            raise TypeMismatchError(f"parameter {self.name!r} must be a number, got {value!r}")
        v = finite(value, f"parameter {self.name!r}")
        test, rule = _RULES[self.domain]
        if not test(v):
            raise ConfigurationError(f"parameter {self.name!r}{rule.format(unit=self.unit)}, got {v}")
        return v


#: Each domain's test and the rule its message states (``real``: finite, already checked).
_RULES = {
    "real": (math.isfinite, ""),
    "positive": (lambda v: v > 0.0, " [{unit}] must be > 0"),
    "nonnegative": (lambda v: v >= 0.0, " [{unit}] must be >= 0"),
    "unit": (lambda v: 0.0 < v <= 1.0, " must be in (0, 1]"),
    "sign": (lambda v: v in (-1.0, 1.0), " must be -1 or +1"),
}

"""The variables of an FMU the project writes, the one list behind its ``modelDescription.xml`` and its
``model_config.h``, where each *group* of consecutive value references (``"P"`` the Real parameters, ...)
becomes ``VR_<group>`` (its first value reference) and ``N_<group>`` (its size)."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

__all__ = ["FmuVariable", "VariableList"]


@dataclass(frozen=True)
class FmuVariable:
    """One FMU variable.

    Attributes
    ----------
    name, vr : str, int
        FMI name and value reference (the ModelVariables index is ``vr + 1``).
    type : {"Real", "Integer", "Enumeration", "Boolean", "Clock"}
        FMI 2.0 type name (FMI 3.0: Float64, Int32, Enumeration, Boolean; Clock: FMI 3.0 only).
    causality, variability, initial, start, unit, description
        As the FMI standard (None: not written).
    group, domain : str
        The value-reference group of the C core; the admissible values of a Real parameter
        (:data:`~fmu_models.variables.DOMAINS`).
    derivative_of, declared_type, min, max : optional
        1-based index of the state it is the derivative of; the type of an Enumeration; an Integer's range.
    clocks, clock : tuple of int, dict
        Value references of its clocks (empty: not clocked); a Clock's attributes (``intervalDecimal`` [s], ...).
    """

    name: str
    vr: int
    type: str
    causality: str
    variability: str
    initial: str | None = None
    start: float | int | bool | None = None
    unit: str | None = None
    description: str = ""
    group: str = ""
    domain: str = "real"
    derivative_of: int | None = None
    declared_type: str | None = None
    min: int | None = None
    max: int | None = None
    clocks: tuple[int, ...] = ()
    clock: dict | None = None


class VariableList:
    """The list ``variables``, added in value-reference order (``vr`` = position) by :meth:`add`
    (or :meth:`parameter`, :meth:`input`, :meth:`output`, :meth:`time` for the common kinds)."""

    def __init__(self):
        self.variables: list[FmuVariable] = []

    def add(self, **fields) -> FmuVariable:
        """Append a variable (``vr`` is its position); returns it."""
        v = FmuVariable(vr=len(self.variables), **fields)
        self.variables.append(v)
        return v

    def parameter(self, name: str, start, description: str, group: str = "P", **fields) -> FmuVariable:
        """Append the fixed parameter ``name`` of exact ``start`` value, ``description``, in
        ``group``; ``fields``: more :class:`FmuVariable` fields (``type`` default Real)."""
        return self.add(**{"type": "Real", **fields}, name=name, causality="parameter", variability="fixed",
                        initial="exact", start=start, description=description, group=group)

    def input(self, name: str, start, description: str, group: str, **fields) -> FmuVariable:
        """Append the input ``name`` with ``start`` value, ``description``, in ``group``; ``fields``:
        more :class:`FmuVariable` fields (``type`` default Real, ``variability`` continuous)."""
        return self.add(**{"type": "Real", "variability": "continuous", **fields}, name=name, causality="input",
                        start=start, description=description, group=group)

    def output(self, name: str, description: str, group: str, **fields) -> FmuVariable:
        """Append the calculated Real output ``name`` with ``description`` in ``group``; ``fields``:
        more :class:`FmuVariable` fields (``variability`` default continuous)."""
        return self.add(**{"variability": "continuous", **fields}, name=name, type="Real", causality="output",
                        initial="calculated", description=description, group=group)

    def time(self, unit: str | None = "s") -> FmuVariable:
        """Append the independent variable ``time`` in ``unit`` (group ``TIME``)."""
        return self.add(name="time", type="Real", causality="independent", variability="continuous", unit=unit,
                        description="simulation time", group="TIME")

    def group(self, name: str) -> list[FmuVariable]:
        """The variables of group ``name``, in order."""
        return [v for v in self.variables if v.group == name]

    def indices(self, groups: Sequence[str]) -> list[int]:
        """1-based ModelVariables indices of every variable in ``groups``."""
        return [v.vr + 1 for v in self.variables if v.group in groups]

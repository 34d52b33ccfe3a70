"""The clocked form of the project's FMUs (FMI 3.0): an input clock ``sample`` whose
activations are the component's sample instants.

A clocked FMU has one Clock variable ``sample`` (``causality="input"``,
``intervalVariability="constant"``, ``intervalDecimal`` the sample period, shift 0: the first
activation is at the start time; ``priority="0"`` for Scheduled Execution), and its inputs
and outputs carry ``clocks="<sample's value reference>"``: they are set and got only while
the clock is active. The C side is in ``c/core_api.h`` and ``c/fmi3_wrapper.c``
(``CLOCK_VR`` and ``CLOCK_INTERVAL`` in ``model_config.h`` select it); the FMU offers
Co-Simulation with Event Mode and Scheduled Execution (one model partition, the clock's).
"""
from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from ..errors import ConfigurationError
from .variable_list import VariableList

__all__ = ["CLOCK_NAME", "check_clocked", "clock_defines", "clock_variables"]

#: The name of the input clock of a clocked FMU.
CLOCK_NAME = "sample"


def check_clocked(clocked: bool, fmi_version: int, what: str) -> None:
    """Refuse ``clocked`` with an FMI version that has no clocks.

    Parameters
    ----------
    clocked
        The clocked form is asked.
    fmi_version
        2 or 3.
    what
        What is exported (for the message).

    Raises
    ------
    ConfigurationError
        ``clocked`` with ``fmi_version`` other than 3.
    """
    if not isinstance(clocked, bool):
        raise ConfigurationError(f"clocked must be True or False, got {clocked!r}")
    if clocked and fmi_version != 3:
        raise ConfigurationError(f"{what}: the clocked form needs FMI 3.0 (FMI {fmi_version}.0 has no clocks); "
                                 "use fmi_version=3 (--fmi-version 3)")


def clock_variables(variables: VariableList, groups: Sequence[str], period: float, description: str) -> VariableList:
    """``variables`` with the clock ``sample`` appended (group ``CLOCK``) and the variables of
    ``groups`` clocked by it (and discrete, as clocked variables are).

    Parameters
    ----------
    variables
        The unclocked FMU's variables (value references kept).
    groups
        The groups whose variables the clock clocks.
    period
        The clock's constant interval [s] (> 0).
    description
        What the activations are (the clock's description).
    """
    if not period > 0:
        raise ConfigurationError(f"the interval of the clock {CLOCK_NAME!r} must be > 0, got {period!r}")
    vr = len(variables.variables)
    out = VariableList()
    for v in variables.variables:
        out.variables.append(dataclasses.replace(v, clocks=(vr,), variability="discrete") if v.group in groups else v)
    out.add(name=CLOCK_NAME, type="Clock", causality="input", variability="discrete", description=description,
            group="CLOCK", clock=dict(intervalVariability="constant", intervalDecimal=repr(float(period)), priority=0))
    return out


def clock_defines(variables: VariableList, period: float) -> list[tuple[str, object]]:
    """The ``model_config.h`` defines of the clocked form (``CLOCK_VR``, ``CLOCK_INTERVAL``
    [s]); none for an FMU without the clock.

    Parameters
    ----------
    variables
        The FMU's variables (with the clock from :func:`clock_variables`, or without).
    period
        The clock's interval [s].
    """
    clock = variables.group("CLOCK")
    if not clock:
        return []
    return [("CLOCK_VR", clock[0].vr), ("CLOCK_INTERVAL", repr(float(period)))]

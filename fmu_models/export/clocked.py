"""The clocked form of the project's FMUs (FMI 3.0): one input Clock ``sample`` of constant interval (the
sample period) that clocks the inputs and outputs; Co-Simulation with Event Mode and Scheduled Execution,
the C side selected by ``CLOCK_VR`` and ``CLOCK_INTERVAL`` (the user guide's page "Taking the estimator to
another tool")."""
from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from ..errors import ConfigurationError
from .variable_list import VariableList

__all__ = ["CLOCK_NAME", "check_clocked", "clock_defines", "clock_variables"]

#: The name of the input clock of a clocked FMU.
CLOCK_NAME = "sample"


def check_clocked(clocked: bool, fmi_version: int, what: str) -> None:
    """Refuse ``clocked`` (the clocked form is asked) with an ``fmi_version`` (2 or 3) that has no clocks;
    ``what`` is exported (for the message).

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
    variables, groups, period, description
        The unclocked FMU's variables (value references kept), the groups the clock clocks, its
        constant interval [s] (> 0) and what its activations are.
    """
    if not period > 0:
        raise ConfigurationError(f"the interval of the clock {CLOCK_NAME!r} must be > 0, got {period!r}")
    vr = len(variables.variables)
    out = VariableList()
    out.variables = [dataclasses.replace(v, clocks=(vr,), variability="discrete") if v.group in groups else v
                     for v in variables.variables]
    out.add(name=CLOCK_NAME, type="Clock", causality="input", variability="discrete", description=description,
            group="CLOCK", clock=dict(intervalVariability="constant", intervalDecimal=repr(float(period)), priority=0))
    return out


def clock_defines(variables: VariableList, period: float) -> list[tuple[str, object]]:
    """The ``model_config.h`` defines ``CLOCK_VR`` and ``CLOCK_INTERVAL`` of the clock of
    ``variables`` (from :func:`clock_variables`) of interval ``period`` [s]; none without it."""
    clock = variables.group("CLOCK")
    return [("CLOCK_VR", clock[0].vr), ("CLOCK_INTERVAL", repr(float(period)))] if clock else []

"""A clocked FMI 3.0 FMU in a run: the standard's call sequences for clocks (the FMU's
clocks as :mod:`cosim.fmi.clocks` reads them; the master's side in
:mod:`cosim.core.clocking`), one module per interface over a shared part.

* :mod:`cosim.fmi.clock_timing`: Initialization Mode (the clocks' intervals set or asked)
  and the timing of a run (the periodic clocks' patterns, the aperiodic and triggered
  clocks due, the intervals read at run time);
* :mod:`cosim.fmi.clock_ports`: the clocked and unclocked inputs and outputs, the output
  clocks' counts and sinks;
* :mod:`cosim.fmi.clock_event`: Event Mode (Model Exchange and Co-Simulation);
* :mod:`cosim.fmi.clock_cs`: Co-Simulation with Event Mode and early return;
* :mod:`cosim.fmi.clock_me`: Model Exchange;
* :mod:`cosim.fmi.clock_se`: Scheduled Execution.

Every call's status is checked; a failing call raises
:class:`~fmu_models.errors.FMUError` naming the call, the time and the FMU's message.
"""
from __future__ import annotations

from ..core.clocking import ClockBoard
from .clock_cs import CSClockedRun
from .clock_me import MEClockedRun
from .clock_se import SEClockedRun
from .clock_timing import ClockedRun

__all__ = ["clocked_run"]


def clocked_run(comp, board: ClockBoard, values, inputs, outputs, integers, integrator=None) -> ClockedRun:
    """The run of clocked FMU component ``comp`` in its interface; its methods ``output``
    and ``update`` are the component's bound output and update functions.

    Parameters
    ----------
    comp, board, values, inputs, outputs, integers
        As for :class:`~cosim.fmi.clock_ports.ClockPorts`.
    integrator : MEIntegrator, optional
        Model Exchange: the component's integrator, whose events go through the run.
    """
    if comp.interface == "me":
        return MEClockedRun(comp, board, values, inputs, outputs, integers, integrator)
    cls = CSClockedRun if comp.interface == "cs" else SEClockedRun
    return cls(comp, board, values, inputs, outputs, integers)

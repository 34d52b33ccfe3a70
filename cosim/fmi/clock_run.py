"""A clocked FMI 3.0 FMU in a run: the call sequence of its interface, Co-Simulation with
Event Mode (:mod:`cosim.fmi.clock_cs`), Model Exchange (:mod:`cosim.fmi.clock_me`) or
Scheduled Execution (:mod:`cosim.fmi.clock_se`); see the clocks page of the documentation.
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
    return (CSClockedRun if comp.interface == "cs" else SEClockedRun)(comp, board, values, inputs, outputs, integers)

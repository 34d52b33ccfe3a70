"""The master core: the component protocol (:mod:`.component`), the master (:mod:`.master`),
the static schedule (:mod:`.schedule`), clocks (:mod:`.clocking`) and the recording of
signals (:mod:`.recording`)."""
from .clocking import ClockedComponent, ClockTicks
from .component import CLOCK, COMPONENTS, Component, ExportedFMU, ExportsFMU, FastBinding, Port, StateEstimator
from .master import Cosimulation
from .recording import MemorySink, ParquetSink, select_signals

__all__ = ["CLOCK", "COMPONENTS", "ClockTicks", "ClockedComponent", "Component", "Cosimulation", "ExportedFMU",
           "ExportsFMU", "FastBinding", "MemorySink", "ParquetSink", "Port", "StateEstimator", "select_signals"]

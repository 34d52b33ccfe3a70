"""The master core: the component protocol (:mod:`.component`), the master (:mod:`.master`),
the static schedule (:mod:`.schedule`) and the recording of signals (:mod:`.recording`)."""
from .component import COMPONENTS, Component, ExportedFMU, ExportsFMU, FastBinding, Port, StateEstimator
from .master import Cosimulation
from .recording import MemorySink, ParquetSink, select_signals

__all__ = ["COMPONENTS", "Component", "Cosimulation", "ExportedFMU", "ExportsFMU", "FastBinding", "MemorySink",
           "ParquetSink", "Port", "StateEstimator", "select_signals"]

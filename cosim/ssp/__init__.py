"""SSP 1.0 (System Structure and Parameterization): a co-simulation written as an SSP
(:mod:`cosim.ssp.export`), and an SSP from any tool run in the project's master (:mod:`cosim.ssp.read`)."""
from .export import SSPExport, export_component, export_ssp
from .read import SSPSystem, open_ssp, run_ssp

__all__ = ["SSPExport", "SSPSystem", "export_component", "export_ssp", "open_ssp", "run_ssp"]

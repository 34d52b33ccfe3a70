"""SSP 1.0 (System Structure and Parameterization): a co-simulation written as an SSP
(:mod:`cosim.ssp.export`), and an SSP from any tool opened and run in the project's master
(:mod:`cosim.ssp.read`: nested systems, parameter files and mappings, transformations and
unit conversions on connections; :mod:`cosim.ssp.system`, :mod:`cosim.ssp.parameters` and
:mod:`cosim.ssp.schema` say how).
"""
from .export import SSPExport, export_component, export_ssp
from .read import SSPSystem, open_ssp, run_ssp

__all__ = ["SSPExport", "SSPSystem", "export_component", "export_ssp", "open_ssp", "run_ssp"]

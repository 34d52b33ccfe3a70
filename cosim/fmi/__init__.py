"""FMU importing: an FMI 1.0, 2.0 or 3.0 FMU as a co-simulation component, connected Model Exchange
FMUs as one system, Model Exchange integration, crash isolation, typed value exchange, safe unpacking."""
from .archive import Extraction, read_description
from .description import INTERFACES
from .fmu_component import FEEDTHROUGH_MODES, FMUComponent
from .me_system import MESystem
from .model_exchange import SOLVERS, MEIntegrator

__all__ = ["FEEDTHROUGH_MODES", "INTERFACES", "SOLVERS", "Extraction", "FMUComponent", "MEIntegrator", "MESystem",
           "read_description"]

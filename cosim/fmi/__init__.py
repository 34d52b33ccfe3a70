"""FMU importing: an FMI 2.0 or 3.0 FMU as a co-simulation component (:mod:`.component`),
its Model Exchange integration (:mod:`.model_exchange`), typed value exchange with its C
functions (:mod:`.exchange`) and safe unpacking (:mod:`.archive`)."""
from .archive import Extraction, read_description
from .component import FEEDTHROUGH_MODES, INTERFACES, FMUComponent
from .model_exchange import SOLVERS, MEIntegrator

__all__ = ["FEEDTHROUGH_MODES", "INTERFACES", "SOLVERS", "Extraction", "FMUComponent", "MEIntegrator",
           "read_description"]

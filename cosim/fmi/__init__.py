"""FMU importing: an FMI 1.0, 2.0 or 3.0 FMU as a co-simulation component (:mod:`.fmu_component`),
connected Model Exchange FMUs as one system (:mod:`.me_system`), Model Exchange integration
(:mod:`.model_exchange`), a crash-isolated FMU in a process of its own (:mod:`.isolated`),
typed value exchange with its C functions (:mod:`.exchange`), what an FMU declares
(:mod:`.description`), ports (:mod:`.ports`), the FMI rules of an instance's life
(:mod:`.instance`) and safe unpacking (:mod:`.archive`)."""
from .archive import Extraction, read_description
from .description import INTERFACES
from .fmu_component import FEEDTHROUGH_MODES, FMUComponent
from .me_system import MESystem
from .model_exchange import SOLVERS, MEIntegrator

__all__ = ["FEEDTHROUGH_MODES", "INTERFACES", "SOLVERS", "Extraction", "FMUComponent", "MEIntegrator", "MESystem",
           "read_description"]

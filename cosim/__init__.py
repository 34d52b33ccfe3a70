"""Co-simulation of FMUs and Python components, each at its own sample period.

The names a user needs, in one place::

    from cosim import Cosimulation, FMUComponent, EstimatorComponent, Sensor, Step, Scenario

Sub-packages: :mod:`cosim.core` (the component protocol, the master, its schedule and
recording), :mod:`cosim.fmi` (FMUs as components), :mod:`cosim.components` (the component
library), :mod:`cosim.experiments` (the papers' experiments); modules: :mod:`cosim.scenario`
(scenario files), :mod:`cosim.ssp` (SSP export and import), :mod:`cosim.output` (output
folders, files, plots), :mod:`cosim.cli` (the command line). Every error is one of
:mod:`fmu_models.errors` (re-exported here).
"""
from fmu_models.errors import (
    BuildError,
    ConfigurationError,
    CosimError,
    FMUError,
    InputError,
    Interrupted,
    NumericalError,
    PendulumCosimError,
    ResourceError,
    TypeMismatchError,
    UnknownNameError,
)
from fmu_models.infra.version import VERSION as __version__

from .components import (
    PRBS,
    Accelerometer,
    Constant,
    Conversion,
    Encoder,
    EstimatorComponent,
    Gyroscope,
    LQRController,
    ModelComponent,
    ProcessNoise,
    Sensor,
    Sine,
    Step,
    Table,
    TiltFusion,
)
from .core import (
    CLOCK,
    COMPONENTS,
    ClockTicks,
    Component,
    Cosimulation,
    ExportedFMU,
    ExportsFMU,
    FastBinding,
    Port,
    StateEstimator,
)
from .fmi import FMUComponent, MESystem
from .fmu_run import open_fmu, run_fmu
from .scenario import Scenario, ScenarioContext
from .ssp import export_ssp, open_ssp, run_ssp

__all__ = [
    "CLOCK",
    "COMPONENTS",
    "PRBS",
    "Accelerometer",
    "BuildError",
    "ClockTicks",
    "Component",
    "ConfigurationError",
    "Constant",
    "Conversion",
    "CosimError",
    "Cosimulation",
    "Encoder",
    "EstimatorComponent",
    "ExportedFMU",
    "ExportsFMU",
    "FMUComponent",
    "FMUError",
    "FastBinding",
    "Gyroscope",
    "InputError",
    "Interrupted",
    "LQRController",
    "MESystem",
    "ModelComponent",
    "NumericalError",
    "PendulumCosimError",
    "Port",
    "ProcessNoise",
    "ResourceError",
    "Scenario",
    "ScenarioContext",
    "Sensor",
    "Sine",
    "StateEstimator",
    "Step",
    "Table",
    "TiltFusion",
    "TypeMismatchError",
    "UnknownNameError",
    "__version__",
    "export_ssp",
    "open_fmu",
    "open_ssp",
    "run_fmu",
    "run_ssp",
]

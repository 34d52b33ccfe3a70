"""The exception family of pendulum-cosim (``fmu_models``, ``estimators`` and ``cosim``).

Every error the project raises on purpose derives from :class:`PendulumCosimError`, so a
caller can catch them all with one ``except``; each also derives from the built-in
exception a Python user would expect (``ValueError`` for a bad value, ``KeyError`` for an
unknown name, ...), so code written against the built-ins keeps working. The command line
prints any of them as one line and exits with status 2 (``--debug`` keeps the traceback).

========================  ==========================================================
class                     raised when
========================  ==========================================================
ConfigurationError        a setting, argument or file describing what to build or run
                          is invalid (a negative mass, a non-PD covariance, a bad
                          scenario, incommensurate periods)
UnknownNameError          a name is not one of the valid ones (the message lists them)
TypeMismatchError         a value or port has the wrong type (strings as a measurement,
                          a Float output wired to a Boolean input)
ResourceError             a run would not fit (memory, disk, schedule size)
InputError                data fed to a running object is invalid (inf in a measurement)
NumericalError            a result became non-finite (a filter diverged)
FMUError                  an FMU file is unusable or an FMU call failed
BuildError                generating or compiling C code failed
CompilerNotFoundError     no C compiler is available
InstallationError         a file the package ships is missing (a broken installation)
RunError                  a run failed
CosimError                a co-simulation failed; keeps the rows recorded so far
Interrupted               a run was stopped by Ctrl-C or SIGTERM (partial results saved)
========================  ==========================================================
"""
from __future__ import annotations

__all__ = [
    "BuildError",
    "CompilerNotFoundError",
    "ConfigurationError",
    "CosimError",
    "FMUError",
    "InputError",
    "InstallationError",
    "Interrupted",
    "NumericalError",
    "PendulumCosimError",
    "ResourceError",
    "RunError",
    "TypeMismatchError",
    "UnknownNameError",
]


class PendulumCosimError(Exception):
    """Base of every error raised on purpose by pendulum-cosim."""


class ConfigurationError(PendulumCosimError, ValueError):
    """A setting, argument or file describing what to build or run is invalid."""


class UnknownNameError(ConfigurationError, KeyError):
    """A name (model, parameter, port, variable, ...) is not one of the valid ones.

    Printed as its plain message (a bare ``KeyError`` would print its repr).
    """

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


class TypeMismatchError(ConfigurationError, TypeError):
    """A value or a port has the wrong type."""


class ResourceError(ConfigurationError):
    """A run would not fit in memory, on disk or in a reasonable schedule (the message
    gives the numbers)."""


class InputError(PendulumCosimError, ValueError):
    """Data fed to a running object (a measurement, an input) is invalid."""


class NumericalError(PendulumCosimError, FloatingPointError):
    """A computed result became non-finite (NaN or inf)."""


class FMUError(PendulumCosimError, RuntimeError):
    """An FMU file is unusable, or an FMU call returned discard, error or fatal."""


class BuildError(PendulumCosimError, RuntimeError):
    """Generating or compiling C code failed (the compiler's output is in the message)."""


class CompilerNotFoundError(BuildError):
    """No C compiler could be found."""


class InstallationError(PendulumCosimError, FileNotFoundError):
    """A file the package ships (C sources, headers, scenarios) is missing: the
    installation is incomplete; reinstalling the package mends it."""


class RunError(PendulumCosimError, RuntimeError):
    """A run (co-simulation, campaign) failed."""


class CosimError(RunError):
    """A component failed during a co-simulation run.

    Parameters
    ----------
    message : str
        What failed, when and why.
    component, time, results
        As the attributes.

    Attributes
    ----------
    component : str
        Name of the failing component.
    time : float
        Simulation time [s] of the failure.
    results : pandas.DataFrame or None
        The signals recorded up to the failure (None when they were streamed to a file).
    """

    def __init__(self, message: str, component: str | None = None, time: float | None = None,
                 results=None):
        super().__init__(message)
        self.component, self.time, self.results = component, time, results


class Interrupted(RunError):
    """A run was stopped by Ctrl-C or SIGTERM; what finished was saved as partial results.

    Parameters
    ----------
    message : str
        Where the run stopped and where the partial results are.
    partial : object
        As the attribute.

    Attributes
    ----------
    partial : object
        Whatever the interrupted function had finished (its documentation says what).
    """

    def __init__(self, message: str, partial=None):
        super().__init__(message)
        self.partial = partial

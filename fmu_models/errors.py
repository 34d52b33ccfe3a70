"""The exception family of pendulum-cosim. Every error raised on purpose derives from
:class:`PendulumCosimError` and from the built-in a Python user would expect (``ValueError`` for a bad
value, ``KeyError`` for an unknown name, ...); the user guide's reliability page says how they show."""
from __future__ import annotations

__all__ = ["BuildError", "CompilerNotFoundError", "ConfigurationError", "CosimError", "FMUError", "InputError",
           "InstallationError", "Interrupted", "NumericalError", "PendulumCosimError", "ResourceError", "RunError",
           "TypeMismatchError", "UnknownNameError"]


class PendulumCosimError(Exception):
    """Base of every error raised on purpose by pendulum-cosim."""


class ConfigurationError(PendulumCosimError, ValueError):
    """A setting, argument or file describing what to build or run is invalid."""


class UnknownNameError(ConfigurationError, KeyError):
    """A name (model, parameter, port, variable, ...) is not one of the valid ones; printed as its
    plain message (a bare ``KeyError`` would print its repr)."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


class TypeMismatchError(ConfigurationError, TypeError):
    """A value or a port has the wrong type."""


class ResourceError(ConfigurationError):
    """A run would not fit in memory, on disk or in a reasonable schedule (the message gives the numbers)."""


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
    """A file the package ships (C sources, headers, scenarios) is missing: reinstalling the package mends it."""


class RunError(PendulumCosimError, RuntimeError):
    """A run (co-simulation, campaign) failed."""


class CosimError(RunError):
    """A component failed during a co-simulation run.

    Parameters
    ----------
    message : str
        What failed, when and why.
    component, time, results : str, float, pandas.DataFrame, optional
        Kept as attributes: the failing component's name, the simulation time [s] of the failure and
        the signals recorded up to it (None when they were streamed to a file).
    """

    def __init__(self, message: str, component: str | None = None, time: float | None = None,
                 results=None):
        super().__init__(message)
        self.component, self.time, self.results = component, time, results


class Interrupted(RunError):
    """A run was stopped by Ctrl-C or SIGTERM; what finished was saved as partial results.

    Parameters
    ----------
    message, partial : str, object
        Where the run stopped and where the partial results are; whatever the interrupted function had
        finished (its documentation says what), kept as an attribute.
    """

    def __init__(self, message: str, partial=None):
        super().__init__(message)
        self.partial = partial

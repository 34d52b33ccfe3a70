"""The one version string of pendulum-cosim, read from the installed package's metadata (set
in ``pyproject.toml``): the packages' ``__version__``, ``--version`` and the FMUs show it."""
from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

__all__ = ["VERSION"]

try:
    #: The installed distribution's version; ``"0+unknown"`` when the code runs from a
    #: source tree that was never installed.
    VERSION: str = version("pendulum-cosim")
except PackageNotFoundError:
    VERSION = "0+unknown"

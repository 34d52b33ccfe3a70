"""Files the package ships beside its code (the FMUs' C sources, the scenarios); a missing one (a broken
installation) is a named error before anything is built from it."""
from __future__ import annotations

from importlib import resources
from pathlib import Path

from ..errors import InstallationError

__all__ = ["shipped", "shipped_files"]


def shipped(package: str, *parts: str) -> Path:
    """The path of the file or folder ``parts`` inside the installed ``package`` (e.g.
    ``shipped("fmu_models.export", "c", "core_api.h")``).

    Raises
    ------
    InstallationError
        It is not there.
    """
    path = Path(str(resources.files(package).joinpath(*parts)))
    if not path.exists():
        raise InstallationError(f"the installed package is incomplete: {'/'.join(parts)} of {package} is missing "
                                f"(looked for {path}); reinstall pendulum-cosim (pip install --force-reinstall "
                                "pendulum-cosim, or pip install . from its source)")
    return path


def shipped_files(package: str, folder: str, names: list[str]) -> list[Path]:
    """The paths of the files ``names`` in the shipped ``folder`` of ``package``, each checked by :func:`shipped`."""
    return [shipped(package, folder, n) for n in names]

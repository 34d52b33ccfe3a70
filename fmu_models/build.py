"""Compile and pack the plant FMUs: ``python -m fmu_models build --out DIR``.

Each FMU holds a native shared library compiled here from CasADi-generated C code, the
plant core and this project's FMI wrapper (``fmu_models/c``, see :mod:`fmu_models.fmu_pack`),
its ``modelDescription.xml`` and its C sources (so that other platforms can rebuild it).
No Python runs inside the FMU.
"""
from __future__ import annotations

from pathlib import Path

from . import MODEL_NAMES, get_model
from .codegen import write_sources
from .errors import CompilerNotFoundError
from .fmu_pack import FMI_VERSIONS, find_compiler, pack_fmu
from .model_description import fmi2_xml, fmi3_xml
from .plant import PlantModel

__all__ = ["FMI_VERSIONS", "CompilerNotFoundError", "build_fmu", "build_fmus", "find_compiler"]


def build_fmu(model: PlantModel | str, out_dir: str | Path = ".", fmi_version: int = 2) -> Path:
    """Build the FMU of one plant model into ``out_dir``; returns the ``.fmu`` path.

    Parameters
    ----------
    model : PlantModel or str
        The model (its current parameter values become the FMU's start values) or a name
        for :func:`fmu_models.get_model`.
    out_dir : path
        Directory to write ``<fmu_name>.fmu`` into (created if missing).
    fmi_version : int
        2 or 3; either way Model Exchange and Co-Simulation in one FMU.

    Raises
    ------
    CompilerNotFoundError
        No C compiler is available.
    BuildError
        The compiler failed (its output is in the message).
    """
    if isinstance(model, str):
        model = get_model(model)

    def generate(folder: Path, guid: str) -> list[str]:
        write_sources(model, guid, folder)
        return ["model_funcs.c"]

    def xml(guid: str, c_files: list[str]) -> str:
        return fmi2_xml(model, guid, c_files) if fmi_version == 2 else fmi3_xml(model, guid)

    return pack_fmu(model.fmu_name, "plant", fmi_version, generate, xml, out_dir,
                    fingerprint=f"{model.p.tolist()}")


def build_fmus(out_dir: str | Path = ".", fmi_version: int = 2,
               models: tuple[str, ...] = MODEL_NAMES) -> list[Path]:
    """Build ``CartPole.fmu`` and ``InertiaWheelPendulum.fmu`` (default models) into ``out_dir``.

    Parameters
    ----------
    out_dir : path
        Output directory (created if missing).
    fmi_version : int
        2 or 3 (see :func:`build_fmu`).
    models : tuple of str
        Registry names of the models to build.
    """
    return [build_fmu(get_model(name), out_dir, fmi_version) for name in models]

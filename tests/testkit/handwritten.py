"""The hand-written third-party test FMUs of ``tests/data`` (C sources and a model
description each), compiled and zipped into an FMU."""
from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import fmpy

DATA = Path(__file__).parents[1] / "data"


class NotBuildable(RuntimeError):
    """The hand-written test FMUs are built for Linux only."""


def build(folder: str, identifier: str, version: int, out: Path, description: str = "modelDescription.xml") -> Path:
    """Compile ``tests/data/<folder>/<identifier>.c`` and zip it with the folder's model
    description ``description`` (shipped as ``modelDescription.xml``) into
    ``out/<identifier>.fmu`` (FMI ``version`` 1, 2 or 3); returns the FMU's path."""
    src = DATA / folder
    plat = ("linux64" if version < 3 else "x86_64-linux") if sys.platform.startswith("linux") else None
    if plat is None:
        raise NotBuildable("the hand-written test FMUs are built for Linux only")
    binaries = Path(out) / "binaries" / plat
    binaries.mkdir(parents=True)
    headers = Path(fmpy.__file__).parent / "c-code"
    cc = shutil.which("cc") or shutil.which("gcc")
    subprocess.run([cc, "-shared", "-fPIC", "-O2", f"-I{headers}", str(src / f"{identifier}.c"),
                    "-o", str(binaries / f"{identifier}.so"), "-lm"], check=True)
    fmu = Path(out) / f"{identifier}.fmu"
    with zipfile.ZipFile(fmu, "w") as z:
        z.write(src / description, "modelDescription.xml")
        z.write(binaries / f"{identifier}.so", f"binaries/{plat}/{identifier}.so")
    return fmu


def logged_calls(path: Path) -> list[str]:
    """The calls a hand-written FMU logged to ``path`` (lines "<instance> <function>"), the
    instance names dropped; asserts that none was one the standard forbids (ILLEGAL)."""
    calls = [line.split(" ", 1)[1] for line in path.read_text().splitlines()] if path.exists() else []
    assert not [c for c in calls if "ILLEGAL" in c], calls
    return calls

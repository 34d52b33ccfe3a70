import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import pytest


@pytest.fixture(scope="session")
def fmu_builds(tmp_path_factory):
    """Both plant FMUs in FMI 2.0 and 3.0, built once per session: {(name, version): path}."""
    from fmu_models import MODEL_NAMES
    from fmu_models.build import build_fmu

    paths = {}
    for version in (2, 3):
        out = tmp_path_factory.mktemp(f"fmi{version}")
        for name in MODEL_NAMES:
            paths[name, version] = str(build_fmu(name, out, fmi_version=version))
    return paths


@pytest.fixture(scope="session")
def fmu_paths(fmu_builds):
    """The FMI 2.0 plant FMUs: {model name: path}."""
    return {name: p for (name, v), p in fmu_builds.items() if v == 2}

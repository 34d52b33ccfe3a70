import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import pytest


@pytest.fixture(scope="session")
def fmu_paths(tmp_path_factory):
    """Both plant FMUs (FMI 2.0), built once per test session: {model name: path}."""
    from fmu_models import MODEL_NAMES
    from fmu_models.build import build_fmu

    out = tmp_path_factory.mktemp("fmus")
    return {name: str(build_fmu(name, out)) for name in MODEL_NAMES}

"""The benchmark scripts load in a fresh process as their commands start them: their imports
resolve to the project's packages (not to the test folders of the same names), and the test
helpers they take from ``tests/testkit`` exist."""
import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).parents[1] / "bench"
SCRIPTS = sorted(BENCH.glob("bench_*.py"))

# the script's module level runs (not its main), then the packages are the installed ones
CHECK = """
import runpy, sys
runpy.run_path(sys.argv[1], run_name="bench_import_check")
import cosim, estimators, fmu_models
for pkg in (cosim, estimators, fmu_models):
    assert getattr(pkg, "__file__", None), f"{pkg.__name__} is a namespace package from {list(pkg.__path__)}"
from fmu_models import build_fmu  # noqa: F401
"""


def test_every_benchmark_is_listed():
    assert len(SCRIPTS) >= 10, SCRIPTS


@pytest.mark.slow
@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.stem)
def test_benchmark_script_loads(script):
    r = subprocess.run([sys.executable, "-c", CHECK, str(script)], cwd=BENCH.parent,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]

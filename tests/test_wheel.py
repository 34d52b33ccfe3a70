"""The built wheel holds every file the packages read at run time, and the sdist the whole
source tree: built with the standard front end (``python -m build``) from a copy of the
tracked files, as a user's ``pip install`` would build them."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
PACKAGES = ("fmu_models", "estimators", "cosim")


def _tracked() -> list[str]:
    if not (ROOT / ".git").exists() or shutil.which("git") is None:
        pytest.skip("needs the git checkout (the list of tracked files)")
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    return [f for f in out.splitlines() if (ROOT / f).is_file()]


@pytest.fixture(scope="module")
def dists(tmp_path_factory):
    pytest.importorskip("build", reason="the standard build front end is in the dev extra")
    tracked = _tracked()
    src = tmp_path_factory.mktemp("src")
    for f in tracked:
        (src / f).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / f, src / f)
    out = tmp_path_factory.mktemp("dist")
    proc = subprocess.run([sys.executable, "-m", "build", "--no-isolation", "--wheel", "--sdist", "--outdir",
                           str(out), str(src)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    wheel, = out.glob("*.whl")
    sdist, = out.glob("*.tar.gz")
    return tracked, wheel, sdist


def test_the_wheel_holds_every_file_of_the_packages(dists):
    tracked, wheel, _ = dists
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
    wanted = {f for f in tracked if f.split("/")[0] in PACKAGES}
    missing = sorted(wanted - names)
    assert not missing, f"left out of the wheel: {missing}"
    assert any(n.endswith(".dist-info/LICENSE") or "/licenses/" in n for n in names), "no LICENSE in the wheel"
    stray = sorted(n for n in names if n.split("/")[0] not in PACKAGES and ".dist-info/" not in n)
    assert not stray, f"files outside the packages in the wheel: {stray}"


def test_the_sdist_holds_the_source_tree(dists):
    tracked, _, sdist = dists
    with tarfile.open(sdist) as t:
        names = {n.split("/", 1)[1] for n in t.getnames() if "/" in n}
    missing = sorted(f for f in tracked if f not in names and not f.endswith(".gitignore"))
    assert not missing, f"left out of the sdist: {missing}"


def test_the_version_is_the_metadata_version(dists):
    from importlib.metadata import version

    import cosim
    import estimators
    import fmu_models

    _, wheel, _ = dists
    assert wheel.name.startswith(f"pendulum_cosim-{version('pendulum-cosim')}-")
    assert fmu_models.__version__ == estimators.__version__ == cosim.__version__ == version("pendulum-cosim")


@pytest.mark.parametrize("missing, command", [
    ("fmu_models/export/c/core_api.h", ["-m", "fmu_models", "build", "--out", "fmus"]),
    ("cosim/scenarios", ["-c", "import sys; from cosim.cli import main; sys.exit(main())", "scenarios"]),
])
def test_a_missing_packaged_file_is_a_named_error(tmp_path, missing, command):
    """An installation that lost a shipped file (a wheel built without it, a pruned folder)
    says which file and how to mend it, with no traceback, and writes nothing."""
    site = tmp_path / "site"
    for pkg in PACKAGES:
        shutil.copytree(ROOT / pkg, site / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    target = site / missing
    shutil.rmtree(target) if target.is_dir() else target.unlink()
    proc = subprocess.run([sys.executable, *command], cwd=tmp_path, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(site)})
    assert proc.returncode == 2, proc.stderr
    name = missing.split("/", 2)[-1] if missing.startswith("fmu_models") else "scenarios"
    assert proc.stderr.startswith("error: the installed package is incomplete:"), proc.stderr
    assert name in proc.stderr and "reinstall" in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "fmus").exists()

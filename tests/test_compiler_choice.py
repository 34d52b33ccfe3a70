"""The C compiler a user names is the one used, or the run is refused by name; a compiler
found on the PATH that fails is named with the fallback taken (CasADi's virtual machine)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

CLI = [sys.executable, "-c", "import sys; from cosim.cli import main; sys.exit(main())"]
FILTER = ("from estimators import EKF, discretize; from fmu_models import get_model; "
          "f = EKF(discretize(get_model('cartpole'), 0.01), [0, 0, 0, 0], 1.0, 0.1, 0.1); print(f.backend)")


def _env(tmp_path: Path, **extra: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "CC"}
    return {**env, "PENDULUM_COSIM_CACHE": str(tmp_path / "cache"), **extra}


def _failing_cc(tmp_path: Path) -> Path:
    """A folder whose ``cc`` always fails, saying why (a broken toolchain on the PATH)."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    cc = bin_dir / "cc"
    cc.write_text("#!/bin/sh\necho 'cc: fatal error: broken toolchain' >&2\nexit 1\n")
    cc.chmod(0o755)
    return bin_dir


@pytest.mark.slow
def test_a_failing_compiler_named_by_cc_refuses_the_run(tmp_path):
    env = _env(tmp_path, CC="/bin/false")
    proc = subprocess.run([sys.executable, "-c", FILTER], env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode != 0 and "BuildError" in proc.stderr and "named by $CC (/bin/false)" in proc.stderr
    out = tmp_path / "out"
    proc = subprocess.run([*CLI, "experiment", "seed000", "--runs", "2", "--out", str(out), "--quiet"], env=env,
                          capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.startswith("error: the C compiler named by $CC (/bin/false) failed"), proc.stderr
    assert "backend='vm'" in proc.stderr and "Traceback" not in proc.stderr
    assert not out.exists()


def test_a_failing_compiler_found_on_the_path_is_named_with_the_fallback(tmp_path):
    bin_dir = _failing_cc(tmp_path)
    env = _env(tmp_path, PATH=f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    proc = subprocess.run([sys.executable, "-W", "always", "-c", FILTER], env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "vm"
    assert f"the C compiler {bin_dir / 'cc'} failed" in proc.stderr and "broken toolchain" in proc.stderr
    assert "virtual machine" in proc.stderr


@pytest.mark.slow
def test_the_command_line_prints_a_fallback_as_one_warning_line(tmp_path):
    bin_dir = _failing_cc(tmp_path)
    env = _env(tmp_path, PATH=f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    proc = subprocess.run([*CLI, "experiment", "seed000", "--runs", "2", "--out", str(tmp_path / "o"), "--quiet",
                           "--set", "scenarios=[[0.2, 0.1]]", "--set", 'readings=["eqs"]', "--set", "duration=0.5"],
                          env=env, capture_output=True, text=True, timeout=600,
                          cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if "virtual machine" in ln]
    assert lines and all(ln.startswith("warning: ") for ln in lines), proc.stderr
    assert "UserWarning" not in proc.stderr and "Traceback" not in proc.stderr

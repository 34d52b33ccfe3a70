"""The master against an FMU that misbehaves at random (tests/data/chaos): Warning, Discard,
Error, Fatal, NaN or inf outputs, sleeps and crashes, in any call, by seed. Every run ends
normally with finite results, or with a named error (the FMU, the FMI call or the signal,
the time) that keeps the rows so far; the FMU's log shows no call the standard forbids,
and every instance that may still be freed is freed."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from testkit.chaos import CRASH, NO_CRASH, STOP, run_seed, scenario

from cosim import Cosimulation, FMUComponent, Sine
from fmu_models.errors import PendulumCosimError


def test_the_master_survives_a_misbehaving_fmu_over_many_seeds(chaos_fmu, tmp_path, monkeypatch):
    log = tmp_path / "chaos.log"
    monkeypatch.setenv("CHAOS_LOG", str(log))
    outcomes = [run_seed(chaos_fmu, seed, 0.01, NO_CRASH, log) for seed in range(150)]
    # the seeds reach both ends: normal runs and named failures
    assert "ok" in outcomes and "CosimError" in outcomes, outcomes


def test_a_crashing_fmu_in_a_process_of_its_own_is_a_named_error(chaos_fmu, tmp_path, monkeypatch):
    log = tmp_path / "chaos.log"
    monkeypatch.setenv("CHAOS_LOG", str(log))
    with pytest.raises(PendulumCosimError, match=r"died \(signal SIGSEGV\)") as info:
        run_seed_raising(chaos_fmu, 3, log)
    assert "chaos" in str(info.value) and "t = " in str(info.value)


def run_seed_raising(fmu, seed, log):
    comp = FMUComponent("chaos", fmu, 0.01, isolate=True,
                        parameters={"seed": seed, "rate": 0.05, "actions": CRASH})
    Cosimulation([Sine("src", 0.01, 1.0, 1.0), comp], {"chaos.u": "src.out"}).run(STOP)


@pytest.mark.slow
def test_a_failing_chaos_run_from_the_command_line_is_one_line_and_keeps_its_rows(chaos_fmu, tmp_path):
    (tmp_path / "s.toml").write_text(scenario(chaos_fmu, "seed = 9, rate = 0.02, actions = 12", 1.0))
    proc = subprocess.run([sys.executable, "-c", "import sys; from cosim.cli import main; sys.exit(main())", "run",
                           "s.toml", "--out", "out"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stderr
    errors = [ln for ln in proc.stderr.splitlines() if ln.startswith("error: ")]
    assert len(errors) == 1 and "component 'chaos' failed at t = " in errors[0] and "fmi2" in errors[0], proc.stderr
    assert "Traceback" not in proc.stderr
    partial = pd.read_csv(tmp_path / "out" / "results.partial.csv", index_col="time")
    assert 0 < len(partial) < 101 and np.isfinite(partial.to_numpy()).all()

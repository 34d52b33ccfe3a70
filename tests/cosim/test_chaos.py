"""The master against an FMU that misbehaves at random (tests/data/chaos): Warning, Discard,
Error, Fatal, NaN or inf outputs, sleeps and crashes, in any call, by seed. Every run ends
normally with finite results, or with a named error (the FMU, the FMI call or the signal,
the time) that keeps the rows so far; the FMU's log shows no call the standard forbids,
and every instance that may still be freed is freed."""
from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pandas as pd
import pytest

from cosim import Cosimulation, FMUComponent, Sine
from fmu_models.errors import PendulumCosimError

#: Every misbehaviour but the crash (bits of the FMU's ``actions`` parameter).
NO_CRASH = 127
CRASH = 128
STOP = 1.0


def run_seed(fmu, seed: int, rate: float, actions: int, log, isolate: bool = False) -> str:
    """One chaos run through the master; returns its outcome class (raises AssertionError
    when a rule is broken)."""
    log.write_text("")
    comp = FMUComponent("chaos", fmu, 0.01, isolate=isolate,
                        parameters={"seed": seed, "rate": rate, "actions": actions, "sleep_us": 200})
    cosim = Cosimulation([Sine("src", 0.01, 1.0, 1.0), comp], {"chaos.u": "src.out"})
    outcome = "ok"
    try:
        df = cosim.run(STOP)
        assert len(df) == 101 and np.isfinite(df.to_numpy()).all(), f"seed {seed}: silently wrong results"
    except PendulumCosimError as e:
        msg = str(e)
        assert "chaos" in msg and "t = " in msg, f"seed {seed}: unnamed failure: {msg}"
        assert "fmi2" in msg or "signal chaos." in msg or "died" in msg, f"seed {seed}: no call named: {msg}"
        rows = getattr(e, "results", None)
        assert isinstance(rows, pd.DataFrame), f"seed {seed}: the rows so far are lost: {msg}"
        assert len(rows) <= 101 and np.isfinite(rows.to_numpy()).all(), f"seed {seed}: bad partial rows"
        assert rows.index.is_monotonic_increasing
        outcome = type(e).__name__
    text = log.read_text()
    illegal = [ln for ln in text.splitlines() if " ILLEGAL " in ln]
    assert not illegal, f"seed {seed}: calls the standard forbids: {illegal[:3]}"
    fatal = " Fatal" in text
    if not isolate or "died" not in outcome:
        assert fatal or "fmi2FreeInstance" in text, f"seed {seed}: the instance was never freed"
    return outcome


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
def test_ten_thousand_chaos_runs(chaos_fmu, tmp_path, monkeypatch):
    log = tmp_path / "chaos.log"
    monkeypatch.setenv("CHAOS_LOG", str(log))
    for seed in range(10_000):
        run_seed(chaos_fmu, seed, 0.005 + 0.02 * (seed % 5) / 4, NO_CRASH, log)


def test_a_failing_chaos_run_from_the_command_line_is_one_line_and_keeps_its_rows(chaos_fmu, tmp_path):
    (tmp_path / "s.toml").write_text(textwrap.dedent(f"""
        [simulation]
        stop_time = 1.0
        [[component]]
        name = "src"
        type = "sine"
        period = 0.01
        amplitude = 1.0
        frequency = 1.0
        [[component]]
        name = "chaos"
        type = "fmu"
        path = "{chaos_fmu}"
        period = 0.01
        parameters = {{ seed = 9, rate = 0.02, actions = 12 }}
        [connections]
        "chaos.u" = "src.out"
    """))
    proc = subprocess.run([sys.executable, "-c", "import sys; from cosim.cli import main; sys.exit(main())", "run",
                           "s.toml", "--out", "out"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stderr
    errors = [ln for ln in proc.stderr.splitlines() if ln.startswith("error: ")]
    assert len(errors) == 1 and "component 'chaos' failed at t = " in errors[0] and "fmi2" in errors[0], proc.stderr
    assert "Traceback" not in proc.stderr
    partial = pd.read_csv(tmp_path / "out" / "results.partial.csv", index_col="time")
    assert 0 < len(partial) < 101 and np.isfinite(partial.to_numpy()).all()

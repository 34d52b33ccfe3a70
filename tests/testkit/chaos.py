"""One run of the master against the chaos FMU (tests/data/chaos) and the rules every run
must keep; shared by tests/cosim/test_chaos.py and bench/bench_soak.py."""
from __future__ import annotations

import numpy as np
import pandas as pd

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


def scenario(fmu, parameters: str, stop_time: float, stream: bool = False) -> str:
    """A scenario file's text: a sine source into the chaos FMU ``fmu`` with ``parameters``
    (TOML inline-table entries, e.g. ``"seed = 9, rate = 0.02, actions = 12"``)."""
    recording = "[recording]\nstream = true\n" if stream else ""
    return (f"[simulation]\nstop_time = {stop_time!r}\n{recording}"
            "[[component]]\nname = \"src\"\ntype = \"sine\"\nperiod = 0.01\namplitude = 1.0\nfrequency = 1.0\n"
            f"[[component]]\nname = \"chaos\"\ntype = \"fmu\"\npath = \"{fmu}\"\nperiod = 0.01\n"
            f"parameters = {{ {parameters} }}\n[connections]\n\"chaos.u\" = \"src.out\"\n")

"""The master against the Modelica Reference FMUs (third-party FMUs, FMI 2.0 and 3.0,
Co-Simulation and Model Exchange), through the Python API and ``pendulum-cosim run``.

Every case either gives the reference result (Co-Simulation: the published one, exactly;
Model Exchange: fmpy's CVODE at rtol 1e-10 within twice the error fmpy itself makes at
the master's tolerance; Scheduled Execution, the Clocks FMU: every activation and tick
counter of the table in its model description) or is refused with a message naming what
is unsupported. The
cases and comparisons are in ``tests/reference_cases.py`` (shared with the benchmark that
writes the README's table).
"""
from __future__ import annotations

import numpy as np
import pytest
from testkit import reference_cases as rc

from fmu_models.errors import PendulumCosimError

pytestmark = pytest.mark.skipif(rc.reference_dir() is None, reason=(
    "the Reference FMUs are absent: expected ../shared/reference-fmus (with fmi2/ and fmi3/) "
    "or the folder named by PENDULUM_COSIM_REFERENCE_FMUS"))

CASES = rc.cases()
IDS = [c.label for c in CASES]


def _string_like(case: rc.Case, name: str) -> bool:
    """A published column that is no port of the master: String/Binary, or a variable this
    FMU version does not have (the FMI 2 Feedthrough has no Int8 etc.)."""
    from fmpy import read_model_description

    md = read_model_description(str(rc.fmu_path(case)))
    types = {v.name: v.type for v in md.modelVariables}
    return name not in types or types[name] in ("String", "Binary")


def check_result(case: rc.Case, df) -> dict:
    r = rc.compare(case, df)
    assert r["rows"] > 0, r
    if case.interface == "se":
        assert r["wrong_ticks"] == {}, r
        assert r["error"] == 0.0, r
        return r
    if case.interface == "cs":
        assert r["error"] == 0.0, r
        assert r["missing"] == 0, r
        assert all(_string_like(case, c) for c in r["not_compared"]), r
    else:
        assert r["columns"] == len(df.columns), r         # every output compared
        assert r["ratio"] <= 2.0, r
    return r


def test_every_model_is_a_case():
    """Both versions' folders are read (9 models: 6 in both versions, 3 FMI 3 only), each
    with each of its interfaces (Clocks has only Scheduled Execution); one refusal is left,
    Roberts in Co-Simulation (its fixed internal step over 1e8 s)."""
    assert len(CASES) == 2 * (6 * 2 + 2) + 1
    assert {c.model for c in CASES} >= {"BouncingBall", "Clocks", "Feedthrough", "Roberts", "StateSpace", "Stair"}
    assert [c.label for c in CASES if c.model == "Clocks"] == ["Clocks-fmi3-se"]
    assert [c.label for c in CASES if c.refused] == ["Roberts-fmi3-cs"]


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_api(case: rc.Case):
    if case.refused:
        with pytest.raises(PendulumCosimError, match=case.refused):
            rc.run_api(case)
        return
    df = rc.run_api(case)
    check_result(case, df)
    if case.model == "Stair":              # asks to stop at 9 s: a normal end, the row at 9 s
        assert df.attrs["stopped"]["time"] == 9.0 and df.index[-1] == 9.0
        assert df["counter"].iloc[-1] == 10
    else:
        assert df.attrs["stopped"] is None
        assert df.index[-1] == pytest.approx(case.stop, rel=1e-12)
    if case.model == "Clocks":             # the table ends at 9 s; at 10 s inClock1 ticks once more
        assert df["inClock1Ticks"].iloc[-1] == 11 and df["totalInClockTicks"].iloc[-1] == 16


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_cli(case: rc.Case, tmp_path):
    """Every case through the command line's main() (in this process: a process start per
    case costs more than the case)."""
    df, proc = rc.run_cli(case, tmp_path)
    assert "Traceback" not in proc.stderr
    if case.refused:
        assert proc.returncode != 0 and df is None
        assert case.refused in proc.stderr, proc.stderr
        assert not (tmp_path / "out" / "results.csv").exists()
        return
    assert proc.returncode == 0, proc.stderr
    api = rc.run_api(case)
    assert list(df.columns) == list(api.columns)
    np.testing.assert_array_equal(df.index.to_numpy(), api.index.to_numpy())
    np.testing.assert_array_equal(df.to_numpy(float), api.to_numpy(float))    # the CSV is exact
    if case.interface == "se":             # the activations the command line wrote: the API's
        check_result(case, df)
        np.testing.assert_array_equal(df.attrs["clock_ticks"]["time"].to_numpy(),
                                      api.attrs["clock_ticks"]["time"].to_numpy())
        assert list(df.attrs["clock_ticks"]["clock"]) == list(api.attrs["clock_ticks"]["clock"])
    if case.model == "Stair":
        assert "asked to stop the run at t = 9 s" in proc.stderr


def test_fmi3_alias_is_its_variable():
    """BouncingBall's ``h_ft`` is an <Alias> of ``h`` (one value reference): the same values."""
    case = next(c for c in CASES if c.label == "BouncingBall-fmi3-me")
    df = rc.run_api(case)
    np.testing.assert_array_equal(df["h_ft"].to_numpy(), df["h"].to_numpy())


def test_roberts_reference_is_independent_of_the_fmu():
    """Roberts' oracle (scipy on the equations written in the test) agrees with its own
    the values SUNDIALS' cvRoberts example prints (at its rtol 1e-4), and the slow end
    state (y1 -> 0, y3 -> 1)."""
    case = next(c for c in CASES if c.label == "Roberts-fmi3-me")
    ref = rc._scipy(case, np.array([case.start, 0.4, 4e3, case.stop]), 1e-10, 1e-16)
    assert ref["y1"].iloc[1] == pytest.approx(9.851712e-01, rel=1e-4)
    assert ref["y2"].iloc[1] == pytest.approx(3.386380e-05, rel=1e-3)
    assert ref["y1"].iloc[2] == pytest.approx(1.831976e-01, rel=1e-3)
    assert ref["y1"].iloc[-1] < 1e-4 and ref["y3"].iloc[-1] > 0.9999


@pytest.mark.slow
def test_the_cli_in_a_process_of_its_own_gives_what_main_gives(tmp_path):
    case = next(c for c in CASES if not c.refused and c.interface == "cs")
    df, proc = rc.run_cli(case, tmp_path / "process", in_process=False)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
    same, _ = rc.run_cli(case, tmp_path / "main")
    np.testing.assert_array_equal(df.to_numpy(float), same.to_numpy(float))

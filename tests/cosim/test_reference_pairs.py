"""Reference FMUs connected to each other: an FMU driving Feedthrough (Co-Simulation and
Model Exchange, continuous and discrete inputs), and integers carried exactly across
connections and start values, every value range-checked against its destination."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from testkit import reference_cases as rc
from testkit.scenario_files import component, write_scenario

from cosim import Cosimulation, FMUComponent
from fmu_models.errors import ConfigurationError, CosimError, PendulumCosimError

pytestmark = pytest.mark.skipif(rc.reference_dir() is None, reason="the Reference FMUs are absent (see "
                                "tests/reference_cases.py)")
CLI = [sys.executable, "-c", "import sys; from cosim.cli import main; sys.exit(main())"]


def fmu(model: str, version: int = 3):
    return rc.reference_dir() / f"fmi{version}" / f"{model}.fmu"


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("interface", ["cs", "me"])
def test_stair_drives_feedthrough(version, interface):
    """Stair's counter (a time-event-driven Int32) into Feedthrough's discrete Int32 input:
    the output equals the counter at every instant, in Model Exchange set in Event Mode;
    Stair's stop request at 9 s ends both."""
    stair = FMUComponent("stair", fmu("Stair", version), 0.2, interface=interface)
    ft = FMUComponent("ft", fmu("Feedthrough", version), 0.2, interface=interface)
    df = Cosimulation([stair, ft], {"ft.Int32_input": "stair.counter"}).run(10.0)
    np.testing.assert_array_equal(df["ft.Int32_output"].to_numpy(), df["stair.counter"].to_numpy())
    assert df["stair.counter"].iloc[-1] == 10 and df.index[-1] == 9.0
    assert df.attrs["stopped"]["component"] == "stair"


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("input_kind", ["continuous", "discrete"])
def test_vanderpol_drives_feedthrough_me(version, input_kind):
    """A continuous signal into an ME Feedthrough's continuous input (Continuous-Time Mode)
    and its discrete input (Event Mode at each communication point): passed on at once."""
    vdp = FMUComponent("vdp", fmu("VanDerPol", version), 0.01, interface="me")
    ft = FMUComponent("ft", fmu("Feedthrough", version), 0.01, interface="me")
    df = Cosimulation([vdp, ft], {f"ft.Float64_{input_kind}_input": "vdp.x0"}).run(2.0)
    np.testing.assert_array_equal(df[f"ft.Float64_{input_kind}_output"].to_numpy(), df["vdp.x0"].to_numpy())
    assert df["vdp.x0"].std() > 0.1


EXACT = {"Int64": [2**63 - 1, -(2**63), 2**53 + 1], "UInt64": [2**64 - 1, 2**53 + 1]}


@pytest.mark.parametrize("kind, value", [(k, v) for k, vs in EXACT.items() for v in vs])
def test_64_bit_integers_are_exact(kind, value):
    """A start value into Feedthrough A, its output into B: the value arrives exactly (no
    float in between), recorded with an exact integer dtype."""
    a = FMUComponent("a", fmu("Feedthrough"), 0.1, start={f"{kind}_input": value})
    b = FMUComponent("b", fmu("Feedthrough"), 0.1)
    df = Cosimulation([a, b], {f"b.{kind}_input": f"a.{kind}_output"}).run(0.3)
    col = df[f"b.{kind}_output"]
    assert col.dtype.kind in "iu" and all(int(v) == value for v in col)


@pytest.mark.parametrize("src_kind, start, dst_kind, rng", [("Int32", 1000, "Int8", "[-128, 127]"),
                                                           ("Int16", -1, "UInt8", "[0, 255]"),
                                                           ("Int64", 2**32, "UInt32", "[0, 4294967295]"),
                                                           ("UInt64", 2**63, "Int64", "[-9223372036854775808, ")])
def test_integers_out_of_the_destination_range_are_refused(src_kind, start, dst_kind, rng):
    a = FMUComponent("a", fmu("Feedthrough"), 0.1, start={f"{src_kind}_input": start})
    b = FMUComponent("b", fmu("Feedthrough"), 0.1)
    sim = Cosimulation([a, b], {f"b.{dst_kind}_input": f"a.{src_kind}_output"})
    with pytest.raises(CosimError) as e:
        sim.run(0.3)
    msg = str(e.value)
    assert f"a.{src_kind}_output" in msg and f"b.{dst_kind}_input" in msg and str(start) in msg and rng in msg, msg


@pytest.mark.parametrize("kind, value", [("Int8", 1000), ("UInt8", -1), ("UInt64", 2**64), ("Int32", 2.5),
                                         ("Int16", True)])
def test_start_values_out_of_range_are_refused_before_the_run(kind, value):
    with pytest.raises(ConfigurationError, match=rf"{kind}_input"):
        FMUComponent("a", fmu("Feedthrough"), 0.1, start={f"{kind}_input": value})


def test_string_and_binary_ports_are_refused_by_name():
    with pytest.raises(PendulumCosimError, match="String_input"):
        b = FMUComponent("b", fmu("Feedthrough"), 0.1, inputs=["String_input"])
        Cosimulation([FMUComponent("a", fmu("Feedthrough"), 0.1), b], {"b.String_input": "a.Int32_output"})


def test_arrays_connect_by_element():
    """StateSpace's array output ``y`` is ports ``y[1]..y[3]``; one element drives a
    Feedthrough input."""
    ss = FMUComponent("ss", fmu("StateSpace"), 0.1)
    ft = FMUComponent("ft", fmu("Feedthrough"), 0.1)
    df = Cosimulation([ss, ft], {"ft.Float64_continuous_input": "ss.y[2]"}).run(1.0)
    np.testing.assert_array_equal(df["ft.Float64_continuous_output"].to_numpy(), df["ss.y[2]"].to_numpy())


def test_a_pair_from_a_scenario_file(tmp_path):
    """The CLI with two Reference FMUs and an exact UInt64 connection."""
    feedthrough = fmu("Feedthrough")
    sc = write_scenario(tmp_path / "s.toml", 0.3,
                        [component("fmu", "a", 0.1, path=feedthrough, start={"UInt64_input": 2**64 - 1}),
                         component("fmu", "b", 0.1, path=feedthrough)],
                        {"b.UInt64_input": "a.UInt64_output", "b.Int32_input": "a.Int32_output"})
    proc = subprocess.run([*CLI, "run", str(sc), "--out", str(tmp_path / "out"), "--no-progress"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    df = pd.read_csv(tmp_path / "out" / "results.csv", index_col="time")
    assert df["b.UInt64_output"].dtype == np.uint64 and (df["b.UInt64_output"] == 2**64 - 1).all()


def _oscillator(**extra):
    """StateSpace resized by its structural parameters to a 2-state harmonic oscillator:
    x' = [[0, 1], [-1, 0]] x, y = x, x(0) = [1, 0] (y1 = cos t, y2 = -sin t)."""
    params = dict(m=2, n=2, r=2, A=[0.0, 1.0, -1.0, 0.0], B=[0.0] * 4, C=[1.0, 0.0, 0.0, 1.0], D=[0.0] * 4,
                  x0=[1.0, 0.0], **extra)
    return FMUComponent("ss", fmu("StateSpace"), 0.1, interface="me", parameters=params, start={"u": [0.0, 0.0]},
                        rtol=1e-9)


def test_structural_parameters_resize_the_ports_and_are_set_in_configuration_mode():
    """The ports follow the structural parameters; the values go to the FMU in
    Configuration Mode (its message proves it: outside it says "Structural variables can
    only be set in Configuration Mode"). The Reference FMU v0.0.41 then refuses every
    conforming call: its setUInt64 advances the value index before ASSERT_NVALUES(1)
    (model.c), so one value is "Expected nValues >= 2 but was 1" -- an FMU bug, reported
    as the FMU's error, not worked around by an illegal call."""
    ss = _oscillator()
    assert ss.output_names == ["y[1]", "y[2]"] and ss.input_names == ["u[1]", "u[2]"]
    with pytest.raises(CosimError, match=r"ss: fmi3SetUInt64\(m = 2\) returned error: Expected nValues >= 2 "
                                         r"but was 1"):
        Cosimulation([ss], {}).run(1.0)


@pytest.mark.parametrize("change, words", [({"A": [0.0, 1.0, -1.0]}, "A takes 9 value"),
                                           ({"n": 6}, r"n: 6 is outside the range the FMU declares for .n. \[0, 5\]"),
                                           ({"n": 2.5}, "n: 2.5 is not an integer"),
                                           ({"n": -1}, r"n: -1 is outside the range of UInt64")])
def test_structural_parameter_errors_are_named_before_the_run(change, words):
    with pytest.raises(ConfigurationError, match=words):
        FMUComponent("ss", fmu("StateSpace"), 0.1, parameters=change)


def test_declared_min_max_are_enforced():
    """BouncingBall declares 0.5 <= e <= 1: e = 1.5 is refused before anything runs."""
    with pytest.raises(ConfigurationError, match=r"e: 1.5 is outside the range the FMU declares for 'e' \[0.5, 1.0\]"):
        FMUComponent("b", fmu("BouncingBall"), 0.01, parameters={"e": 1.5})
    FMUComponent("b", fmu("BouncingBall"), 0.01, parameters={"e": 0.9})

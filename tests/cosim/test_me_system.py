"""Connected Model Exchange FMUs integrated as one system (:class:`cosim.MESystem`):
connections inside every right-hand side (against independent scipy solutions of the
coupled equations), joint events, discrete connections in Event Mode, refusals."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import solve_ivp
from testkit import reference_cases as rc
from testkit.scenario_files import component, write_scenario

from cosim import Cosimulation, FMUComponent, MESystem, Sine
from fmu_models.errors import ConfigurationError, UnknownNameError

needs_reference = pytest.mark.skipif(rc.reference_dir() is None, reason="the Reference FMUs are absent")
CLI = [sys.executable, "-c", "import sys; from cosim.cli import main; sys.exit(main())"]
TAU = 0.5          # the hand-written BouncingBallME's lag: x' = (u - x) / tau


def ref(model: str, version: int = 3):
    return rc.reference_dir() / f"fmi{version}" / f"{model}.fmu"


def _vdp_lag(version: int):
    """VanDerPol x0 -> lag u, and the coupled ODE solved by scipy (mu = 1)."""
    def f(t, y):
        return [y[1], (1 - y[0] ** 2) * y[1] - y[0], (y[0] - y[2]) / TAU]
    return f, [2.0, 0.0, 0.0]


@needs_reference
@pytest.mark.parametrize("version", [2, 3])
def test_connections_inside_the_right_hand_side(bouncing_me_fmu, version):
    """One solver for both FMUs: the lag sees VanDerPol's x0 as it moves within a step;
    separate components hold it over each step (a zero-order-hold error of order 0.1)."""
    def members(rtol):
        return (FMUComponent("vdp", ref("VanDerPol", version), 0.1, interface="me", rtol=rtol),
                FMUComponent("lag", bouncing_me_fmu, 0.1, interface="me", rtol=rtol))
    system = MESystem("sys", members(1e-8), {"lag.u": "vdp.x0"}, 0.1, rtol=1e-8)
    joint = Cosimulation([system], {}).run(2.0)
    separate = Cosimulation(list(members(1e-8)), {"lag.u": "vdp.x0"}).run(2.0)
    f, y0 = _vdp_lag(version)
    exact = solve_ivp(f, (0, 2.0), y0, method="Radau", rtol=1e-11, atol=1e-13, t_eval=joint.index.to_numpy()).y
    err_joint = np.abs(joint["sys.lag.x"].to_numpy() - exact[2]).max()
    err_separate = np.abs(separate["lag.x"].to_numpy() - exact[2]).max()
    assert err_joint < 1e-5 and err_separate > 1e-2, (err_joint, err_separate)
    assert np.abs(joint["sys.vdp.x0"].to_numpy() - exact[0]).max() < 1e-5


def test_a_ring_of_states_is_no_algebraic_loop(bouncing_me_fmu):
    """Two lags feeding each other (x1' = (x2 - x1)/tau, x2' = (x1 - x2)/tau): their outputs
    are states, so the ring is allowed; x1 = (1 + exp(-2t/tau))/2 exactly; both balls bounce
    (state events of either member stop the joint solver)."""
    a = FMUComponent("a", bouncing_me_fmu, 0.05, interface="me", start={"x": 1.0})
    b = FMUComponent("b", bouncing_me_fmu, 0.05, interface="me")
    df = Cosimulation([MESystem("ring", [a, b], {"a.u": "b.x", "b.u": "a.x"}, 0.05, rtol=1e-9)], {}).run(2.0)
    t = df.index.to_numpy()
    np.testing.assert_allclose(df["ring.a.x"].to_numpy(), (1 + np.exp(-2 * t / TAU)) / 2, atol=1e-6)
    np.testing.assert_allclose(df["ring.a.x"] + df["ring.b.x"], 1.0, atol=1e-7)
    assert df["ring.a.bounces"].iloc[-1] >= 3 and (df["ring.a.bounces"] == df["ring.b.bounces"]).all()


@needs_reference
@pytest.mark.parametrize("version", [2, 3])
def test_discrete_connections_in_the_joint_event_iteration(version):
    """Stair's counter (time events) into Feedthrough's discrete Int32 input inside the
    system: the joint event iteration passes the new value at the event itself; Stair's
    stop request at 9 s ends the run normally."""
    stair = FMUComponent("stair", ref("Stair", version), 0.2, interface="me")
    ft = FMUComponent("ft", ref("Feedthrough", version), 0.2, interface="me")
    df = Cosimulation([MESystem("s", [stair, ft], {"ft.Int32_input": "stair.counter"}, 0.2)], {}).run(10.0)
    np.testing.assert_array_equal(df["s.ft.Int32_output"].to_numpy(), df["s.stair.counter"].to_numpy())
    assert df.index[-1] == 9.0 and df["s.stair.counter"].iloc[-1] == 10
    assert df.attrs["stopped"]["component"] == "s" and "member stair requested" in df.attrs["stopped"]["reason"]


def test_external_inputs_are_held_like_a_single_fmu(bouncing_me_fmu):
    """An input of the system driven by the master: the same as the FMU alone."""
    sine = Sine("src", 0.05, amplitude=1.0, frequency=1.0)
    alone = Cosimulation([sine, FMUComponent("lag", bouncing_me_fmu, 0.05, interface="me")],
                         {"lag.u": "src.out"}).run(1.0)
    system = MESystem("sys", [FMUComponent("lag", bouncing_me_fmu, 0.05, interface="me")], {}, 0.05)
    joint = Cosimulation([Sine("src", 0.05, amplitude=1.0, frequency=1.0), system], {"sys.lag.u": "src.out"}).run(1.0)
    np.testing.assert_allclose(joint["sys.lag.x"].to_numpy(), alone["lag.x"].to_numpy(), atol=1e-9)


@needs_reference
def test_an_algebraic_loop_between_members_is_refused():
    a = FMUComponent("a", ref("Feedthrough"), 0.1, interface="me")
    b = FMUComponent("b", ref("Feedthrough"), 0.1, interface="me")
    with pytest.raises(ConfigurationError, match=r"\['a', 'b'\].*algebraic loop"):
        MESystem("s", [a, b], {"a.Float64_continuous_input": "b.Float64_continuous_output",
                               "b.Float64_continuous_input": "a.Float64_continuous_output"}, 0.1)


@needs_reference
def test_refusals_name_the_problem(bouncing_me_fmu):
    cs = FMUComponent("cs", ref("Dahlquist"), 0.1, interface="cs")
    with pytest.raises(ConfigurationError, match="member 'cs' is a Co-Simulation FMU"):
        MESystem("s", [cs], {}, 0.1)
    lag = FMUComponent("lag", bouncing_me_fmu, 0.1, interface="me")
    with pytest.raises(UnknownNameError, match="no member 'vdp'; members: lag"):
        MESystem("s", [lag], {"lag.u": "vdp.x0"}, 0.1)
    with pytest.raises(UnknownNameError, match="member 'lag' has no output 'y'"):
        MESystem("s", [lag], {"lag.u": "lag.y"}, 0.1)
    iso = FMUComponent("iso", bouncing_me_fmu, 0.1, interface="me", isolate=True)
    with pytest.raises(ConfigurationError, match="cannot be isolated"):
        MESystem("s", [iso], {}, 0.1)


@pytest.mark.slow
@needs_reference
def test_from_a_scenario_file(bouncing_me_fmu, tmp_path):
    sc = write_scenario(tmp_path / "s.toml", 1.0, [
        component("me_system", "sys", 0.1, rtol=1e-8, connections={"lag.u": "vdp.x0"},
                  members=[{"name": "vdp", "path": ref("VanDerPol")}, {"name": "lag", "path": bouncing_me_fmu}])])
    proc = subprocess.run([*CLI, "run", str(sc), "--out", str(tmp_path / "out"), "--no-progress"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    df = pd.read_csv(tmp_path / "out" / "results.csv", index_col="time")
    api = Cosimulation([MESystem("sys", [FMUComponent("vdp", ref("VanDerPol"), 0.1, interface="me"),
                                         FMUComponent("lag", bouncing_me_fmu, 0.1, interface="me")],
                                 {"lag.u": "vdp.x0"}, 0.1, rtol=1e-8)], {}).run(1.0)
    np.testing.assert_array_equal(df.to_numpy(float), api.to_numpy(float))
    (tmp_path / "bad.toml").write_text(sc.read_text().replace('name = "lag"\n', 'name = "lag"\nperiod = 0.2\n'))
    proc = subprocess.run([*CLI, "run", str(tmp_path / "bad.toml"), "--out", str(tmp_path / "o2")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0 and "Traceback" not in proc.stderr and "period is the system's" in proc.stderr

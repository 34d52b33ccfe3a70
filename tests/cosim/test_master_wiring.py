"""The master's second stage: order from the wiring, algebraic loops, periods, typed ports,
Model Exchange FMUs, recording control and the component protocol."""
import inspect
import itertools
import math

import numpy as np
import pandas as pd
import pytest
from testkit.scenario_files import component, write_scenario

import cosim.core.component as protocol
from cosim.components.control import LQRController
from cosim.components.estimation import EstimatorComponent
from cosim.components.plant_model import ModelComponent
from cosim.components.sensors import ProcessNoise, Sensor
from cosim.components.sources import Constant, Sine, Step
from cosim.core.component import Component
from cosim.core.master import Cosimulation
from cosim.fmi.fmu_component import FMUComponent
from cosim.scenario import Scenario
from estimators import EKF, discretize
from fmu_models import get_model
from fmu_models.errors import ConfigurationError, CosimError, TypeMismatchError


class Affine(Component):
    """y = a + b u: a pure direct-feedthrough block."""

    reentrant = True

    def __init__(self, name, period, a=0.0, b=1.0):
        super().__init__(name, period, ["u"], ["y"])
        self.a, self.b = a, b

    def output(self, t, u):
        return np.array([self.a + self.b * u[0]])


def _seed000_parts(plant_fmu=None):
    model = get_model("cartpole")
    plant = (FMUComponent("plant", plant_fmu, 0.01, start=dict(zip(model.state_names, model.x0)))
             if plant_fmu else ModelComponent("plant", model, 0.01))
    sys_ = discretize(model, 0.01)
    return [plant,
            Sensor("sensor", 0.01, ["x", "theta"], noise_std=0.3, seed=2),
            EstimatorComponent("ekf", lambda: EKF(sys_, model.x0, 1.0, 0.2, 0.1)),
            Step("force", 0.01, 2.0, -0.5, 0.5),
            ProcessNoise("noise", 0.01, model.state_names, 0.2, seed=1)]


SEED000_WIRING = {"plant.F": "force.out", "sensor.x": "plant.x", "sensor.theta": "plant.theta",
                  "ekf.F": "force.out", "ekf.y_x": "sensor.y_x", "ekf.y_theta": "sensor.y_theta",
                  **{f"plant.w_{s}": f"noise.w_{s}" for s in ("x", "x_dot", "theta", "theta_dot")}}


@pytest.mark.slow
def test_any_component_order_gives_the_papers_loop(fmu_paths):
    """Every permutation of the seed 000 loop gives identical signals, and the filter sees
    exactly the paper's timing (predict with u_{k-1}, update with y_k)."""
    ref = None
    for perm in itertools.permutations(range(5)):
        parts = _seed000_parts(fmu_paths["cartpole"])
        df = Cosimulation([parts[i] for i in perm], SEED000_WIRING).run(3.0)
        df = df[sorted(df.columns)]
        if ref is None:
            ref = df
        else:
            pd.testing.assert_frame_equal(df, ref, check_exact=True)
    # the paper's loop by hand: x_k = f(x_{k-1}, u_{k-1}) + w_{k-1}; y_k = h(x_k) + v_k
    model = get_model("cartpole")
    sys_ = discretize(model, 0.01)
    ekf = EKF(sys_, model.x0, 1.0, 0.2, 0.1)
    y = ref[["sensor.y_x", "sensor.y_theta"]].to_numpy()
    u = ref["force.out"].to_numpy()
    est = [model.x0] + [ekf.step([u[k - 1]], y[k]) for k in range(1, len(ref))]
    np.testing.assert_allclose(ref[["ekf.x", "ekf.x_dot", "ekf.theta", "ekf.theta_dot"]].to_numpy(),
                               np.array(est), rtol=0, atol=1e-12)


def test_a_reversed_chain_adds_no_latency():
    src = Sine("src", 0.01, 1.0, 2.0)
    chain = [Affine("a", 0.01, b=2.0), Affine("b", 0.01, b=3.0), Affine("c", 0.01, a=1.0)]
    conn = {"a.u": "src.out", "b.u": "a.y", "c.u": "b.y"}
    fwd = Cosimulation([src, *chain], conn).run(1.0)
    rev = Cosimulation([*reversed(chain), src], conn).run(1.0)
    np.testing.assert_array_equal(fwd["c.y"], rev["c.y"][fwd.index])
    np.testing.assert_allclose(fwd["c.y"], 1 + 6 * fwd["src.out"], rtol=1e-15)
    # an explicit order is still possible: listed last, the source is read a sample late
    given = Cosimulation([*chain, src], conn, order="given").run(1.0)
    np.testing.assert_allclose(given["a.y"].to_numpy()[1:], 2 * given["src.out"].to_numpy()[:-1])


def test_algebraic_loops_are_refused_with_their_ports_named(typed_fmu):
    a, b = Affine("a", 0.01, a=1.0, b=0.5), Affine("b", 0.01)
    loop = r"algebraic loop: (a\.y -> b\.u, b\.y -> a\.u|b\.y -> a\.u, a\.y -> b\.u)"
    with pytest.raises(ConfigurationError, match=loop):
        Cosimulation([a, b], {"b.u": "a.y", "a.u": "b.y"})
    f1 = FMUComponent("f1", typed_fmu, 0.01, inputs=["in_f64"], outputs=["out_f64"])
    f2 = FMUComponent("f2", typed_fmu, 0.01, inputs=["in_f64"], outputs=["out_f64"])
    with pytest.raises(ConfigurationError, match=r"algebraic loop: .*f1\.out_f64 -> f2\.in_f64"):
        Cosimulation([f1, f2], {"f2.in_f64": "f1.out_f64", "f1.in_f64": "f2.out_f64"})
    # a loop broken by an FMU read as left limits runs, one step late
    f3 = FMUComponent("f3", typed_fmu, 0.01, inputs=["in_f64"], outputs=["out_f64"], feedthrough="none")
    src = Constant("src", 0.01, 2.0)
    add = Affine("add", 0.01, a=1.0, b=0.5)
    df = Cosimulation([add, f3, src], {"f3.in_f64": "add.y", "add.u": "f3.out_f64"}).run(0.05)
    assert df["f3.out_f64"].iloc[0] == 0.0 and df["add.y"].iloc[1] == pytest.approx(1.5)


@pytest.mark.parametrize("solver", ["newton", "fixed-point"])
def test_an_iterated_linear_loop_reaches_its_fixed_point(solver):
    """a.y = 1 + 0.5 b.y, b.y = a.y: the fixed point is a.y = b.y = 2 at every instant
    (without iteration the old master gave 1.5 and 1.75 at t = 0)."""
    a, b = Affine("a", 0.01, a=1.0, b=0.5), Affine("b", 0.01)
    cs = Cosimulation([a, b], {"b.u": "a.y", "a.u": "b.y"}, loops="iterate", loop_solver=solver,
                      loop_tolerance=1e-12)
    assert "algebraic loop, solved by iteration" in cs.describe()
    df = cs.run(0.05)
    np.testing.assert_allclose(df[["a.y", "b.y"]].to_numpy(), 2.0, rtol=1e-12)
    # a loop through a component that cannot evaluate twice is refused
    ekf_like = EstimatorComponent("e", lambda: EKF(discretize(get_model("cartpole"), 0.01),
                                                   np.zeros(4), 1.0, 0.1, 0.1))
    with pytest.raises(ConfigurationError, match="cannot be iterated: e"):
        Cosimulation([ekf_like, Affine("g", 0.01), Affine("h", 0.01), Constant("f", 0.01, 0.0)],
                     {"g.u": "e.x", "h.u": "e.theta", "e.y_x": "g.y", "e.y_theta": "h.y", "e.F": "f.out"},
                     loops="iterate")


def test_a_divergent_loop_stops_with_a_named_error():
    a, b = Affine("a", 0.01, a=1.0, b=2.0), Affine("b", 0.01)       # y = 1 + 2y: fixed point -1
    cs = Cosimulation([a, b], {"b.u": "a.y", "a.u": "b.y"}, loops="iterate", loop_solver="fixed-point",
                      loop_max_iter=20)
    with pytest.raises(CosimError, match="did not converge in 20 iterations at t = 0 s"):
        cs.run(0.05)
    newton = Cosimulation([a, b], {"b.u": "a.y", "a.u": "b.y"}, loops="iterate")
    np.testing.assert_allclose(newton.run(0.02)["a.y"], -1.0, rtol=1e-12)


def test_a_component_level_cycle_is_split_at_the_fmu(fmu_paths):
    """plant.x -> controller -> plant.F is not a loop (x does not depend on F now), but
    der(x_dot) does; the plant is evaluated twice: states first, derivatives later."""
    model = get_model("cartpole")
    outs = model.state_names + ["der(x_dot)"]
    plant = FMUComponent("plant", fmu_paths["cartpole"], 0.01, outputs=outs,
                         start={"theta": 0.05, "x": 0.0, "x_dot": 0.0, "theta_dot": 0.0})
    lqr = LQRController("lqr", model, 0.01, Q=[1.0, 1.0, 10.0, 1.0], R=[[1.0]])
    conn = {"plant.F": "lqr.F", **{f"lqr.{s}": f"plant.{s}" for s in model.state_names}}
    cs = Cosimulation([plant, lqr], conn)
    assert [str(u) for g in cs.schedule for u in g.units] == \
        ["plant (free outputs)", "lqr", "plant (dependent outputs)"]
    df = cs.run(1.0)
    # der(x_dot) at t is f(x_t, F_t) with the command of the same instant
    x = df[[f"plant.{s}" for s in model.state_names]].to_numpy()
    f = np.array([model.f(xi, [F])[1] for xi, F in zip(x, df["lqr.F"])])
    np.testing.assert_allclose(df["plant.der(x_dot)"], f, rtol=1e-12, atol=1e-12)
    assert abs(df["plant.theta"].iloc[-1]) < 0.05


@pytest.mark.parametrize("periods", [(0.001, math.pi / 1000), (0.01, 0.010001)])
def test_incommensurate_periods_are_refused_before_anything_runs(periods):
    a, b = Constant("a", periods[0], 1.0), Constant("b", periods[1], 2.0)
    with pytest.raises(ConfigurationError, match=r"periods \(a .* s, b .* s\)"):
        Cosimulation([a, b], {})


def test_typed_fmi3_ports_pass_at_the_same_instant(typed_fmu):
    ft = FMUComponent("ft", typed_fmu, 0.1)
    assert {p.name: p.type for p in ft.input_ports} == {"in_f32": "Float32", "in_i32": "Int32",
                                                        "in_bool": "Boolean", "in_enum": "Enumeration",
                                                        "in_f64": "Float64"}
    sources = [Sine("s", 0.1, 1.0, 1.0), Constant("one", 0.1, 1.0)]

    class Counter(Component):
        reentrant = True

        def __init__(self):
            super().__init__("k", 0.1, outputs=[protocol.Port("i", "Int32"), protocol.Port("b", "Boolean"),
                                                protocol.Port("e", "Int64")])

        def output(self, t, u):
            k = round(t / 0.1)
            return np.array([k - 5, k % 2, 1 + k % 3])

    conn = {"ft.in_f32": "s.out", "ft.in_f64": "s.out", "ft.in_i32": "k.i", "ft.in_bool": "k.b",
            "ft.in_enum": "k.e"}
    df = Cosimulation([ft, *sources, Counter()], conn).run(1.0)
    np.testing.assert_allclose(df["ft.out_f32"], df["s.out"].astype(np.float32), rtol=0)
    np.testing.assert_array_equal(df["ft.out_f64"], df["s.out"])
    np.testing.assert_array_equal(df["ft.out_i32"], df["k.i"])
    np.testing.assert_array_equal(df["ft.out_bool"], df["k.b"])
    np.testing.assert_array_equal(df["ft.out_enum"], df["k.e"])
    np.testing.assert_array_equal(df["ft.count"], np.arange(11))     # Int64, one doStep per 0.1 s
    with pytest.raises(TypeMismatchError, match="a Float64 output cannot drive a Int32 input"):
        Cosimulation([FMUComponent("ft", typed_fmu, 0.1), sources[0]], {"ft.in_i32": "s.out"})


def test_a_model_exchange_only_fmu_runs_from_a_scenario_file(bouncing_me_fmu, tmp_path):
    scen = write_scenario(tmp_path / "ball.toml", 1.0,
                          [component("fmu", "ball", 0.01, path=bouncing_me_fmu, solver="cvode", rtol=1e-9),
                           component("constant", "push", 0.01, value=1.0)], {"ball.u": "push.out"})
    df = Scenario.load(scen).run()
    g, h0, e = 9.81, 1.0, 0.7
    t1 = math.sqrt(2 * h0 / g)                                   # first bounce, state event
    after = df.loc[0.6]                                          # between the bounces
    v_expected = e * g * t1 - g * (0.6 - t1)
    assert after["ball.v"] == pytest.approx(v_expected, abs=1e-5)
    assert df["ball.bounces"].loc[0.45] == 0 and df["ball.bounces"].loc[0.46] == 1
    np.testing.assert_array_equal(df["ball.ticks"].loc[[0.24, 0.25, 0.5, 0.99, 1.0]], [0, 1, 2, 3, 4])
    np.testing.assert_allclose(df["ball.x"], 1 - np.exp(-df.index / 0.5), atol=1e-6)   # time events
    # fixed-step Euler: same ODE, first-order accurate; the bounce is found at the step end
    euler = Cosimulation([FMUComponent("ball", bouncing_me_fmu, 0.01, solver="euler", solver_step=1e-4),
                          Constant("push", 0.01, 1.0)], {"ball.u": "push.out"}).run(1.0)
    assert euler["ball.v"].loc[0.6] == pytest.approx(v_expected, abs=2e-3)


@pytest.mark.parametrize("version", [2, 3])
def test_the_plants_agree_in_model_exchange_and_co_simulation(fmu_builds, version):
    model = get_model("cartpole")
    path = fmu_builds["cartpole", version]
    src = Sine("src", 0.01, 0.5, 0.7)
    cs = Cosimulation([FMUComponent("p", path, 0.01), src], {"p.F": "src.out"}).run(3.0)
    me = Cosimulation([FMUComponent("p", path, 0.01, interface="me", solver="euler"), src],
                      {"p.F": "src.out"}).run(3.0)
    np.testing.assert_allclose(me.to_numpy(), cs.to_numpy(), rtol=0, atol=1e-12)
    rk = Cosimulation([FMUComponent("p", path, 0.01, parameters={"integrator": 2, "substeps": 4}), src],
                      {"p.F": "src.out"}).run(3.0)
    me_rk = Cosimulation([FMUComponent("p", path, 0.01, interface="me", solver="rk4", solver_step=0.0025), src],
                         {"p.F": "src.out"}).run(3.0)
    np.testing.assert_allclose(me_rk.to_numpy(), rk.to_numpy(), rtol=0, atol=1e-11)
    cv = Cosimulation([FMUComponent("p", path, 0.01, interface="me", rtol=1e-10), src],
                      {"p.F": "src.out"}).run(3.0)
    np.testing.assert_allclose(cv.to_numpy(), rk.to_numpy(), rtol=0, atol=1e-6)
    assert model.nx == 4


def test_recording_interval_selection_and_streaming(fmu_paths, tmp_path):
    parts = _seed000_parts(fmu_paths["cartpole"])
    cs = Cosimulation(parts, SEED000_WIRING)
    full = cs.run(5.0)
    some = Cosimulation(_seed000_parts(fmu_paths["cartpole"]), SEED000_WIRING).run(
        5.0, signals=["plant.*", "ekf.x"], output_interval=0.05)
    assert list(some.columns) == ["plant.x", "plant.x_dot", "plant.theta", "plant.theta_dot",
                                  "plant.y_x", "plant.y_theta", "ekf.x"]
    pd.testing.assert_frame_equal(some, full.loc[full.index[::5], some.columns], check_exact=True)
    path = Cosimulation(_seed000_parts(fmu_paths["cartpole"]), SEED000_WIRING).run_to_parquet(
        tmp_path / "run.parquet", 5.0, chunk_rows=37)
    streamed = pd.read_parquet(path)
    pd.testing.assert_frame_equal(streamed, full, check_exact=True)
    assert not list(tmp_path.glob(".*tmp"))
    with pytest.raises(ConfigurationError, match="base steps of 0.01 s: output_interval 0.015 s is 1.5"):
        cs.run(1.0, output_interval=0.015)
    with pytest.raises(KeyError, match="'plnt.*' matches no signal"):
        cs.run(1.0, signals="plnt.*")


def test_a_failed_streamed_run_leaves_a_partial_file_not_a_finished_one(fmu_paths, tmp_path):
    class Boom(Component):
        def __init__(self):
            super().__init__("boom", 0.01, outputs=["y"])

        def output(self, t, u):
            if t > 0.3:
                raise RuntimeError("deliberate")
            return np.zeros(1)

    with pytest.raises(CosimError, match="boom") as err:
        Cosimulation([Boom()], {}).run_to_parquet(tmp_path / "r.parquet", 1.0, chunk_rows=7)
    assert not (tmp_path / "r.parquet").exists()
    part = pd.read_parquet(err.value.results)
    assert err.value.results.name == "r.partial.parquet" and len(part) == 31


def test_describe_and_dry_run_show_order_and_latency(tmp_path, capsys):
    from cosim.cli import main

    cs = Cosimulation(_seed000_parts(), SEED000_WIRING)
    text = cs.describe()
    assert "sensor.y_x -> ekf.y_x: direct feedthrough" in text
    assert "force.out -> ekf.F: consumed at t by update" in text
    assert main(["run", "seed000_cartpole", "--out", str(tmp_path / "o"), "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert "evaluation order" in out and not (tmp_path / "o" / "results.csv").exists()


def test_the_component_protocol_is_documented_and_is_all_a_new_component_needs():
    doc = inspect.getdoc(protocol)
    for word in ("output", "update", "feedthrough", "reentrant", "bind", "reset", "close"):
        assert word in doc
    for name in ("output", "update", "reset", "close", "sample", "from_scenario"):
        assert inspect.getdoc(getattr(Component, name)), name
    from cosim.core.component import ExportsFMU, FastBinding

    assert inspect.getdoc(FastBinding.bind) and inspect.getdoc(ExportsFMU.export_fmu)
    # every component of the package implements the protocol
    from cosim.components import imu, sources

    classes = [FMUComponent, ModelComponent, EstimatorComponent, LQRController, Sensor, ProcessNoise,
               imu.Accelerometer, imu.Gyroscope, imu.Encoder, imu.TiltFusion, sources.Constant,
               sources.Step, sources.Sine, sources.PRBS, sources.Table]
    assert all(issubclass(c, Component) for c in classes)

    class Integrator(Component):          # a user component with state and no feedthrough
        def __init__(self):
            super().__init__("i", 0.1, ["u"], ["y"], feedthrough=False)

        def reset(self, t0):
            super().reset(t0)
            self.s = 0.0

        def output(self, t, u):
            return np.array([self.s])

        def update(self, t, u):
            self.s += 0.1 * u[0]

    # a loop through it is not algebraic: y_{k+1} = y_k + 0.1 (1 - y_k)
    df = Cosimulation([Integrator(), Affine("err", 0.1, a=1.0, b=-1.0)],
                      {"i.u": "err.y", "err.u": "i.y"}).run(1.0)
    np.testing.assert_allclose(df["i.y"], 1 - 0.9 ** np.arange(11), rtol=1e-12)
    with pytest.raises(TypeError, match="not a cosim.core.component.Component"):
        Cosimulation([object()], {})


def test_every_shipped_component_type_is_usable_from_a_scenario_file(tmp_path):
    """The seed 002 loop (plant model, accelerometer, gyroscope, encoder, tilt fusion, bias
    EKF, LQR) written as a scenario file gives the experiment's own numbers."""
    from cosim import COMPONENTS, Cosimulation, Scenario
    from cosim.experiments import seed002
    from cosim.experiments.campaign import realisation_seeds

    s = seed002.Settings()
    sa, sg = realisation_seeds(s.seed, 0, 0)
    sc = Scenario.load(write_scenario(tmp_path / "loop.toml", 2.0, [
        component("plant_model", "plant", s.T, model="iwp", method="rk4", substeps=s.substeps,
                  start={"alpha": s.alpha0}, outputs=["alpha", "alpha_dot", "phi_dot", "der(alpha_dot)"],
                  feedthrough="none"),
        component("accelerometer", "acc", s.T, r=s.r_acc, noise_std=s.acc_std, seed=sa),
        component("gyroscope", "gyro", s.T, noise_std=s.gyro_std, bias=s.gyro_bias, seed=sg),
        component("encoder", "encoder", s.T, counts_per_rev=s.counts_per_rev),
        component("tilt_fusion", "fusion", s.T, q_angle=s.fusion_q_angle, q_bias=s.fusion_q_bias, r_tilt=s.fusion_r),
        component("estimator", "ekf", s.T, filter="EKF", model="iwp", bias_on="y_alpha_dot", x0=[0.0] * 4, P0=s.P0,
                  Q=0.01, R=0.01),
        component("lqr", "lqr", s.T, model="iwp", Q=list(s.lqr_q), R=[[s.lqr_r]], u_limits=[-s.i_max, s.i_max])],
        {"plant.i": "lqr.i", "acc.alpha": "plant.alpha", "acc.alpha_dot": "plant.alpha_dot",
         "acc.alpha_ddot": "plant.der(alpha_dot)", "gyro.alpha_dot": "plant.alpha_dot",
         "encoder.phi_dot": "plant.phi_dot", "fusion.a_t": "acc.a_t", "fusion.a_r": "acc.a_r",
         "fusion.omega": "gyro.omega", "ekf.i": "lqr.i", "ekf.y_alpha": "fusion.alpha",
         "ekf.y_alpha_dot": "fusion.alpha_dot", "ekf.y_phi_dot": "encoder.phi_dot", "lqr.alpha": "ekf.alpha",
         "lqr.alpha_dot": "ekf.alpha_dot", "lqr.phi_dot": "ekf.phi_dot"}))
    kinds = {type(c).kind for c in sc.cosim.components}
    assert kinds == {"plant_model", "accelerometer", "gyroscope", "encoder", "tilt_fusion", "estimator", "lqr"}
    assert kinds <= set(COMPONENTS.names())
    comps, conn = seed002._components(s, "Q = R = 0.01", 0, "fast")
    ref = Cosimulation(comps, conn).run(2.0)
    got = sc.run()
    np.testing.assert_allclose(got.to_numpy(), ref[got.columns].to_numpy(), rtol=0, atol=1e-12)


def test_an_estimator_called_directly_takes_a_missing_measurement_without_a_warning():
    # a NaN measurement means "missing" (nan_is_missing); the direct calls bind the estimator
    # on a private buffer, whose integer copy must not cast the real inputs (a NaN would warn)
    cp = get_model("cartpole")
    est = EstimatorComponent("ekf", lambda: EKF(discretize(cp, 0.01), x0=cp.x0, P0=1.0, Q=1e-3, R=1e-2))
    est.reset(0.0)
    u = np.array([0.0, np.nan, 0.1])
    first = est.output(0.0, u)
    est.update(0.0, u)
    second = est.output(0.01, u)
    assert np.isfinite(first).all() and np.isfinite(second).all()

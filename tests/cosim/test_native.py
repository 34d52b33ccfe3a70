"""The native kernel against the Python loop: the same results bit for bit, the same named
errors with the same partial results, the same stops, interrupts and streamed files."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from testkit import reference_cases as rc
from testkit.chaos import NO_CRASH

import cosim
import estimators
from cosim import Cosimulation, FMUComponent, Sine
from cosim.components.estimation import EstimatorComponent
from cosim.components.sources import Constant, Step
from cosim.core.component import Component
from cosim.scenario import Scenario
from fmu_models import get_model
from fmu_models.errors import ConfigurationError, Interrupted, PendulumCosimError

ENGINES = ("python", "native")
SCENARIOS = sorted(Path(cosim.__file__).parent.glob("scenarios/*.toml"))


def outcome(make, run=lambda cs: cs.run(1.0, progress=False)):
    """(result or partial rows, error class name, message) of ``run(make(engine))`` per engine."""
    out = {}
    for engine in ENGINES:
        cs = make(engine)
        try:
            out[engine] = (run(cs), None, None)
        except PendulumCosimError as e:
            rows = e.partial if isinstance(e, Interrupted) else getattr(e, "results", None)
            out[engine] = (rows, type(e).__name__, str(e))
    return out


def assert_same(out):
    (a, ea, ma), (b, eb, mb) = out["python"], out["native"]
    assert (ea, ma) == (eb, mb)
    if isinstance(a, pd.DataFrame):
        assert isinstance(b, pd.DataFrame)
        assert list(a.columns) == list(b.columns) and list(a.dtypes) == list(b.dtypes)
        np.testing.assert_array_equal(a.index.to_numpy(), b.index.to_numpy())
        assert a.equals(b), (a.compare(b) if a.shape == b.shape else (a.shape, b.shape))
        assert a.attrs.get("stopped") == b.attrs.get("stopped")
    else:
        assert a == b


def ekf(name="ekf", covariance="diagonal"):
    system = estimators.discretize(get_model("cartpole"), 0.01)
    return EstimatorComponent(name, lambda: estimators.EKF(system, [0.5, 0, 1.8, 0.5], 1.0, 0.2, 0.1),
                              covariance=covariance)


class Gain(Component):
    """A user's own Python component."""

    def __init__(self, name, period, k):
        super().__init__(name, period, ["u"], ["y"])
        self.k = k

    def output(self, t, u):
        return self.k * u


class Failing(Component):
    def __init__(self, name, period, at, what):
        super().__init__(name, period, outputs=["y"])
        self.at, self.what = at, what

    def output(self, t, u):
        if t >= self.at - 1e-12:
            if self.what == "nan":
                return np.array([np.nan])
            if self.what == "interrupt":
                raise KeyboardInterrupt
            if self.what == "huge":
                return np.array([1.7e308])
            raise RuntimeError("deliberate failure")
        return np.array([0.1])


@pytest.mark.parametrize("path", SCENARIOS, ids=[p.stem for p in SCENARIOS])
def test_every_shipped_scenario_gives_the_same_bits(path):
    def make(engine):
        sc = Scenario.load(path)
        sc.cosim.engine = engine
        make.sc = sc
        return sc.cosim

    out = outcome(make, lambda cs: cs.run(make.sc.stop_time, make.sc.start_time, progress=False))
    assert out["python"][1] is None
    assert_same(out)
    assert "native" in make.sc.cosim.describe().split("engine:")[1]


@pytest.mark.parametrize("version", (2, 3))
def test_plant_source_filter_and_a_python_component_give_the_same_bits(fmu_builds, version):
    def make(engine):
        plant = FMUComponent("plant", fmu_builds["cartpole", version], 0.01, start={"theta": 1.8})
        return Cosimulation([ekf(covariance="full"), plant, Step("force", 0.02, 0.3, -0.5, 0.5),
                             Gain("gain", 0.01, 0.5), Constant("c", 0.05, 2.0)],
                            {"plant.F": "force.out", "ekf.F": "force.out", "ekf.y_x": "plant.y_x",
                             "gain.u": "plant.theta", "ekf.y_theta": "gain.y"}, engine=engine)

    out = outcome(make)
    assert out["python"][1] is None and len(out["python"][0]) == 101
    assert_same(out)
    text = make("auto").describe()
    assert "plant            native" in text and "gain             Python (a Python component)" in text


@pytest.mark.parametrize("cov", ["full", "diagonal"])
def test_noise_sensor_and_prbs_run_natively_and_draw_the_same_numbers(fmu_builds, cov):
    """Sensor, process noise and PRBS in the kernel: the same rows of the same block-drawn
    noise streams (over several blocks, with periods of 1 and 2 base steps), beside a delayed
    sensor and a counter-generator one that stay in Python and share nothing with them."""
    from cosim.components.noise import PerInstantNoise
    from cosim.components.sensors import ProcessNoise, Sensor
    from cosim.components.sources import PRBS

    def make(engine):
        plant = FMUComponent("plant", fmu_builds["cartpole", 2], 0.01, start={"theta": 1.8})
        states = ["x", "x_dot", "theta", "theta_dot"]
        return Cosimulation(
            [plant, PRBS("force", 0.01, 0.5, 0.07, 5, 3, offset=0.1),
             ProcessNoise("noise", 0.01, states, [[1e-4, 2e-5, 0, 0], [2e-5, 1e-4, 0, 0], [0, 0, 1e-4, 0],
                                                  [0, 0, 0, 3e-4]] if cov == "full" else [1e-4, 2e-4, 3e-5, 3e-4],
                          seed=4),
             Sensor("s", 0.02, ["x", "theta"], noise_std=[0.1, 0.2], bias=[0.01, -0.02], seed=5),
             Sensor("late", 0.01, ["x"], noise_std=0.1, delay=2, seed=6),
             Sensor("ctr", 0.01, ["theta"], noise_std=0.1, generator="counter", seed=7)],
            {"plant.F": "force.out", **{f"plant.w_{x}": f"noise.w_{x}" for x in states},
             "s.x": "plant.x", "s.theta": "plant.theta", "late.x": "plant.x", "ctr.theta": "plant.theta"},
            engine=engine)

    steps = 3 * PerInstantNoise.BLOCK + 17
    out = outcome(make, lambda cs: cs.run(steps * 0.01, progress=False))
    assert out["python"][1] is None and len(out["python"][0]) == steps + 1
    assert_same(out)
    text = make("auto").describe()
    paths = {line.split()[0]: line.split()[1] for line in text.splitlines() if len(line.split()) > 1}
    assert [paths[c] for c in ("force", "noise", "s", "late", "ctr")] == ["native"] * 3 + ["Python"] * 2
    assert "delay or quantisation" in text and "counter generator" in text


def test_block_drawn_noise_is_the_stream_drawn_one_instant_at_a_time():
    from cosim.components.noise import PerInstantNoise

    noise, rng = PerInstantNoise(11, 3), np.random.default_rng(11)
    for k in range(2 * PerInstantNoise.BLOCK + 5):
        first = noise.at(0.5 * k)
        np.testing.assert_array_equal(noise.at(0.5 * k), first)        # the same instant: the same draw
        np.testing.assert_array_equal(first, rng.standard_normal(3))


def test_an_fmu_chain_streamed_to_parquet_in_small_chunks_gives_the_same_file(fmu_builds, tmp_path):
    def make(engine):
        plants = [FMUComponent(f"p{i}", fmu_builds["cartpole", 2], 0.01) for i in range(4)]
        conn = {f"p{i}.F": f"p{i - 1}.x" for i in range(1, 4)}
        return Cosimulation([*plants, Sine("src", 0.03, 1.0, 2.0)], {**conn, "p0.F": "src.out"}, engine=engine)

    def run(cs):
        path = tmp_path / f"{cs.engine}.parquet"
        cs.run_to_parquet(path, 2.0, signals=["p*.x", "p3.*", "src.out"], output_interval=0.03, chunk_rows=7,
                          progress=False)
        return pd.read_parquet(path)

    assert_same(outcome(make, run))


@pytest.mark.parametrize("what", ["raise", "nan", "interrupt"])
def test_a_failure_in_a_python_component_is_the_same_error_with_the_same_rows(fmu_builds, what):
    def make(engine):
        plant = FMUComponent("plant", fmu_builds["cartpole", 2], 0.01)
        return Cosimulation([plant, Failing("bad", 0.01, 0.73, what)], {"plant.F": "bad.y"}, engine=engine)

    out = outcome(make)
    assert out["python"][1] == ("Interrupted" if what == "interrupt" else "CosimError")
    assert_same(out)
    assert len(out["native"][0]) > 50


def test_a_non_finite_fmu_output_in_the_native_kernel_is_named_the_same(fmu_builds):
    def make(engine):
        plant = FMUComponent("plant", fmu_builds["cartpole", 2], 0.01, start={"theta": 1.8})
        return Cosimulation([plant, Constant("force", 0.01, 1e300)], {"plant.F": "force.out"}, engine=engine)

    out = outcome(make, lambda cs: cs.run(5.0, progress=False))
    assert out["python"][1] == "CosimError" and "plant" in out["python"][2]
    assert_same(out)


def test_a_misbehaving_fmu_gives_the_same_errors_and_rows(chaos_fmu, tmp_path, monkeypatch):
    monkeypatch.setenv("CHAOS_LOG", str(tmp_path / "chaos.log"))
    classes = set()
    for seed in range(30):
        def make(engine, seed=seed):
            comp = FMUComponent("chaos", chaos_fmu, 0.01,
                                parameters={"seed": seed, "rate": 0.01, "actions": NO_CRASH, "sleep_us": 0})
            return Cosimulation([Sine("src", 0.01, 1.0, 1.0), comp], {"chaos.u": "src.out"}, engine=engine)

        out = outcome(make)
        assert_same(out)
        classes.add(out["python"][1])
    assert None in classes and "CosimError" in classes, classes


needs_reference = pytest.mark.skipif(rc.reference_dir() is None, reason="the Reference FMUs are absent")
CS_CASES = [c for c in rc.cases() if c.interface == "cs" and not c.refused] if rc.reference_dir() else []


@needs_reference
@pytest.mark.parametrize("case", CS_CASES, ids=[c.label for c in CS_CASES])
def test_reference_fmus_give_the_same_bits(case):
    def make(engine):
        comp = FMUComponent("m", rc.fmu_path(case), case.period, parameters=case.parameters or None)
        return Cosimulation([comp], {}, engine=engine)

    assert_same(outcome(make, lambda cs: cs.run(case.stop, case.start, progress=False)))


def test_engine_choices_are_checked_and_described():
    with pytest.raises(ConfigurationError, match="engine must be one of"):
        Cosimulation([Constant("c", 0.1, 1.0)], {}, engine="fast")
    with pytest.raises(ConfigurationError, match="engine='native' cannot run .*jacobi"):
        Cosimulation([Constant("c", 0.1, 1.0)], {}, order="jacobi", engine="native")
    text = Cosimulation([Constant("c", 0.1, 1.0)], {}, engine="python").describe()
    assert "every call runs in Python (engine='python')" in text
    cs = Cosimulation([Constant("c", 0.1, 1.0)], {}, order="jacobi")
    with pytest.raises(ConfigurationError, match="engine must be one of"):
        cs.engine = "fast"
    with pytest.raises(ConfigurationError, match="engine='native' cannot run .*jacobi"):
        cs.engine = "native"
    assert cs.engine == "auto"
    cs.engine = "python"
    assert cs.engine == "python"


def test_ctrl_c_is_seen_within_a_chunk_of_native_steps(fmu_builds):
    import _thread
    import threading
    import time

    plant = FMUComponent("plant", fmu_builds["cartpole", 2], 0.001)
    cs = Cosimulation([plant, Constant("force", 0.001, 0.0)], {"plant.F": "force.out"}, engine="native")
    timer = threading.Timer(0.3, _thread.interrupt_main)
    start = time.perf_counter()
    timer.start()
    try:
        with pytest.raises(Interrupted, match="interrupted at t = ") as info:
            cs.run(1e5, output_interval=1.0, progress=False)      # 1e8 base steps
    finally:
        timer.cancel()
    assert time.perf_counter() - start < 5.0
    rows = info.value.partial
    assert isinstance(rows, pd.DataFrame) and len(rows) > 0 and np.isfinite(rows.to_numpy()).all()
    assert plant.instance is None                              # freed


ARGS = {"IAE": {"window": 10}, "SWML": {"window": 20, "every": 10, "early_until": 4},
        "IAE full": {"window": 10, "form": "full"}}


@pytest.mark.parametrize("kind", ["IAE", "SWML", "IAE full"])
def test_adaptive_filters_run_their_hook_and_keep_the_same_history(fmu_builds, kind):
    system = estimators.discretize(get_model("cartpole"), 0.01)
    cls = getattr(estimators, kind.split()[0])
    comps = {}

    def make(engine):
        filt = EstimatorComponent("f", lambda: cls(system, [0.5, 0, 1.8, 0.5], 1.0, 0.2, 0.1, **ARGS[kind]))
        comps[engine] = filt
        plant = FMUComponent("plant", fmu_builds["cartpole", 2], 0.01, start={"theta": 1.8})
        return Cosimulation([filt, plant, Step("force", 0.01, 0.5, -0.5, 0.5)],
                            {"plant.F": "force.out", "f.F": "force.out", "f.y_x": "plant.y_x",
                             "f.y_theta": "plant.y_theta"}, engine=engine)

    # IAE: 1500 steps, adapting at each, so the history outgrows its first 1024 rows (the
    # kernel records the rows, and Python when they are full; the full form's projection is
    # Python's); the others 200
    steps = 1500 if kind == "IAE" else 200
    assert_same(outcome(make, lambda cs: cs.run(steps * 0.01, progress=False)))
    a, b = (comps[e].filter for e in ENGINES)
    assert a.k == b.k == steps
    np.testing.assert_array_equal(a.x, b.x)
    hist = a.noise_history()
    assert len(hist) > (1024 if kind == "IAE" else 1) and hist.equals(b.noise_history())
    assert "f                native" in make("auto").describe()


def test_a_failure_streamed_to_parquet_leaves_the_same_partial_file(fmu_builds, tmp_path):
    def make(engine):
        plant = FMUComponent("plant", fmu_builds["cartpole", 3], 0.01)
        return Cosimulation([plant, Failing("bad", 0.01, 0.73, "raise")], {"plant.F": "bad.y"}, engine=engine)

    def run(cs):
        return cs.run_to_parquet(tmp_path / f"{cs.engine}.parquet", 1.0, chunk_rows=7, progress=False)

    out = outcome(make, run)
    (a, ea, ma), (b, eb, mb) = out["python"], out["native"]
    assert ea == eb == "CosimError" and ma.replace("python", "native") == mb
    assert a.name == "python.partial.parquet" and b.name == "native.partial.parquet"
    pa, pb = pd.read_parquet(a), pd.read_parquet(b)
    assert len(pa) == 73 and pa.equals(pb)


def _same(a, b) -> bool:
    """Exact equality of nested results (dicts, lists, arrays, frames)."""
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, (pd.DataFrame, pd.Series)):
        return a.equals(b)
    if isinstance(a, np.ndarray):
        return a.shape == b.shape and np.array_equal(a, b, equal_nan=a.dtype.kind in "fc")
    if isinstance(a, float) and np.isnan(a):
        return isinstance(b, float) and np.isnan(b)
    return a == b


@pytest.mark.slow
def test_the_seed_000_campaign_on_the_master_path_is_the_same_on_both_engines(monkeypatch):
    from cosim.experiments import seed000

    s = seed000.Settings(runs=2, duration=1.0)
    init = Cosimulation.__init__
    results = {}
    for engine in ENGINES:
        monkeypatch.setattr(Cosimulation, "__init__", lambda self, *a, engine=engine, **k: init(
            self, *a, **{**k, "engine": engine}))
        results[engine] = [seed000.master_task(i, "eqs", s) for i in range(len(s.scenarios))]
    assert _same(results["python"], results["native"])


def test_a_filter_driven_out_of_range_ends_the_run_the_same_way(fmu_builds):
    system = estimators.discretize(get_model("cartpole"), 0.01)

    def make(engine):
        filt = EstimatorComponent("ekf", lambda: estimators.EKF(system, [0.5, 0, 1.8, 0.5], 1.0, 0.2, 0.1,
                                                                 nan_is_missing=False))
        plant = FMUComponent("plant", fmu_builds["cartpole", 2], 0.01)
        return Cosimulation([filt, plant, Failing("y", 0.01, 0.42, "huge"), Constant("force", 0.01, 0.2)],
                            {"plant.F": "force.out", "ekf.F": "force.out", "ekf.y_x": "plant.y_x",
                             "ekf.y_theta": "y.y"}, engine=engine)

    out = outcome(make)
    assert out["python"][1] == "CosimError" and "ekf" in out["python"][2], out["python"][2]
    assert_same(out)


def test_without_a_working_compiler_auto_takes_the_python_loop_and_native_is_refused(tmp_path, monkeypatch):
    from cosim.core import native

    monkeypatch.setattr(native, "_kernel", [])
    monkeypatch.setenv("PENDULUM_COSIM_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("CC", "/bin/false")
    comps = [Step("s", 0.01, 0.5, 0.0, 1.0), Gain("g", 0.01, 2.0)]
    with pytest.warns(UserWarning, match="native co-simulation kernel is not available"):
        df = Cosimulation(comps, {"g.u": "s.out"}).run(1.0, progress=False)
    assert df["g.y"].iloc[-1] == 2.0
    with pytest.raises(ConfigurationError, match="engine='native': the native kernel is not available"):
        Cosimulation(comps, {"g.u": "s.out"}, engine="native").run(1.0, progress=False)
    assert list(tmp_path.glob("cache/kernel_*")) == []


@pytest.mark.parametrize("version", (2, 3))
def test_a_co_simulation_fmu_keeps_its_library_loaded_between_runs(fmu_builds, version):
    """The next run instantiates again on the loaded library (the same functions, the same
    numbers); release() unloads it, and a run after that loads it anew."""
    plant = FMUComponent("plant", fmu_builds["cartpole", version], 0.01, start={"theta": 1.8})
    cs = Cosimulation([plant, Step("force", 0.01, 0.3, -0.5, 0.5)], {"plant.F": "force.out"})
    first = cs.run(1.0, progress=False)
    kept = plant._library_box[0]
    assert kept is not None and plant.instance is None
    second = cs.run(1.0, progress=False)
    assert plant._library_box[0] is kept and first.equals(second)
    plant.release()
    assert plant._library_box[0] is None
    assert cs.run(1.0, progress=False).equals(first) and plant._library_box[0] is not kept
    plant.release()

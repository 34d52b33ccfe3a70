"""The plant FMUs (FMI 2.0 and 3.0): validation, simulation against the PlantModel,
directional derivatives, FMU state and every refusal path."""
import numpy as np
import pytest
from fmpy import dump, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu
from testkit.fmu_helpers import Instance

from fmu_models import get_model

# The project's two plants by name: a model another test module registers (a user's own)
# must not become a case here when that module happens to be imported first.
CASES = [(name, v) for v in (2, 3) for name in ("cartpole", "iwp")]


def x0_of(name):
    return get_model(name).x0 if name == "cartpole" else np.array([0.3, -0.2, 5.0])


@pytest.mark.parametrize("name,version", CASES)
def test_fmu_validates_without_problems(fmu_builds, name, version):
    assert validate_fmu(fmu_builds[name, version]) == []


@pytest.mark.parametrize("version", [2, 3])
def test_dump_shows_units_and_descriptions(fmu_builds, capsys, version):
    dump(fmu_builds["cartpole", version])
    text = capsys.readouterr().out
    assert "Model Exchange, Co-Simulation" in text
    assert "horizontal force on the cart" in text and " N " in text
    assert "pole angle from upright" in text and "rad" in text


@pytest.mark.parametrize("name,version", CASES)
@pytest.mark.parametrize("integrator,substeps", [(1, 1), (2, 1), (2, 4), (1, 3)])
def test_cosimulation_matches_plant_model(fmu_builds, name, version, integrator, substeps):
    model = get_model(name)
    x0 = x0_of(name)
    start = dict(zip(model.state_names, x0), integrator=integrator, substeps=substeps)
    res = simulate_fmu(fmu_builds[name, version], stop_time=2.0, output_interval=0.01,
                       fmi_type="CoSimulation", start_values=start)
    X = np.array([res[n] for n in model.state_names]).T
    ref = model.simulate(x0, np.zeros(model.nu), 0.01, 200,
                         method=["euler", "rk4"][integrator - 1], substeps=substeps)
    np.testing.assert_allclose(X, ref, rtol=0, atol=1e-10)
    Y = np.array([res[n] for n in model.output_names]).T
    np.testing.assert_allclose(Y, [model.h(x) for x in ref], atol=1e-10)


@pytest.mark.parametrize("name,version", CASES)
def test_model_exchange_with_fmpy_euler_matches_plant_model(fmu_builds, name, version):
    model = get_model(name)
    x0 = x0_of(name)
    res = simulate_fmu(fmu_builds[name, version], stop_time=1.0, output_interval=0.01,
                       step_size=0.01, fmi_type="ModelExchange", solver="Euler",
                       start_values=dict(zip(model.state_names, x0)))
    X = np.array([res[n] for n in model.state_names]).T
    np.testing.assert_allclose(X, model.simulate(x0, np.zeros(model.nu), 0.01, 100),
                               rtol=0, atol=1e-10)


@pytest.mark.parametrize("version", [2, 3])
def test_inputs_noise_and_any_step_follow_the_truth_map_on_its_grid(fmu_builds, version):
    """x_k = step(x_{k-1}, F_{k-1}) + w_{k-1} (seed 000 eq 12) on the 10 ms grid whatever the
    communication steps (5, 10, 15, 20, 2.5 ms, mixed): the step from grid instant k is driven
    by the input set at the last communication point at or before it; between instants the
    state holds."""
    model = get_model("cartpole")
    inst = Instance(fmu_builds["cartpole", version]).init()
    rng = np.random.default_rng(0)
    pattern = [0.015, 0.005, 0.01, 0.0025, 0.0025, 0.005, 0.02, 0.01, 0.03]
    grid = [model.x0.copy()]
    t, k_next = 0.0, 1        # k_next: the next grid instant
    set_at = []               # (time, F, w) of every setting
    in_vrs = [inst.vr["F"]] + [inst.vr[f"w_{n}"] for n in model.state_names]
    try:
        for n in range(120):
            F, w = rng.uniform(-1, 1), rng.normal(0, 0.01, 4)
            h = pattern[n % len(pattern)]
            inst.set_reals(in_vrs, [F, *w])
            set_at.append((t, F, w))
            inst.do_step(t, h)
            t += h
            while k_next * 0.01 <= t + 1e-9:          # grid instants reached by this step
                t_k = (k_next - 1) * 0.01
                _, F_k, w_k = [s for s in set_at if s[0] <= t_k + 1e-9][-1]
                grid.append(model.step(grid[-1], [F_k], 0.01) + w_k)
                k_next += 1
            np.testing.assert_allclose(inst.get(*model.state_names), grid[-1], rtol=0, atol=1e-12)
    finally:
        inst.free()


@pytest.mark.parametrize("name,version", CASES)
def test_directional_derivatives_equal_casadi_jacobians(fmu_builds, name, version):
    model = get_model(name)
    inst = Instance(fmu_builds[name, version], kind="me").init()
    vr = inst.vr
    rng = np.random.default_rng(7)
    unknowns = [vr[f"der({n})"] for n in model.state_names] + [vr[n] for n in model.output_names]
    knowns = [vr[n] for n in model.state_names + model.input_names]
    try:
        inst.fmu.enterContinuousTimeMode()
        for _ in range(50):
            x = rng.uniform(-3, 3, model.nx) * [1, 5, 2, 5][: model.nx]
            u = rng.uniform(-5, 5, model.nu)
            inst.set_states(x)
            inst.set_reals([vr[n] for n in model.input_names], u)
            J = np.array([inst.directional(unknowns, knowns, e.tolist())
                          for e in np.eye(len(knowns))]).T
            A, B = model.linearize(x, u)
            ref = np.vstack([np.hstack([A, B]),
                             np.hstack([model.H(x), np.zeros((model.ny, model.nu))])])
            np.testing.assert_allclose(J, ref, rtol=1e-12, atol=1e-12)
    finally:
        inst.free()


@pytest.mark.parametrize("name,version", CASES)
def test_save_propagate_restore_is_bit_identical(fmu_builds, name, version):
    model = get_model(name)
    inst = Instance(fmu_builds[name, version], start={"integrator": 2, "substeps": 2}).init()
    u_vr = [inst.vr[n] for n in model.input_names]

    def run(t, n):
        out = []
        for k in range(n):
            inst.set_reals(u_vr, [np.sin(0.1 * k)] * model.nu)
            inst.do_step(t, 0.01)
            t += 0.01
            out.append(inst.get(*model.state_names))
        return np.array(out)

    try:
        run(0.0, 30)
        state = inst.get_state()
        first = run(0.3, 50)
        inst.set_state(state)
        again = run(0.3, 50)
        assert np.array_equal(first, again)
        restored = inst.deserialize(inst.serialize(state))
        inst.set_state(restored)
        assert np.array_equal(run(0.3, 50), first)
        inst.free_state(state)
        inst.free_state(restored)
    finally:
        inst.free()


def _expect_error(inst, fn, *args, match, restore=True):
    """fn(*args) returns Error with a message containing ``match``. The instance is then in the
    error state; ``restore``: the FMU state saved before the call brings it back (SetFMUState,
    what the standard allows after an Error)."""
    saved = inst.get_state()
    with pytest.raises(FMICallException, match="error"):
        fn(*args)
    assert any(match in m for _, m in inst.messages), inst.messages
    if restore:
        inst.set_state(saved)
    inst.free_state(saved)


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("param,value,why", [("mc", -1.0, "must be > 0"), ("l", 0.0, "must be > 0"),
                                             ("Bc", -0.1, "must be >= 0"), ("g", float("nan"), "not finite")])
def test_invalid_parameters_are_refused(fmu_builds, version, param, value, why):
    inst = Instance(fmu_builds["cartpole", version])
    try:
        _expect_error(inst, inst.set, param, value, match=param)
        assert any(why in m for _, m in inst.messages)
        inst.init()                                  # the instance is still usable
        _expect_error(inst, inst.set, "mc", 2.0, match="is fixed")
    finally:
        inst.free()


@pytest.mark.parametrize("version", [2, 3])
def test_bad_calls_return_errors_and_the_process_survives(fmu_builds, version):
    inst = Instance(fmu_builds["iwp", version])
    try:
        _expect_error(inst, inst.do_step, 0.0, 0.01, match="not allowed in Instantiated")
        _expect_error(inst, inst.set, "s", 0.5, match="-1 or +1")
        _expect_error(inst, inst.set, "integrator", 7, match="integrator = 7 must be in [1, 2]")
        _expect_error(inst, inst.set, "substeps", 0, match="substeps")
        _expect_error(inst, inst.set, "step_size", -1.0, match="step_size")
        inst.init()
        _expect_error(inst, inst.set, "i", float("nan"), match="i: value nan is not finite")
        _expect_error(inst, inst.set, "y_alpha", 1.0, match="calculated")
        _expect_error(inst, inst.do_step, 0.0, -0.01, match="must be > 0")
        _expect_error(inst, inst.do_step, 5.0, 0.01, match="differs from the FMU time")
        _expect_error(inst, inst.get_reals, [9999], match="no Real variable")
        _expect_error(inst, inst.deserialize, b"x" * 10, match="expected")
        inst.do_step(0.0, 0.01)                      # still works after all the refusals
        # a state that blows up: huge current -> non-finite -> error, state kept
        inst.set("i", 1e308)
        x_before = inst.get("alpha", "alpha_dot", "phi_dot")
        _expect_error(inst, inst.do_step, 0.01, 0.01, match="non-finite", restore=False)
        assert inst.get("alpha", "alpha_dot", "phi_dot") == x_before   # read for debugging after the Error
    finally:
        inst.free()


@pytest.mark.parametrize("version", [2, 3])
def test_wrong_instantiation_token_is_refused(fmu_builds, version):
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    from fmpy.fmi3 import FMU3Slave

    path = fmu_builds["iwp", version]
    md = read_model_description(path)
    fmu = (FMU2Slave if version == 2 else FMU3Slave)(
        guid="{wrong}", unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier)
    with pytest.raises(Exception, match="[Ff]ailed to instantiate"):
        fmu.instantiate()
    fmu.freeLibrary()


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("kind", ["cs", "me"])
def test_a_state_restored_after_an_error_brings_back_its_own_rules(fmu_builds, version, kind):
    """An FMU state is saved only before an Error (no GetFMUState after one): restoring a state
    saved in Instantiated gives Instantiated's rules, where the derivative functions are refused
    (not the error state's, where getters answer for debugging)."""
    inst = Instance(fmu_builds["cartpole", version], kind=kind)
    try:
        saved = inst.get_state()                      # in Instantiated
        with pytest.raises(FMICallException):
            inst.set("mc", -1.0)                      # an Error: the error state
        with pytest.raises(FMICallException):
            inst.get_state()                          # nothing is saved after an Error
        assert any("GetFMU" in m and "not allowed after a call returned Error" in m for _, m in inst.messages)
        inst.set_state(saved)                         # back to Instantiated and its rules
        x = inst.vr["x"]
        with pytest.raises(FMICallException):
            inst.directional([x], [x], [1.0])
        assert any("not allowed in Instantiated" in m for _, m in inst.messages), inst.messages
        inst.free_state(saved)
    finally:
        inst.free()

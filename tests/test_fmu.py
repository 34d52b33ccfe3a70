"""The plant FMUs: validation, simulation against the PlantModel, derivatives, FMU state, errors."""
from ctypes import c_double

import numpy as np
import pytest
from fmpy import dump, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from fmu_models import MODEL_NAMES, get_model
from fmu_helpers import Instance

NAMES = list(MODEL_NAMES)


def x0_of(name):
    return get_model(name).x0 if name == "cartpole" else np.array([0.3, -0.2, 5.0])


@pytest.mark.parametrize("name", NAMES)
def test_fmu_validates_without_problems(fmu_paths, name):
    assert validate_fmu(fmu_paths[name]) == []


def test_dump_shows_units_and_descriptions(fmu_paths, capsys):
    dump(fmu_paths["cartpole"])
    text = capsys.readouterr().out
    assert "Model Exchange, Co-Simulation" in text
    assert "horizontal force on the cart" in text and " N " in text
    assert "pole angle from upright" in text and "rad" in text


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("integrator,substeps", [(1, 1), (2, 1), (2, 4), (1, 3)])
def test_cosimulation_matches_plant_model(fmu_paths, name, integrator, substeps):
    model = get_model(name)
    x0 = x0_of(name)
    start = dict(zip(model.state_names, x0), integrator=integrator, substeps=substeps)
    res = simulate_fmu(fmu_paths[name], stop_time=2.0, output_interval=0.01,
                       fmi_type="CoSimulation", start_values=start)
    X = np.array([res[n] for n in model.state_names]).T
    ref = model.simulate(x0, np.zeros(model.nu), 0.01, 200,
                         method=["euler", "rk4"][integrator - 1], substeps=substeps)
    np.testing.assert_allclose(X, ref, rtol=0, atol=1e-10)
    Y = np.array([res[n] for n in model.output_names]).T
    np.testing.assert_allclose(Y, [model.h(x) for x in ref], atol=1e-10)


@pytest.mark.parametrize("name", NAMES)
def test_model_exchange_with_fmpy_euler_matches_plant_model(fmu_paths, name):
    model = get_model(name)
    x0 = x0_of(name)
    res = simulate_fmu(fmu_paths[name], stop_time=1.0, output_interval=0.01, step_size=0.01,
                       fmi_type="ModelExchange", solver="Euler",
                       start_values=dict(zip(model.state_names, x0)))
    X = np.array([res[n] for n in model.state_names]).T
    np.testing.assert_allclose(X, model.simulate(x0, np.zeros(model.nu), 0.01, 100),
                               rtol=0, atol=1e-10)


def test_inputs_noise_and_partial_steps_follow_the_truth_map(fmu_paths):
    """x_k = step(x_{k-1}, F_{k-1}) + w_{k-1} (seed 000 eq 12); 15 ms steps = 10 ms + 5 ms partial."""
    model = get_model("cartpole")
    inst = Instance(fmu_paths["cartpole"]).init()
    rng = np.random.default_rng(0)
    x, t = model.x0.copy(), 0.0
    w_names = [f"w_{n}" for n in model.state_names]
    try:
        for k in range(100):
            F, w = rng.uniform(-1, 1), rng.normal(0, 0.01, 4)
            h = 0.015 if k % 3 == 0 else 0.01
            inst.fmu.setReal([inst.vr["F"]] + [inst.vr[n] for n in w_names], [F, *w])
            inst.fmu.doStep(t, h)
            t += h
            x = model.step(x, [F], 0.01)
            if h > 0.01:
                x = model.step(x, [F], h - 0.01)
            x = x + w
            np.testing.assert_allclose(inst.get(*model.state_names), x, rtol=0, atol=1e-12)
    finally:
        inst.free()


@pytest.mark.parametrize("name", NAMES)
def test_directional_derivatives_equal_casadi_jacobians(fmu_paths, name):
    model = get_model(name)
    inst = Instance(fmu_paths[name], kind="me").init()
    vr = inst.vr
    rng = np.random.default_rng(7)
    unknowns = [vr[f"der({n})"] for n in model.state_names] + [vr[n] for n in model.output_names]
    knowns = [vr[n] for n in model.state_names + model.input_names]
    try:
        inst.fmu.enterContinuousTimeMode()
        for _ in range(50):
            x = rng.uniform(-3, 3, model.nx) * [1, 5, 2, 5][: model.nx]
            u = rng.uniform(-5, 5, model.nu)
            inst.fmu.setContinuousStates((c_double * model.nx)(*x), model.nx)
            inst.fmu.setReal([vr[n] for n in model.input_names], u.tolist())
            J = np.array([inst.fmu.getDirectionalDerivative(unknowns, knowns, e.tolist())
                          for e in np.eye(len(knowns))]).T
            A, B = model.linearize(x, u)
            ref = np.vstack([np.hstack([A, B]), np.hstack([model.H(x), np.zeros((model.ny, model.nu))])])
            np.testing.assert_allclose(J, ref, rtol=1e-12, atol=1e-12)
    finally:
        inst.free()


@pytest.mark.parametrize("name", NAMES)
def test_save_propagate_restore_is_bit_identical(fmu_paths, name):
    model = get_model(name)
    inst = Instance(fmu_paths[name], start={"integrator": 2, "substeps": 2}).init()
    u_vr = [inst.vr[n] for n in model.input_names]

    def run(t, n):
        out = []
        for k in range(n):
            inst.fmu.setReal(u_vr, [np.sin(0.1 * k)] * model.nu)
            inst.fmu.doStep(t, 0.01)
            t += 0.01
            out.append(inst.get(*model.state_names))
        return np.array(out)

    try:
        run(0.0, 30)
        state = inst.fmu.getFMUstate()
        first = run(0.3, 50)
        inst.fmu.setFMUstate(state)
        again = run(0.3, 50)
        assert np.array_equal(first, again)
        blob = inst.fmu.serializeFMUstate(state)
        restored = inst.fmu.deSerializeFMUstate(blob)
        inst.fmu.setFMUstate(restored)
        assert np.array_equal(run(0.3, 50), first)
        inst.fmu.freeFMUstate(state)
        inst.fmu.freeFMUstate(restored)
    finally:
        inst.free()


def _expect_error(inst, fn, *args, match):
    with pytest.raises(FMICallException, match="error"):
        fn(*args)
    assert any(match in m for _, m in inst.messages), inst.messages


@pytest.mark.parametrize("param,value,why", [("mc", -1.0, "must be > 0"), ("l", 0.0, "must be > 0"),
                                             ("Bc", -0.1, "must be >= 0"), ("g", float("nan"), "not finite")])
def test_invalid_parameters_are_refused(fmu_paths, param, value, why):
    inst = Instance(fmu_paths["cartpole"])
    try:
        _expect_error(inst, inst.set, param, value, match=param)
        assert any(why in m for _, m in inst.messages)
        inst.init()                                  # the instance is still usable
        _expect_error(inst, inst.set, "mc", 2.0, match="is fixed")
    finally:
        inst.free()


def test_bad_calls_return_errors_and_the_process_survives(fmu_paths):
    inst = Instance(fmu_paths["iwp"])
    try:
        _expect_error(inst, inst.fmu.doStep, 0.0, 0.01, match="not allowed in instantiated")
        _expect_error(inst, inst.set, "s", 0.5, match="-1 or +1")
        _expect_error(inst, inst.set, "integrator", 7, match="valid values are 1 (euler) and 2 (rk4)")
        _expect_error(inst, inst.set, "substeps", 0, match="substeps")
        _expect_error(inst, inst.set, "step_size", -1.0, match="step_size")
        inst.init()
        _expect_error(inst, inst.set, "i", float("nan"), match="i: value nan is not finite")
        _expect_error(inst, inst.set, "y_alpha", 1.0, match="calculated")
        _expect_error(inst, inst.fmu.doStep, 0.0, -0.01, match="must be > 0")
        _expect_error(inst, inst.fmu.doStep, 5.0, 0.01, match="differs from the FMU time")
        _expect_error(inst, inst.fmu.getReal, [9999], match="no Real variable")
        _expect_error(inst, inst.fmu.deSerializeFMUstate, b"x" * 10, match="expected")
        inst.fmu.doStep(0.0, 0.01)                  # still works after all the refusals
        # a state that blows up: huge current -> non-finite -> error, state kept
        inst.set("i", 1e308)
        x_before = inst.get("alpha", "alpha_dot", "phi_dot")
        _expect_error(inst, inst.fmu.doStep, 0.01, 0.01, match="non-finite")
        assert inst.get("alpha", "alpha_dot", "phi_dot") == x_before
    finally:
        inst.free()


def test_wrong_guid_is_refused(fmu_paths):
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(fmu_paths["iwp"])
    fmu = FMU2Slave(guid="{wrong}", unzipDirectory=extract(fmu_paths["iwp"]),
                    modelIdentifier=md.coSimulation.modelIdentifier)
    with pytest.raises(Exception, match="Failed to instantiate"):
        fmu.instantiate()
    fmu.freeLibrary()

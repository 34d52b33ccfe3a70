"""Public API of fmu_models: names, parameters, shapes, errors."""
import numpy as np
import pytest

from fmu_models import get_model, model_names


def test_names_and_defaults():
    cp = get_model("cartpole")
    assert cp.state_names == ["x", "x_dot", "theta", "theta_dot"]
    assert cp.input_names == ["F"] and cp.output_names == ["y_x", "y_theta"]
    assert cp.params == {"mc": 0.94, "mp": 0.23, "l": 0.33, "Bc": 0.44, "Bp": 0.05, "g": 9.81}
    np.testing.assert_array_equal(cp.x0, [0.5, 0, 1.8, 0.5])
    iwp = get_model("iwp")
    assert iwp.state_names == ["alpha", "alpha_dot", "phi_dot"]
    assert iwp.params["s"] == -1.0
    for name in model_names():
        m = get_model(name)
        for v in m.states + m.inputs + m.outputs + m.parameters:
            assert v.unit and v.description


def test_parameter_override_and_errors():
    cp = get_model("cartpole", mp=0.5)
    assert cp.params["mp"] == 0.5 and get_model("cartpole").params["mp"] == 0.23
    with pytest.raises(KeyError, match="valid parameters: mc, mp, l, Bc, Bp, g"):
        get_model("cartpole", M3=1.0)
    with pytest.raises(KeyError, match="valid models"):
        get_model("segway")
    with pytest.raises(ValueError, match="'l'.*> 0"):
        get_model("cartpole", l=0.0)
    with pytest.raises(ValueError, match="finite"):
        get_model("cartpole", g=float("nan"))
    with pytest.raises(ValueError, match="-1 or \\+1"):
        get_model("iwp", s=0.5)
    assert get_model("iwp", s=1).params["s"] == 1.0


def test_shape_and_value_errors():
    cp = get_model("cartpole")
    with pytest.raises(ValueError, match=r"state x must have shape \(4,\)"):
        cp.f(np.zeros(3), [0.0])
    with pytest.raises(ValueError, match=r"input u must have shape \(1,\)"):
        cp.step(np.zeros(4), [0.0, 1.0], 0.01)
    with pytest.raises(ValueError, match="NaN"):
        cp.f([0, 0, np.nan, 0], [0.0])
    with pytest.raises(ValueError, match="dt"):
        cp.step(np.zeros(4), 0.0, -0.01)
    with pytest.raises(ValueError, match="unknown method 'rk45'"):
        cp.step(np.zeros(4), 0.0, 0.01, method="rk45")
    with pytest.raises(ValueError, match="substeps"):
        cp.jacobians(np.zeros(4), 0.0, 0.01, method="rk4", substeps=0)
    f_col = cp.f(np.zeros((4, 1)), 0.0)           # column vectors and scalars are accepted
    assert f_col.shape == (4,)


def test_simulate_matches_repeated_steps():
    cp = get_model("cartpole")
    u = np.where(np.arange(50) < 20, -0.5, 0.5)[:, None]
    xs = cp.simulate(cp.x0, u, 0.01, 50, method="rk4", substeps=2)
    x = cp.x0
    for k in range(50):
        x = cp.step(x, u[k], 0.01, method="rk4", substeps=2)
    np.testing.assert_allclose(xs[-1], x, rtol=1e-14, atol=1e-14)
    # the papers' truth model: one Euler step is eqs 14-17 (x_k = x_{k-1} + T f)
    np.testing.assert_allclose(cp.step(cp.x0, [0.5], 0.01), cp.x0 + 0.01 * cp.f(cp.x0, [0.5]),
                               rtol=1e-15)

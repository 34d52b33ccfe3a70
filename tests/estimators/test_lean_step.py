"""The lean step (runtime.lean_step) equals the general one for every input a user may give,
and refuses every bad one with a named error, the filter's state unchanged."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators import EKF, discretize
from fmu_models import get_model
from fmu_models.errors import PendulumCosimError

CP = discretize(get_model("cartpole"), 0.01)
X0 = [0.5, 0.0, 1.8, 0.5]
finite = st.floats(-1e3, 1e3, allow_nan=False)
entry = st.one_of(finite, st.integers(-5, 5), st.just(float("nan")), st.just(float("inf")), st.text(max_size=2),
                  st.none(), st.lists(finite, max_size=2), st.booleans())
vector = st.one_of(st.lists(entry, min_size=0, max_size=3), st.tuples(finite, finite), st.text(max_size=3),
                   finite, st.none(), st.lists(finite, min_size=1, max_size=3).map(np.array),
                   finite.map(np.float64), finite.map(np.float32), finite.map(np.array))


@pytest.fixture(scope="module")
def pair():
    return EKF(CP, X0, 1.0, 0.2, 0.1), EKF(CP, X0, 1.0, 0.2, 0.1)


@settings(max_examples=300, deadline=None)
@given(u=vector, y=vector)
def test_the_lean_step_agrees_with_the_general_one_or_refuses_by_name(pair, u, y):
    lean, general = pair
    general.reset(lean.x, lean.P)
    before = lean.x
    try:
        expected = general._step(u, y)
    except PendulumCosimError as e:
        with pytest.raises(type(e)):
            lean.step(u, y)
        np.testing.assert_array_equal(lean.x, before)          # a refused step changes nothing
        return
    got = lean.step(u, y)
    np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(lean.P, general.P)
    lean.reset(X0, 1.0)


def test_the_lean_step_is_the_instance_step_and_a_user_override_wins():
    f = EKF(CP, X0, 1.0, 0.2, 0.1)
    assert "step" in vars(f)

    class Logged(EKF):
        def step(self, u, y, mask=None):
            self.calls = getattr(self, "calls", 0) + 1
            return super().step(u, y, mask)

    g = Logged(CP, X0, 1.0, 0.2, 0.1)
    assert "step" not in vars(g)
    g.step([0.5], [0.5, 1.8])
    assert g.calls == 1 and g.k == 1


@pytest.mark.parametrize("u", [0.5, np.float64(0.5), np.array(0.5), np.array([0.5]), (0.5,), 1])
def test_a_bare_number_for_the_one_input_is_the_one_element_vector(u):
    """The cart-pole has one input: ``ekf.step(U[k], Y[k])`` with a 1-D ``U`` passes a numpy
    float64; it means the vector ``[U[k]]``, on the lean path (no slow-path fallback)."""
    f, g = EKF(CP, X0, 1.0, 0.2, 0.1), EKF(CP, X0, 1.0, 0.2, 0.1)
    np.testing.assert_array_equal(f.step(u, [0.52, 1.79]), g.step([0.5 if u != 1 else 1.0], [0.52, 1.79]))
    np.testing.assert_array_equal(f.P, g.P)

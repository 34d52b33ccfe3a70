"""Fixtures of the estimator tests."""
import pytest

from estimators import discretize
from fmu_models import get_model


@pytest.fixture(scope="session")
def cp():
    """The cart-pole's Euler map at T = 0.01 s (the papers' discrete model)."""
    return discretize(get_model("cartpole"), 0.01)

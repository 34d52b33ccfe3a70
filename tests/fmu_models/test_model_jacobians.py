"""Exactness of every Jacobian the models expose, at 200+ random points of a wide box."""
import numpy as np
import pytest
from testkit.oracles import central_difference_jacobian, complex_step_jacobian, iwp_numpy

from estimators import FMUProcessModel, discretize
from fmu_models import build_fmu, get_model

N_POINTS = 200


def random_points(model, rng, n=N_POINTS):
    """Angles over the full circle and beyond, large rates and inputs."""
    if model.name == "cartpole":
        lo = np.array([-5, -10, -2 * np.pi, -30, -20.0])
    else:
        lo = np.array([-2 * np.pi, -30, -500, -5.0])
    return rng.uniform(lo, -lo, size=(n, lo.size))


@pytest.fixture(params=["cartpole", "iwp"])
def model(request):
    return get_model(request.param)


def split(model, z):
    return z[: model.nx], z[model.nx:]


def test_continuous_jacobians_match_central_differences(model):
    rng = np.random.default_rng(1)
    for z in random_points(model, rng):
        x, u = split(model, z)
        A, B = model.linearize(x, u)
        J = central_difference_jacobian(lambda zz: model.f(*split(model, zz)), z)
        scale = max(1.0, np.abs(model.f(x, u)).max())
        # 4th-order differences with h = 1e-4 (relative): truncation ~1e-16 * f^(5),
        # rounding ~1e-16 |f| / 1e-4: 1e-8 relative to the scale is a safe bound.
        np.testing.assert_allclose(np.hstack([A, B]), J, atol=1e-8 * scale, rtol=1e-7)


def test_measurement_jacobian_matches_central_differences(model):
    rng = np.random.default_rng(2)
    for z in random_points(model, rng, 50):
        x, _ = split(model, z)
        np.testing.assert_allclose(model.H(x), central_difference_jacobian(model.h, x),
                                   atol=1e-9)


@pytest.mark.parametrize("method,substeps", [("euler", 1), ("euler", 4), ("rk4", 1), ("rk4", 3)])
def test_discrete_jacobians_match_central_differences(model, method, substeps):
    rng = np.random.default_rng(3)
    dt = 0.01
    for z in random_points(model, rng):
        x, u = split(model, z)
        F, G = model.jacobians(x, u, dt, method=method, substeps=substeps)
        J = central_difference_jacobian(
            lambda zz: model.step(*split(model, zz), dt, method=method, substeps=substeps), z)
        scale = max(1.0, np.abs(x).max())
        np.testing.assert_allclose(np.hstack([F, G]), J, atol=1e-8 * scale, rtol=1e-7)


@pytest.fixture(scope="module")
def plant_fmus(tmp_path_factory):
    """The project's plant FMUs (Model Exchange), built on first use: (model name, FMI version) -> path."""
    built, root = {}, tmp_path_factory.mktemp("plant_fmus")

    def get(name: str, version: int):
        if (name, version) not in built:
            built[name, version] = build_fmu(name, root / f"{name}{version}", fmi_version=version)
        return built[name, version]
    return get


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("method,substeps", [("euler", 1), ("euler", 4), ("rk4", 1), ("rk4", 3)])
def test_fmu_process_model_jacobians_equal_the_exact_ones(model, plant_fmus, version, method, substeps):
    """The FMU column: the model's own FMU as a process model (its directional derivatives
    through the integrator's stages) gives the exact Jacobians of the CasADi map, 1e-10."""
    dt = 0.01
    fmu = FMUProcessModel(plant_fmus(model.name, version), dt, model.output_names, model.input_names, method=method,
                          substeps=substeps)
    exact = discretize(model, dt, method, substeps)
    for z in random_points(model, np.random.default_rng(6)):
        x, u = split(model, z)
        np.testing.assert_allclose(fmu.F(x, u), exact.F(x, u), rtol=0, atol=1e-10)     # measured: 4.4e-16
        np.testing.assert_allclose(fmu.G(x, u), exact.G(x, u), rtol=0, atol=1e-10)
        np.testing.assert_allclose(fmu.H(x), exact.H(x), rtol=0, atol=1e-10)


def test_euler_map_jacobian_is_identity_plus_dt_A(model):
    """Exact relation: d/dx [x + T f] = I + T A, d/du = T B (seed 000 eq 20 form)."""
    rng = np.random.default_rng(4)
    dt = 0.01
    for z in random_points(model, rng, 50):
        x, u = split(model, z)
        F, G = model.jacobians(x, u, dt)
        A, B = model.linearize(x, u)
        np.testing.assert_allclose(F, np.eye(model.nx) + dt * A, rtol=1e-14, atol=1e-14)
        np.testing.assert_allclose(G, dt * B, rtol=1e-14, atol=1e-16)
        Ad, _Bd = model.discretize(x, u, dt, method="euler")
        np.testing.assert_allclose(Ad, F, rtol=1e-14, atol=1e-14)


def test_iwp_jacobian_equals_complex_step_on_independent_equations():
    model = get_model("iwp")
    rng = np.random.default_rng(5)
    p = tuple(model.p)
    for z in random_points(model, rng):
        x, u = split(model, z)
        np.testing.assert_allclose(model.f(x, u), iwp_numpy(x, u, p), rtol=1e-13, atol=1e-12)
        J = complex_step_jacobian(lambda zz: iwp_numpy(zz[:3], zz[3:], p), z)
        np.testing.assert_allclose(np.hstack(model.linearize(x, u)), J, rtol=1e-13, atol=1e-12)


def test_zoh_discretisation_is_exact_for_the_linearisation(model):
    """ZOH (Ad, Bd) must propagate the linear model exactly: compare with fine RK4 of A x + B u."""
    x0 = model.x0 * 0
    A, B = model.linearize(x0, np.zeros(model.nu))
    dt = 0.02
    Ad, Bd = model.discretize(x0, np.zeros(model.nu), dt)
    x, u = np.arange(1.0, model.nx + 1) * 0.1, np.array([0.3])
    n = 2000
    h = dt / n
    z = x.copy()
    for _ in range(n):
        k1 = A @ z + B @ u
        k2 = A @ (z + h / 2 * k1) + B @ u
        k3 = A @ (z + h / 2 * k2) + B @ u
        k4 = A @ (z + h * k3) + B @ u
        z = z + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    np.testing.assert_allclose(Ad @ x + Bd @ u, z, rtol=1e-11, atol=1e-12)

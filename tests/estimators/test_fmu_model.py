"""A Model Exchange FMU as the filters' process model (estimators.FMUProcessModel).

Oracles: the project's CasADi models (the cart-pole FMU is generated from the same equations,
so every filter, the smoother, EM and the PCRB must give the CasADi model's numbers), an EKF of
the Van der Pol equations written here in numpy (the Reference FMU VanDerPol, FMI 3.0 and 2.0),
the FMU's own finite differences, and a hand-written FMU that misbehaves on request and checks
the FMI 3.0 call sequence (tests/data/hostile_me).
"""
from __future__ import annotations

import zipfile

import numpy as np
import pytest
from testkit import handwritten
from testkit.reference_cases import reference_dir

from estimators import (
    EKF,
    IAE,
    KF,
    MFIAE,
    SWML,
    UKF,
    BatchFilter,
    FMUProcessModel,
    discretize,
    em_noise,
    export_fmu,
    posterior_crb,
    rts_smooth,
)
from fmu_models import build_fmu, get_model
from fmu_models.errors import ConfigurationError, FMUError, NumericalError, TypeMismatchError, UnknownNameError

CARTPOLE = get_model("cartpole")
KW = dict(x0=[0.5, 0, 1.8, 0.5], P0=1.0, Q=0.2, R=0.1)
N = 500


@pytest.fixture(scope="module")
def cartpole_fmus(tmp_path_factory):
    """The project's cart-pole FMU (Model Exchange and Co-Simulation), FMI 2.0 and 3.0."""
    out = tmp_path_factory.mktemp("cartpole")
    return {v: build_fmu(CARTPOLE, out / str(v), fmi_version=v) for v in (2, 3)}


@pytest.fixture(scope="module")
def record():
    """A 500-step record of the cart-pole swinging, measured with noise, random force."""
    rng = np.random.default_rng(7)
    xs = CARTPOLE.simulate(KW["x0"], np.zeros(1), 0.01, N, method="rk4")
    ys = np.array([CARTPOLE.h(x) for x in xs[1:]]) + 0.05 * rng.standard_normal((N, 2))
    return 0.5 * rng.standard_normal((N, 1)), ys


def cartpole_models(path, method="rk4", substeps=1):
    return (FMUProcessModel(path, 0.01, CARTPOLE.output_names, CARTPOLE.input_names, method=method,
                            substeps=substeps),
            discretize(CARTPOLE, 0.01, method, substeps))


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("method", ["rk4", "euler"])
def test_cartpole_fmu_ekf_equals_casadi_ekf(cartpole_fmus, record, version, method):
    """The goal: the FMU-based EKF equals the CasADi-based one within 1e-9 over 500 steps (same
    integrator and step), step by step and in one native run."""
    us, ys = record
    fmu, cas = cartpole_models(cartpole_fmus[version], method)
    a, b = EKF(fmu, **KW), EKF(cas, **KW)
    for k in range(N):
        np.testing.assert_allclose(a.step(us[k], ys[k]), b.step(us[k], ys[k]), rtol=0, atol=1e-9)
        np.testing.assert_allclose(a.P, b.P, rtol=0, atol=1e-9)
    ra, rb = EKF(fmu, **KW).run(us, ys), EKF(cas, **KW).run(us, ys)
    np.testing.assert_allclose(ra.x, rb.x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ra.P, rb.P, rtol=0, atol=1e-9)
    assert "directional derivatives" in ra.jacobians and ra.jacobians != rb.jacobians


@pytest.mark.parametrize("make", [
    lambda s: KF(s, **KW, x_op=KW["x0"]),
    lambda s: UKF(s, **KW),
    lambda s: IAE(s, **KW, window=10),
    lambda s: MFIAE(s, KW["x0"], 1.0, 0.2, 0.1, window=10),
    pytest.param(lambda s: SWML(s, KW["x0"], 1.0, 0.2, 0.1, window=20, every=10, early_until=10),
                 marks=pytest.mark.slow),
], ids=["KF", "UKF", "IAE", "MFIAE", "SWML"])
def test_every_filter_takes_the_fmu_model(cartpole_fmus, record, make):
    us, ys = record
    fmu, cas = cartpole_models(cartpole_fmus[2])
    ra, rb = make(fmu).run(us[:200], ys[:200]), make(cas).run(us[:200], ys[:200])
    np.testing.assert_allclose(ra.x, rb.x, rtol=0, atol=1e-8)
    np.testing.assert_allclose(ra.P, rb.P, rtol=0, atol=1e-8)


def test_smoother_em_batch_and_pcrb_take_the_fmu_model(cartpole_fmus, record):
    us, ys = record
    fmu, cas = cartpole_models(cartpole_fmus[2])
    a, b = EKF(fmu, **KW), EKF(cas, **KW)
    sa, sb = rts_smooth(a, a.run(us[:200], ys[:200])), rts_smooth(b, b.run(us[:200], ys[:200]))
    np.testing.assert_allclose(sa.x, sb.x, rtol=0, atol=1e-8)
    ea = em_noise(EKF(fmu, **KW), us[:100], ys[:100], n_iter=3, structure="diagonal")
    eb = em_noise(EKF(cas, **KW), us[:100], ys[:100], n_iter=3, structure="diagonal")
    np.testing.assert_allclose(ea.Q, eb.Q, rtol=1e-7, atol=1e-12)
    np.testing.assert_allclose(ea.R, eb.R, rtol=1e-7, atol=1e-12)
    Y = np.stack([ys[:100], ys[:100] + 0.01])
    ba, bb = BatchFilter(EKF(fmu, **KW), 2).run(us[:100], Y), BatchFilter(EKF(cas, **KW), 2).run(us[:100], Y)
    np.testing.assert_allclose(ba.x, bb.x, rtol=0, atol=1e-8)
    X = CARTPOLE.simulate(KW["x0"], us[:100], 0.01, 100, method="rk4")[None]
    pa, pb = posterior_crb(fmu, X, us[:100], 0.2, 0.1), posterior_crb(cas, X, us[:100], 0.2, 0.1)
    np.testing.assert_allclose(pa.P, pb.P, rtol=1e-9, atol=1e-12)
    assert "directional derivatives" in pa.jacobians and "directional" in ba.jacobians


def test_describe_and_the_refused_export(cartpole_fmus):
    fmu, _ = cartpole_models(cartpole_fmus[3], "euler", 2)
    text = fmu.describe()
    for words in ("FMI 3.0 Model Exchange", "x, x_dot, theta, theta_dot", "inputs (1): F", "y_x, y_theta",
                  "euler, 2 substep(s)", "directional derivatives", "SetFMUState"):
        assert words in text
    with pytest.raises(ConfigurationError, match="cannot be packed into an FMU"):
        export_fmu(EKF(fmu, **KW), "unused")


# ---------------------------------------------------------------------------- the Reference FMU VanDerPol
MU, H, Q, R = 1.0, 0.1, 1e-3, 0.01


def vdp_rhs(x):
    return np.array([x[1], MU * (1 - x[0] ** 2) * x[1] - x[0]])


def vdp_jac(x):
    return np.array([[0.0, 1.0], [-2 * MU * x[0] * x[1] - 1, MU * (1 - x[0] ** 2)]])


def vdp_rk4(x):
    """The RK4 map of the Van der Pol equations over H and its exact Jacobian (the stages'
    tangents), in numpy."""
    k1 = vdp_rhs(x)
    k2 = vdp_rhs(x + H / 2 * k1)
    k3 = vdp_rhs(x + H / 2 * k2)
    k4 = vdp_rhs(x + H * k3)
    d1 = vdp_jac(x)
    d2 = vdp_jac(x + H / 2 * k1) @ (np.eye(2) + H / 2 * d1)
    d3 = vdp_jac(x + H / 2 * k2) @ (np.eye(2) + H / 2 * d2)
    d4 = vdp_jac(x + H * k3) @ (np.eye(2) + H * d3)
    return x + H / 6 * (k1 + 2 * k2 + 2 * k3 + k4), np.eye(2) + H / 6 * (d1 + 2 * d2 + 2 * d3 + d4)


def numpy_ekf(x, P, ys):
    """An EKF of the same equations: the measurement x0 with variance R, Joseph form."""
    Hm, out = np.array([[1.0, 0.0]]), []
    for y in ys:
        x, F = vdp_rk4(x)
        P = F @ P @ F.T + Q * np.eye(2)
        S = Hm @ P @ Hm.T + R
        K = P @ Hm.T / S
        x = x + (K * (y - x[0])).ravel()
        A = np.eye(2) - K @ Hm
        P = A @ P @ A.T + R * K @ K.T
        out.append(x)
    return np.array(out)


@pytest.fixture(scope="module", params=[3, 2], ids=["fmi3", "fmi2"])
def vanderpol(request):
    folder = reference_dir()
    if folder is None:
        pytest.skip("the Modelica Reference FMUs are absent (set PENDULUM_COSIM_REFERENCE_FMUS to a folder with "
                    "fmi2/ and fmi3/)")
    return folder / f"fmi{request.param}" / "VanDerPol.fmu"


def vdp_truth(runs, steps, seed=3):
    rng = np.random.default_rng(seed)
    X = np.empty((runs, steps + 1, 2))
    X[:, 0] = np.array([2.0, 0.0]) + 0.1 * rng.standard_normal((runs, 2))
    for k in range(steps):
        X[:, k + 1] = [vdp_rk4(x)[0] for x in X[:, k]]
        X[:, k + 1] += np.sqrt(Q) * rng.standard_normal((runs, 2))
    return X, X[:, 1:, :1] + np.sqrt(R) * rng.standard_normal((runs, steps, 1))


def test_vanderpol_ekf_equals_a_numpy_ekf_of_the_same_equations(vanderpol):
    model = FMUProcessModel(vanderpol, H, ["x0"], parameters={"mu": MU})
    _, Y = vdp_truth(1, 200)
    ekf = EKF(model, [2.0, 0.0], 0.01, Q, R)
    got = np.array([ekf.step((), y) for y in Y[0]])
    np.testing.assert_allclose(got, numpy_ekf(np.array([2.0, 0.0]), 0.01 * np.eye(2), Y[0, :, 0]), rtol=0,
                               atol=1e-9)


def test_vanderpol_directional_and_difference_jacobians_agree(vanderpol):
    exact = FMUProcessModel(vanderpol, H, ["x0", "x1"])
    fd = FMUProcessModel(vanderpol, H, ["x0", "x1"], jacobian="fd")
    assert "directional" in exact.jacobians and "central differences" in fd.jacobians
    X, _ = vdp_truth(1, 200)
    for x in X[0]:
        np.testing.assert_allclose(fd.F(x, []), exact.F(x, []), rtol=0, atol=1e-6)
        np.testing.assert_allclose(fd.F(x, []), vdp_rk4(x)[1], rtol=0, atol=1e-6)
        np.testing.assert_allclose(exact.F(x, []), vdp_rk4(x)[1], rtol=0, atol=1e-12)


@pytest.mark.slow
def test_vanderpol_filters_against_the_pcrb_on_the_fmu_model(vanderpol):
    """EKF, UKF and SWML (given the true Q, R; its MAP form, a prior of 1 nat on ln q and ln r)
    on the FMU model against the bound computed on the same model: no estimator beats the
    bound, and SWML is at most 3 % above the EKF (measured: 1.5 to 2 % on x0, under 0.5 % on x1)."""
    model = FMUProcessModel(vanderpol, H, ["x0"])
    runs, steps = 100, 200
    X, Y = vdp_truth(runs, steps)
    us = np.zeros((steps, 0))
    bound = posterior_crb(model, X, us, Q, R, P0=0.01)
    rmse = {}
    for name, filt in (("EKF", EKF(model, [2.0, 0.0], 0.01, Q, R)), ("UKF", UKF(model, [2.0, 0.0], 0.01, Q, R)),
                       ("SWML", SWML(model, [2.0, 0.0], 0.01, Q, R, prior_sd=1.0))):
        err = BatchFilter(filt, runs).run(us, Y).x[:, 1:] - X[:, 1:]
        rmse[name] = np.sqrt(np.mean(err ** 2, axis=(0, 1)))
        assert (rmse[name] >= 0.9 * np.sqrt(bound.mse[1:].mean(axis=0))).all(), name
    assert (rmse["SWML"] <= 1.03 * rmse["EKF"]).all()


# ---------------------------------------------------------------------------- refusals and hostile FMUs
@pytest.fixture(scope="module")
def hostile(tmp_path_factory):
    try:
        return handwritten.build("hostile_me", "HostileME", 3, tmp_path_factory.mktemp("hostile"))
    except handwritten.NotBuildable as e:
        pytest.skip(str(e))


def hostile_model(path, mode, **kw):
    return FMUProcessModel(path, 0.05, ["y"], ["u"], parameters={"mode": mode, "limit": 0.8}, **kw)


@pytest.fixture
def call_log(tmp_path, monkeypatch):
    log = tmp_path / "calls.txt"
    monkeypatch.setenv("HOSTILE_LOG", str(log))
    yield log
    text = log.read_text() if log.exists() else ""
    assert "VIOLATION" not in text, text


def rising(n=60):
    """Measurements that pull x0 past the FMU's limit (0.8) after about 40 steps."""
    return np.zeros((n, 1)), (0.5 + 0.01 * np.arange(n))[:, None]


@pytest.mark.parametrize("mode,error,words", [
    (1, NumericalError, "derivative of state x1 is nan"),
    (2, FMUError, "fmi3GetContinuousStateDerivatives returned Error (the FMU logged: x0 is past the limit)"),
    (3, FMUError, "event indicator 1 (of 1) changes sign inside a sample period"),
    (6, FMUError, "asked for Event Mode"),
    (5, FMUError, "returned Fatal"),
], ids=["nan", "error", "state-event", "step-event", "fatal"])
def test_hostile_fmu_is_a_named_error_and_the_filter_keeps_its_state(hostile, call_log, mode, error, words):
    model = hostile_model(hostile, mode)
    us, ys = rising()
    ekf = EKF(model, [0.5, 0.0], 0.01, 1e-4, 1e-3)
    with pytest.raises(error, match=None) as info:
        for k in range(len(ys)):
            before = ekf.x, ekf.P, ekf.k
            ekf.step(us[k], ys[k])
    assert words in str(info.value) and "filter state unchanged" in str(info.value)
    np.testing.assert_array_equal(ekf.x, before[0])
    np.testing.assert_array_equal(ekf.P, before[1])
    assert ekf.k == before[2]
    start = ekf.x, ekf.P
    with pytest.raises(error):
        ekf.run(us, ys)                     # a whole run: the same error, the state kept
    np.testing.assert_array_equal(ekf.x, start[0])
    with pytest.raises(error, match="returned Fatal earlier" if mode == 5 else "realisation 1"):
        BatchFilter(EKF(model, [0.5, 0.0], 0.01, 1e-4, 1e-3), 2).run(us, np.stack([np.full_like(ys, 0.5), ys]))
    if mode == 5:                           # after Fatal the FMU is never called again
        with pytest.raises(FMUError, match="returned Fatal earlier"):
            EKF(model, [0.5, 0.0], 0.01, 1e-4, 1e-3).step(us[0], ys[0])
    else:                                   # restored from its saved state: it works again
        ekf.reset([0.5, 0.0], 0.01)
        ekf.step(us[0], ys[0])
    assert (call_log.exists() and "RETURNED" in call_log.read_text()) == (mode in (2, 5))


def test_a_time_event_and_wrong_directional_derivatives_are_refused(hostile, call_log):
    with pytest.raises(FMUError, match="schedules a time event at t = 0.5 s"):
        hostile_model(hostile, 4)
    with pytest.raises(FMUError, match="directional derivatives disagree with its own finite differences"):
        hostile_model(hostile, 7)
    assert "central differences" in hostile_model(hostile, 7, jacobian="fd").jacobians


def test_the_well_behaved_fmu_keeps_the_call_sequence(hostile, call_log):
    model = hostile_model(hostile, 0)
    us, ys = rising(100)
    EKF(model, [0.5, 0.0], 0.01, 1e-4, 1e-3).run(us, ys)
    UKF(model, [0.5, 0.0], 0.01, 1e-4, 1e-3).run(us, ys)
    assert not call_log.exists() or not call_log.read_text()


def patched(path, out, old, new):
    """A copy of the FMU at ``path`` whose modelDescription.xml has ``old`` replaced by ``new``."""
    with zipfile.ZipFile(path) as z, zipfile.ZipFile(out, "w") as w:
        for item in z.infolist():
            data = z.read(item)
            if item.filename == "modelDescription.xml":
                assert old.encode() in data
                data = data.replace(old.encode(), new.encode())
            w.writestr(item, data)
    return out


def test_what_cannot_be_honoured_is_refused_by_name(hostile, tmp_path, spring_damper_fmu):
    with pytest.raises(FMUError, match="no Model Exchange interface"):
        FMUProcessModel(spring_damper_fmu, 0.01, ["x"])
    f32 = patched(hostile, tmp_path / "f32.fmu", '<Float64 name="x1"', '<Float32 name="x1"')
    with pytest.raises(TypeMismatchError, match="continuous state 'x1' is Float32"):
        FMUProcessModel(f32, 0.05, ["y"])
    through = patched(hostile, tmp_path / "through.fmu", '<Output valueReference="6" dependencies="1 3"/>',
                      '<Output valueReference="6" dependencies="1 3 5"/>')
    with pytest.raises(ConfigurationError, match="depends directly on the input"):
        FMUProcessModel(through, 0.05, ["y"], ["u"])
    with pytest.raises(UnknownNameError, match="no variable 'z'"):
        FMUProcessModel(hostile, 0.05, ["z"])
    with pytest.raises(ConfigurationError, match="not an input"):
        FMUProcessModel(hostile, 0.05, ["y"], ["k"])
    with pytest.raises(ConfigurationError, match="errs by .* above the tolerance 1e-12: use about"):
        FMUProcessModel(hostile, 0.05, ["y"], tolerance=1e-12)
    with pytest.raises(ConfigurationError, match="is not a parameter"):
        FMUProcessModel(hostile, 0.05, ["y"], parameters={"x0": 1.0})


def test_an_fmu_with_time_events_is_refused(bouncing_me_fmu):
    """The FMI 2.0 bouncing ball (a time event every 0.25 s) is refused for its time event."""
    with pytest.raises(FMUError, match="time event at t = 0.25 s"):
        FMUProcessModel(bouncing_me_fmu, 0.01, ["h"])


def test_without_a_saved_state_an_error_frees_the_instance(hostile, tmp_path, call_log):
    """An FMU that cannot save its state: every evaluation a trial step from the start time,
    no CompletedIntegratorStep; after Error the instance is freed and made again."""
    plain = patched(hostile, tmp_path / "plain.fmu", 'canGetAndSetFMUState="true"', 'canGetAndSetFMUState="false"')
    model = FMUProcessModel(plain, 0.05, ["y"], ["u"], parameters={"mode": 2, "limit": 0.8})
    assert "not restorable" in model.describe()
    us, ys = rising()
    ekf = EKF(model, [0.5, 0.0], 0.01, 1e-4, 1e-3)
    with pytest.raises(FMUError, match="returned Error"):
        ekf.run(us, ys)
    np.testing.assert_allclose(ekf.step(us[0], ys[0]), EKF(hostile_model(hostile, 0), [0.5, 0.0], 0.01, 1e-4,
                                                                             1e-3).step(us[0], ys[0]), atol=1e-15)


def test_the_virtual_machine_calls_the_same_compiled_model(cartpole_fmus, record):
    """Without compiling the filter's step (CasADi's virtual machine), the model's own compiled
    code is called all the same: the same numbers (to the rounding of the filter's algebra)."""
    us, ys = record
    fmu, _ = cartpole_models(cartpole_fmus[3])
    a, b = EKF(fmu, **KW, backend="vm"), EKF(fmu, **KW)
    assert a.backend == "vm"
    np.testing.assert_allclose(a.run(us[:50], ys[:50]).x, b.run(us[:50], ys[:50]).x, rtol=0, atol=1e-12)

"""Clocked estimator FMUs (FMI 3.0): the input clock ``sample`` at the filter's period, in
Co-Simulation with Event Mode and as Scheduled Execution, equal to the Python EKF in an
independent driver written here on fmpy's classes and in the project's master; illegal calls
answered with Error and a message; the clocked form refused for FMI 2.0."""
import re
import zipfile
from ctypes import c_double, c_int, c_uint32

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3ScheduledExecution, FMU3Slave, fmi3LogMessageCallback
from fmpy.validation import validate_fmu

from cosim.cli import main
from cosim.components.estimation import EstimatorComponent
from cosim.components.sensors import ProcessNoise, Sensor
from cosim.components.sources import PRBS
from cosim.core.master import Cosimulation
from cosim.fmi.fmu_component import FMUComponent
from estimators import EKF
from estimators.filter_fmu import export_filter_fmu
from fmu_models import get_model
from fmu_models.errors import ConfigurationError
from fmu_models.export.signal_fmu import SignalSpec, build_signal_fmu

X0 = [0.5, 0.0, 1.8, 0.5]
T = 0.01


def make_ekf(cp):
    return EKF(cp, X0, 1.0, 0.2, 0.1)


@pytest.fixture(scope="module")
def record(cp):
    """300 steps of the cart-pole with noise: inputs u_k and measurements y_k (y_0 unused,
    two missing channels on the way)."""
    rng = np.random.default_rng(11)
    us = np.where(np.arange(301) * T < 1.0, -0.5, 0.5)
    x, ys = np.array(X0), [np.full(2, np.nan)]
    for k in range(300):
        x = cp.f(x, [us[k]]) + rng.normal(0, np.sqrt(0.2), 4)
        ys.append(cp.h(x) + rng.normal(0, np.sqrt(0.1), 2))
    ys = np.array(ys)
    ys[[37, 210], 1] = np.nan
    return us, ys


@pytest.fixture(scope="module")
def reference(cp, record):
    """The Python EKF's estimates and variances at every instant (row 0: the initial ones)."""
    us, ys = record
    f = make_ekf(cp)
    xs, ps = [f.x.copy()], [np.diag(f.P).copy()]
    for k in range(1, len(ys)):
        xs.append(f.step([us[k - 1]], ys[k]).copy())
        ps.append(np.diag(f.P).copy())
    return np.array(xs), np.array(ps)


@pytest.fixture(scope="module")
def clocked_ekf(cp, tmp_path_factory):
    return export_filter_fmu(make_ekf(cp), tmp_path_factory.mktemp("clocked"), fmi_version=3, clocked=True)


class Driver:
    """The clocked FMU through fmpy's FMU3Slave (Event Mode) or FMU3ScheduledExecution, its
    log messages in ``messages``: independent of the project's master."""

    def __init__(self, path, interface, folder, event_mode=True):
        self.md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.messages = []
        self._cb = fmi3LogMessageCallback(lambda env, status, cat, msg: self.messages.append(msg.decode()))
        iface = self.md.coSimulation if interface == "cs" else self.md.scheduledExecution
        cls = FMU3Slave if interface == "cs" else FMU3ScheduledExecution
        self.fmu = cls(guid=self.md.guid, unzipDirectory=extract(str(path), str(folder)),
                       modelIdentifier=iface.modelIdentifier, instanceName="ekf")
        if interface == "cs":
            self.fmu.instantiate(loggingOn=True, eventModeUsed=event_mode, logMessage=self._cb)
        else:
            self.fmu.instantiate(loggingOn=True, logMessage=self._cb)
        self.fmu.enterInitializationMode(startTime=0.0)
        self.fmu.exitInitializationMode()
        self.clock = self.vr["sample"]

    def refs(self, names):
        return [self.vr[n] for n in names]


def run_event_mode(d, us, ys, outs):
    """Co-Simulation with Event Mode: at each activation time Event Mode, fmi3SetClock, the
    clocked inputs, the clocked outputs, fmi3UpdateDiscreteStates; then a step to the next."""
    fmu, got = d.fmu, []
    for k in range(len(ys)):
        if k:
            fmu.enterEventMode()
        fmu.setClock([d.clock], [True])
        fmu.setFloat64(d.refs(["y_x", "y_theta"]), list(ys[k]))
        fmu.setFloat64(d.refs(["F"]), [us[k]])
        got.append(fmu.getFloat64(d.refs(outs)))
        fmu.updateDiscreteStates()
        fmu.enterStepMode()
        fmu.doStep(k * T, T)
    return np.array(got)


def run_scheduled(d, us, ys, outs):
    """Scheduled Execution: the inputs, fmi3ActivateModelPartition at each activation time,
    the outputs."""
    fmu, got = d.fmu, []
    for k in range(len(ys)):
        fmu.setFloat64(d.refs(["y_x", "y_theta"]), list(ys[k]))
        fmu.setFloat64(d.refs(["F"]), [us[k]])
        fmu.activateModelPartition(d.clock, k * T)
        got.append(fmu.getFloat64(d.refs(outs)))
    return np.array(got)


def test_the_clocked_fmu_declares_its_clock_and_clocked_variables(clocked_ekf):
    assert validate_fmu(str(clocked_ekf)) == []
    md = read_model_description(str(clocked_ekf))
    assert md.coSimulation.hasEventMode and md.scheduledExecution is not None
    clocks = [v for v in md.modelVariables if v.type == "Clock"]
    assert [(c.name, c.causality, c.intervalVariability) for c in clocks] == [("sample", "input", "constant")]
    xml = re.search(r"<Clock [^>]*>", extract_xml(clocked_ekf)).group(0)
    assert 'intervalDecimal="0.01"' in xml and 'priority="0"' in xml
    for v in md.modelVariables:
        clocked = v.causality in ("input", "output") and v.type != "Clock"
        assert (v.clocks == clocks) == clocked, v.name


def extract_xml(path):
    with zipfile.ZipFile(path) as z:
        return z.read("modelDescription.xml").decode()


@pytest.mark.parametrize("interface", ["cs", "se"])
def test_clocked_ekf_in_an_fmpy_driver_equals_the_python_ekf(cp, record, reference, clocked_ekf, tmp_path,
                                                              interface):
    us, ys = record
    d = Driver(clocked_ekf, interface, tmp_path)
    outs = list(cp.state_names) + [f"P_{s}" for s in cp.state_names]
    got = (run_event_mode if interface == "cs" else run_scheduled)(d, us, ys, outs)
    d.fmu.terminate()
    d.fmu.freeInstance()
    xs, ps = reference
    np.testing.assert_allclose(got[:, :4], xs, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[:, 4:], ps, rtol=0, atol=1e-12)
    assert d.messages == []


@pytest.mark.parametrize("interface", ["cs", "se"])
def test_the_master_runs_the_clocked_ekf_like_the_python_component(cp, fmu_paths, clocked_ekf, interface):
    def parts(estimator):
        model = get_model("cartpole")
        plant = FMUComponent("plant", fmu_paths["cartpole"], T, start=dict(zip(model.state_names, X0)))
        return [estimator, plant, Sensor("sensor", T, ["x", "theta"], noise_std=0.3, seed=2),
                PRBS("force", T, 0.5, 1.0, 7, 28), ProcessNoise("noise", T, model.state_names, 0.2, seed=1)]

    wiring = {"plant.F": "force.out", "sensor.x": "plant.x", "sensor.theta": "plant.theta",
              "ekf.F": "force.out", "ekf.y_x": "sensor.y_x", "ekf.y_theta": "sensor.y_theta",
              **{f"plant.w_{s}": f"noise.w_{s}" for s in ("x", "x_dot", "theta", "theta_dot")}}
    py = Cosimulation(parts(EstimatorComponent("ekf", lambda: make_ekf(cp))), wiring).run(3.0)
    fmu = FMUComponent("ekf", clocked_ekf, T, inputs=["F", "y_x", "y_theta"], interface=interface)
    assert fmu.clock_model is not None and fmu.interface == interface
    native = Cosimulation(parts(fmu), wiring).run(3.0)
    cols = [f"ekf.{s}" for s in cp.state_names] + [f"ekf.P_{s}" for s in cp.state_names]
    np.testing.assert_allclose(native[cols].to_numpy(), py[cols].to_numpy(), rtol=0, atol=1e-12)


# ---------------------------------------------------------------------------- illegal calls
def _cs_step_over(d):
    d.fmu.setClock([d.clock], [True])
    d.fmu.updateDiscreteStates()
    d.fmu.enterStepMode()
    d.fmu.doStep(0.0, 2 * T)


def _cs_missed(d):
    _cs_to_first_step(d)
    d.fmu.enterEventMode()
    d.fmu.updateDiscreteStates()
    d.fmu.enterStepMode()
    d.fmu.doStep(T, T)


def _cs_to_first_step(d):
    d.fmu.setClock([d.clock], [True])
    d.fmu.updateDiscreteStates()
    d.fmu.enterStepMode()
    d.fmu.doStep(0.0, T)


def _cs_not_due(d):
    d.fmu.setClock([d.clock], [True])
    d.fmu.updateDiscreteStates()
    d.fmu.setClock([d.clock], [True])


def _cs_get_in_step_mode(d):
    _cs_to_first_step(d)
    d.fmu.getFloat64(d.refs(["x"]))


def _cs_set_inactive(d):
    d.fmu.setFloat64(d.refs(["y_x"]), [0.1])


def _cs_step_mode_while_active(d):
    d.fmu.setClock([d.clock], [True])
    d.fmu.enterStepMode()


def _cs_deactivate(d):
    d.fmu.setClock([d.clock], [False])


def _cs_wrong_clock(d):
    d.fmu.setClock([d.vr["x"]], [True])


def _cs_set_interval(d):
    d.fmu.fmi3SetIntervalDecimal(d.fmu.component, (c_uint32 * 1)(d.clock), 1, (c_double * 1)(0.02))


def _cs_activate(d):
    d.fmu.fmi3ActivateModelPartition(d.fmu.component, d.clock, 0.0)


def _se_get_before(d):
    d.fmu.getFloat64(d.refs(["x"]))


def _se_get_after_set(d):
    d.fmu.activateModelPartition(d.clock, 0.0)
    d.fmu.setFloat64(d.refs(["y_x"]), [0.1])
    d.fmu.getFloat64(d.refs(["x"]))


def _se_skip(d):
    d.fmu.activateModelPartition(d.clock, 0.0)
    d.fmu.activateModelPartition(d.clock, 2 * T)


def _se_twice(d):
    d.fmu.activateModelPartition(d.clock, 0.0)
    d.fmu.activateModelPartition(d.clock, 0.0)


def _se_wrong_clock(d):
    d.fmu.activateModelPartition(d.vr["F"], 0.0)


def _se_set_clock(d):
    d.fmu.setClock([d.clock], [True])


def _se_do_step(d):
    d.fmu.fmi3DoStep(d.fmu.component, 0.0, T, True, *(None,) * 4)


def _se_enter_event_mode(d):
    d.fmu.enterEventMode()


ILLEGAL = {
    "step over an activation": ("cs", _cs_step_over, "passes the activation of the clock sample at 0.01"),
    "step from a missed activation": ("cs", _cs_missed, "activation of the clock sample at 0.01"),
    "clock not due": ("cs", _cs_not_due, "not due at t = 0 s: its next activation is at 0.01"),
    "clocked output in Step Mode": ("cs", _cs_get_in_step_mode, "x is clocked by the clock sample, which is not"),
    "clocked input, clock inactive": ("cs", _cs_set_inactive, "y_x is clocked by the clock sample"),
    "Step Mode while active": ("cs", _cs_step_mode_while_active, "fmi3UpdateDiscreteStates must end"),
    "deactivate": ("cs", _cs_deactivate, "cannot be deactivated"),
    "not a clock": ("cs", _cs_wrong_clock, "no input Clock has value reference"),
    "set the interval": ("cs", _cs_set_interval, "constant: its interval and shift cannot be set"),
    "activate a partition in CS": ("cs", _cs_activate, "fmi3ActivateModelPartition: not allowed in Event Mode"),
    "get before the first activation": ("se", _se_get_before, "get it after fmi3ActivateModelPartition"),
    "get after a set": ("se", _se_get_after_set, "nor after a set without an activation"),
    "skip an activation": ("se", _se_skip, "skips the activation of the clock sample at 0.01"),
    "activate twice": ("se", _se_twice, "not due at t = 0 s"),
    "not the clock": ("se", _se_wrong_clock, "no input Clock has value reference"),
    "fmi3SetClock in SE": ("se", _se_set_clock, "fmi3SetClock: not allowed in Clock Activation Mode"),
    "fmi3DoStep in SE": ("se", _se_do_step, "fmi3DoStep: not allowed in Clock Activation Mode"),
    "Event Mode in SE": ("se", _se_enter_event_mode, "not allowed in Clock Activation Mode (Scheduled Execution"),
}


@pytest.mark.parametrize("case", list(ILLEGAL))
def test_illegal_calls_are_answered_with_error_and_a_message(clocked_ekf, tmp_path, case):
    interface, script, message = ILLEGAL[case]
    d = Driver(clocked_ekf, interface, tmp_path)
    with pytest.raises(FMICallException, match="status 3"):
        script(d)
    assert any(message in m for m in d.messages), d.messages
    with pytest.raises(FMICallException):                      # only what the standard allows after an Error
        interval(d) if interface == "cs" else d.fmu.activateModelPartition(d.clock, T)
    d.fmu.freeInstance()


def test_co_simulation_without_event_mode_is_refused(clocked_ekf, tmp_path):
    with pytest.raises(Exception, match="Failed to instantiate"):
        Driver(clocked_ekf, "cs", tmp_path, event_mode=False)


def test_interval_and_shift_are_the_declared_ones(clocked_ekf, tmp_path):
    d = Driver(clocked_ekf, "cs", tmp_path)
    assert interval(d) == (T, 1)                                        # fmi3IntervalUnchanged
    shift = (c_double * 1)(-1.0)
    d.fmu.getShiftDecimal((c_uint32 * 1)(d.clock), shift)
    assert shift[0] == 0.0
    d.fmu.freeInstance()


def interval(d):
    """fmi3GetIntervalDecimal of the clock: (interval [s], qualifier)."""
    iv, q = (c_double * 1)(), (c_int * 1)()
    d.fmu.getIntervalDecimal((c_uint32 * 1)(d.clock), iv, q)
    return iv[0], q[0]


@pytest.mark.parametrize("interface", ["cs", "se"])
def test_fmu_state_saved_at_an_activation_continues_bit_identically(cp, record, clocked_ekf, tmp_path, interface):
    """Saved while the clock is active (Co-Simulation: in Event Mode after fmi3SetClock;
    Scheduled Execution: between activations), restored in the same and, serialised, in a
    fresh instance: the activation gives the same bits."""
    us, ys = record
    outs = list(cp.state_names)
    d = Driver(clocked_ekf, interface, tmp_path / "a")
    fresh = Driver(clocked_ekf, interface, tmp_path / "b")
    run = run_event_mode if interface == "cs" else run_scheduled
    run(d, us[:50], ys[:50], outs)

    def activation(drv):
        f = drv.fmu
        if interface == "cs":
            return f.getFloat64(drv.refs(outs))
        f.setFloat64(drv.refs(["y_x", "y_theta"]), list(ys[50]))
        f.activateModelPartition(drv.clock, 50 * T)
        return f.getFloat64(drv.refs(outs))

    if interface == "cs":
        d.fmu.enterEventMode()
        d.fmu.setClock([d.clock], [True])
        d.fmu.setFloat64(d.refs(["y_x", "y_theta"]), list(ys[50]))
    state = d.fmu.getFMUState()
    first = activation(d)
    if interface == "cs":
        d.fmu.updateDiscreteStates()
    d.fmu.setFMUState(state)
    assert activation(d) == first
    fresh.fmu.setFMUState(fresh.fmu.deserializeFMUState(d.fmu.serializeFMUState(state)))
    assert activation(fresh) == first
    d.fmu.freeFMUState(state)
    for drv in (d, fresh):
        drv.fmu.terminate()
        drv.fmu.freeInstance()


# ---------------------------------------------------------------------------- FMI 2.0
def test_fmi2_refuses_the_clocked_form(cp, tmp_path, capsys):
    with pytest.raises(ConfigurationError, match="the clocked form needs FMI 3.0"):
        export_filter_fmu(make_ekf(cp), tmp_path, fmi_version=2, clocked=True)
    with pytest.raises(ConfigurationError, match="the clocked form needs FMI 3.0"):
        build_signal_fmu(SignalSpec("constant", T, ["out"], reals=[("value", 1.0, "real", "v")]), tmp_path, 2,
                         clocked=True)
    assert list(tmp_path.iterdir()) == []
    assert main(["export-fmu", "seed000_cartpole", "--out", str(tmp_path / "f"), "--clocked"]) == 2
    err = capsys.readouterr().err
    assert "the clocked form needs FMI 3.0" in err and "Traceback" not in err
    assert not (tmp_path / "f").exists()

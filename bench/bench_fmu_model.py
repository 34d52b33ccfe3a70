"""Benchmark: microseconds per EKF step on a Model Exchange FMU's process model, against
filterpy's EKF on the same FMU through fmpy, and against CasADi's own FMU import.

Run: python bench/bench_fmu_model.py [--write-docs]
The FMU is the project's cart-pole (4 states, 1 input, 2 outputs; FMI 2.0 and 3.0, Model
Exchange with directional derivatives), one period of 0.01 s by one RK4 step, the same data
for every filter; each figure is the fastest of 7 repeats of 2000 steps from Python (inputs as
lists), each filter warmed up first. Baselines in the same run:

* our EKF on the CasADi model of the same plant (no FMU);
* filterpy's ``ExtendedKalmanFilter`` on the same FMU (FMI 2.0) through fmpy's ``FMU2Model``:
  the RK4 map in numpy calling ``setTime``, ``setContinuousStates``, ``setReal`` and
  ``getDerivatives``, its Jacobian from ``getDirectionalDerivative`` through the stages (the
  same exact derivative), the measurement from ``getReal`` and its Jacobian from
  ``getDirectionalDerivative``;
* our EKF on CasADi's own FMU import (``casadi.DaeBuilder`` of the unpacked FMU, its
  ``FmuFunction`` in an RK4 step of CasADi expressions): CasADi cannot generate code for an
  ``FmuFunction``, so that filter runs in CasADi's virtual machine.
"""
from __future__ import annotations

import ctypes
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from estimators import EKF, DiscreteModel, FMUProcessModel, discretize
from fmu_models import build_fmu, get_model

sys.path.append(str(Path(__file__).parent))          # bench/doc_tables.py, from any folder
import doc_tables
from bench_estimators import per_step

N, DT = 2000, 0.01
_DOUBLE_P = ctypes.POINTER(ctypes.c_double)
X0, P0, Q, R = [0.5, 0.0, 1.8, 0.5], 1.0, 0.2, 0.1


def data(model, n=N, seed=0):
    rng = np.random.default_rng(seed)
    us = np.where(np.arange(n) * DT % 4 < 2, -0.5, 0.5)[:, None]
    xs = model.simulate(X0, us, DT, n, method="rk4")
    return us, np.array([model.h(x) for x in xs[1:]]) + rng.normal(0, 0.05, (n, 2))


def time_filter(make, us, ys):
    f, ul, yl = make(), us.tolist(), ys.tolist()

    def run():
        f.reset(X0, P0)
        step = f.step
        for k in range(N):
            step(ul[k], yl[k])
    run()                                   # warm up
    return per_step(run, N)


class FmpyCartpole:
    """The FMU's map, Jacobians and measurement through fmpy's FMU2Model (see the module
    documentation)."""

    def __init__(self, path: Path, folder: str):
        from fmpy import read_model_description
        from fmpy.fmi2 import FMU2Model

        md = read_model_description(str(path))
        zipfile.ZipFile(path).extractall(folder)
        vr = {v.name: v.valueReference for v in md.modelVariables}
        model = get_model("cartpole")
        self.x, self.dx = [vr[s] for s in model.state_names], [vr[f"der({s})"] for s in model.state_names]
        self.u, self.y = [vr[s] for s in model.input_names], [vr[s] for s in model.output_names]
        fmu = FMU2Model(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.modelExchange.modelIdentifier,
                        instanceName="bench")
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.newDiscreteStates()
        fmu.enterContinuousTimeMode()
        self.fmu, self.buf = fmu, np.zeros(4)

    def rhs(self, t, x):
        fmu, dx = self.fmu, self.buf
        fmu.setTime(t)
        fmu.setContinuousStates(np.ascontiguousarray(x).ctypes.data_as(_DOUBLE_P), 4)
        fmu.getDerivatives(dx.ctypes.data_as(_DOUBLE_P), 4)
        return dx.copy()

    def jacobian(self, unknowns):
        return np.array([self.fmu.getDirectionalDerivative(unknowns, [k], [1.0]) for k in self.x]).T

    def f_F(self, x, u):
        """One RK4 step and its Jacobian by the stages' tangents."""
        h = DT
        self.fmu.setReal(self.u, list(u))
        k1 = self.rhs(0.0, x)
        d1 = self.jacobian(self.dx)
        k2 = self.rhs(h / 2, x + h / 2 * k1)
        d2 = self.jacobian(self.dx) @ (np.eye(4) + h / 2 * d1)
        k3 = self.rhs(h / 2, x + h / 2 * k2)
        d3 = self.jacobian(self.dx) @ (np.eye(4) + h / 2 * d2)
        k4 = self.rhs(h, x + h * k3)
        d4 = self.jacobian(self.dx) @ (np.eye(4) + h * d3)
        return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4), np.eye(4) + h / 6 * (d1 + 2 * d2 + 2 * d3 + d4)

    def h(self, x):
        self.fmu.setContinuousStates(np.ascontiguousarray(x).ctypes.data_as(_DOUBLE_P), 4)
        return np.array(self.fmu.getReal(self.y)).reshape(-1, 1)

    def H(self, x):
        self.fmu.setContinuousStates(np.ascontiguousarray(x).ctypes.data_as(_DOUBLE_P), 4)
        return self.jacobian(self.y)


def filterpy_on_fmpy(path: Path, folder: str, us, ys):
    from filterpy.kalman import ExtendedKalmanFilter

    model = FmpyCartpole(path, folder)
    fp = ExtendedKalmanFilter(4, 2)
    zs = [y.reshape(-1, 1) for y in ys]

    def run():
        fp.x, fp.P, fp.Q, fp.R = np.array(X0).reshape(-1, 1), P0 * np.eye(4), Q * np.eye(4), R * np.eye(2)
        for k in range(N):
            x, F = model.f_F(fp.x.ravel(), us[k])
            fp.F, fp.x = F, x.reshape(-1, 1)
            fp.P = F @ fp.P @ F.T + fp.Q
            fp.update(zs[k], lambda x: model.H(x.ravel()), lambda x: model.h(x.ravel()))
    run()
    return per_step(run, N), fp.x.ravel()


def casadi_import(path: Path, folder: str) -> DiscreteModel:
    """Our filters' model from CasADi's own FMU import (an RK4 step around its FmuFunction)."""
    import casadi as ca

    zipfile.ZipFile(path).extractall(folder)
    f = ca.DaeBuilder("cartpole", folder).create("f", ["x", "u"], ["ode"])
    x, u = ca.SX.sym("x", 4), ca.SX.sym("u", 1)
    w = ca.vertcat(u, ca.SX.zeros(4))              # the FMU's inputs: F and the process-noise inputs
    k1 = f(x, w)
    k2 = f(x + DT / 2 * k1, w)
    k3 = f(x + DT / 2 * k2, w)
    k4 = f(x + DT * k3, w)
    m = get_model("cartpole")
    return DiscreteModel(x, u, x + DT / 6 * (k1 + 2 * k2 + 2 * k3 + k4), ca.vertcat(x[0], x[2]), DT, m.state_names,
                         m.input_names, m.output_names, "cartpole (CasADi's FMU import)")


def main():
    options = doc_tables.parse_options(__doc__)
    plant = get_model("cartpole")
    us, ys = data(plant)
    results, work = {}, Path(tempfile.mkdtemp(prefix="bench_fmu_model_"))
    cas = discretize(plant, DT, "rk4")
    results["EKF, CasADi model"] = time_filter(lambda: EKF(cas, X0, P0, Q, R), us, ys)
    paths = {v: build_fmu(plant, work / f"fmi{v}", fmi_version=v) for v in (2, 3)}
    final = {}
    for v, path in paths.items():
        model = FMUProcessModel(path, DT, plant.output_names, plant.input_names)
        results[f"EKF, FMU model (FMI {v}.0)"] = time_filter(lambda m=model: EKF(m, X0, P0, Q, R), us, ys)
        f = EKF(model, X0, P0, Q, R)
        results[f"EKF run, FMU model (FMI {v}.0), per step"] = per_step(lambda f=f: (f.reset(X0, P0), f.run(us, ys)), N)
        final[v] = f.run(us, ys).x[-1]
    results["filterpy EKF, the FMU through fmpy"], fp_last = filterpy_on_fmpy(paths[2], str(work / "fmpy"), us, ys)
    vm = casadi_import(paths[2], str(work / "casadi"))
    results["EKF, CasADi's FMU import (virtual machine)"] = time_filter(
        lambda: EKF(vm, X0, P0, Q, R, backend="vm"), us, ys)
    width = max(map(len, results))
    for name, value in results.items():
        print(f"{name:<{width}}  {value:8.2f} us")
    ours = results["EKF, FMU model (FMI 2.0)"]
    vm_step = results["EKF, CasADi's FMU import (virtual machine)"]
    print(f"speed-up over filterpy + fmpy: {results['filterpy EKF, the FMU through fmpy'] / ours:.0f}x; over "
          f"CasADi's FMU import: {vm_step / ours:.1f}x; the FMU costs {ours - results['EKF, CasADi model']:.2f} us "
          "a step over the CasADi model")
    print(f"last estimate, ours against filterpy + fmpy: {np.abs(final[2] - fp_last).max():.1e} apart")
    if options.write_docs:
        doc_tables.write_docs(__file__, results)


def steps_table(saved) -> str:
    """The tutorial's table: µs per EKF step on the cart-pole FMU, ours against the others."""
    r = saved["bench_fmu_model"]["figures"]
    ours = r["EKF, FMU model (FMI 2.0)"]

    def times(name):
        return f"{r[name]:.2f}" if r[name] < 10 else f"{r[name]:.0f} ({r[name] / ours:.0f}x)"
    return doc_tables.with_provenance(saved, "bench_fmu_model", doc_tables.table(
        ["EKF on the cart-pole (4 states), RK4, from Python", "µs/step"], [
            ["on the FMU's process model, FMI 2.0 / 3.0",
             f"{r['EKF, FMU model (FMI 2.0)']:.2f} / {r['EKF, FMU model (FMI 3.0)']:.2f}"],
            ["the same, a whole record in one native call (per step), FMI 2.0 / 3.0",
             f"{r['EKF run, FMU model (FMI 2.0), per step']:.2f} / {r['EKF run, FMU model (FMI 3.0), per step']:.2f}"],
            ["on the CasADi model of the same plant (no FMU)", times("EKF, CasADi model")],
            ["filterpy's EKF, the same FMU through fmpy", times("filterpy EKF, the FMU through fmpy")],
            ["on CasADi's own FMU import (virtual machine)", times("EKF, CasADi's FMU import (virtual machine)")]]))


TABLES = {"fmu-steps": steps_table}

if __name__ == "__main__":
    main()

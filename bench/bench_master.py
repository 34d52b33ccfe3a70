"""Benchmark: the master's wall time for 5 s of the cart-pole (1 ms plant step, 10 ms EKF)
against a bare loop of fmpy doStep calls on the same FMU, in the same run.

Run: python bench/bench_master.py
Overhead = master - (bare loop + the estimator's own time); medians of 7 repeats.
"""
from __future__ import annotations

import tempfile
import time

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from cosim.estimation import EstimatorComponent
from cosim.fmu_component import FMUComponent
from cosim.master import Cosimulation
from cosim.sensors import Sensor
from cosim.sources import Step
from estimators import EKF, discretize
from fmu_models import get_model
from fmu_models.build import build_fmu

T_END, H, T_EST, REPEATS = 5.0, 0.001, 0.01, 7


def bare_loop(path):
    """What a user would write with fmpy alone: set the force, doStep, read x and theta.

    Returns (loop time, total time including instantiation and freeing)."""
    start = time.perf_counter()
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path),
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bare")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.setReal([vr["step_size"]], [H])
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    n = int(round(T_END / H))
    t0 = time.perf_counter()
    for k in range(n):
        t = k * H
        fmu.setReal([vr["F"]], [-0.5 if t < 2.0 else 0.5])
        fmu.doStep(t, H)
        fmu.getReal([vr["x"], vr["theta"]])
    wall = time.perf_counter() - t0
    fmu.terminate()
    fmu.freeInstance()
    return wall, time.perf_counter() - start


def estimator_alone(sys_, x0):
    ekf = EKF(sys_, x0, 1.0, 1e-6, 1e-4)
    ys = np.tile([0.5, 1.8], (int(round(T_END / T_EST)), 1))
    t0 = time.perf_counter()
    for y in ys:
        ekf.step([0.5], y)
    return time.perf_counter() - t0


def master_run(path, sys_, x0):
    plant = FMUComponent("plant", path, H, parameters={"step_size": H})
    comps = [plant, Step("force", T_EST, 2.0, -0.5, 0.5),
             Sensor("sensor", T_EST, ["x", "theta"], noise_std=0.01, seed=1),
             EstimatorComponent("ekf", lambda: EKF(sys_, x0, 1.0, 1e-6, 1e-4))]
    conn = {"plant.F": "force.out", "sensor.x": "plant.x", "sensor.theta": "plant.theta",
            "ekf.F": "force.out", "ekf.y_x": "sensor.y_x", "ekf.y_theta": "sensor.y_theta"}
    cs = Cosimulation(comps, conn)
    t0 = time.perf_counter()
    cs.run(T_END)
    return cs.timings["loop"], time.perf_counter() - t0


def main():
    model = get_model("cartpole")
    sys_ = discretize(model, T_EST)
    with tempfile.TemporaryDirectory() as out:
        path = str(build_fmu(model, out))
        master_run(path, sys_, model.x0)      # warm-up (compiles the filter once)
        bare, bare_total = np.median([bare_loop(path) for _ in range(REPEATS)], axis=0)
        est = np.median([estimator_alone(sys_, model.x0) for _ in range(REPEATS)])
        mast, mast_total = np.median([master_run(path, sys_, model.x0) for _ in range(REPEATS)], axis=0)
    print("5 s cart-pole, plant step 1 ms (5000 doSteps), EKF every 10 ms (500 steps), "
          "sensor and source every 10 ms")
    print("                                   stepping loop   whole run (with instantiation)")
    print(f"bare fmpy doStep loop:             {bare * 1e3:7.1f} ms      {bare_total * 1e3:7.1f} ms")
    print(f"estimator alone:                   {est * 1e3:7.1f} ms")
    print(f"master, whole closed loop:         {mast * 1e3:7.1f} ms      {mast_total * 1e3:7.1f} ms")
    print(f"master over (bare loop + estimator): {(mast / (bare + est) - 1) * 100:+.0f} % "
          f"(loops), {(mast_total / (bare_total + est) - 1) * 100:+.0f} % (whole runs)")


if __name__ == "__main__":
    main()

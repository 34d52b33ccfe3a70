"""Benchmark: FMU build time and the cost of one doStep (one internal Euler step) through fmpy.

Run: python bench/bench_fmu.py [--write-docs]
"""
from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

from fmu_models import build_fmu

sys.path.append(str(Path(__file__).parent))          # bench/doc_tables.py, from any folder
import doc_tables


def time_steps(path, version, n=20_000, with_input=True):
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    cls = FMU2Slave if version == 2 else FMU3Slave
    fmu = cls(guid=md.guid, unzipDirectory=extract(path),
              modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bench")
    fmu.instantiate()
    if version == 2:
        fmu.setupExperiment(startTime=0)
    fmu.enterInitializationMode()
    get = fmu.getReal if version == 2 else fmu.getFloat64
    set_ = fmu.setReal if version == 2 else fmu.setFloat64
    set_([vr["step_size"]], [0.001])          # one internal step per 1 ms doStep (the plant's grid)
    fmu.exitInitializationMode()
    outs, ins = [vr["y_x"], vr["y_theta"]], [vr["F"]]
    t, h = 0.0, 0.001
    t0 = time.perf_counter()
    for k in range(n):
        if with_input:
            set_(ins, [0.5 if k % 2000 < 1000 else -0.5])
        fmu.doStep(t, h)
        get(outs)
        t += h
    dt = (time.perf_counter() - t0) / n
    fmu.terminate()
    fmu.freeInstance()
    return dt


def main():
    args = doc_tables.parse_options(__doc__)
    figures = {}
    with tempfile.TemporaryDirectory() as out:
        os.environ["PENDULUM_COSIM_CACHE"] = out + "/empty-cache"     # the build is timed uncached
        for version in (2, 3):
            t0 = time.perf_counter()
            path = str(build_fmu("cartpole", out + f"/v{version}", fmi_version=version))
            build_s = time.perf_counter() - t0
            a = np.median([time_steps(path, version, with_input=False) for _ in range(3)])
            b = np.median([time_steps(path, version, with_input=True) for _ in range(3)])
            print(f"FMI {version}.0 CartPole: build {build_s:.2f} s; doStep + 2 outputs "
                  f"{a * 1e6:.2f} us; with 1 input set each step {b * 1e6:.2f} us")
            figures[f"fmi{version}"] = {"build_s": build_s, "step_us": a * 1e6, "step_input_us": b * 1e6}
    if args.write_docs:
        doc_tables.write_docs(__file__, figures)


def fmu_table(saved) -> str:
    """The performance page's table: the CartPole FMU's build and doStep through fmpy."""
    f = saved["bench_fmu"]["figures"]
    rows = [("build (generate, compile, pack; not cached)", "build_s", "{:.2f} s"),
            ("`doStep` + read 2 outputs", "step_us", "{:.2f} µs"),
            ("same, setting 1 input each step", "step_input_us", "{:.2f} µs")]
    return doc_tables.with_provenance(saved, "bench_fmu", doc_tables.table(
        ["", "FMI 2.0", "FMI 3.0"], [[label, *(form.format(f[v][key]) for v in ("fmi2", "fmi3"))]
                                    for label, key, form in rows]))


TABLES = {"fmu": fmu_table}


if __name__ == "__main__":
    main()

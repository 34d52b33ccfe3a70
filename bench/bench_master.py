"""Benchmark: the master's own cost per base step, against what a user would write instead.

Run: python bench/bench_master.py [--long]

Same FMU (the cart-pole plant, FMI 2.0 Co-Simulation, 1 ms steps, 5 s = 5000 steps), same
work per step (set the force, doStep, read the 6 outputs into a record), three ways:

* fmpy's ``FMU2Slave`` loop: ``setReal``, ``doStep``, ``getReal`` and a row copy;
* a raw ctypes loop: the FMU's functions called with prebuilt ctypes arguments (the
  cheapest a Python loop can be), rows copied into a preallocated array;
* the master: plant FMU and a force source held at 10 ms, every signal recorded.

"master own cost" = (master loop - raw loop) / steps. Medians of 7 repeats, all in this
run. ``--long`` adds a 1e6-step run streamed to Parquet and reports its peak RSS beside a
1e5-step one (constant memory means equal peaks).
"""
from __future__ import annotations

import argparse
import ctypes
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from cosim.components.sources import Constant, Step
from cosim.core.master import Cosimulation
from cosim.fmi.fmu_component import FMUComponent
from fmu_models import build_fmu, get_model

T_END, H, REPEATS = 5.0, 0.001, 7
N = round(T_END / H)


def _instance(path):
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path),
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bare")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.setReal([vr["step_size"]], [H])
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    outs = [vr[n] for n in ("x", "x_dot", "theta", "theta_dot", "y_x", "y_theta")]
    return fmu, vr, outs


def fmpy_loop(path) -> float:
    """What a user would write with fmpy alone."""
    fmu, vr, outs = _instance(path)
    rec = np.empty((N + 1, len(outs)))
    rec[0] = fmu.getReal(outs)
    t0 = time.perf_counter()
    for k in range(N):
        t = k * H
        fmu.setReal([vr["F"]], [-0.5 if t < 2.0 else 0.5])
        fmu.doStep(t, H)
        rec[k + 1] = fmu.getReal(outs)
    wall = time.perf_counter() - t0
    fmu.terminate()
    fmu.freeInstance()
    return wall


def raw_loop(path) -> float:
    """The same calls through raw ctypes pointers with prebuilt arguments."""
    fmu, vr, outs = _instance(path)
    dll, c = fmu.dll, ctypes.c_void_p(fmu.component)

    def fn(name):
        f = getattr(dll, name)
        f = type(f).from_address(ctypes.addressof(f))
        f.restype, f.argtypes = ctypes.c_int, None
        return f

    set_real, do_step, get_real = fn("fmi2SetReal"), fn("fmi2DoStep"), fn("fmi2GetReal")
    in_vr, out_vr = (ctypes.c_uint32 * 1)(vr["F"]), (ctypes.c_uint32 * len(outs))(*outs)
    in_buf, out_buf = (ctypes.c_double * 1)(), (ctypes.c_double * len(outs))()
    out_np = np.ctypeslib.as_array(out_buf)
    one, n_out, D = ctypes.c_size_t(1), ctypes.c_size_t(len(outs)), ctypes.c_double
    rec = np.empty((N + 1, len(outs)))
    get_real(c, out_vr, n_out, out_buf)
    rec[0] = out_np
    t0 = time.perf_counter()
    for k in range(N):
        t = k * H
        in_buf[0] = -0.5 if t < 2.0 else 0.5
        set_real(c, in_vr, one, in_buf)
        do_step(c, D(t), D(H), 1)
        get_real(c, out_vr, n_out, out_buf)
        rec[k + 1] = out_np
    wall = time.perf_counter() - t0
    fmu.terminate()
    fmu.freeInstance()
    return wall


def master(path) -> float:
    plant = FMUComponent("plant", path, H, parameters={"step_size": H})
    cs = Cosimulation([plant, Step("force", 0.01, 2.0, -0.5, 0.5)], {"plant.F": "force.out"})
    cs.run(T_END, progress=False)
    return cs.timings["loop"]


def long_run(path, steps: int) -> str:
    """Peak RSS [MiB] of a fresh process streaming ``steps`` base steps to Parquet."""
    code = f"""
import resource, tempfile, sys
from cosim.fmi.fmu_component import FMUComponent
from cosim.core.master import Cosimulation
from cosim.components.sources import Constant, Step
plant = FMUComponent("plant", {str(path)!r}, {H}, parameters={{"step_size": {H}}})
cs = Cosimulation([plant, Step("force", 0.01, 2.0, -0.5, 0.5)], {{"plant.F": "force.out"}})
with tempfile.TemporaryDirectory() as d:
    cs.run_to_parquet(d + "/r.parquet", {steps * H}, progress=False)
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, cs.timings["loop"])
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    rss, loop = map(float, out.split())
    return f"{steps:>9d} steps streamed: peak RSS {rss:6.1f} MiB, loop {loop:6.2f} s ({loop / steps * 1e6:.2f} us/step)"


def setup_time(n: int) -> tuple[float, float]:
    """Wall times [s] to prepare ``n`` independent constant sources: the constructor
    (checks, layout, evaluation order) and the run's own setup (binding, schedule)."""
    comps = [Constant(f"c{i}", 0.01, 1.0) for i in range(n)]
    t0 = time.perf_counter()
    cs = Cosimulation(comps, {})
    built = time.perf_counter() - t0
    cs.run(0.01, progress=False)
    return built, cs.timings["setup"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--long", action="store_true", help="also the 1e6-step streamed run (about 1 min)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as out:
        path = str(build_fmu(get_model("cartpole"), out))
        master(path)                                     # warm-up
        f = np.median([fmpy_loop(path) for _ in range(REPEATS)])
        r = np.median([raw_loop(path) for _ in range(REPEATS)])
        m = np.median([master(path) for _ in range(REPEATS)])
        print(f"cart-pole FMU (FMI 2.0 CS), {N} steps of {H * 1e3:g} ms, 6 outputs recorded per step; "
              f"medians of {REPEATS}")
        print(f"  fmpy FMU2Slave loop    {f * 1e3:7.2f} ms  {f / N * 1e6:5.2f} us/step")
        print(f"  raw ctypes loop        {r * 1e3:7.2f} ms  {r / N * 1e6:5.2f} us/step")
        print(f"  master (plant + source){m * 1e3:7.2f} ms  {m / N * 1e6:5.2f} us/step")
        print(f"  master own cost over the raw loop: {(m - r) / N * 1e6:+.2f} us per base step; "
              f"master / fmpy loop = {m / f:.2f}")
        print("setup of n independent constant sources (constructor + run setup):")
        for count in (1_000, 10_000, 100_000):
            built, bound = setup_time(count)
            print(f"  n = {count:>7d}: {built + bound:7.3f} s  (constructor {built:.3f} s, run setup {bound:.3f} s)")
        if args.long:
            fmu = Path(out, "keep.fmu")
            fmu.write_bytes(Path(path).read_bytes())
            print(long_run(fmu, 100_000))
            print(long_run(fmu, 1_000_000))


if __name__ == "__main__":
    main()

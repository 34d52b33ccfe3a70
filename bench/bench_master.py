"""Benchmark: the master's own cost per base step, against what a user would write instead.

Run: python bench/bench_master.py [--long] [--write-docs]

Same FMU (the cart-pole plant, FMI 2.0 Co-Simulation, 1 ms steps, 5 s = 5000 steps), same
work per step (set the force, doStep, read the 6 outputs into a record, the EKF's step),
four ways, for the plant alone, the plant with a force source, the plant with a source
and an EKF, and a chain of 10 plant FMUs:

* fmpy's ``FMU2Slave`` loop: ``setReal``, ``doStep``, ``getReal`` and a row copy;
* a raw ctypes loop: the FMU's functions called with prebuilt ctypes arguments (the
  cheapest a Python loop can be), rows copied into a preallocated array;
* the master's Python loop (``engine="python"``) and its native kernel
  (``engine="native"``): every signal recorded.

Also the EKF's compiled step alone (a native run of the filter over 5000 steps) and the
setup of 1e3, 1e4 and 1e5 independent constant sources. Medians of 7 repeats, all in this
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

import estimators
from cosim.components.estimation import EstimatorComponent
from cosim.components.sources import Constant, Step
from cosim.core.master import Cosimulation
from cosim.fmi.fmu_component import FMUComponent
from fmu_models import build_fmu, get_model

sys.path.append(str(Path(__file__).parent))          # bench/doc_tables.py, from any folder
import doc_tables

T_END, H, REPEATS = 5.0, 0.001, 7
N = round(T_END / H)
OUTS = ("x", "x_dot", "theta", "theta_dot", "y_x", "y_theta")
#: the cases: (FMUs, force source, EKF)
CASES = {"plant alone": (1, False, False), "plant + source": (1, True, False),
         "plant + source + EKF": (1, True, True), "10-FMU chain": (10, True, False)}


def _instance(path, name="bare"):
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path),
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.setReal([vr["step_size"]], [H])
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    return fmu, vr, [vr[n] for n in OUTS]


def _ekf():
    system = estimators.discretize(get_model("cartpole"), H)
    return estimators.EKF(system, [0.0, 0.0, 0.1, 0.0], 1.0, 0.2, 0.1)


def _force(t: float) -> float:
    return -0.5 if t < 2.0 - 1e-12 else 0.5


def fmpy_loop(path, case) -> float:
    """What a user would write with fmpy alone: set the force (the source's value, or the
    previous FMU's ``x`` in the chain), doStep, getReal, a row copy (and the EKF's step)."""
    n_fmu, source, with_ekf = CASES[case]
    fmus = [_instance(path, f"bare{i}") for i in range(n_fmu)]
    ekf = _ekf() if with_ekf else None
    vf = [fmu[1]["F"] for fmu in fmus]
    rec = np.empty((N + 1, 6 * n_fmu))
    for i, (fmu, _, outs) in enumerate(fmus):
        rec[0, 6 * i:6 * i + 6] = fmu.getReal(outs)
    t0 = time.perf_counter()
    for k in range(N):
        t = k * H
        for i, (fmu, _, outs) in enumerate(fmus):
            if source:
                fmu.setReal([vf[i]], [_force(t) if i == 0 else rec[k, 6 * i - 6]])
            fmu.doStep(t, H)
            rec[k + 1, 6 * i:6 * i + 6] = fmu.getReal(outs)
        if ekf is not None:
            ekf.step([_force(t)], rec[k + 1, 4:6])
    wall = time.perf_counter() - t0
    for fmu, _, _ in fmus:
        fmu.terminate()
        fmu.freeInstance()
    return wall


def raw_loop(path, case) -> float:
    """The same calls through raw ctypes pointers with prebuilt arguments."""
    n_fmu, source, with_ekf = CASES[case]
    ekf = _ekf() if with_ekf else None
    fmus, calls = [], []
    for i in range(n_fmu):
        fmu, vr, outs = _instance(path, f"bare{i}")
        dll, c = fmu.dll, ctypes.c_void_p(fmu.component)

        def fn(name, dll=dll):
            f = getattr(dll, name)
            f = type(f).from_address(ctypes.addressof(f))
            f.restype, f.argtypes = ctypes.c_int, None
            return f

        in_vr, out_vr = (ctypes.c_uint32 * 1)(vr["F"]), (ctypes.c_uint32 * len(outs))(*outs)
        in_buf, out_buf = (ctypes.c_double * 1)(), (ctypes.c_double * len(outs))()
        fmus.append(fmu)
        calls.append((fn("fmi2SetReal"), fn("fmi2DoStep"), fn("fmi2GetReal"), c, in_vr, in_buf, out_vr, out_buf,
                      np.ctypeslib.as_array(out_buf)))
    one, n_out, D = ctypes.c_size_t(1), ctypes.c_size_t(6), ctypes.c_double
    rec = np.empty((N + 1, 6 * n_fmu))
    for i, (_, _, get_real, c, _, _, out_vr, out_buf, out_np) in enumerate(calls):
        get_real(c, out_vr, n_out, out_buf)
        rec[0, 6 * i:6 * i + 6] = out_np
    t0 = time.perf_counter()
    for k in range(N):
        t = k * H
        for i, (set_real, do_step, get_real, c, in_vr, in_buf, out_vr, out_buf, out_np) in enumerate(calls):
            if source:
                in_buf[0] = _force(t) if i == 0 else rec[k, 6 * i - 6]
                set_real(c, in_vr, one, in_buf)
            do_step(c, D(t), D(H), 1)
            get_real(c, out_vr, n_out, out_buf)
            rec[k + 1, 6 * i:6 * i + 6] = out_np
        if ekf is not None:
            ekf.step([_force(t)], rec[k + 1, 4:6])
    wall = time.perf_counter() - t0
    for fmu in fmus:
        fmu.terminate()
        fmu.freeInstance()
    return wall


def master(path, case="plant + source", engine="auto") -> float:
    """The master's loop time [s]: plant FMU(s), a force source held at 10 ms, the EKF
    component, every signal recorded."""
    n_fmu, source, with_ekf = CASES[case]
    plants = [FMUComponent(f"p{i}", path, H, parameters={"step_size": H}) for i in range(n_fmu)]
    comps, conn = list(plants), {f"p{i}.F": f"p{i - 1}.x" for i in range(1, n_fmu)}
    if source:
        comps.append(Step("force", 0.01, 2.0, -0.5, 0.5))
        conn["p0.F"] = "force.out"
    if with_ekf:
        comps.append(EstimatorComponent("ekf", _ekf, H))
        conn.update({"ekf.F": "force.out", "ekf.y_x": "p0.y_x", "ekf.y_theta": "p0.y_theta"})
    cs = Cosimulation(comps, conn, engine=engine)
    cs.run(T_END, progress=False)
    return cs.timings["loop"]


def filter_step() -> float:
    """The EKF's compiled step [s per step]: a native run over N steps (no Python per step)."""
    ekf = _ekf()
    rng = np.random.default_rng(0)
    us, ys = np.zeros((N, 1)), rng.normal(size=(N, 2)) * 0.1
    t0 = time.perf_counter()
    ekf.run(us, ys, keep="estimates")
    return (time.perf_counter() - t0) / N


def setup_time(n: int) -> tuple[float, float]:
    """Wall times [s] to prepare ``n`` independent constant sources: the constructor
    (checks, layout, evaluation order) and the run's own setup (binding, schedule)."""
    comps = [Constant(f"c{i}", 0.01, 1.0) for i in range(n)]
    t0 = time.perf_counter()
    cs = Cosimulation(comps, {})
    built = time.perf_counter() - t0
    cs.run(0.01, progress=False)
    return built, cs.timings["setup"]


def long_run(path, steps: int) -> tuple[float, float]:
    """Peak RSS [MiB] of a fresh process streaming ``steps`` base steps to Parquet, and its loop time [s]."""
    code = f"""
import resource, tempfile, sys
from cosim.fmi.fmu_component import FMUComponent
from cosim.core.master import Cosimulation
import estimators
from cosim.components.estimation import EstimatorComponent
from cosim.components.sources import Constant, Step
plant = FMUComponent("plant", {str(path)!r}, {H}, parameters={{"step_size": {H}}})
cs = Cosimulation([plant, Step("force", 0.01, 2.0, -0.5, 0.5)], {{"plant.F": "force.out"}})
with tempfile.TemporaryDirectory() as d:
    cs.run_to_parquet(d + "/r.parquet", {steps * H}, progress=False)
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, cs.timings["loop"])
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    rss, loop = map(float, out.split())
    print(f"{steps:>9d} steps streamed: peak RSS {rss:6.1f} MiB, loop {loop:6.2f} s ({loop / steps * 1e6:.2f} us/step)")
    return rss, loop


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--long", action="store_true", help="also the 1e6-step streamed run (about 1 min)")
    doc_tables.add_option(parser)
    args = parser.parse_args()
    figures = {}
    with tempfile.TemporaryDirectory() as out:
        path = str(build_fmu(get_model("cartpole"), out))
        master(path, engine="native")                    # warm-up (compiles the kernel once)
        us = {}
        print(f"cart-pole FMU (FMI 2.0 CS), {N} steps of {H * 1e3:g} ms, every output recorded per step; "
              f"medians of {REPEATS} [us per base step]")
        print(f"  {'case':22s} {'fmpy loop':>10s} {'raw ctypes':>10s} {'master py':>10s} {'native':>10s}")
        for case in CASES:
            row = [np.median([fn(*a) for _ in range(REPEATS)]) / N * 1e6 for fn, a in (
                (fmpy_loop, (path, case)), (raw_loop, (path, case)), (master, (path, case, "python")),
                (master, (path, case, "native")))]
            us[case] = row
            print(f"  {case:22s} " + " ".join(f"{x:10.3f}" for x in row))
        step = np.median([filter_step() for _ in range(REPEATS)]) * 1e6
        print(f"  EKF compiled step (native run): {step:.3f} us")
        ps, pse = us["plant + source"], us["plant + source + EKF"]
        print(f"goal: native plant + source / raw ctypes loop = {ps[3] / ps[1]:.3f} (at most 0.3)")
        print(f"goal: native plant + source + EKF = {pse[3]:.3f} us, at most native plant + source + 1.5 x "
              f"EKF step = {ps[3] + 1.5 * step:.3f} us")
        print(f"per FMU: native 10-FMU chain {us['10-FMU chain'][3] / 10:.3f} us, plant alone "
              f"{us['plant alone'][3]:.3f} us (python master: {us['10-FMU chain'][2] / 10:.3f} and "
              f"{us['plant alone'][2]:.3f} us)")
        print("setup of n independent constant sources (constructor + run setup):")
        figures.update(us_per_step=us, ekf_step_us=step, setup_s={})
        for count in (1_000, 10_000, 100_000):
            built, bound = setup_time(count)
            figures["setup_s"][str(count)] = built + bound
            print(f"  n = {count:>7d}: {built + bound:7.3f} s  (constructor {built:.3f} s, run setup {bound:.3f} s)")
        if args.long:
            fmu = Path(out, "keep.fmu")
            fmu.write_bytes(Path(path).read_bytes())
            figures["streamed_rss_mib"] = {str(n): long_run(fmu, n)[0] for n in (100_000, 1_000_000)}
    if args.write_docs:
        doc_tables.write_docs(__file__, figures)


def _us(x: float) -> str:
    return f"{x:.1f}" if x >= 10 else f"{x:.2f}" if x >= 1 else f"{x:.3f}"


def _count(n: str) -> str:
    return f"{int(n):,}".replace(",", " ")


def master_table(saved) -> str:
    """The performance page's tables: µs per base step, four ways; what the kernel adds; the setup."""
    f = saved["bench_master"]["figures"]
    us = f["us_per_step"]
    ps, pse, chain, alone = us["plant + source"], us["plant + source + EKF"], us["10-FMU chain"], us["plant alone"]
    parts = [
        doc_tables.table(["", "fmpy `FMU2Slave` loop", "raw ctypes loop", "master, Python loop",
                          "master, native kernel"], [[case, *map(_us, us[case])] for case in CASES]),
        doc_tables.table(["derived from the table", ""], [
            ["native kernel over the raw ctypes loop, plant + source", f"{ps[3] / ps[1]:.2g}x"],
            ["what the EKF component adds in the native kernel, per step",
             f"{pse[3] - ps[3]:.3f} µs (its compiled step alone, in a native `run`: {f['ekf_step_us']:.3f} µs)"],
            ["10-FMU chain per FMU, native kernel / Python loop",
             f"{chain[3] / 10:.3f} / {chain[2] / 10:.2f} µs (the plant alone: {alone[3]:.3f} / {alone[2]:.2f} µs)"]]),
        doc_tables.table(["setup (constructor and run) of independent constant sources",
                          *map(_count, f["setup_s"])],
                         [["seconds", *(f"{s:.2g}" for s in f["setup_s"].values())]])]
    if "streamed_rss_mib" in f:
        rss = f["streamed_rss_mib"]
        parts.append(doc_tables.table(["`--long`: plant + source streamed to Parquet",
                                       *(f"{_count(n)} steps" for n in rss)],
                                      [["peak RSS", *(f"{v:.1f} MiB" for v in rss.values())]]))
    return doc_tables.with_provenance(saved, "bench_master", *parts)


TABLES = {"master": master_table}


if __name__ == "__main__":
    main()

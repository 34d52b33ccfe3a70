"""Benchmark: microseconds per filter step on the cart-pole, against filterpy.

Run: python bench/bench_estimators.py [--write-docs]
Every filter runs the same data (seed 000 scenario-like truth); each figure is the
fastest of 7 repeats of 5000 steps (this shared machine's speed varies by up to 50 %
between runs; the fastest repeat is the least disturbed), each filter warmed up first.
``step`` is timed with the inputs as Python lists (``[0.5]``, ``[0.52, 1.79]``), as
rows of numpy arrays, and with the one-element ``u`` as a bare number (a float, and a
numpy float64: ``U[k]`` of a 1-D ``U``). filterpy's EKF and UKF get the exact Jacobians/model from the same
CasADi model (numpy calls), so the comparison is of the filter machinery.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter

from estimators import EKF, IAE, KF, MFIAE, UKF, BatchFilter, discretize
from fmu_models import get_model

sys.path.append(str(Path(__file__).parent))          # bench/doc_tables.py, from any folder
import doc_tables

N, REPEATS = 5000, 7


def data(sys_, n=N, seed=0):
    rng = np.random.default_rng(seed)
    us = np.where(np.arange(n) * 0.01 % 4 < 2, -0.5, 0.5)[:, None]
    x, ys = np.array([0.5, 0, 1.8, 0.5]), []
    for k in range(n):
        x = sys_.f(x, us[k]) + rng.normal(0, 1e-3, 4)
        ys.append(sys_.h(x) + rng.normal(0, 0.05, 2))
    return us, np.array(ys)


def per_step(fn, n):
    times = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) / n * 1e6)
    return float(np.min(times))          # the least disturbed repeat: this VM's speed varies


def main():
    options = doc_tables.parse_options(__doc__)
    sys_ = discretize(get_model("cartpole"), 0.01)
    us, ys = data(sys_)
    x0, P0, Q, R = np.array([0.5, 0, 1.8, 0.5]), np.eye(4), 1e-6 * np.eye(4), 2.5e-3 * np.eye(2)
    results = {}
    ul, yl = us.tolist(), ys.tolist()
    u_float, u_np = us[:, 0].tolist(), us[:, 0]         # a float and a numpy float64 per step
    for name, make in [("KF", lambda: KF(sys_, x0, P0, Q, R)), ("EKF", lambda: EKF(sys_, x0, P0, Q, R)),
                       ("UKF", lambda: UKF(sys_, x0, P0, Q, R)),
                       ("IAE", lambda: IAE(sys_, x0, P0, Q, R)),
                       ("MF-IAE", lambda: MFIAE(sys_, x0, P0, 1e-6, 2.5e-3))]:
        inputs = [("lists", ul, yl), ("arrays", us, ys)]
        if name == "EKF":
            inputs += [("float u", u_float, yl), ("numpy scalar u", u_np, yl)]
        for label, u_in, y_in in inputs:
            f = make()

            def run(f=f, u_in=u_in, y_in=y_in):
                f.reset(x0, P0)
                step = f.step
                for k in range(N):
                    step(u_in[k], y_in[k])
            run()                                   # warm up
            results[f"{name} ({label})"] = per_step(run, N)

    fp = ExtendedKalmanFilter(4, 2)

    def run_fp_ekf():
        fp.x, fp.P, fp.Q, fp.R = x0.reshape(-1, 1).copy(), P0.copy(), Q, R
        for k in range(N):
            xv = fp.x.ravel()
            fp.F = sys_.F(xv, us[k])
            fp.x = sys_.f(xv, us[k]).reshape(-1, 1)
            fp.P = fp.F @ fp.P @ fp.F.T + fp.Q
            fp.update(ys[k].reshape(-1, 1), lambda x: sys_.H(x.ravel()),
                      lambda x: sys_.h(x.ravel()).reshape(-1, 1))
    results["filterpy EKF (model via CasADi numpy calls)"] = per_step(run_fp_ekf, N)

    # conservative baseline: filterpy's algebra alone, model values precomputed along
    # our EKF's trajectory (f, F, h, H cost nothing here)
    ours = EKF(sys_, x0, P0, Q, R)
    table = []
    for k in range(N):
        xk = ours.x
        table.append((sys_.F(xk, us[k]), sys_.f(xk, us[k]).reshape(-1, 1)))
        ours.predict(us[k])
        xp = ours.x
        table[-1] += (sys_.H(xp), sys_.h(xp).reshape(-1, 1))
        ours.update(ys[k])
    zs = [y.reshape(-1, 1) for y in ys]

    def run_fp_algebra():
        fp.x, fp.P, fp.Q, fp.R = x0.reshape(-1, 1).copy(), P0.copy(), Q, R
        for k in range(N):
            F, fx, H, hx = table[k]
            fp.F = F
            fp.x = fx
            fp.P = F @ fp.P @ F.T + fp.Q
            fp.update(zs[k], lambda x, H=H: H, lambda x, hx=hx: hx)
    results["filterpy EKF (algebra only, model precomputed)"] = per_step(run_fp_algebra, N)

    pts = MerweScaledSigmaPoints(4, alpha=0.5, beta=2.0, kappa=0.0)
    fu = UnscentedKalmanFilter(4, 2, 0.01, hx=sys_.h, fx=lambda x, dt, u: sys_.f(x, u), points=pts)

    def run_fp_ukf():
        fu.x, fu.P, fu.Q, fu.R = x0.copy(), P0.copy(), Q, R
        for k in range(N):
            fu.predict(u=us[k])
            fu.update(ys[k])
    results["filterpy UKF"] = per_step(run_fp_ukf, N)

    runs = 100
    for name, cls, args in (("EKF", EKF, (Q, R)), ("UKF", UKF, (Q, R)),
                            ("MF-IAE", MFIAE, (1e-6, 2.5e-3))):
        b = BatchFilter(cls(sys_, x0, P0, *args), runs)
        Y = np.repeat(ys[:, None, :], runs, axis=1)

        def run_batch(b=b, Y=Y):
            for k in range(N // 10):
                b.step(us[k], Y[k])
        results[f"batched {name} ({runs} runs), per realisation-step"] = per_step(run_batch, N // 10) / runs

    width = max(map(len, results))
    for name, us_step in results.items():
        print(f"{name:<{width}}  {us_step:8.2f} us")
    ekf, ukf = results["EKF (lists)"], results["UKF (lists)"]
    print(f"EKF speed-up over filterpy's EKF algebra alone: "
          f"{results['filterpy EKF (algebra only, model precomputed)'] / ekf:.0f}x, "
          f"with the model calls: {results['filterpy EKF (model via CasADi numpy calls)'] / ekf:.0f}x; "
          f"UKF over filterpy's UKF: {results['filterpy UKF'] / ukf:.0f}x; "
          f"UKF/EKF {ukf / ekf:.2f}, MF-IAE/EKF {results['MF-IAE (lists)'] / ekf:.2f}")
    print(f"EKF step with a scalar u against lists: float {results['EKF (float u)'] / ekf:.2f}x, "
          f"numpy float64 {results['EKF (numpy scalar u)'] / ekf:.2f}x")
    if options.write_docs:
        doc_tables.write_docs(__file__, results)


def steps_table(saved) -> str:
    """The performance page's table: µs per step from Python, ours against filterpy's."""
    r = saved["bench_estimators"]["figures"]
    ekf, ukf = r["EKF (lists)"], r["UKF (lists)"]

    def row(names, kind):
        return " / ".join(f"{r[f'{n} ({kind})']:.2f}" for n in names)
    fp_model = r["filterpy EKF (model via CasADi numpy calls)"]
    fp_algebra = r["filterpy EKF (algebra only, model precomputed)"]
    batched = " / ".join(f"{r[f'batched {n} (100 runs), per realisation-step']:.2f}" for n in ("EKF", "UKF", "MF-IAE"))
    return doc_tables.with_provenance(saved, "bench_estimators", doc_tables.table(
        ["filter", "µs/step, inputs as lists", "as numpy rows"], [
            ["KF / EKF / UKF", row(("KF", "EKF", "UKF"), "lists"), row(("KF", "EKF", "UKF"), "arrays")],
            ["IAE / MF-IAE (adaptation and fuzzy inference compiled in the step)", row(("IAE", "MF-IAE"), "lists"),
             row(("IAE", "MF-IAE"), "arrays")],
            ["EKF, the one-element `u` as a float / a numpy scalar",
             f"{r['EKF (float u)']:.2f} / {r['EKF (numpy scalar u)']:.2f}", ""],
            ["filterpy EKF, model by CasADi numpy calls", f"{fp_model:.1f} ({fp_model / ekf:.0f}x our EKF)", ""],
            ["filterpy EKF, its algebra alone (model values precomputed)",
             f"{fp_algebra:.1f} ({fp_algebra / ekf:.0f}x our EKF)", ""],
            ["filterpy UKF", f"{r['filterpy UKF']:.0f} ({r['filterpy UKF'] / ukf:.0f}x our UKF)", ""],
            ["batched EKF / UKF / MF-IAE, 100 realisations, per realisation-step", batched, ""]]))


TABLES = {"steps": steps_table}


if __name__ == "__main__":
    main()

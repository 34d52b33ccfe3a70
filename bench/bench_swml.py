"""Benchmark: the cost of SWML against the EKF it starts as (issue 21 goal: SWML ``run`` at
most 25x the EKF ``run`` per step), cart-pole, 5 s records (500 steps, the seed 000
length) and 5000 steps, the fastest of 7 repeats; and the burst of one update.

Run: python bench/bench_swml.py
"""
from __future__ import annotations

import math
import time
from functools import partial

import numpy as np

from estimators import EKF, SWML, BatchFilter, discretize
from fmu_models import get_model


def record(cp, n, seed=0):
    rng = np.random.default_rng(seed)
    x, us, ys = np.array([0.5, 0.0, 1.8, 0.5]), [], []
    for k in range(n):
        u = [0.5 if (k // 100) % 2 else -0.5]
        x = cp.f(x, u) + rng.normal(0, math.sqrt(0.2), 4)
        us.append(u)
        ys.append(cp.h(x) + rng.normal(0, math.sqrt(0.1), 2))
    return np.array(us), np.array(ys)


def best(fn, repeats=7):
    """The fastest of ``repeats`` calls of ``fn`` [s]."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def rerun(f, x0, us, ys) -> None:
    """``f.run`` from the start again (same initial state and noise)."""
    f.reset(x0, 1.0)
    f.set_noise(1e-3, 10.0)
    f.run(us, ys)


def one_length(cp, x0, n: int) -> str:
    """The table row for records of ``n`` steps."""
    us, ys = record(cp, n)
    ekf, swml = EKF(cp, x0, 1.0, 1e-3, 10.0), SWML(cp, x0, 1.0, 1e-3, 10.0)
    ekf.run(us, ys), swml.run(us, ys)                         # compile and warm
    te, ts = best(partial(rerun, ekf, x0, us, ys)), best(partial(rerun, swml, x0, us, ys))
    Y = np.repeat(ys[None], 100, axis=0)
    be, bs = (best(partial(BatchFilter(f, 100).run, us, Y), 3)
              for f in (EKF(cp, x0, 1.0, 1e-3, 10.0), SWML(cp, x0, 1.0, 1e-3, 10.0)))
    return (f"| {n} steps | {te / n * 1e6:.2f} | {ts / n * 1e6:.2f} | {ts / te:.1f}x | "
            f"{be / n / 100 * 1e6:.2f} / {bs / n / 100 * 1e6:.2f} |")


def campaign_form(cp, x0) -> None:
    """SWML as the campaigns run it (MAP with the posterior average, an update every step up
    to step 20) against the plain form and the EKF, ``run`` over 500 steps."""
    us, ys = record(cp, 500)
    forms = {"EKF": EKF(cp, x0, 1.0, 1e-3, 10.0), "SWML (ML)": SWML(cp, x0, 1.0, 1e-3, 10.0),
             "SWML (MAP, posterior-averaged)": SWML(cp, x0, 1.0, 1e-3, 10.0, prior_sd=math.log(100.0),
                                                    posterior_average=True, early_every=1, keep_r_nats=0.0,
                                                    max_fall=10.0)}
    cost = {}
    for name, f in forms.items():
        f.run(us, ys)                                                   # compile and warm
        cost[name] = best(partial(rerun, f, x0, us, ys)) / 500 * 1e6
    print("\n500 steps, run [us/step]: " + ", ".join(f"{n} {c:.2f} ({c / cost['EKF']:.1f}x the EKF)"
                                                    for n, c in cost.items()))


def main() -> None:
    cp = discretize(get_model("cartpole"), 0.01)
    x0 = [0.5, 0.0, 1.8, 0.5]
    print("| record | EKF run [us/step] | SWML run [us/step] | ratio | "
          "batched x100, per realisation-step: EKF / SWML |")
    print("|---|---|---|---|---|")
    for n in (500, 5000):
        print(one_length(cp, x0, n))
    campaign_form(cp, x0)
    us, ys = record(cp, 200)
    g = SWML(cp, x0, 1.0, 1e-3, 10.0)
    times = []
    for k in range(200):
        t0 = time.perf_counter()
        g.step(us[k], ys[k])
        times.append(time.perf_counter() - t0)
    t = np.array(times[1:]) * 1e6
    upd = [k for k in range(1, 200) if (k + 1) % 50 == 0 and k + 1 > 20]
    rest = [k for k in range(21, 199) if k not in upd]
    print(f"\nSWML step from Python: {np.median(t[np.array(rest) - 1]):.1f} us between updates, "
          f"{np.median(t[np.array(upd) - 1]):.0f} us at an update (window 100, every 50 steps)")


if __name__ == "__main__":
    main()

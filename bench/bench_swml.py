"""Benchmark: the cost of SWML against the EKF it starts as, cart-pole, 5 s records (500
steps, the seed 000 length) and 5000 steps, the fastest of 7 repeats; the campaigns' form;
and the burst of one update.

Run: python bench/bench_swml.py [--write-docs]
"""
from __future__ import annotations

import math
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np

from estimators import EKF, SWML, BatchFilter, discretize
from fmu_models import get_model

sys.path.append(str(Path(__file__).parent))          # bench/doc_tables.py, from any folder
import doc_tables


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


def one_length(cp, x0, n: int) -> dict[str, float]:
    """µs per step for records of ``n`` steps: the EKF's and SWML's ``run``, and batched x100
    per realisation-step."""
    us, ys = record(cp, n)
    ekf, swml = EKF(cp, x0, 1.0, 1e-3, 10.0), SWML(cp, x0, 1.0, 1e-3, 10.0)
    ekf.run(us, ys), swml.run(us, ys)                         # compile and warm
    te, ts = best(partial(rerun, ekf, x0, us, ys)), best(partial(rerun, swml, x0, us, ys))
    Y = np.repeat(ys[None], 100, axis=0)
    be, bs = (best(partial(BatchFilter(f, 100).run, us, Y), 3)
              for f in (EKF(cp, x0, 1.0, 1e-3, 10.0), SWML(cp, x0, 1.0, 1e-3, 10.0)))
    return {"ekf": te / n * 1e6, "swml": ts / n * 1e6, "ekf_batched": be / n / 100 * 1e6,
            "swml_batched": bs / n / 100 * 1e6}


def _row(n: int, r: dict[str, float]) -> list[str]:
    return [f"{n} steps{' (seed 000)' if n == 500 else ''}", f"{r['ekf']:.2f} µs", f"{r['swml']:.2f} µs",
            f"{r['swml'] / r['ekf']:.1f}x", f"{r['ekf_batched']:.2f} / {r['swml_batched']:.2f} µs"]


def campaign_form(cp, x0) -> dict[str, float]:
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
    return cost


def main() -> None:
    args = doc_tables.parse_options(__doc__)
    cp = discretize(get_model("cartpole"), 0.01)
    x0 = [0.5, 0.0, 1.8, 0.5]
    lengths = {}
    for n in (500, 5000):
        lengths[str(n)] = one_length(cp, x0, n)
        print(" | ".join(_row(n, lengths[str(n)])))
    forms = campaign_form(cp, x0)
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
    between, update = float(np.median(t[np.array(rest) - 1])), float(np.median(t[np.array(upd) - 1]))
    print(f"\nSWML step from Python: {between:.1f} us between updates, {update:.0f} us at an update (window 100, "
          "every 50 steps)")
    if args.write_docs:
        doc_tables.write_docs(__file__, {"lengths": lengths, "forms_500": forms, "step_between": between,
                                         "step_update": update})


HEAD = ["record", "EKF `run`", "SWML `run`", "ratio", "batched x100, per realisation-step: EKF / SWML"]


def swml_table(saved) -> str:
    """The performance page's tables: SWML's `run` against the EKF's, its campaign form, its step."""
    f = saved["bench_swml"]["figures"]
    forms = f["forms_500"]
    return doc_tables.with_provenance(
        saved, "bench_swml", doc_tables.table(HEAD, [_row(int(n), r) for n, r in f["lengths"].items()]),
        doc_tables.table(["500 steps, `run`", "µs/step", "against the EKF"],
                         [[name, f"{c:.2f}", f"{c / forms['EKF']:.1f}x"]
                          for name, c in sorted(forms.items(), key=lambda item: item[1])]),
        doc_tables.table(["SWML `step` from Python (window 100, an update every 50 steps)", "µs"],
                         [["between updates", f"{f['step_between']:.1f}"],
                          ["at an update", f"{f['step_update']:.0f}"]]))


TABLES = {"swml": swml_table}


if __name__ == "__main__":
    main()

"""Benchmark: offline estimation, per step, against what a user would write otherwise.

Run: python bench/bench_offline.py [--write-docs]

Same data and model in one run (medians of 5 repeats):

* cart-pole EKF: ``run`` (one native call for the record; keeping every diagnostic, or
  the estimates only) against ``step`` called N times;
  the RTS smoother on the stored pass; UKF and MF-IAE ``run`` for scale;
* a linear model (the cart-pole linearised at the hanging position, 4 states, 2 outputs):
  our KF ``run`` + RTS against pykalman's ``filter``/``smooth`` and filterpy's
  ``batch_filter`` + ``rts_smoother``; one EM iteration (learning Q and R) against
  pykalman's ``em`` iteration.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from estimators import EKF, KF, MFIAE, UKF, discretize, em_noise, rts_smooth
from fmu_models import get_model

sys.path.append(str(Path(__file__).parent))          # bench/doc_tables.py, from any folder
import doc_tables

REPEATS = 5
KEEP = "EKF run, keep='estimates' (x, P only)"


def median_time(fn, repeats=REPEATS) -> float:
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return float(np.median(out))


def cartpole_record(cp, N, x0, model=None, q=1e-3, r=1e-3, seed=1):
    model = model or cp
    rng = np.random.default_rng(seed)
    t = np.arange(N) * 0.01
    us = (0.5 * np.sin(0.7 * t) + 0.3 * np.sign(np.sin(2.3 * t)))[:, None]
    x, ys = np.array(x0, float), np.empty((N, 2))
    for k in range(N):
        x = model.f(x, us[k]) + rng.normal(0, np.sqrt(q), 4)
        ys[k] = model.h(x) + rng.normal(0, np.sqrt(r), 2)
    return us, ys


def main() -> None:
    args = doc_tables.parse_options(__doc__)
    cp = discretize(get_model("cartpole"), 0.01)
    x0 = np.array([0.0, 0.0, np.pi, 0.0])
    N = 100_000
    us, ys = cartpole_record(cp, N, x0)
    rows = []

    def per_step(label, seconds, n=N):
        rows.append((label, seconds / n * 1e6))

    ekf = EKF(cp, x0, 1e-2, 1e-3, 1e-3)
    ekf.run(us[:10], ys[:10])
    per_step("EKF run (one native call)", median_time(lambda: (ekf.reset(x0, 1e-2 * np.eye(4)), ekf.run(us, ys))))
    per_step(KEEP,
             median_time(lambda: (ekf.reset(x0, 1e-2 * np.eye(4)), ekf.run(us, ys, keep="estimates"))))

    def steps():
        ekf.reset(x0, 1e-2 * np.eye(4))
        for k in range(20_000):
            ekf.step(us[k], ys[k])
    per_step("EKF step() x N from Python", median_time(steps), 20_000)
    ekf.reset(x0, 1e-2 * np.eye(4))
    run = ekf.run(us, ys)
    rts_smooth(ekf, run)
    per_step("extended RTS smoother", median_time(lambda: rts_smooth(ekf, run)))
    for name, f in (("UKF run", UKF(cp, x0, 1e-2, 1e-3, 1e-3)), ("MF-IAE run", MFIAE(cp, x0, 1e-2, 1e-3, 1e-3))):
        f.run(us[:10], ys[:10])
        per_step(name, median_time(lambda f=f: (f.reset(x0, 1e-2 * np.eye(4)), f.run(us, ys))))

    # ------------------------------------------------------------------ linear model, three libraries
    lin = cp.linearized(x0, [0.0])
    Nl = 5_000
    us_l, ys_l = cartpole_record(cp, Nl, x0, model=lin)
    F, G, H = lin.F(x0, [0.0]), lin.G(x0, [0.0]), lin.H(x0)
    c = lin.f(np.zeros(4), [0.0])                      # affine offset of the linearised map
    Q0, R0, P0 = 1e-3 * np.eye(4), 1e-3 * np.eye(2), 1e-2 * np.eye(4)
    kf = KF(cp, x0, P0, Q0, R0, x_op=x0, u_op=[0.0])

    def ours_filter_smooth():
        kf.reset(x0, P0)
        rts_smooth(kf, kf.run(us_l, ys_l))
    ours_filter_smooth()
    t_ours = median_time(ours_filter_smooth)
    per_step(f"ours: KF run + RTS ({Nl} steps)", t_ours, Nl)
    offsets = (G @ us_l.T).T + c                       # B u_k + c, per step
    try:
        from pykalman import KalmanFilter

        pk = KalmanFilter(transition_matrices=F, observation_matrices=H, transition_covariance=Q0,
                          observation_covariance=R0, transition_offsets=offsets[1:],
                          initial_state_mean=x0, initial_state_covariance=P0)
        # pykalman's first observation is of the initial state: give it the state after step 0
        t_pk = median_time(lambda: pk.smooth(ys_l), 3)
        per_step("pykalman filter + smooth", t_pk, Nl)
    except ImportError:
        t_pk = np.nan
    try:
        from filterpy.kalman import KalmanFilter as FKF
        from filterpy.kalman import rts_smoother

        def filterpy_fs():
            fk = FKF(4, 2)
            fk.F, fk.H, fk.Q, fk.R, fk.x, fk.P = F, H, Q0, R0, x0.copy(), P0.copy()
            fk.B = G
            mu, cov, _, _ = fk.batch_filter(ys_l, us=us_l)
            rts_smoother(mu, cov, [F] * Nl, [Q0] * Nl)
        t_fp = median_time(filterpy_fs, 3)
        per_step("filterpy batch_filter + rts_smoother", t_fp, Nl)
    except ImportError:
        t_fp = np.nan

    # EM: one iteration, Q and R
    Nem = 2_000
    us_e, ys_e = us_l[:Nem], ys_l[:Nem]
    kf.reset(x0, P0)
    kf.set_noise(Q0, R0)
    em_noise(kf, us_e, ys_e, n_iter=1, tol=1e-300)
    t_em = median_time(lambda: (kf.set_noise(Q0, R0), kf.reset(x0, P0),
                                em_noise(kf, us_e, ys_e, n_iter=5, tol=1e-300))) / 5
    t_em_pk = np.nan
    try:
        pk = KalmanFilter(transition_matrices=F, observation_matrices=H, transition_covariance=Q0,
                          observation_covariance=R0, transition_offsets=offsets[1:Nem],
                          initial_state_mean=x0, initial_state_covariance=P0,
                          em_vars=["transition_covariance", "observation_covariance"])
        t_em_pk = median_time(lambda: pk.em(ys_e, n_iter=2), 3) / 2
    except NameError:
        pass
    print(f"Offline estimation, per step (us); cart-pole EKF on {N} steps; linear model on {Nl} steps; "
          f"medians of {REPEATS}")
    for label, v in rows:
        print(f"  {label:45s} {v:8.3f}")
    print(f"  EM iteration ({Nem} steps), ours                    {t_em * 1e3:8.2f} ms")
    print(f"  EM iteration ({Nem} steps), pykalman                {t_em_pk * 1e3:8.2f} ms   "
          f"(ours {t_em_pk / t_em:.0f}x faster)")
    print(f"  KF + RTS: ours {t_pk / t_ours:.0f}x faster than pykalman, {t_fp / t_ours:.0f}x faster than filterpy")
    if args.write_docs:
        doc_tables.write_docs(__file__, {"us_per_step": dict(rows), "em_ms": t_em * 1e3,
                                         "em_pykalman_ms": t_em_pk * 1e3})


def offline_table(saved) -> str:
    """The performance page's table: µs per step of runs, smoothing and EM, ours against pykalman and filterpy."""
    f = saved["bench_offline"]["figures"]
    r = f["us_per_step"]
    ours = next(v for k, v in r.items() if k.startswith("ours: KF run + RTS"))
    pk, fp, em, em_pk = (r["pykalman filter + smooth"], r["filterpy batch_filter + rts_smoother"], f["em_ms"],
                         f["em_pykalman_ms"])
    return doc_tables.with_provenance(saved, "bench_offline", doc_tables.table(["", "µs/step"], [
        ["EKF `run` (one native call, every diagnostic kept)", f"{r['EKF run (one native call)']:.3f}"],
        ['EKF `run(keep="estimates")`', f"{r[KEEP]:.3f}"],
        ["EKF `step` called N times from Python (numpy rows)", f"{r['EKF step() x N from Python']:.2f}"],
        ["extended RTS smoother", f"{r['extended RTS smoother']:.3f}"],
        ["UKF `run` / MF-IAE `run`", f"{r['UKF run']:.3f} / {r['MF-IAE run']:.2f}"],
        ["**KF `run` + RTS, ours**", f"**{ours:.3f}**"],
        ["pykalman `filter` + `smooth`", f"{pk:.1f} ({pk / ours:.0f}x ours)"],
        ["filterpy `batch_filter` + `rts_smoother`", f"{fp:.1f} ({fp / ours:.0f}x ours)"],
        ["**EM iteration (2000 steps), ours**", f"**{em:.2f} ms**"],
        ["pykalman `em` iteration", f"{em_pk:.0f} ms ({em_pk / em:.0f}x ours)"]]))


TABLES = {"offline": offline_table}


if __name__ == "__main__":
    main()

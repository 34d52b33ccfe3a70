"""SWML (issue 21): the sliding-window ML + ALS adaptive EKF.

Convergence on a linear-Gaussian model from 1000x wrong q and r; one window update equal
to a plain numpy re-implementation of the method (a Kalman filter, the time-varying ALS
sums, the safeguarded Newton step, the selection rules); step, run, batch and FMU forms
equal; refusals named."""
from __future__ import annotations

import math
from functools import partial

import numpy as np
import pytest
from testkit.fmu_helpers import Instance

from estimators import SWML, BatchFilter, linear_model
from estimators.consistency import nees_test, nis_test
from fmu_models.errors import ConfigurationError, InputError

A = np.array([[1.0, 0.1], [0.0, 0.9]])
B = np.array([[0.0], [0.1]])
C = np.eye(2)
Q_TRUE, R_TRUE = 0.04, 0.25


def linear_record(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    us = np.sin(0.05 * np.arange(n))[:, None]
    x, ys = np.zeros(2), []
    for k in range(n):
        x = A @ x + B @ us[k] + rng.normal(0, math.sqrt(Q_TRUE), 2)
        ys.append(C @ x + rng.normal(0, math.sqrt(R_TRUE), 2))
    return us, np.array(ys)


@pytest.fixture(scope="module")
def lin():
    return linear_model(A, B, C, 0.1)


@pytest.mark.parametrize("factor", [1e-3, 1e3])
def test_converges_to_the_true_q_and_r_from_1000x_wrong(lin, factor):
    us, ys = linear_record(4000)
    f = SWML(lin, [0.0, 0.0], 1.0, factor * Q_TRUE, factor * R_TRUE)
    f.run(us, ys)
    hist = f.noise_history()
    late = hist[hist.index >= 2000]                       # the second half: every update since
    q, r = late["Q_x1"].mean(), late["R_y1"].mean()
    assert q == pytest.approx(Q_TRUE, rel=0.15) and r == pytest.approx(R_TRUE, rel=0.1), (q, r)
    assert hist.index[1:12].tolist() == [2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 50]   # the schedule


@pytest.mark.slow
def test_posterior_average_keeps_the_filter_consistent_from_1000x_too_small_noise(lin):
    """100 realisations of 200 steps from Q0 = R0 = 1e-3 times the truth: with the prior and
    the posterior average the average NEES and NIS lie inside their two-sided 95 % chi-square
    bands; the plain ML form (the same data) is far above them (overconfident start)."""
    runs, n = 100, 200
    rng = np.random.default_rng(5)
    us = np.sin(0.05 * np.arange(n))[:, None]
    X, Y = np.zeros((runs, n + 1, 2)), np.zeros((runs, n, 2))
    for k in range(n):
        X[:, k + 1] = X[:, k] @ A.T + us[k] @ B.T + rng.normal(0, math.sqrt(Q_TRUE), (runs, 2))
        Y[:, k] = X[:, k + 1] @ C.T + rng.normal(0, math.sqrt(R_TRUE), (runs, 2))
    verdicts = {}
    for name, options in (("ML", {}), ("MAP averaged", {"prior_sd": math.log(100.0), "posterior_average": True,
                                                        "early_every": 1, "keep_r_nats": 0.0, "max_fall": 10.0})):
        out = BatchFilter(SWML(lin, [0.0, 0.0], 1.0, 1e-3 * Q_TRUE, 1e-3 * R_TRUE, **options), runs).run(us, Y)
        e = out.x[:, 1:] - X[:, 1:]
        nees = np.einsum("rki,rki->rk", e, np.linalg.solve(out.P[:, 1:], e[..., None])[..., 0])
        verdicts[name] = (nees_test(nees, 2), nis_test(out.nis, 2))
    ne, ni = verdicts["MAP averaged"]
    assert ne.consistent and ni.consistent, (ne.average, ni.average)
    ne, ni = verdicts["ML"]
    assert ne.average > 10 * ne.band[1] and not ni.consistent, (ne.average, ni.average)


# ---------------------------------------------------------------------------- numpy oracle
def np_window(x, P, lq, lr, us, ys, als=False):
    """The Kalman filter over the window slots at theta: (ll, x, P[, ALS normal equations])."""
    n, p = 2, 2
    q, r = math.exp(lq), math.exp(lr)
    ll = 0.0
    G = [np.zeros((n, n)), np.zeros((n, n)), P.copy()]
    N = [np.zeros((n, p))] * 3
    L = [np.zeros((n, p))] * 3
    e1 = e2 = np.zeros(p)
    f1 = f2 = 0.0
    sums = np.zeros(5)
    for u, y in zip(us, ys):
        xp = A @ x + B @ u
        Pp = A @ P @ A.T + q * np.eye(n)
        S = C @ Pp @ C.T + r * np.eye(p)
        K = np.linalg.solve(S, C @ Pp).T
        e = y - C @ xp
        x = xp + K @ e
        IKH = np.eye(n) - K @ C
        P = IKH @ Pp @ IKH.T + r * K @ K.T
        ll += -0.5 * (np.linalg.slogdet(S)[1] + e @ np.linalg.solve(S, e))
        if als:
            Pi = [A @ G[0] @ A.T + np.eye(n), A @ G[1] @ A.T, A @ G[2] @ A.T]
            E0 = [C @ Pi[0] @ C.T, C @ Pi[1] @ C.T + np.eye(p), C @ Pi[2] @ C.T]
            E1 = [C @ A @ N[i] for i in range(3)]
            E2 = [C @ A @ L[i] for i in range(3)]
            for E, obs, w in ((E0, np.outer(e, e), 1.0), (E1, np.outer(e, e1), f1), (E2, np.outer(e, e2), f2)):
                D = obs - E[2]
                sums += w * np.array([np.sum(E[0] * E[0]), np.sum(E[0] * E[1]), np.sum(E[1] * E[1]),
                                      np.sum(E[0] * D), np.sum(E[1] * D)])
            G = [IKH @ Pi[i] @ IKH.T for i in range(3)]
            G[1] = G[1] + K @ K.T
            Nn = [IKH @ Pi[i] @ C.T for i in range(3)]
            Nn[1] = Nn[1] - K
            L = [IKH @ A @ N[i] for i in range(3)]
            N = Nn
            e2, e1, f2, f1 = e1, e, f1, 1.0
    return (ll, x, P, sums) if als else (ll, x, P)


def np_update(x_s, P_s, q0, r0, us, ys, qb, rb, h=0.25, max_factor=10.0, keep=2.0, max_fall=2.0, prior=None,
              average=False):
    """One SWML update (the method of issue 21 as documented in estimators/swml.py); with
    ``prior = (sd, q_c, r_c)`` the window's log-posterior (MAP), with ``average`` also the
    posterior-averaged end state and the new outer points: ``(q, r, x, P[, points])``."""
    lq0, lr0 = math.log(q0), math.log(r0)
    window = np_window

    if prior is not None:
        sd, qc, rc = prior

        def window(x_s, P_s, lq, lr, us, ys, als=False):
            out = np_window(x_s, P_s, lq, lr, us, ys, als)
            pen = 0.5 * ((lq - math.log(qc)) ** 2 + (lr - math.log(rc)) ** 2) / sd ** 2
            return (out[0] - pen, *out[1:])

    l0, x0, P0, (a11, a12, a22, b1, b2) = window(x_s, P_s, lq0, lr0, us, ys, als=True)
    det = a11 * a22 - a12 ** 2
    qa, ra = ((a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det) if det > 1e-300 else (q0, r0)
    lo_q, hi_q = math.log(max(qb[0], q0 / max_fall)), math.log(qb[1])
    lo_r, hi_r = math.log(max(rb[0], r0 / max_fall)), math.log(rb[1])

    def clamp(lq, lr):
        return min(max(lq, lo_q), hi_q), min(max(lr, lo_r), hi_r)

    ta = clamp(math.log(max(qa, 1e-300)), math.log(max(ra, 1e-300)))
    ea = window(x_s, P_s, *ta, us, ys)
    use_a = ea[0] > l0 and (ta[1] >= lr0 or ea[0] >= l0 + keep)
    ts, ls = (ta, ea[0]) if use_a else ((lq0, lr0), l0)
    pts = [(ts[0] + h, ts[1]), (ts[0] - h, ts[1]), (ts[0], ts[1] + h), (ts[0], ts[1] - h), (ts[0] + h, ts[1] + h)]
    evs = [window(x_s, P_s, *pt, us, ys) for pt in pts]
    lpq, lmq, lpr, lmr, lpp = (e[0] for e in evs)
    g = np.array([(lpq - lmq) / (2 * h), (lpr - lmr) / (2 * h)])
    Hm = np.array([[(lpq - 2 * ls + lmq) / h ** 2, (lpp - lpq - lpr + ls) / h ** 2],
                   [(lpp - lpq - lpr + ls) / h ** 2, (lpr - 2 * ls + lmr) / h ** 2]])
    if Hm[0, 0] < 0 and np.linalg.det(Hm) > 0:
        step = -np.linalg.solve(Hm, g)
    else:
        step = h * g / max(np.linalg.norm(g), 1e-300)
    step = np.clip(step, -math.log(max_factor), math.log(max_factor))
    tn = clamp(ts[0] + step[0], ts[1] + step[1])
    en = window(x_s, P_s, *tn, us, ys)
    cands = [(ta, ea), *zip(pts, evs), (tn, en)]
    best = ((lq0, lr0), (l0, x0, P0))

    def inside(t):
        return lo_q - 1e-12 <= t[0] <= hi_q + 1e-12 and lo_r - 1e-12 <= t[1] <= hi_r + 1e-12

    for t, ev in cands:                                   # first the points that keep r
        if inside(t) and t[1] >= lr0 and ev[0] > best[1][0]:
            best = (t, ev)
    bar = best[1][0] + keep
    for t, ev in cands:                                   # then those lowering r, by keep nats
        if inside(t) and t[1] < lr0 and ev[0] > max(best[1][0], bar):
            best = (t, ev)
    (lq, lr), (lb, xb, Pb) = best
    if lr < lr0:                                          # lowering r must pay at the chosen q too
        ek = window(x_s, P_s, lq, max(lr0, lr), us, ys)
        if ek[0] > lb - keep:
            lr, lb, xb, Pb = lr0, ek[0], ek[1], ek[2]
    if not average:
        return math.exp(lq), math.exp(lr), xb, Pb
    lam = -Hm
    if not (lam[0, 0] > 0 and np.linalg.det(lam) > 0):
        lam = np.diag(np.maximum(np.diag(lam), 1.0 / prior[0] ** 2))
    L = np.linalg.cholesky(np.linalg.inv(lam))
    lo, hi = np.log([qb[0], rb[0]]), np.log([qb[1], rb[1]])
    pts = [np.clip(np.array([lq, lr]) + sign * math.sqrt(3.0) * L[:, j], lo, hi) for sign in (1, -1) for j in (0, 1)]
    ends, w = [(xb, Pb)], [1 / 3]
    for pt in pts:                                        # a diverged re-run (200 nats below) is left out
        li, xe, Pe = window(x_s, P_s, *pt, us, ys)
        ends.append((xe, Pe))
        w.append(1 / 6 if li > lb - 200.0 else 0.0)
    w = [wi / sum(w) for wi in w]
    xm, Pm = np_mixture(ends, w)
    return math.exp(lq), math.exp(lr), xm, Pm, pts, w


def np_mixture(ends, w=(1 / 3, 1 / 6, 1 / 6, 1 / 6, 1 / 6)):
    """The mixture of the centre and the four outer points with weights ``w``."""
    xm = sum(wi * x for wi, (x, _) in zip(w, ends))
    return xm, sum(wi * (P + np.outer(x - xm, x - xm)) for wi, (x, P) in zip(w, ends))


@pytest.mark.parametrize("options", [{}, {"prior_sd": 1.5}, {"prior_sd": 1.5, "posterior_average": True}],
                         ids=["ML", "MAP", "MAP averaged"])
def test_one_window_update_equals_a_numpy_reimplementation(lin, options):
    """W = 20, M = 10, no early updates: the updates at steps 10 (a half-empty window from
    the initial state), 20 (full, from the initial state) and 30 (from the state stored at
    step 10) against the numpy oracle, to 1e-9: the window's maximum likelihood, with a prior
    (MAP), and with the state and covariance averaged over the posterior (at every step: the
    Kalman step at the centre and at the four outer points, mixed)."""
    us, ys = linear_record(40, seed=3)
    x0, P0 = np.zeros(2), np.eye(2)
    f = SWML(lin, x0, P0, 1e-3, 3.0, window=20, every=10, early_until=0, **options)
    qb, rb = f.q_bounds, f.r_bounds
    x, P, q, r = x0.copy(), P0.copy(), 1e-3, 3.0
    sd = options.get("prior_sd")
    prior = None if sd is None else (sd, 1e-3, 3.0)
    average = options.get("posterior_average", False)
    d = math.sqrt(3.0) * (sd or 0.0)
    pts = [np.log([1e-3, 3.0]) + o for o in ([d, 0], [0, d], [-d, 0], [0, -d])]   # the prior's points
    weights = [1 / 3] + [1 / 6] * 4
    stored = {0: (x0.copy(), P0.copy())}
    for k in range(1, 31):
        ends = [np_window(x, P, math.log(q), math.log(r), us[k - 1:k], ys[k - 1:k])[1:]]
        if average:
            ends += [np_window(x, P, *pt, us[k - 1:k], ys[k - 1:k])[1:] for pt in pts]
        x, P = np_mixture(ends, weights) if average else ends[0]
        if k % 10 == 0:
            start = max(0, k - 20)
            res = np_update(*stored[start], q, r, us[start:k], ys[start:k], qb, rb, prior=prior, average=average)
            q, r, x, P = res[:4]
            pts, weights = (res[4], res[5]) if average else (pts, weights)
            stored[k] = (x.copy(), P.copy())
        got = f.step(us[k - 1], ys[k - 1])
        np.testing.assert_allclose(got, x, rtol=0, atol=1e-9, err_msg=f"k = {k}")
        np.testing.assert_allclose(f.P, P, rtol=0, atol=1e-9)
        assert f.Q[0, 0] == pytest.approx(q, rel=1e-9) and f.R[0, 0] == pytest.approx(r, rel=1e-9), k
    assert list(f.noise_history().index) == [0, 10, 20, 30]
    assert f.Q[0, 0] != 1e-3 and f.R[0, 0] != 3.0                       # it did adapt


# ---------------------------------------------------------------------------- forms
@pytest.fixture(scope="module")
def record(cp):
    rng = np.random.default_rng(11)
    x, us, ys = np.array([0.5, 0.0, 1.8, 0.5]), [], []
    for k in range(300):
        u = [0.5 if (k // 100) % 2 else -0.5]
        x = cp.f(x, u) + rng.normal(0, math.sqrt(0.2), 4)
        us.append(u)
        ys.append(cp.h(x) + rng.normal(0, math.sqrt(0.1), 2))
    ys = np.array(ys)
    ys[[40, 170], 0] = np.nan                              # missing channels inside windows
    return np.array(us), ys


def make(cp, **options):
    return SWML(cp, [0.5, 0.0, 1.8, 0.5], 1.0, 1e-3, 10.0, window=50, every=25, **options)


@pytest.mark.slow
@pytest.mark.parametrize("options", [{}, {"prior_sd": 2.0, "posterior_average": True, "early_every": 1}],
                         ids=["ML", "MAP averaged"])
def test_step_run_batch_and_fmu_agree(cp, record, tmp_path, options):
    from estimators.filter_fmu import export_filter_fmu

    us, ys = record
    make = partial(globals()["make"], **options)
    stepped = make(cp)
    xs = np.array([stepped.step(us[k], ys[k]) for k in range(len(ys))])
    run = make(cp).run(us, ys)
    np.testing.assert_allclose(run.x[1:], xs, rtol=0, atol=1e-12)
    assert run.Q[-1, 0] == pytest.approx(stepped.Q[0, 0], rel=1e-12)
    batch = BatchFilter(make(cp), 3).run(us, np.repeat(ys[None], 3, axis=0))
    np.testing.assert_allclose(batch.x[:, 1:], np.repeat(xs[None], 3, axis=0), rtol=0, atol=1e-12)
    path = export_filter_fmu(make(cp), tmp_path, fmi_version=2, name="swml")
    inst = Instance(str(path)).init()
    try:
        got = []
        for k in range(len(ys)):
            inst.set("F", us[k][0])
            inst.do_step(k * 0.01, 0.01)
            for n, v in zip(cp.output_names, ys[k]):
                inst.set(n, v)
            got.append(inst.get(*cp.state_names))
        np.testing.assert_allclose(np.array(got), xs, rtol=0, atol=1e-10)
        assert inst.get("Q_x")[0] == pytest.approx(stepped.Q[0, 0], rel=1e-10)
    finally:
        inst.free()


@pytest.mark.slow
def test_history_lists_every_update(cp, record):
    us, ys = record
    f = make(cp)
    f.run(us, ys)
    assert list(f.noise_history().index) == [0, *range(2, 21, 2), *range(25, 301, 25)]


def test_bad_settings_and_inputs_are_named(cp):
    x0 = [0.5, 0.0, 1.8, 0.5]
    for kw, msg in (({"window": 30, "every": 25}, "window = 30 must be a multiple of every = 25"),
                    ({"early_until": 200}, "early_until must be a whole number of steps in 0..window"),
                    ({"max_factor": 1.0}, "max_factor must be > 1"),
                    ({"keep_r_nats": -1}, "keep_r_nats must be >= 0"),
                    ({"window": 10**6, "every": 10}, "window = 1000000 is longer than 2000 steps"),
                    ({"posterior_average": True}, "posterior_average needs a prior"),
                    ({"prior_sd": -1.0}, "prior_sd")):
        with pytest.raises(ConfigurationError, match=msg):
            SWML(cp, x0, 1.0, 0.1, 0.1, **kw)
    with pytest.raises(ConfigurationError, match="Q must be a multiple of the identity"):
        SWML(cp, x0, 1.0, [0.1, 0.2, 0.1, 0.1], 0.1)
    f = SWML(cp, x0, 1.0, 0.1, 0.1)
    with pytest.raises(InputError):
        f.step([np.inf], [0.1, 0.2])
    assert f.k == 0

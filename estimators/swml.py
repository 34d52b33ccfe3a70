"""Sliding-window maximum-likelihood adaptive EKF (SWML), started from autocovariance least squares.

Beyond the source papers: the EKF's ``Q = q I``, ``R = r I`` (seed 000 eqs 24-25) re-estimated by
maximum likelihood (Schweppe 1965) or MAP over a re-filtered window, from an ALS candidate (Odelson,
Rajamani and Rawlings 2006), optionally averaging the state over the posterior of ``(ln q, ln r)``;
the manual's estimators page gives the method. The whole filter is one compiled Function
(:meth:`SWML.wrap_step`).
"""
from __future__ import annotations

import math

import casadi as ca
import numpy as np

from fmu_models.errors import ConfigurationError
from fmu_models.infra import checks

from .adaptive import AdaptationRecord, bound_parameters, bounds_around
from .discrete import DiscreteModel, checked_model
from .ekf import EKF
from .linalg import BAD_RESULT, OK, finite_flag, log_det, mask_measurement
from .protocol import Parameter, StepContext, StepResult

__all__ = ["MAX_WINDOW", "SWML"]

#: The unscented weights of the posterior average (the centre, then the four outer points).
UT_WEIGHTS = (1.0 / 3.0, 1.0 / 6.0, 1.0 / 6.0, 1.0 / 6.0, 1.0 / 6.0)
#: An outer point of the posterior average whose window log-posterior lies more than this
#: many nats below the kept point's is left out (its re-run has diverged). Measured on the
#: seed 000 sweep: with 50 a cell loses its consistency, with 1000 a diverged re-run is kept.
DROP_NATS = 200.0

#: Longest window, whose re-runs are compiled into the step (about 1.7 s of C compilation per
#: 100 steps of window, once per configuration, then cached).
MAX_WINDOW = 2000


def _scalar_variance(M, n: int, what: str) -> float:
    """``v`` if ``M`` (a scalar, a vector or a matrix, checked as a covariance) is ``v I``."""
    C = checks.covariance(M, n, what)
    v = float(C[0, 0])
    if np.abs(C - v * np.eye(n)).max() > 1e-12 * v:
        raise ConfigurationError(f"SWML: {what} must be a multiple of the identity (it estimates {what} = v I), "
                                 f"got diagonal {np.diag(C).tolist()}")
    return v


class SWML(AdaptationRecord, EKF, register="SWML"):
    """EKF whose ``Q = q I`` and ``R = r I`` are re-estimated by maximum likelihood over a
    sliding window of innovations, started from an ALS estimate.

    Parameters
    ----------
    system, x0, P0, gate, nan_is_missing, backend
        As :class:`~estimators.base.KalmanBase`.
    Q, R : float or array_like
        The initial ``q I`` and ``r I`` (a scalar, or a multiple of the identity).
    window, every : int
        W, the steps in the window (default 100; a multiple of ``every``, at most :data:`MAX_WINDOW`),
        and M, the steps between updates after the start (default 50).
    early_until, early_every : int
        Up to step ``early_until`` (default 20; 0: none) an update every ``early_every`` steps
        (default 2) over all steps so far.
    fd_step : float
        Finite-difference step in ``ln q``, ``ln r`` (default 0.25).
    max_factor, max_fall : float
        Largest change of a variance by the Newton step (default 10), and largest factor by
        which it may fall in one update (default 2).
    keep_r_nats : float
        Likelihood gain [nats] a point must bring to lower r (default 2).
    q_bounds, r_bounds : (float, float), optional
        Bounds of q and r (default 1e-4 and 1e4 times the initial values).
    prior_sd : float, optional
        Standard deviation [nats] of a Gaussian prior on ``ln q`` and ``ln r`` centred at the
        initial values: the updates maximise the window's posterior (MAP; default None: ML).
    posterior_average : bool
        Average the state and covariance over the posterior of ``(ln q, ln r)`` at every step
        (five unscented points; needs ``prior_sd``; default False).
    """

    name = "SWML"
    adapts_noise = True

    def __init__(self, system: DiscreteModel, x0, P0, Q, R, window: int = 100, every: int = 50,
                 early_until: int = 20, early_every: int = 2, fd_step: float = 0.25, max_factor: float = 10.0,
                 keep_r_nats: float = 2.0, max_fall: float = 2.0, q_bounds=None, r_bounds=None,
                 prior_sd: float | None = None, posterior_average: bool = False,
                 gate: float | None = None, nan_is_missing: bool = True, backend: str = "compiled"):
        system = checked_model(system)
        q0, r0 = _scalar_variance(Q, system.nx, "Q"), _scalar_variance(R, system.ny, "R")
        self.window = checks.positive_int(window, "window")
        if self.window > MAX_WINDOW:
            raise ConfigurationError(f"SWML: window = {self.window} is longer than {MAX_WINDOW} steps (its re-runs are "
                                     "compiled into the step); use a shorter window")
        self.every = checks.positive_int(every, "every")
        if self.window % self.every:
            raise ConfigurationError(f"SWML: window = {self.window} must be a multiple of every = {self.every} "
                                     "(the window starts at a stored state)")
        self.early_until = int(checks.finite(early_until, "early_until"))
        if self.early_until != early_until or not 0 <= self.early_until <= self.window:
            raise ConfigurationError(f"SWML: early_until must be a whole number of steps in 0..window, "
                                     f"got {early_until!r}")
        self.early_every = checks.positive_int(early_every, "early_every")
        self.fd_step = checks.positive(fd_step, "fd_step")
        self.max_factor = checks.positive(max_factor, "max_factor")
        self.keep_r_nats = checks.finite(keep_r_nats, "keep_r_nats")
        if self.keep_r_nats < 0:
            raise ConfigurationError(f"SWML: keep_r_nats must be >= 0, got {keep_r_nats}")
        self.max_fall = checks.positive(max_fall, "max_fall")
        if self.max_factor <= 1 or self.max_fall < 1:
            raise ConfigurationError(f"SWML: max_factor must be > 1 and max_fall >= 1, got {max_factor}, {max_fall}")
        self.prior_sd = None if prior_sd is None else checks.positive(prior_sd, "prior_sd")
        self.posterior_average = bool(posterior_average)
        if self.posterior_average and self.prior_sd is None:
            raise ConfigurationError("SWML: posterior_average needs a prior (set prior_sd): the posterior of "
                                     "(ln q, ln r) of a short window is not proper without one")
        self._prior_centre = (q0, r0)
        self.q_bounds = bounds_around(np.array([q0]), q_bounds, "q_bounds")
        self.r_bounds = bounds_around(np.array([r0]), r_bounds, "r_bounds")
        super().__init__(system, x0, P0, q0, r0, gate, nan_is_missing, backend)
        self._init_adaptation_record()

    def config_key(self) -> tuple:
        """Window, schedule and the update's constants (the bounds are step inputs)."""
        return (self.window, self.every, self.early_until, self.early_every, self.fd_step, self.max_factor,
                self.keep_r_nats, self.max_fall, self.prior_sd, self.posterior_average)

    def step_parameters(self) -> list[Parameter]:
        """The bounds of q and r (``q_bounds``, ``r_bounds``) and, with a prior, its centre
        (``noise_prior``: the initial q and r; FMU parameters ``q_prior``, ``r_prior``)."""
        prior = [] if self.prior_sd is None else [
            Parameter("noise_prior", self._prior_centre, "positive",
                      ("centre of the prior of the process noise variance",
                       "centre of the prior of the measurement noise variance"), ("q_prior", "r_prior"))]
        return bound_parameters(self.q_bounds, self.r_bounds) + prior

    def extra_state(self) -> dict:
        """The window (``wu``, ``wy``, ``wv``: inputs, measurements, valid channels; ``wa``: 1 for
        a slot holding a step), the states stored every ``every`` steps (``snap_x``, ``snap_P``,
        oldest first), the initial state (``x_init``, ``P_init``) and the step count."""
        s, W, n_snap = self.system, self.window, self.window // self.every
        x0, P0 = self._start
        return {"wu": np.zeros(s.nu * W), "wy": np.zeros(s.ny * W), "wv": np.zeros(s.ny * W), "wa": np.zeros(W),
                "snap_x": np.tile(x0, n_snap), "snap_P": np.tile(P0.ravel(order="F"), n_snap),
                "x_init": x0.copy(), "P_init": P0.ravel(order="F").copy(), "count": np.zeros(1),
                **({"sigma": np.array(self._prior_points(*map(math.log, self._prior_centre)))}
                   if self.posterior_average else {})}

    def _prior_points(self, lq, lr):
        """The four outer unscented points of the prior centred at ``(lq, lr)`` (floats or SX),
        ``(lq_1, lr_1, ..., lq_4, lr_4)``, then the five weights :data:`UT_WEIGHTS`."""
        d = math.sqrt(3.0) * self.prior_sd
        return [lq + d, lr, lq, lr + d, lq - d, lr, lq, lr - d, *UT_WEIGHTS]

    def fmu_noise_parameters(self) -> list[Parameter]:
        """``q0`` and ``r0``: the initial ``Q = q0 I``, ``R = r0 I``."""
        return [Parameter("q0", self.Q[0, 0], "positive", "initial process noise variance (Q = q0 I)"),
                Parameter("r0", self.R[0, 0], "positive", "initial measurement noise variance (R = r0 I)")]

    def fmu_noise(self, p):
        """``Q = q0 I``, ``R = r0 I``."""
        s = self.system
        return p["q0"] * ca.SX.eye(s.nx), p["r0"] * ca.SX.eye(s.ny)

    def fmu_initial(self, p):
        """The initial state, with the window's stored states at the FMU's ``x0``, ``P0``."""
        out = super().fmu_initial(p)
        n_snap = self.window // self.every
        P = ca.reshape(ca.diag(p["P0"]), -1, 1)
        out.update(snap_x=ca.repmat(p["x0"], n_snap, 1), snap_P=ca.repmat(P, n_snap, 1), x_init=p["x0"], P_init=P)
        if self.posterior_average:
            out["sigma"] = ca.vertcat(*self._prior_points(ca.log(p["q0"]), ca.log(p["r0"])))
        return out

    def adapt_expr(self, ctx: StepContext, result: StepResult) -> dict:
        """Push the step into the window; store the state at every ``every``-th step.
        Declares the output ``adapted`` (set by the update, :meth:`wrap_step`)."""
        s, W, M = self.system, self.window, self.every
        n, n_snap = s.nx, W // M

        def push(flat, rows, value):
            ring = ca.reshape(flat, rows, flat.numel() // rows if rows else W)     # a model may have no input
            return ca.horzcat(ring[:, 1:], value) if ring.shape[1] > 1 else value

        st, count = ctx.state, ctx.state["count"]
        due = ca.fmod(count, M) == 0                     # ctx.x is the state after step `count`
        sx, sP = ca.reshape(st["snap_x"], n, n_snap), ca.reshape(st["snap_P"], n * n, n_snap)
        ctx.output("adapted", ca.SX(0))
        keep = {"sigma": st["sigma"]} if self.posterior_average else {}
        return {**keep, "wu": push(st["wu"], s.nu, ctx.u), "wy": push(st["wy"], s.ny, ctx.y),
                "wv": push(st["wv"], s.ny, ctx.valid), "wa": push(st["wa"], 1, ca.SX(1)),
                "snap_x": ca.if_else(due, push(sx, n, ctx.x), sx),
                "snap_P": ca.if_else(due, push(sP, n * n, ca.reshape(ctx.P, -1, 1)), sP),
                "count": count + 1}

    def _window_step(self):
        """One EKF step of a window re-run at ``theta`` (:meth:`_RerunStep.function`)."""
        return _RerunStep(self).function("swml_window_step")

    def als_step(self):
        """One step of the window re-run at the current ``theta`` that also accumulates the
        ALS normal equations (a CasADi Function; its carried state ``c`` packs the affine
        coefficients (in q, r, 1) of the posterior error covariance ``G``, of
        ``N = Cov(eps - K e, e)`` and of ``L`` (the two-step cross term), the last two
        innovations and the sums ``a11, a12, a22, b1, b2``).

        The expectations (time-varying ALS): ``Pi_j = F_j G_{j-1} F_j^T + q I``;
        ``E[e_j e_j^T] = H Pi_j H^T + r I``, ``E[e_j e_{j-1}^T] = H_j F_j N_{j-1}``,
        ``E[e_j e_{j-2}^T] = H_j F_j L_{j-1}``; then ``G_j = (I-KH) Pi (I-KH)^T + r K K^T``,
        ``N_j = (I-KH) Pi H^T - r K``, ``L_j = (I-KH) F_j N_{j-1}``. Products of complete,
        accepted measurement vectors enter the least squares.
        """
        n, p = self.system.nx, self.system.ny
        st = _RerunStep(self)
        shapes = [(n, n)] * 3 + [(n, p)] * 6 + [(p, 1)] * 2 + [(1, 1)] * 2 + [(5, 1)]
        offsets = np.cumsum([0] + [rows * cols for rows, cols in shapes]).tolist()
        c = ca.SX.sym("c", offsets[-1])
        parts = [ca.reshape(piece, *shape) for piece, shape in zip(ca.vertsplit(c, offsets), shapes)]
        G, Nc, L, (e1, e2, f1, f2, sums) = parts[0:3], parts[3:6], parts[6:9], parts[9:]
        _, F = self.system.transition(st.x, st.u)
        upd = st.upd
        _, H = self.system.measurement(st.xp)
        _, _, Mv = mask_measurement(st.v, ca.SX.eye(p), ca.SX.zeros(p))
        Hm, Ka = ca.mtimes(Mv, H), upd.accepted * upd.K
        e = upd.innovation
        Inx = ca.SX.eye(n)
        Pi = [ca.mtimes([F, G[0], F.T]) + Inx, ca.mtimes([F, G[1], F.T]), ca.mtimes([F, G[2], F.T])]
        E0 = [ca.mtimes([H, Pi[0], H.T]), ca.mtimes([H, Pi[1], H.T]) + ca.SX.eye(p), ca.mtimes([H, Pi[2], H.T])]
        HF = ca.mtimes(H, F)
        E1 = [ca.mtimes(HF, Nc[i]) for i in range(3)]
        E2 = [ca.mtimes(HF, L[i]) for i in range(3)]
        full = st.a * upd.accepted * ca.mmin(st.v)
        acc = [sums[i] for i in range(5)]
        for E, obs, w in ((E0, ca.mtimes(e, e.T), full), (E1, ca.mtimes(e, e1.T), full * f1),
                          (E2, ca.mtimes(e, e2.T), full * f2)):
            D = obs - E[2]
            dot = lambda A, B: ca.sum1(ca.sum2(A * B))          # noqa: E731 - Frobenius product
            for i, term in enumerate((dot(E[0], E[0]), dot(E[0], E[1]), dot(E[1], E[1]), dot(E[0], D),
                                      dot(E[1], D))):
                acc[i] = acc[i] + w * term
        IKH = Inx - ca.mtimes(Ka, Hm)
        G_new = [ca.mtimes([IKH, Pi[i], IKH.T]) for i in range(3)]
        G_new[1] = G_new[1] + ca.mtimes(Ka, Ka.T)
        N_new = [ca.mtimes([IKH, Pi[i], H.T]) for i in range(3)]
        N_new[1] = N_new[1] - Ka
        L_new = [ca.mtimes([IKH, F, Nc[i]]) for i in range(3)]
        new = ca.vertcat(*[ca.reshape(m, -1, 1) for m in (*G_new, *N_new, *L_new)], e, e1, full, f1,
                         ca.vertcat(*acc))
        return st.function("swml_als_step", c, new)

    def wrap_step(self, step: ca.Function) -> ca.Function:
        """The EKF step (with the window bookkeeping of :meth:`adapt_expr`), then the update
        at update times, as one MX Function with the step's inputs and outputs."""
        s, W = self.system, self.window
        n, n_snap = s.nx, W // self.every
        ins = [ca.MX.sym(step.name_in(i), step.sparsity_in(i)) for i in range(step.n_in())]
        names_out = step.name_out()
        out = dict(zip(names_out, step.call(ins)))
        by = dict(zip(step.name_in(), ins))
        k = out["count_new"]
        early = ca.logic_and(ca.logic_and(k <= self.early_until, ca.fmod(k, self.early_every) == 0), k > 0)
        regular = ca.logic_and(k > self.early_until, ca.fmod(k, self.every) == 0)
        index = ca.if_else(regular, 2, ca.if_else(early, 1, 0))
        branches = [_WindowUpdate(self, slots).function() for slots in (0, self.early_until, None)]
        cond = ca.Function.conditional("swml_update", branches, branches[0])
        sx = ca.reshape(out["snap_x_new"], n, n_snap)[:, 0]
        sP = ca.reshape(out["snap_P_new"], n * n, n_snap)[:, 0]
        sg = by["sigma"] if self.posterior_average else ca.MX.zeros(13)
        if self.posterior_average:               # the step at the posterior's outer points, mixed
            ws, last = self._window_step(), slice(W - 1, W)
            uk = ca.reshape(out["wu_new"], s.nu, W)[:, last]
            yk, vk = (ca.reshape(out[k], s.ny, W)[:, last] for k in ("wy_new", "wv_new"))
            xc, Pc = ca.reshape(out["x_new"], n, 1), ca.reshape(out["P_new"], n, n)
            ends = [(xc, Pc)] + [tuple(ws(by["x"], ca.reshape(by["P"], n, n), 0, uk, yk, vk, 1, sg[2 * i],
                                          sg[2 * i + 1], by["gate"])[:2]) for i in range(4)]
            xm, Pm = _mixture(ends, [sg[8 + i] for i in range(5)])
            ok = finite_flag([xm, Pm])
            out["x_new"] = ca.reshape(ca.if_else(ok, xm, xc), out["x_new"].shape)
            out["P_new"] = ca.reshape(ca.if_else(ok, Pm, Pc), out["P_new"].shape)
        res = cond(index, ca.reshape(out["x_new"], n, 1), ca.reshape(out["P_new"], n, n),
                   ca.reshape(out["Q_new"], n, n), ca.reshape(out["R_new"], s.ny, s.ny), out["wu_new"],
                   out["wy_new"], out["wv_new"], out["wa_new"], sx, sP, by["x_init"], by["P_init"], by["gate"],
                   by["q_bounds"], by["r_bounds"], by.get("noise_prior", ca.DM.ones(2)), sg)
        keys = ("x_new", "P_new", "Q_new", "R_new", "adapted") + (("sigma_new",) if self.posterior_average else ())
        for key, val in zip(keys, res):
            out[key] = ca.densify(ca.reshape(val, out[key].shape))
        out["status"] = ca.if_else(out["status"] != 0, out["status"],
                                   ca.if_else(finite_flag([out["x_new"], out["P_new"]]), OK, BAD_RESULT))
        return ca.Function("step", ins, [out[nm] for nm in names_out], step.name_in(), names_out)


def _mixture(ends, w):
    """Mean and covariance of the mixture of the ``(x_i, P_i)`` of ``ends`` with weights ``w``."""
    xm = sum(wi * xe for wi, (xe, _) in zip(w, ends))
    Pm = sum(wi * (Pe + ca.mtimes(xe - xm, (xe - xm).T)) for wi, (xe, Pe) in zip(w, ends))
    return xm, 0.5 * (Pm + Pm.T)


class _RerunStep:
    """One EKF step of a window re-run at ``theta = (ln q, ln r)`` (SX): the symbols ``x``, ``P``,
    ``ll`` (the log-likelihood so far), the slot's ``u``, ``y``, ``v`` (valid channels), ``a``
    (1: the slot holds a step), ``lq``, ``lr``, ``gate``; the prior ``xp``, ``Pp``; the ``upd``."""

    def __init__(self, filt: SWML):
        s, sym = filt.system, ca.SX.sym
        self.x, self.P, self.ll = sym("x", s.nx), sym("P", s.nx, s.nx), sym("ll")
        self.u, self.y, self.v, self.a = sym("u", s.nu), sym("y", s.ny), sym("v", s.ny), sym("a")
        self.lq, self.lr, self.gate = sym("lq"), sym("lr"), sym("gate")
        ctx = StepContext(s, self.x, self.P, ca.exp(self.lq) * ca.SX.eye(s.nx), ca.exp(self.lr) * ca.SX.eye(s.ny),
                          self.u, self.y, self.v, self.gate)
        self.xp, self.Pp = filt.predict_expr(ctx)
        self.upd = filt.update_expr(ctx, self.xp, self.Pp)

    def function(self, name: str, c: ca.SX | None = None, c_new: ca.SX | None = None) -> ca.Function:
        """``(x, P, ll[, c], u, y, v, a, lq, lr, gate) -> (x', P', ll'[, c'])``: the step, and a
        carried column ``c`` that becomes ``c_new``; an inactive slot changes nothing."""
        upd, a = self.upd, self.a
        gain = -0.5 * (log_det(upd.S) + upd.nis) * upd.accepted
        carried = [] if c is None else [c]
        return ca.Function(name, [self.x, self.P, self.ll, *carried, self.u, self.y, self.v, a, self.lq, self.lr,
                                  self.gate],
                           [ca.if_else(a, upd.x, self.x), ca.if_else(a, upd.P, self.P), self.ll + a * gain,
                            *[ca.if_else(a, c_new, c) for c in carried]])


class _WindowUpdate:
    """The update of :class:`SWML` (steps 1-5 of the manual's estimators page) as an MX Function
    over the last ``slots`` window slots from the initial state (the early updates), or, with
    ``slots=None``, over the whole window from the oldest stored state (``slots=0``: none)."""

    def __init__(self, filt: SWML, slots: int | None):
        s, W = filt.system, filt.window
        n, p = s.nx, s.ny
        MX = ca.MX
        self.filt, self.slots, self.n, self.p = filt, slots, n, p
        self.x, self.P, self.Q, self.R = MX.sym("x", n), MX.sym("P", n, n), MX.sym("Q", n, n), MX.sym("R", p, p)
        self.window = MX.sym("wu", s.nu * W), MX.sym("wy", p * W), MX.sym("wv", p * W), MX.sym("wa", W)
        self.stored = MX.sym("sx", n), MX.sym("sP", n * n), MX.sym("xi", n), MX.sym("Pi", n * n)
        self.gate, self.qb, self.rb, self.pc = MX.sym("gate"), MX.sym("qb", 2), MX.sym("rb", 2), MX.sym("pc", 2)
        self.sg = MX.sym("sg", 13)
        self.inputs = [self.x, self.P, self.Q, self.R, *self.window, *self.stored, self.gate, self.qb, self.rb,
                       self.pc, self.sg]

    def function(self) -> ca.Function:
        """``(x, P, Q, R, wu, wy, wv, wa, sx, sP, xi, Pi, gate, qb, rb, pc, sg) -> (x, P, Q, R,
        adapted, sg)``."""
        MX, n, p = ca.MX, self.n, self.p
        if self.slots == 0:                                     # no update
            return ca.Function("swml_none", self.inputs, [self.x, self.P, self.Q, self.R, MX(0), self.sg])
        self._slice_window()
        l0, end0, theta_als = self._als()
        lo_q, hi_q = ca.log(ca.fmax(self.qb[0], self.q0 / self.filt.max_fall)), ca.log(self.qb[1])
        lo_r, hi_r = ca.log(ca.fmax(self.rb[0], self.r0 / self.filt.max_fall)), ca.log(self.rb[1])
        self.bounds = lo_q, hi_q, lo_r, hi_r
        cands, hess = self._candidates(l0, theta_als)
        best_l, best_t, best_x, best_P = self._best(cands, l0, end0)
        sigma = self.sg
        if self.filt.posterior_average:
            best_x, best_P, sigma = self._posterior_average(best_t, best_l, best_x, best_P, hess)
        ok_end = finite_flag([best_x, best_P])
        x_new, P_new = ca.if_else(ok_end, best_x, self.x), ca.if_else(ok_end, best_P, self.P)
        Q_new = ca.if_else(ok_end, ca.exp(best_t[0]), self.q0) * MX.eye(n)
        R_new = ca.if_else(ok_end, ca.exp(best_t[1]), self.r0) * MX.eye(p)
        name = "swml_window" if self.slots is None else "swml_early"
        return ca.Function(name, self.inputs, [x_new, P_new, Q_new, R_new, MX(1), ca.if_else(ok_end, sigma, self.sg)])

    def _slice_window(self) -> None:
        """The window's slots the update runs over, its start and the current ``theta``."""
        s, W, n, p = self.filt.system, self.filt.window, self.n, self.p
        wu, wy, wv, wa = self.window
        sx, sP, xi, Pi = self.stored
        N = self.N = W if self.slots is None else self.slots
        cols = slice(W - N, W)
        self.U, self.Y = ca.reshape(wu, s.nu, W)[:, cols], ca.reshape(wy, p, W)[:, cols]
        self.V, self.A = ca.reshape(wv, p, W)[:, cols], ca.reshape(wa, 1, W)[:, cols]
        self.start = (sx, ca.reshape(sP, n, n)) if self.slots is None else (xi, ca.reshape(Pi, n, n))
        self.lfold = self.filt._window_step().mapaccum("swml_ll", N, [0, 1, 2], [0, 1, 2])
        self.prior = ca.log(self.pc[0]), ca.log(self.pc[1])
        self.q0, self.r0 = self.Q[0, 0], self.R[0, 0]
        self.lq0, self.lr0 = ca.log(self.q0), ca.log(self.r0)

    def _rep(self, z):
        return ca.repmat(z, 1, self.N)

    def objective(self, ll, lq, lr):
        """The window's log-likelihood, with a prior plus its log-density (MAP)."""
        sd = self.filt.prior_sd
        mq, mr = self.prior
        return ll if sd is None else ll - 0.5 * ((lq - mq) ** 2 + (lr - mr) ** 2) / sd ** 2

    def run(self, lq, lr):
        """The window re-run at ``theta = (lq, lr)``: ``(objective, x at its end, P at its end)``."""
        xs, Ps, lls = self.lfold(*self.start, 0, self.U, self.Y, self.V, self.A, self._rep(lq), self._rep(lr),
                                 self._rep(self.gate))
        return self.objective(lls[-1], lq, lr), xs[:, -1], Ps[:, -self.n:]

    def clamp(self, lq, lr, bounds=None):
        """``theta`` within its bounds (or within ``bounds``, ``(lo_q, hi_q, lo_r, hi_r)``)."""
        lo_q, hi_q, lo_r, hi_r = bounds or self.bounds
        return ca.fmin(ca.fmax(lq, lo_q), hi_q), ca.fmin(ca.fmax(lr, lo_r), hi_r)

    def inside(self, lq, lr):
        """1 if ``theta`` lies within its bounds (to 1e-12)."""
        lo_q, hi_q, lo_r, hi_r = self.bounds
        return ca.logic_and(ca.logic_and(lq >= lo_q - 1e-12, lq <= hi_q + 1e-12),
                            ca.logic_and(lr >= lo_r - 1e-12, lr <= hi_r + 1e-12))

    def _als(self):
        """The window re-run at the current ``theta`` with the ALS sums (step 2): its objective,
        its end ``(x, P)`` and the ALS ``(q, r)`` (the current one if the equations are singular)."""
        n, q0, r0, lq0, lr0 = self.n, self.q0, self.r0, self.lq0, self.lr0
        als = self.filt.als_step()
        # G = P at the window start (its constant part), nothing else yet
        c_init = ca.vertcat(ca.MX.zeros(2 * n * n), ca.reshape(self.start[1], -1, 1),
                            ca.MX.zeros(als.size1_in(3) - 3 * n * n))
        afold = als.mapaccum("swml_als", self.N, [0, 1, 2, 3], [0, 1, 2, 3])
        xs0, Ps0, lls0, cs = afold(*self.start, 0, c_init, self.U, self.Y, self.V, self.A, self._rep(lq0),
                                   self._rep(lr0), self._rep(self.gate))
        l0, end0 = self.objective(lls0[-1], lq0, lr0), (xs0[:, -1], Ps0[:, -n:])
        sums = cs[-5:, -1]
        a11, a12, a22, b1, b2 = (sums[i] for i in range(5))
        det = a11 * a22 - a12 * a12
        ok = det > 1e-300
        qa = ca.if_else(ok, (a22 * b1 - a12 * b2) / ca.if_else(ok, det, 1), q0)
        ra = ca.if_else(ok, (a11 * b2 - a12 * b1) / ca.if_else(ok, det, 1), r0)
        return l0, end0, (qa, ra)

    def _candidates(self, l0, theta_als):
        """The points evaluated (step 3), ``((lq, lr), objective, (x, P) at the window's end)``:
        the ALS point, the finite-difference points and the Newton step's; and the Hessian
        ``(H11, H12, H22)``."""
        tiny = 1e-300                                       # "negative parts floored" at the lower bounds
        lqa, lra = self.clamp(ca.log(ca.fmax(theta_als[0], tiny)), ca.log(ca.fmax(theta_als[1], tiny)))
        la, *endA = self.run(lqa, lra)
        keep, lq0, lr0 = self.filt.keep_r_nats, self.lq0, self.lr0
        use_a = ca.logic_and(ca.logic_and(finite_flag([la]), la > l0), ca.logic_or(lra >= lr0, la >= l0 + keep))
        lqs, lrs = ca.if_else(use_a, lqa, lq0), ca.if_else(use_a, lra, lr0)
        ls = ca.if_else(use_a, la, l0)
        h = self.filt.fd_step
        pts = [(lqs + h, lrs), (lqs - h, lrs), (lqs, lrs + h), (lqs, lrs - h), (lqs + h, lrs + h)]
        evals = [self.run(*pt) for pt in pts]
        lpq, lmq, lpr, lmr, lpp = (ev[0] for ev in evals)
        g = ca.vertcat((lpq - lmq) / (2 * h), (lpr - lmr) / (2 * h))
        H11, H22 = (lpq - 2 * ls + lmq) / h ** 2, (lpr - 2 * ls + lmr) / h ** 2
        H12 = (lpp - lpq - lpr + ls) / h ** 2
        detH = H11 * H22 - H12 * H12
        negdef = ca.logic_and(H11 < 0, detH > 0)
        newton = ca.vertcat(-(H22 * g[0] - H12 * g[1]), -(-H12 * g[0] + H11 * g[1])) / ca.if_else(negdef, detH, 1)
        uphill = h * g / ca.fmax(ca.norm_2(g), 1e-300)
        step = ca.if_else(negdef, newton, uphill)
        cap = math.log(self.filt.max_factor)
        step = ca.fmin(ca.fmax(step, -cap), cap)
        lqn, lrn = self.clamp(lqs + step[0], lrs + step[1])
        evn = self.run(lqn, lrn)
        cands = [((lqa, lra), la, endA), *[(pt, ev[0], ev[1:]) for pt, ev in zip(pts, evals)],
                 ((lqn, lrn), evn[0], evn[1:])]
        return cands, (H11, H12, H22)

    def _best(self, cands, l0, end0):
        """The point kept (steps 3-4) of the candidates ``cands`` and the current point (objective
        ``l0``, end ``end0``): ``(objective, theta, x, P)``."""
        keep, lr0 = self.filt.keep_r_nats, self.lr0
        best_l, best_t, best_x, best_P = l0, (self.lq0, lr0), end0[0], end0[1]
        # first the best point that keeps r; a point lowering r must beat it by keep_r_nats
        for lowers in (False, True):
            bar = best_l + keep if lowers else None
            for (lq, lr), lval, (xe, Pe) in cands:
                kind = lr < lr0 if lowers else lr >= lr0
                ok = ca.logic_and(ca.logic_and(self.inside(lq, lr), finite_flag([lval])), kind)
                take = ca.logic_and(ok, lval > (ca.fmax(best_l, bar) if lowers else best_l))
                best_l = ca.if_else(take, lval, best_l)
                best_t = (ca.if_else(take, lq, best_t[0]), ca.if_else(take, lr, best_t[1]))
                best_x, best_P = ca.if_else(take, xe, best_x), ca.if_else(take, Pe, best_P)
        # the gain of lowering r at the chosen q: kept only if it is worth keep_r_nats there too
        evk = self.run(best_t[0], ca.fmax(lr0, best_t[1]))
        back = ca.logic_and(ca.logic_and(best_t[1] < lr0, finite_flag([evk[0]])), evk[0] > best_l - keep)
        best_t = (best_t[0], ca.if_else(back, lr0, best_t[1]))
        best_x, best_P = ca.if_else(back, evk[1], best_x), ca.if_else(back, evk[2], best_P)
        return ca.if_else(back, evk[0], best_l), best_t, best_x, best_P

    def _posterior_average(self, theta, l_best, x_best, P_best, hess):
        """The window's end state and covariance averaged over the Laplace approximation of the
        posterior of ``theta`` (the manual's estimators page; a point not finite left out, a mixture
        not finite replaced by the kept point), and the points and weights (13)."""
        H11, H12, H22 = hess
        a, b, d = -H11, -H12, -H22
        pd = ca.logic_and(a > 0, a * d - b * b > 0)
        floor = 1.0 / self.filt.prior_sd ** 2
        a, b, d = ca.if_else(pd, a, ca.fmax(a, floor)), ca.if_else(pd, b, 0), ca.if_else(pd, d, ca.fmax(d, floor))
        det = a * d - b * b
        s11, s12, s22 = d / det, -b / det, a / det                    # Lambda^-1
        l11 = ca.sqrt(s11)
        l21 = s12 / l11
        l22 = ca.sqrt(ca.fmax(s22 - l21 * l21, 0))
        c = math.sqrt(3.0)
        given = (ca.log(self.qb[0]), ca.log(self.qb[1]), ca.log(self.rb[0]), ca.log(self.rb[1]))
        pts = [self.clamp(theta[0] + sign * c * dq, theta[1] + sign * c * dr, given)
               for sign in (1.0, -1.0) for dq, dr in ((l11, l21), (0, l22))]
        ends, raw = [(x_best, P_best)], [ca.MX(UT_WEIGHTS[0])]
        for pt, w0 in zip(pts, UT_WEIGHTS[1:]):
            li, xe, Pe = self.run(*pt)
            fine = finite_flag([li, xe, Pe])
            ends.append((ca.if_else(fine, xe, x_best), ca.if_else(fine, Pe, P_best)))
            raw.append(ca.if_else(ca.logic_and(fine, li > l_best - DROP_NATS), w0, 0))
        total = sum(raw)
        w = [wi / total for wi in raw]
        xm, Pm = _mixture(ends, w)
        ok = finite_flag([xm, Pm])
        return (ca.if_else(ok, xm, x_best), ca.if_else(ok, Pm, P_best),
                ca.vertcat(*[v for pt in pts for v in pt], *[ca.if_else(ok, wi, w0) for wi, w0 in zip(w, UT_WEIGHTS)]))

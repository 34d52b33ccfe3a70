"""The interface and machinery shared by every Gaussian filter in this package.

A filter builds three CasADi Functions from the model's expressions, once per model
(cached on the :class:`~estimators.system.DiscreteModel`): ``predict``, ``update`` and the
fused ``step`` (predict then update). Each is bound to the filter's numpy arrays with
:class:`~estimators._buffered.BufferedFunction`, so a step is one call into CasADi plus a
few array copies. Every Function also returns a status: 1 if an input was NaN or inf,
2 if the result was not finite; the filter then raises and keeps its previous state.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from . import checks
from ._buffered import BufferedFunction, matrix
from ._compiled import compile_functions
from .system import DiscreteModel

OK, BAD_INPUT, BAD_RESULT = 0, 1, 2


def symmetric(M: ca.SX) -> ca.SX:
    """(M + M^T)/2: keeps a covariance exactly symmetric against rounding."""
    return 0.5 * (M + M.T)


def joseph_update(xp, Pp, innov, H, S, R):
    """Kalman gain and Joseph-form update (seed 002 eqs 13-16; stable for any gain).

    ``K = Pp H^T S^{-1}`` computed by solving ``S K^T = H Pp`` (no inverse);
    ``P = (I - K H) Pp (I - K H)^T + K R K^T``.
    """
    n = xp.numel()
    K = ca.solve(S, ca.mtimes(H, Pp)).T
    IKH = ca.SX.eye(n) - ca.mtimes(K, H)
    P = symmetric(ca.mtimes([IKH, Pp, IKH.T]) + ca.mtimes([K, R, K.T]))
    return xp + ca.mtimes(K, innov), P, K


def _finite(expr_list) -> ca.SX:
    """1 if every entry of the expressions is finite, else 0 (NaN and inf fail the test)."""
    total = sum(ca.sum1(ca.vec(e)) for e in expr_list)
    return ca.fabs(total) < ca.inf


class KalmanBase:
    """Common interface: ``predict(u)``, ``update(y)``, ``step(u, y)``.

    Parameters
    ----------
    system : DiscreteModel
        The discrete model the filter runs on (see :func:`estimators.discretize`).
    x0 : array_like, shape (nx,)
        Initial state estimate.
    P0, Q, R : array_like
        Initial state covariance (nx, nx), process noise covariance (nx, nx) and
        measurement noise covariance (ny, ny); each may also be a diagonal vector or a
        scalar (times identity). Must be symmetric positive definite.

    Attributes
    ----------
    x : ndarray, shape (nx,)
        Current state estimate (after the last update, or the prior after ``predict``).
    P : ndarray, shape (nx, nx)
        Its covariance.
    x_prior, P_prior : ndarray
        Prediction of the last step.
    Q, R : ndarray
        Current noise covariances.
    innovation : ndarray, shape (ny,)
        Last innovation ``y - h(x_prior)`` (seed 000 eq 26).
    S : ndarray, shape (ny, ny)
        Its predicted covariance.
    K : ndarray, shape (nx, ny)
        Last gain.
    nis : float
        Normalised innovation squared ``innovation^T S^{-1} innovation``.
    backend : str
        ``"compiled"`` (native code, default) or ``"vm"`` (CasADi's virtual machine).
    k : int
        Number of predictions done.
    log : list of dict
        Adaptation record ``{"k", "Q", "R"}``, one entry per change of Q or R (adaptive
        filters append every step; the first entry holds the initial values).
    """

    name = "base"

    def __init__(self, system: DiscreteModel, x0, P0, Q, R, backend: str = "compiled"):
        if not isinstance(system, DiscreteModel):
            raise TypeError("system must be a DiscreteModel (build one with estimators.discretize)")
        self.system = system
        n, m, p = system.nx, system.nu, system.ny
        # canonical arrays, shared by the bound functions (column-major flat storage)
        self._x = checks.vector(x0, n, "x0").copy()
        self._P = np.asfortranarray(checks.covariance(P0, n, "P0")).ravel(order="F").copy()
        self._Q = checks.covariance(Q, n, "Q").ravel(order="F").copy()
        self._R = checks.covariance(R, p, "R").ravel(order="F").copy()
        self._u, self._y = np.zeros(m), np.zeros(p)
        self._nu, self._ny = m, p
        self.k = 0
        self.log = [{"k": 0, "Q": self.Q.copy(), "R": self.R.copy()}]
        key = self._cache_key() + (backend,)
        if key not in system.cache:
            system.cache[key] = compile_functions(list(self._build_functions()), backend)
        fns, self.backend = system.cache[key]
        self._bind(*fns)

    # ---------------------------------------------------------------- symbolic parts
    def _cache_key(self):
        return (type(self).__name__,)

    def _predict_expr(self, x, P, u, Q):
        """Return (x_prior, P_prior) expressions. Subclasses implement."""
        raise NotImplementedError

    def _update_expr(self, xp, Pp, y, R):
        """Return (x, P, innovation, S, K) expressions. Subclasses implement."""
        raise NotImplementedError

    def _symbols(self):
        s = self.system
        return (ca.SX.sym("x", s.nx), ca.SX.sym("P", s.nx, s.nx), ca.SX.sym("u", s.nu),
                ca.SX.sym("y", s.ny), ca.SX.sym("Q", s.nx, s.nx), ca.SX.sym("R", s.ny, s.ny))

    def _step_exprs(self):
        """Symbols and output expressions of the fused step, for subclasses that extend it."""
        x, P, u, y, Q, R = self._symbols()
        xp, Pp = self._predict_expr(x, P, u, Q)
        xu, Pu, innov, S, K = self._update_expr(xp, Pp, y, R)
        nis = ca.dot(innov, ca.solve(S, innov))
        return (x, P, u, y, Q, R), dict(x_new=xu, P_new=Pu, x_prior=xp, P_prior=Pp,
                                        innov=innov, S=S, K=K, nis=nis)

    @staticmethod
    def _status(inputs, outputs):
        return ca.if_else(_finite(inputs), ca.if_else(_finite(outputs), OK, BAD_RESULT), BAD_INPUT)

    def _build_functions(self):
        d = ca.densify
        x, P, u, y, Q, R = self._symbols()
        xp, Pp = self._predict_expr(x, P, u, Q)
        pred = ca.Function("predict", [x, P, u, Q], [d(xp), d(Pp), self._status([u], [xp, Pp])],
                           ["x", "P", "u", "Q"], ["x_prior", "P_prior", "status"])
        xu, Pu, innov, S, K = self._update_expr(x, P, y, R)
        nis = ca.dot(innov, ca.solve(S, innov))
        upd = ca.Function("update", [x, P, y, R],
                          [d(xu), d(Pu), d(innov), d(S), d(K), nis, self._status([y], [xu, Pu])],
                          ["x", "P", "y", "R"], ["x_new", "P_new", "innov", "S", "K", "nis", "status"])
        (x, P, u, y, Q, R), out = self._step_exprs()
        names = ["x_new", "P_new", "x_prior", "P_prior", "innov", "S", "K", "nis"]
        step = ca.Function("step", [x, P, u, y, Q, R],
                           [d(out[k]) for k in names]
                           + [self._status([u, y], [out["x_new"], out["P_new"]])],
                           ["x", "P", "u", "y", "Q", "R"], names + ["status"])
        return pred, upd, step

    # ---------------------------------------------------------------- binding
    def _bind(self, pred, upd, step):
        s = self.system
        n, p = s.nx, s.ny
        self._xprior, self._Pprior = np.zeros(n), np.zeros(n * n)
        self._xnew, self._Pnew = np.zeros(n), np.zeros(n * n)
        self._innov, self._S, self._K = np.zeros(p), np.zeros(p * p), np.zeros(n * p)
        self._nis, self._status_arr = np.zeros(1), np.zeros(1)
        self._fpred = BufferedFunction(pred, {0: self._x, 1: self._P, 2: self._u, 3: self._Q},
                                       {0: self._xprior, 1: self._Pprior, 2: self._status_arr})
        self._fupd = BufferedFunction(upd, {0: self._x, 1: self._P, 2: self._y, 3: self._R},
                                      {0: self._xnew, 1: self._Pnew, 2: self._innov, 3: self._S,
                                       4: self._K, 5: self._nis, 6: self._status_arr})
        # the fused step ping-pongs between two (x, P) array pairs: no copies on the hot path
        self._xs, self._Ps = (self._x, self._xnew), (self._P, self._Pnew)
        self._cur = 0
        self._fsteps = tuple(self._bind_step(step, i) for i in (0, 1))

    def _bind_step(self, step, i):
        """The fused step reading pair ``i`` and writing pair ``1 - i``."""
        j = 1 - i
        return BufferedFunction(step, {0: self._xs[i], 1: self._Ps[i], 2: self._u, 3: self._y,
                                       4: self._Q, 5: self._R},
                                {0: self._xs[j], 1: self._Ps[j], 2: self._xprior, 3: self._Pprior,
                                 4: self._innov, 5: self._S, 6: self._K, 7: self._nis,
                                 8: self._status_arr})

    def _sync(self):
        """Bring the current (x, P) into the canonical pair read by predict/update."""
        if self._cur:
            self._x[:] = self._xnew
            self._P[:] = self._Pnew
            self._cur = 0

    # ---------------------------------------------------------------- public state
    x = property(lambda self: self._xs[self._cur].copy(), doc="State estimate, shape (nx,).")
    P = property(lambda self: matrix(self._Ps[self._cur], self.system.nx, self.system.nx).copy(),
                 doc="State covariance, shape (nx, nx).")
    x_prior = property(lambda self: self._xprior.copy())
    P_prior = property(lambda self: matrix(self._Pprior, self.system.nx, self.system.nx).copy())
    Q = property(lambda self: matrix(self._Q, self.system.nx, self.system.nx).copy())
    R = property(lambda self: matrix(self._R, self.system.ny, self.system.ny).copy())
    innovation = property(lambda self: self._innov.copy())
    S = property(lambda self: matrix(self._S, self.system.ny, self.system.ny).copy())
    K = property(lambda self: matrix(self._K, self.system.nx, self.system.ny).copy())
    nis = property(lambda self: float(self._nis[0]))

    def set_noise(self, Q=None, R=None) -> None:
        """Replace Q and/or R (validated: symmetric positive definite)."""
        if Q is not None:
            self._Q[:] = checks.covariance(Q, self.system.nx, "Q").ravel(order="F")
        if R is not None:
            self._R[:] = checks.covariance(R, self.system.ny, "R").ravel(order="F")
        self.log.append({"k": self.k, "Q": self.Q, "R": self.R})

    # ---------------------------------------------------------------- stepping
    def _set_u(self, u):
        try:
            if self._nu > 1 and len(u) != self._nu:
                raise ValueError
            self._u[:] = u
        except (ValueError, TypeError):
            raise ValueError(f"u must have shape ({self._nu},), got shape {np.shape(u)}") from None

    def _set_y(self, y):
        try:
            if len(y) != self._ny:
                raise ValueError
            self._y[:] = y
        except (ValueError, TypeError):
            raise ValueError(f"y must have shape ({self._ny},), got shape {np.shape(y)}") from None

    def _check(self, what: str):
        st = self._status_arr[0]
        if st == BAD_INPUT:
            raise ValueError(f"{self.name}: {what} contains NaN or inf at step {self.k} "
                             f"(u = {self._u}, y = {self._y}); filter state unchanged "
                             "(pass y=None for a step without measurement)")
        if st == BAD_RESULT:
            raise FloatingPointError(f"{self.name}: the estimate became non-finite at step {self.k}; "
                                     "filter state unchanged (diverged, or covariances too large)")

    def predict(self, u) -> np.ndarray:
        """Time update with input ``u`` (nu,); returns the prior state estimate."""
        self._sync()
        self._set_u(u)
        self._fpred.trigger()
        if self._status_arr[0]:
            self._check("u")
        self._x[:] = self._xprior
        self._P[:] = self._Pprior
        self.k += 1
        return self._x.copy()

    def update(self, y) -> np.ndarray:
        """Measurement update with ``y`` (ny,); returns the posterior state estimate."""
        self._sync()
        self._set_y(y)
        self._fupd.trigger()
        if self._status_arr[0]:
            self._check("y")
        self._x[:] = self._xnew
        self._P[:] = self._Pnew
        self._after_update()
        return self._x.copy()

    def step(self, u, y) -> np.ndarray:
        """Predict with ``u`` then update with ``y``; ``y=None`` predicts only.

        Returns a copy of the new state estimate, shape ``(nx,)``.
        """
        if y is None:
            return self.predict(u)
        self._set_u(u)
        self._set_y(y)
        self._fsteps[self._cur].trigger()
        if self._status_arr[0]:
            self._check("u or y")
        self._cur ^= 1
        self.k += 1
        self._after_update()
        return self._xs[self._cur].copy()

    def _after_update(self):
        """Hook for adaptive filters (runs after every measurement update)."""

    def run(self, us, ys) -> np.ndarray:
        """Filter whole sequences: ``us`` (N, nu), ``ys`` (N, ny) with NaN rows allowed for
        missing measurements. Returns the estimates, shape (N, nx)."""
        us, ys = np.asarray(us, float), np.asarray(ys, float)
        out = np.empty((len(us), self.system.nx))
        for k in range(len(us)):
            yk = ys[k]
            out[k] = self.step(us[k], None if np.all(np.isnan(yk)) else yk)
        return out

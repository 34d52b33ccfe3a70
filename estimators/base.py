"""The interface and machinery shared by every Gaussian filter in this package.

A filter is a *state* (arrays ``x, P, Q, R`` and, for adaptive filters, more) and three
CasADi Functions built once per model (cached on the
:class:`~estimators.system.DiscreteModel`) and compiled to native code: ``predict``,
``update`` and the fused ``step``, which maps the whole state to the next one. Each is
bound to the filter's numpy arrays with :class:`~estimators._buffered.BufferedFunction`;
the fused step ping-pongs between two copies of the state, so a step is one call into
native code plus the copies of ``u`` and ``y``. Every Function also returns a status: 1
if an input was NaN or inf, 2 if the result was not finite; the filter then raises and
keeps its previous state.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from fmu_models import checks
from ._buffered import BufferedFunction, matrix
from ._compiled import compile_functions
from .history import NoiseHistory
from .system import DiscreteModel

OK, BAD_INPUT, BAD_RESULT = 0, 1, 2
#: Outputs of every fused step besides the state, in order.
DIAGNOSTICS = ("x_prior", "P_prior", "innov", "S", "K", "nis")


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


def _status(inputs, outputs):
    return ca.if_else(_finite(inputs), ca.if_else(_finite(outputs), OK, BAD_RESULT), BAD_INPUT)


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
    backend : {"compiled", "vm"}
        Run the filter's CasADi Functions as compiled native code (cached on disk, about
        10x faster; needs a C compiler, else falls back to "vm") or in CasADi's VM.

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
        The backend in use.
    k : int
        Number of predictions done.
    history : NoiseHistory
        Record of the diagonals of Q and R: the initial values, each :meth:`set_noise`,
        and every adaptation of an adaptive filter; :meth:`noise_history` gives it as a
        DataFrame.
    """

    name = "base"

    def __init__(self, system: DiscreteModel, x0, P0, Q, R, backend: str = "compiled"):
        if not isinstance(system, DiscreteModel):
            raise TypeError("system must be a DiscreteModel (build one with estimators.discretize)")
        self.system = system
        n, m, p = system.nx, system.nu, system.ny
        self._nu, self._ny = m, p
        init = {"x": checks.vector(x0, n, "x0"),
                "P": checks.covariance(P0, n, "P0").ravel(order="F"),
                "Q": checks.covariance(Q, n, "Q").ravel(order="F"),
                "R": checks.covariance(R, p, "R").ravel(order="F"),
                **self._extra_state_init()}
        # two copies of the state; self._cur says which holds the current one
        self._pairs = {k: (np.array(v, float), np.array(v, float)) for k, v in init.items()}
        self._cur = 0
        self._u, self._y = np.zeros(m), np.zeros(p)
        self._diag = {"x_prior": np.zeros(n), "P_prior": np.zeros(n * n), "innov": np.zeros(p),
                      "S": np.zeros(p * p), "K": np.zeros(n * p), "nis": np.zeros(1)}
        self._status_arr = np.zeros(1)
        self.k = 0
        key = self._cache_key() + (backend,)
        if key not in system.cache:
            raw = list(self._build_functions())
            system.cache[key] = compile_functions(raw, backend) + (raw,)
        fns, self.backend, self._raw_functions = system.cache[key]
        self._bind(*fns)
        self.history = NoiseHistory(n, p)
        self._record()

    # ---------------------------------------------------------------- symbolic parts
    def _cache_key(self):
        return (type(self).__name__,)

    def _extra_state_init(self) -> dict:
        """Initial values of extra state arrays (adaptive filters), by name."""
        return {}

    def _predict_expr(self, x, P, u, Q):
        """Return (x_prior, P_prior) expressions. Subclasses implement."""
        raise NotImplementedError

    def _update_expr(self, xp, Pp, y, R):
        """Return (x, P, innovation, S, K) expressions. Subclasses implement."""
        raise NotImplementedError

    def _sym(self, name, rows, cols=1):
        return ca.SX.sym(name, rows, cols)

    def _step_spec(self):
        """Fused step: ``(state symbols, extra input symbols, new state, diagnostics, extra outputs)``.

        Adaptive filters extend it: the new Q and R become functions of the step.
        """
        s = self.system
        st = {"x": self._sym("x", s.nx), "P": self._sym("P", s.nx, s.nx),
              "Q": self._sym("Q", s.nx, s.nx), "R": self._sym("R", s.ny, s.ny)}
        u, y = self._sym("u", s.nu), self._sym("y", s.ny)
        xp, Pp = self._predict_expr(st["x"], st["P"], u, st["Q"])
        xu, Pu, innov, S, K = self._update_expr(xp, Pp, y, st["R"])
        nis = ca.dot(innov, ca.solve(S, innov))
        new = {"x": xu, "P": Pu, "Q": st["Q"], "R": st["R"]}
        diag = dict(zip(DIAGNOSTICS, (xp, Pp, innov, S, K, nis)))
        return st, {"u": u, "y": y}, new, diag, {}

    def _build_functions(self):
        d = ca.densify
        s = self.system
        x, P, u, y = (self._sym("x", s.nx), self._sym("P", s.nx, s.nx), self._sym("u", s.nu),
                      self._sym("y", s.ny))
        Q, R = self._sym("Q", s.nx, s.nx), self._sym("R", s.ny, s.ny)
        xp, Pp = self._predict_expr(x, P, u, Q)
        pred = ca.Function("predict", [x, P, u, Q], [d(xp), d(Pp), _status([u], [xp, Pp])],
                           ["x", "P", "u", "Q"], ["x_prior", "P_prior", "status"])
        xu, Pu, innov, S, K = self._update_expr(x, P, y, R)
        nis = ca.dot(innov, ca.solve(S, innov))
        upd = ca.Function("update", [x, P, y, R],
                          [d(xu), d(Pu), d(innov), d(S), d(K), nis, _status([y], [xu, Pu])],
                          ["x", "P", "y", "R"], ["x_new", "P_new", "innov", "S", "K", "nis", "status"])
        st, ins, new, diag, extra = self._step_spec()
        outs = [d(new[k]) for k in st] + [d(diag[k]) for k in DIAGNOSTICS] + [d(v) for v in extra.values()]
        status = _status(list(ins.values()), [new["x"], new["P"], new["Q"], new["R"]])
        step = ca.Function("step", list(st.values()) + list(ins.values()), outs + [status],
                           list(st) + list(ins),
                           [f"{k}_new" for k in st] + list(DIAGNOSTICS) + list(extra) + ["status"])
        return pred, upd, step

    # ---------------------------------------------------------------- binding
    def _bind(self, pred, upd, step):
        zero = {k: v[0] for k, v in self._pairs.items()}
        self._fpred = BufferedFunction(pred, {0: zero["x"], 1: zero["P"], 2: self._u, 3: zero["Q"]},
                                       {0: self._diag["x_prior"], 1: self._diag["P_prior"],
                                        2: self._status_arr})
        self._xnew, self._Pnew = np.zeros_like(zero["x"]), np.zeros_like(zero["P"])
        self._fupd = BufferedFunction(upd, {0: zero["x"], 1: zero["P"], 2: self._y, 3: zero["R"]},
                                      {0: self._xnew, 1: self._Pnew, 2: self._diag["innov"],
                                       3: self._diag["S"], 4: self._diag["K"], 5: self._diag["nis"],
                                       6: self._status_arr})
        # step inputs: state, then u, y and any extra inputs; outputs: new state,
        # diagnostics, extra outputs, status
        self._inputs = {"u": self._u, "y": self._y}
        for i in range(step.n_in()):
            name = step.name_in(i)
            if name not in self._pairs and name not in self._inputs:
                self._inputs[name] = np.zeros(step.nnz_in(i))
        self._extra = {step.name_out(i): np.zeros(step.nnz_out(i)) for i in range(step.n_out())
                       if step.name_out(i) not in DIAGNOSTICS and step.name_out(i) != "status"
                       and not step.name_out(i).endswith("_new")}
        self._fsteps = tuple(self._bind_step(step, i) for i in (0, 1))

    def _bind_step(self, step, i):
        """The fused step reading state copy ``i`` and writing copy ``1 - i``."""
        args, res = {}, {}
        for j in range(step.n_in()):
            name = step.name_in(j)
            args[j] = self._pairs[name][i] if name in self._pairs else self._inputs[name]
        for j in range(step.n_out()):
            name = step.name_out(j)
            if name.endswith("_new"):
                res[j] = self._pairs[name[:-4]][1 - i]
            elif name == "status":
                res[j] = self._status_arr
            elif name in self._diag:
                res[j] = self._diag[name]
            else:
                res[j] = self._extra[name]
        return BufferedFunction(step, args, res)

    def _now(self, key: str) -> np.ndarray:
        """The current copy of state array ``key`` (shared, not a copy)."""
        return self._pairs[key][self._cur]

    def _sync(self):
        """Bring the current state into copy 0, which predict and update read."""
        if self._cur:
            for a, b in self._pairs.values():
                a[:] = b
            self._cur = 0

    # ---------------------------------------------------------------- public state
    def _mat(self, key, rows, cols):
        return matrix(self._now(key), rows, cols).copy()

    x = property(lambda self: self._now("x").copy(), doc="State estimate, shape (nx,).")
    P = property(lambda self: self._mat("P", self.system.nx, self.system.nx),
                 doc="State covariance, shape (nx, nx).")
    Q = property(lambda self: self._mat("Q", self.system.nx, self.system.nx),
                 doc="Process noise covariance, shape (nx, nx).")
    R = property(lambda self: self._mat("R", self.system.ny, self.system.ny),
                 doc="Measurement noise covariance, shape (ny, ny).")
    x_prior = property(lambda self: self._diag["x_prior"].copy())
    P_prior = property(lambda self: matrix(self._diag["P_prior"], self.system.nx, self.system.nx).copy())
    innovation = property(lambda self: self._diag["innov"].copy())
    S = property(lambda self: matrix(self._diag["S"], self.system.ny, self.system.ny).copy())
    K = property(lambda self: matrix(self._diag["K"], self.system.nx, self.system.ny).copy())
    nis = property(lambda self: float(self._diag["nis"][0]))

    def set_noise(self, Q=None, R=None) -> None:
        """Replace Q and/or R (validated: symmetric positive definite)."""
        if Q is not None:
            self._now("Q")[:] = checks.covariance(Q, self.system.nx, "Q").ravel(order="F")
        if R is not None:
            self._now("R")[:] = checks.covariance(R, self.system.ny, "R").ravel(order="F")
        self._record()

    def _record(self) -> None:
        n, p = self.system.nx, self.system.ny
        self.history.append(self.k, np.concatenate([self._now("Q")[:: n + 1], self._now("R")[:: p + 1]]))

    def noise_history(self):
        """How Q and R changed: DataFrame indexed by step with their diagonals."""
        return self.history.to_frame(self.system.state_names, self.system.output_names)

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
        x, P = self._pairs["x"][0], self._pairs["P"][0]
        x[:] = self._diag["x_prior"]
        P[:] = self._diag["P_prior"]
        self.k += 1
        return x.copy()

    def update(self, y) -> np.ndarray:
        """Measurement update with ``y`` (ny,); returns the posterior state estimate.

        Adaptive filters adapt Q and R only in :meth:`step` (their adaptation is part of
        the fused step); a separate update leaves Q and R unchanged.
        """
        self._sync()
        self._set_y(y)
        self._fupd.trigger()
        if self._status_arr[0]:
            self._check("y")
        x, P = self._pairs["x"][0], self._pairs["P"][0]
        x[:] = self._xnew
        P[:] = self._Pnew
        return x.copy()

    supports_batch = True

    def _prepare_step(self):
        """Hook: fill extra step inputs before the fused step (adaptive filters)."""

    def _after_step(self):
        """Hook: runs after every fused step, once the new state is current."""

    def step(self, u, y) -> np.ndarray:
        """Predict with ``u`` then update with ``y``; ``y=None`` predicts only.

        Returns a copy of the new state estimate, shape ``(nx,)``.
        """
        if y is None:
            return self.predict(u)
        self._set_u(u)
        self._set_y(y)
        self._prepare_step()
        self._fsteps[self._cur].trigger()
        if self._status_arr[0]:
            self._check("u or y")
        self._cur ^= 1
        self.k += 1
        self._after_step()
        return self._pairs["x"][self._cur].copy()

    def run(self, us, ys) -> np.ndarray:
        """Filter whole sequences: ``us`` (N, nu), ``ys`` (N, ny) with NaN rows for
        missing measurements. Returns the estimates, shape (N, nx)."""
        us, ys = np.asarray(us, float), np.asarray(ys, float)
        out = np.empty((len(us), self.system.nx))
        for k in range(len(us)):
            yk = ys[k]
            out[k] = self.step(us[k], None if np.all(np.isnan(yk)) else yk)
        return out

"""The interface and machinery shared by every Gaussian filter in this package.

A filter is a *state* (arrays ``x, P, Q, R`` and, for adaptive filters, more) and one
CasADi Function built once per model and filter configuration, the fused ``step``, which
maps the state and ``(u, y, mask)`` to the next state and the step's diagnostics. It is
compiled to native code (:mod:`estimators._compiled`) and:

* bound to the filter's numpy arrays (:class:`~estimators._buffered.BufferedFunction`,
  ping-pong between two copies of the state): :meth:`KalmanBase.step` is one native
  call plus the copies of ``u`` and ``y``;
* folded over a whole trajectory (:meth:`KalmanBase.run`: one native call, returning every
  step's estimate, covariance and diagnostics; :mod:`estimators._fold`);
* mapped over Monte Carlo realisations (:class:`~estimators.batch.BatchFilter`).

Missing measurements: the step takes a 0/1 ``mask`` per measurement channel; a NaN
measurement counts as missing too (unless ``nan_is_missing=False``). The update then uses
the valid channels only (rows of ``H`` and of the innovation zeroed, ``S`` padded with
ones on the missing diagonal: exactly the update of the reduced measurement vector), and
with no valid channel the step is a prediction. An optional chi-square gate refuses a
measurement vector whose NIS exceeds ``gate`` (the step is then a prediction, and
``accepted`` is 0). Every step also returns a status: 1 if ``u`` or a valid ``y`` entry
was NaN or inf, 2 if the result was not finite; the filter then raises and keeps its
previous state. Finiteness is tested entry by entry, so no finite value can overflow the test.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from fmu_models import checks
from fmu_models.errors import (
    ConfigurationError,
    InputError,
    NumericalError,
    TypeMismatchError,
    UnknownNameError,
)

from ._buffered import BufferedFunction, matrix
from ._compiled import compile_functions
from .history import NoiseHistory
from .system import DiscreteModel

__all__ = ["DIAGNOSTICS", "FilterRun", "KalmanBase", "gated_gain", "joseph_update",
           "mask_measurement", "symmetric"]

OK, BAD_INPUT, BAD_RESULT = 0, 1, 2
#: Outputs of every fused step besides the state, in order.
DIAGNOSTICS = ("x_prior", "P_prior", "innov", "S", "K", "nis", "accepted", "logdet_S")
#: Outputs that are symmetric matrices (exactly: their lower triangle mirrors the upper).
SYMMETRIC = ("P_new", "P_prior", "S", "Q_new", "R_new")
#: What run(keep="estimates") does not store.
DROPPABLE = ("x_prior", "P_prior", "innov", "S", "K")
KEEP = ("all", "estimates")
#: The step's inputs after the state arrays.
STEP_INPUTS = ("u", "y", "mask", "gate", "nan_missing")
#: Options of the compiled Functions: common subexpressions merged once more after the
#: Jacobians (AD re-creates e.g. cos(theta) beside the model's own; 6 transcendental calls
#: become 2 in the cart-pole EKF step, 0.31 -> 0.2x us).
CSE = {"cse": True}


def symmetric(M: ca.SX) -> ca.SX:
    """The symmetric matrix with ``M``'s upper triangle: a covariance exactly symmetric by
    construction, and only the upper triangle of ``M`` is ever computed (the generated
    code drops the other half; 16 % fewer operations in the cart-pole EKF step)."""
    n = M.shape[0]
    out = ca.SX(n, n)
    for i in range(n):
        for j in range(n):
            out[i, j] = M[min(i, j), max(i, j)]
    return out


def cholesky_lower(P: ca.SX) -> ca.SX:
    """Lower-triangular L with ``P = L L^T``, written out for a symbolic n x n matrix."""
    n = P.shape[0]
    L = ca.SX.zeros(n, n)
    for j in range(n):
        d = P[j, j] - sum((L[j, k] ** 2 for k in range(j)), ca.SX(0))
        L[j, j] = ca.sqrt(d)
        for i in range(j + 1, n):
            L[i, j] = (P[i, j] - sum((L[i, k] * L[j, k] for k in range(j)), ca.SX(0))) / L[j, j]
    return L


def spd_solve(A: ca.SX, B: ca.SX) -> ca.SX:
    """``X`` with ``A X = B`` for a symmetric positive-definite ``A``, by its Cholesky
    factor (forward and back substitution; about 40 % fewer operations than CasADi's
    general symbolic solve for a 4 x 4 system). A matrix that is not positive definite
    gives NaN, which the filters' status reports."""
    L = cholesky_lower(A)
    n, m = A.shape[0], B.shape[1]
    Y = ca.SX.zeros(n, m)
    for i in range(n):
        row = B[i, :] - (ca.mtimes(L[i, :i], Y[:i, :]) if i else 0)
        Y[i, :] = row / L[i, i]
    X = ca.SX.zeros(n, m)
    for i in range(n - 1, -1, -1):
        row = Y[i, :] - (ca.mtimes(L[i + 1:, i].T, X[i + 1:, :]) if i < n - 1 else 0)
        X[i, :] = row / L[i, i]
    return X


def log_det(S: ca.SX) -> ca.SX:
    """``log det S`` of a symmetric positive-definite matrix: one log of the expanded
    determinant up to 3 x 3, the Cholesky factor's diagonal beyond."""
    n = S.shape[0]
    if n <= 3:
        return ca.log(ca.det(S))
    L = cholesky_lower(S)
    return 2 * sum((ca.log(L[i, i]) for i in range(n)), ca.SX(0))


def gated_gain(S, B, innov, gate):
    """Gain ``K = B^T S^{-1}``, ``nis = innov^T S^{-1} innov`` and the gate's verdict
    ``nis <= gate``, from one Cholesky solve ``S Z = [B, innov]`` (no inverse)."""
    Z = spd_solve(S, ca.horzcat(B, innov))
    K = Z[:, : B.shape[1]].T
    nis = ca.dot(innov, Z[:, B.shape[1]])
    return K, nis, nis <= gate


def mask_measurement(valid, S_raw, innov_raw):
    """The update of the valid channels only, at fixed size: ``S`` with the rows and
    columns of missing channels replaced by those of the identity, and their innovation
    zeroed. Returns ``(S, innov, M)`` with ``M = diag(valid)``."""
    M = ca.diag(valid)
    S = symmetric(ca.mtimes([M, S_raw, M]) + ca.diag(1 - valid))
    return S, valid * innov_raw, M


def joseph_update(xp, Pp, innov, H, S, R, gate=ca.inf):
    """Kalman gain and Joseph-form update (seed 002 eqs 13-16; stable for any gain).

    ``K = Pp H^T S^{-1}`` (by a solve, no inverse); with ``Ka = K`` if the NIS passes the
    ``gate``, else 0: ``x = xp + Ka innov``, ``P = (I - Ka H) Pp (I - Ka H)^T + Ka R Ka^T``.
    Returns ``(x, P, K, nis, accepted)``.
    """
    n = xp.numel()
    K, nis, acc = gated_gain(S, ca.mtimes(H, Pp), innov, gate)
    Ka = acc * K
    IKH = ca.SX.eye(n) - ca.mtimes(Ka, H)
    P = symmetric(ca.mtimes([IKH, Pp, IKH.T]) + ca.mtimes([Ka, R, Ka.T]))
    return xp + ca.mtimes(Ka, innov), P, K, nis, acc


def _finite(expr_list) -> ca.SX:
    """1 if every entry is finite, else 0. Each entry is tested on its own (``|e| < inf``
    is 0 for NaN and inf) and the 0/1 results are counted, so nothing can overflow (a sum
    of the entries would, for finite values such as 1.5e308). (``e - e == 0`` would not
    do: CasADi simplifies ``e - e`` to 0.)"""
    count = sum(ca.sum1(ca.vec(ca.fabs(e) < ca.inf)) for e in expr_list)
    return count == sum(e.numel() for e in expr_list)


def not_nan(y: ca.SX) -> ca.SX:
    """1 where ``y`` is not NaN (inf included), per entry (``y == y`` would be simplified
    to 1 by CasADi)."""
    return ca.fabs(y) <= ca.inf


def used_measurement(y: ca.SX, mask: ca.SX, nan_missing: ca.SX) -> tuple[ca.SX, ca.SX]:
    """``(valid, y_used)``: a channel is used if its mask is set and (unless NaN is an error,
    ``nan_missing`` 0) it is not NaN; ``y_used`` is 0 in the others, so that a NaN of an
    unused channel stays out of every expression."""
    valid = mask * ca.if_else(nan_missing, not_nan(y), 1)
    return valid, ca.if_else(valid, y, 0)


def _log_likelihood(nis, logdet_S, n_used, accepted) -> float:
    """``-1/2 sum (nis + log det S + n_used log 2 pi)`` over the accepted steps (a missing
    channel contributes 1 to S's diagonal: log 1 = 0)."""
    terms = np.asarray(nis) + np.asarray(logdet_S) + np.asarray(n_used) * np.log(2 * np.pi)
    return -0.5 * float(np.sum(terms[np.asarray(accepted, bool)]))


def _upper(M: ca.SX) -> ca.SX:
    """The upper-triangular entries of a square matrix, as a column."""
    n = M.shape[0]
    return ca.vertcat(*[M[i, j] for j in range(n) for i in range(j + 1)])


def _status(inputs, outputs):
    return ca.if_else(_finite(inputs), ca.if_else(_finite(outputs), OK, BAD_RESULT), BAD_INPUT)


class FilterRun:
    """The result of :meth:`KalmanBase.run`: every step's estimate and diagnostics.

    Attributes (``N`` steps; arrays indexed by step ``k = 1..N`` in row ``k - 1``, except
    ``x`` and ``P`` which also hold the initial estimate in row 0):

    x : ndarray, shape (N + 1, nx)
        Estimates, row 0 the initial one.
    P : ndarray, shape (N + 1, nx, nx)
        Their covariances.
    x_prior, P_prior : ndarray, shapes (N, nx), (N, nx, nx)
        Predictions.
    innovation : ndarray, shape (N, ny)
        Innovations (0 in missing channels).
    S : ndarray, shape (N, ny, ny)
        Innovation covariances (1 on the diagonal of missing channels).
    K : ndarray, shape (N, nx, ny)
        Gains.
    nis : ndarray, shape (N,)
    accepted : ndarray of bool, shape (N,)
        False where the gate refused the measurement.
    mask : ndarray of bool, shape (N, ny)
        The channels used (valid and not NaN).
    us : ndarray, shape (N, nu)
        The inputs (the smoother needs them).
    Q, R : ndarray, shapes (N + 1, nx), (N + 1, ny)
        Diagonals of Q and R in force after each step (row 0: initial).
    log_likelihood : float
        Gaussian log-likelihood of the measurements,
        ``-1/2 sum_k (nis_k + log det(2 pi S_k))`` over the valid channels.
    """

    def __init__(self, **arrays):
        self.__dict__.update(arrays)

    def to_frame(self, filt: KalmanBase):
        """Tidy DataFrame indexed by step ``k`` (0..N) with the estimate, the covariance
        diagonal, the innovation and NIS (NaN at k = 0)."""
        import pandas as pd

        s = filt.system
        n = len(self.x)
        data = {name: self.x[:, i] for i, name in enumerate(s.state_names)}
        data.update({f"P_{name}": self.P[:, i, i] for i, name in enumerate(s.state_names)})
        for j, name in enumerate(s.output_names):
            data[f"innovation_{name}"] = np.r_[np.nan, self.innovation[:, j]]
        data["nis"] = np.r_[np.nan, self.nis]
        data["accepted"] = np.r_[True, self.accepted]
        return pd.DataFrame(data, index=pd.RangeIndex(n, name="k"))


class KalmanBase:
    """Common interface: ``predict(u)``, ``update(y)``, ``step(u, y)``, ``run(us, ys)``.

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
    gate : float, optional
        Chi-square gate on the NIS: a measurement vector with ``nis > gate`` is refused
        (the step predicts only). E.g. ``scipy.stats.chi2.ppf(0.999, ny)``. Default None
        (no gate).
    nan_is_missing : bool
        A NaN measurement channel is missing (default True); with False it is an error.
    backend : {"compiled", "vm"}
        Run the filter's CasADi Function as compiled native code (cached on disk, about
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
        Last innovation ``y - h(x_prior)`` (seed 000 eq 26; 0 in missing channels).
    S : ndarray, shape (ny, ny)
        Its predicted covariance.
    K : ndarray, shape (nx, ny)
        Last gain.
    nis : float
        Normalised innovation squared ``innovation^T S^{-1} innovation``.
    accepted : bool
        False if the gate refused the last measurement.
    backend : str
        The backend in use.
    k : int
        Number of steps done.
    history : NoiseHistory
        Record of the diagonals of Q and R: the initial values, each :meth:`set_noise`,
        and every adaptation of an adaptive filter; :meth:`noise_history` gives it as a
        DataFrame.
    """

    name = "base"
    #: Whether the fused step holds the whole filter (BatchFilter and native run use it).
    supports_batch = True
    #: Whether Q and R are part of the state (adaptive filters) or fixed parameters of
    #: the step (then they are not carried from step to step).
    adapts_noise = False

    def __init__(self, system: DiscreteModel, x0, P0, Q, R, gate: float | None = None,
                 nan_is_missing: bool = True, backend: str = "compiled"):
        if not isinstance(system, DiscreteModel):
            raise TypeMismatchError("system must be a DiscreteModel (build one with estimators.discretize)")
        self.system = system
        n, m, p = system.nx, system.nu, system.ny
        self._nu, self._ny = m, p
        self.gate = np.inf if gate is None else checks.positive(gate, "gate")
        self.nan_is_missing = bool(nan_is_missing)
        noise = {"Q": checks.covariance(Q, n, "Q").ravel(order="F"),
                 "R": checks.covariance(R, p, "R").ravel(order="F")}
        init = {"x": checks.vector(x0, n, "x0", ConfigurationError),
                "P": checks.covariance(P0, n, "P0").ravel(order="F"),
                **(noise if self.adapts_noise else {}), **self._extra_state_init()}
        # two copies of the state; self._cur says which holds the current one
        self._pairs = {k: (np.array(v, float), np.array(v, float)) for k, v in init.items()}
        self._noise = {} if self.adapts_noise else noise     # fixed Q, R: step parameters
        self._cur = 0
        self._u, self._y, self._mask = np.zeros(m), np.zeros(p), np.ones(p)
        self._const = {"gate": np.array([self.gate]), "nan_missing": np.array([float(self.nan_is_missing)]),
                       **{k: np.asarray(v, float).ravel() for k, v in self._extra_params().items()}}
        self.k = 0
        key = self.cache_key + (backend,)
        if key not in system.cache:
            raw = self._build_step()
            system.cache[key] = compile_functions([raw], backend) + (raw,)
        (step,), self.backend, self._raw_step = system.cache[key]
        self._bind(step)
        self.history = NoiseHistory(n, p)
        self._record()

    # ---------------------------------------------------------------- symbolic parts
    @property
    def cache_key(self) -> tuple:
        """What identifies this filter's compiled step (type and configuration)."""
        return (type(self).__name__,)

    def _extra_state_init(self) -> dict:
        """Initial values of extra state arrays (adaptive filters), by name."""
        return {}

    def _extra_params(self) -> dict:
        """Values of extra fixed inputs of the step (e.g. adaptation bounds), by name; the
        subclass adds a symbol of the same name to the step's inputs. Being inputs, not
        constants, they do not change the compiled code."""
        return {}

    def _predict_expr(self, x, P, u, Q):
        """Return (x_prior, P_prior) expressions. Subclasses implement."""
        raise NotImplementedError

    def _update_expr(self, xp, Pp, y, R, valid, gate):
        """Return (x, P, innovation, S, K, nis, accepted) expressions for the valid channels
        (``valid``: 0/1 per channel; a NIS above ``gate`` refuses the update). Subclasses
        implement (with :func:`mask_measurement` and :func:`gated_gain`)."""
        raise NotImplementedError

    def _sym(self, name, rows=1, cols=1):
        return ca.SX.sym(name, rows, cols)

    def _step_spec(self):
        """Fused step: ``(state symbols, input symbols, new state, diagnostics, extra outputs)``.

        Adaptive filters extend it: the new Q and R become functions of the step.
        """
        s = self.system
        st = {"x": self._sym("x", s.nx), "P": self._sym("P", s.nx, s.nx)}
        noise = {"Q": self._sym("Q", s.nx, s.nx), "R": self._sym("R", s.ny, s.ny)}
        ins = {"u": self._sym("u", s.nu), "y": self._sym("y", s.ny), "mask": self._sym("mask", s.ny),
               "gate": self._sym("gate"), "nan_missing": self._sym("nan_missing")}
        (st if self.adapts_noise else ins).update(noise)
        #: symbols of the filter-specific fixed inputs (see _extra_params)
        self._param_syms = {k: self._sym(k, np.size(v)) for k, v in self._extra_params().items()}
        ins.update(self._param_syms)
        valid, y_used = used_measurement(ins["y"], ins["mask"], ins["nan_missing"])
        xp, Pp = self._predict_expr(st["x"], st["P"], ins["u"], noise["Q"])
        xu, Pu, innov, S, K, nis, acc = self._update_expr(xp, Pp, y_used, noise["R"], valid, ins["gate"])
        new = {"x": xu, "P": Pu, **({"Q": noise["Q"], "R": noise["R"]} if self.adapts_noise else {})}
        diag = dict(zip(DIAGNOSTICS, (xp, Pp, innov, S, K, nis, acc, log_det(S))))
        self._valid_expr, self._inputs_checked = valid, [ins["u"], y_used]
        return st, ins, new, diag, {}

    def _build_step(self) -> ca.Function:
        d = ca.densify
        st, ins, new, diag, extra = self._step_spec()
        outs = [d(new[k]) for k in st] + [d(diag[k]) for k in DIAGNOSTICS] + [d(v) for v in extra.values()]
        # each distinct entry once (a symmetric matrix's lower triangle repeats the upper)
        checked = [new["x"]] + [_upper(new[k]) for k in ("P", "Q", "R") if k in new]
        status = _status(self._inputs_checked, checked)
        return ca.Function("step", list(st.values()) + list(ins.values()), outs + [status],
                           list(st) + list(ins),
                           [f"{k}_new" for k in st] + list(DIAGNOSTICS) + list(extra) + ["status"], CSE)

    # ---------------------------------------------------------------- binding
    def _bind(self, step: ca.Function) -> None:
        self._inputs = {"u": self._u, "y": self._y, "mask": self._mask, **self._const}
        self._diag = {name: np.zeros(step.nnz_out(name)) for name in DIAGNOSTICS}
        self._extra = {step.name_out(i): np.zeros(step.nnz_out(i)) for i in range(step.n_out())
                       if step.name_out(i) not in DIAGNOSTICS and step.name_out(i) != "status"
                       and not step.name_out(i).endswith("_new")}
        self._status_arr = np.zeros(1)
        self._fsteps = tuple(self._bind_step(step, i) for i in (0, 1))

    def _bind_step(self, step, i):
        """The fused step reading state copy ``i`` and writing copy ``1 - i``."""
        args, res = {}, {}
        for j in range(step.n_in()):
            name = step.name_in(j)
            args[j] = (self._pairs[name][i] if name in self._pairs else
                       self._noise[name] if name in self._noise else self._inputs[name])
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
        """The current copy of state array ``key`` (or of the fixed Q or R; shared)."""
        return self._pairs[key][self._cur] if key in self._pairs else self._noise[key]

    # ---------------------------------------------------------------- public state
    def state_arrays(self) -> dict[str, np.ndarray]:
        """Copies of the flat state arrays (CasADi column-major), by name: ``x, P``, and
        ``Q, R`` with any other adaptive state; what :class:`~estimators.BatchFilter`
        starts from."""
        return {k: v[self._cur].copy() for k, v in self._pairs.items()}

    def parameter_arrays(self) -> dict[str, np.ndarray]:
        """Copies of the step's fixed inputs, flat column-major: ``gate``,
        ``nan_missing``, ``Q, R`` of a non-adaptive filter and any filter-specific ones."""
        return {k: v.copy() for k, v in {**self._const, **self._noise}.items()}

    def step_function(self) -> ca.Function:
        """The uncompiled fused step (a CasADi Function; see the module documentation)."""
        return self._raw_step

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
    accepted = property(lambda self: bool(self._diag["accepted"][0]))

    def reset(self, x0=None, P0=None) -> None:
        """Start again from ``x0`` (nx,) and ``P0`` (default: keep the current ones), with
        the current Q and R; the step count and an adaptive filter's window restart too."""
        n = self.system.nx
        x = self.x if x0 is None else checks.vector(x0, n, "x0", ConfigurationError)
        P = self.P if P0 is None else checks.covariance(P0, n, "P0")
        init = self._extra_state_init()
        for name, (a, b) in self._pairs.items():
            value = {"x": x, "P": P.ravel(order="F")}.get(name, init.get(name, a if self._cur == 0 else b))
            a[:] = value
            b[:] = value
        self._cur, self.k = 0, 0
        self._record()

    def set_noise(self, Q=None, R=None) -> None:
        """Replace Q and/or R (validated first: symmetric positive definite; on a refusal
        nothing changes)."""
        q = None if Q is None else checks.covariance(Q, self.system.nx, "Q").ravel(order="F")
        r = None if R is None else checks.covariance(R, self.system.ny, "R").ravel(order="F")
        if q is not None:
            self._now("Q")[:] = q
        if r is not None:
            self._now("R")[:] = r
        self._record()

    def _record(self) -> None:
        n, p = self.system.nx, self.system.ny
        self.history.append(self.k, np.concatenate([self._now("Q")[:: n + 1], self._now("R")[:: p + 1]]))

    def noise_history(self):
        """How Q and R changed: DataFrame indexed by step with their diagonals."""
        return self.history.to_frame(self.system.state_names, self.system.output_names)

    # ---------------------------------------------------------------- stepping
    def _set(self, buf: np.ndarray, value, what: str, allow_scalar: bool) -> None:
        if value is None:
            raise TypeMismatchError(f"{self.name}: {what} is None; expected {len(buf)} number(s)")
        if isinstance(value, (str, bytes)):
            raise TypeMismatchError(f"{self.name}: {what} must be numbers, got the string {value!r}")
        scalar = np.ndim(value) == 0
        if scalar and not (allow_scalar and len(buf) == 1):
            raise InputError(f"{self.name}: {what} must have shape ({len(buf)},), got the scalar {value!r}")
        try:
            if not scalar and len(value) != len(buf):
                raise InputError(f"{self.name}: {what} must have shape ({len(buf)},), got shape {np.shape(value)}")
            buf[:] = value
        except TypeError:
            raise TypeMismatchError(f"{self.name}: {what} must be {len(buf)} number(s), got {value!r}") from None
        except ValueError as e:
            if isinstance(e, InputError):
                raise
            raise TypeMismatchError(f"{self.name}: {what} must be numbers, got {value!r}") from None

    def _set_measurement(self, y, mask) -> None:
        self._set(self._y, y, "y", True)
        if mask is None:
            self._mask[:] = 1.0
        else:
            self._set(self._mask, mask, "mask", True)

    def _used_channels(self, ys: np.ndarray, masks: np.ndarray) -> np.ndarray:
        """Which channels of ``ys`` (..., ny) an update uses: masked in and (unless NaN is an
        error) not NaN."""
        return (masks != 0) & (~np.isnan(ys) if self.nan_is_missing else True)

    def _explain(self, what: str) -> None:
        """Raise the error of a failed step (the state is unchanged)."""
        st = self._status_arr[0]
        if st == BAD_INPUT:
            bad_u = np.flatnonzero(~np.isfinite(self._u))
            if len(bad_u):
                raise InputError(f"{self.name}: u contains NaN or inf at index {bad_u.tolist()} at step {self.k} "
                                 f"(u = {self._u}); filter state unchanged")
            used = self._mask != 0
            bad_y = np.flatnonzero(used & np.isinf(self._y) | (used & np.isnan(self._y) & ~self.nan_is_missing))
            raise InputError(f"{self.name}: y contains {'inf' if np.isinf(self._y[bad_y]).any() else 'NaN'} at "
                             f"index {bad_y.tolist()} at step {self.k} (y = {self._y}); filter state unchanged"
                             + ("" if self.nan_is_missing else " (nan_is_missing=False)"))
        if st == BAD_RESULT:
            raise NumericalError(f"{self.name}: the estimate became non-finite at step {self.k} ({what}); "
                                 "filter state unchanged (diverged, or covariances too large)")

    def _prepare_step(self):
        """Hook: fill extra step inputs before the fused step (none by default)."""

    def _after_step(self):
        """Hook: runs after every fused step, once the new state is current."""

    def step(self, u, y, mask=None) -> np.ndarray:
        """Predict with ``u`` (nu,), then update with ``y`` (ny,).

        ``y=None`` predicts only. NaN entries of ``y`` are missing channels (unless
        ``nan_is_missing=False``); ``mask`` (ny,) of bool marks further channels as
        missing (False). Returns a copy of the new state estimate, shape ``(nx,)``.

        Raises
        ------
        InputError
            ``u`` or a used ``y`` entry is NaN or inf, or a shape is wrong (the state is
            then unchanged).
        TypeMismatchError
            ``u`` or ``y`` is not numbers.
        NumericalError
            The estimate became non-finite (the state is unchanged).
        """
        self._set(self._u, u, "u", True)
        if y is None:
            self._y[:] = 0.0
            self._mask[:] = 0.0
        else:
            self._set_measurement(y, mask)
        self._prepare_step()
        self._fsteps[self._cur].trigger()
        if self._status_arr[0]:
            self._explain("step")
        self._cur ^= 1
        self.k += 1
        self._after_step()
        return self._pairs["x"][self._cur].copy()

    def predict(self, u) -> np.ndarray:
        """Time update with input ``u`` (nu,): a step without measurement; returns the
        prior state estimate."""
        return self.step(u, None)

    def update(self, y, mask=None) -> np.ndarray:
        """Measurement update alone with ``y`` (ny,) (and ``mask``), taking the current
        estimate as the prior: x and P are replaced by the update, and the diagnostics
        (innovation, S, K, nis, accepted) describe it. Q and R do not adapt here. Returns
        the posterior estimate."""
        s = self.system
        key = ("update", self.cache_key, self.backend)
        if key not in s.cache:
            xs, Ps, Rs = self._sym("x", s.nx), self._sym("P", s.nx, s.nx), self._sym("R", s.ny, s.ny)
            ys, ms, gs, nms = (self._sym("y", s.ny), self._sym("mask", s.ny), self._sym("gate"),
                               self._sym("nan_missing"))
            valid, y_used = used_measurement(ys, ms, nms)
            xu, Pu, innov, S, K, nis, acc = self._update_expr(xs, Ps, y_used, Rs, valid, gs)
            d = ca.densify
            fn = ca.Function("update", [xs, Ps, Rs, ys, ms, gs, nms],
                             [d(xu), d(Pu), d(innov), d(S), d(K), nis, acc, log_det(S),
                              _status([y_used], [xu, _upper(Pu)])], CSE)
            s.cache[key] = compile_functions([fn], self.backend)[0][0]
        self._set_measurement(y, mask)
        x_prior, P_prior = self._now("x").copy(), self._now("P").copy()
        res = s.cache[key](self._now("x"), matrix(self._now("P"), s.nx, s.nx),
                           matrix(self._now("R"), s.ny, s.ny), self._y, self._mask,
                           self.gate, float(self.nan_is_missing))
        self._status_arr[0] = float(res[-1])
        if self._status_arr[0]:
            self._explain("update")
        self._now("x")[:] = np.asarray(res[0]).ravel()
        self._now("P")[:] = np.asarray(res[1]).ravel(order="F")
        self._diag["x_prior"][:], self._diag["P_prior"][:] = x_prior, P_prior
        for name, value in zip(("innov", "S", "K", "nis", "accepted", "logdet_S"), res[2:8]):
            self._diag[name][:] = np.asarray(value).ravel(order="F")
        return self.x

    # ---------------------------------------------------------------- whole trajectories
    def native_fold(self):
        """The fused step folded over trajectories in native code
        (:class:`~estimators._fold.NativeFold`), compiled and cached on the model: what
        :meth:`run` and :meth:`BatchFilter.run <estimators.BatchFilter.run>` call."""
        from ._fold import NativeFold

        s = self.system
        key = ("fold", self.cache_key, self.backend)
        if key not in s.cache:
            s.cache[key] = NativeFold(self._raw_step, len(self._pairs), self.backend)
        return s.cache[key]

    def check_record(self, us, ys, masks=None):
        """A record ``(us, ys, masks)`` as contiguous float arrays of shapes (N, nu), (N, ny),
        (N, ny), or :class:`InputError` / :class:`TypeMismatchError` naming the problem."""
        us = checks.float_array(us, "us")
        ys = checks.float_array(ys, "ys")
        N = ys.shape[0] if ys.ndim else 0
        if us.ndim == 1 and self._nu == 1:
            us = us[:, None]
        if ys.ndim == 1 and self._ny == 1:
            ys = ys[:, None]
        if ys.shape != (N, self._ny) or us.shape != (N, self._nu):
            raise InputError(f"{self.name}: run needs us of shape (N, {self._nu}) and ys of shape "
                             f"(N, {self._ny}); got {us.shape} and {ys.shape}")
        if not np.isfinite(us).all():
            k = int(np.flatnonzero(~np.isfinite(us).all(axis=1))[0])
            raise InputError(f"{self.name}: us contains NaN or inf at index {k}")
        if masks is None:
            m = np.ones((N, self._ny))
        else:
            m = checks.float_array(masks, "masks")
            if m.shape != (N, self._ny):
                raise InputError(f"{self.name}: masks must have shape ({N}, {self._ny}), got {m.shape}")
        return tuple(np.ascontiguousarray(a, dtype=float) for a in (us, ys, m))

    def run(self, us, ys, masks=None, y0=None, keep: str = "all") -> FilterRun:
        """Filter whole sequences in one native call: ``step(us[k], ys[k], masks[k])`` for
        ``k = 0..N-1``.

        Parameters
        ----------
        y0 : array_like, shape (ny,), optional
            A measurement of the initial state: ``update(y0)`` before the first step (the
            model of pykalman and of EM over a record that starts with a measurement).
            ``x[0]``, ``P[0]`` of the result are then the updated ones and the
            log-likelihood includes it.
        us : array_like, shape (N, nu)
            Inputs; ``us[k]`` is held over the step that ends at measurement ``ys[k]``.
        ys : array_like, shape (N, ny)
            Measurements; NaN entries are missing (all NaN: a prediction only).
        masks : array_like of bool, shape (N, ny), optional
            False marks further missing channels.
        keep : {"all", "estimates"}
            Keep every diagnostic (default; what :func:`~estimators.rts_smooth` needs), or
            only the estimates ``x``, ``P`` (and the NIS, the acceptance and the
            log-likelihood): 192 instead of 464 bytes a step for the cart-pole EKF, for
            long records; the other attributes of the result are then None.

        Returns
        -------
        FilterRun
            Every step's estimate, covariance and diagnostics; the filter is left at the
            last step, as after N calls of :meth:`step` (equal to 1e-12).

        Raises
        ------
        InputError, NumericalError
            As :meth:`step`, naming the step; the filter's state is then unchanged.
        """
        us, ys, masks = self.check_record(us, ys, masks)
        if keep not in KEEP:
            raise UnknownNameError(f"{self.name}: keep must be one of {KEEP}, got {keep!r}")
        y0_ll = 0.0
        if y0 is not None:
            self.update(y0)
            d = self._diag
            y0_ll = _log_likelihood(d["nis"], d["logdet_S"], [self._used_channels(self._y, self._mask).sum()],
                                    d["accepted"] != 0)
        if not self.supports_batch:
            result = self._run_by_steps(us, ys, masks)
            result.log_likelihood += y0_ll
            return result
        N = len(ys)
        state = {k: v[None] for k, v in self.state_arrays().items()}
        init = self._initial_for_run
        fold = self.native_fold()
        # outputs carrying the state get a leading row for the initial state (FilterRun.x, .P)
        outs, views = fold.outputs(1, N, state, DROPPABLE if keep == "estimates" else ())
        args = {"u": us[None], "y": ys[None], "mask": masks[None],
                **{k: v[None] for k, v in self.parameter_arrays().items()}}
        fold(1, N, args, state, views)
        status = outs["status"][0, :, 0]
        if status.any():
            k = int(np.flatnonzero(status)[0])
            self._status_arr[0] = status[k]
            self._u[:], self._y[:], self._mask[:] = us[k], ys[k], masks[k]
            k_saved, self.k = self.k, self.k + k
            try:
                self._explain(f"run index {k}")
            finally:
                self.k = k_saved
        cat = {name: a[0] for name, a in outs.items()}
        result = self._make_run(cat, us, ys, masks, init)
        result.log_likelihood += y0_ll
        for name in self._pairs:                   # the filter now stands at the last step
            self._pairs[name][self._cur][:] = cat[f"{name}_new"][-1]
        for name in DIAGNOSTICS:
            self._diag[name][:] = cat[name][-1] if name in cat else views[name][0, -1]
        self.k += N
        self._after_run({name: (v[1:] if name.endswith("_new") else v) for name, v in cat.items()})
        return result

    def _make_run(self, cat: dict, us, ys, masks, init: dict) -> FilterRun:
        """A FilterRun from per-step outputs ``cat`` (row ``k``: step k's output, flat in
        CasADi's column-major layout) and the state ``init`` before the first step."""
        nx, ny = self.system.nx, self.system.ny

        def mats(name, r, c):
            if name in SYMMETRIC:      # mirrored by construction: the column-major rows are row-major
                return cat[name].reshape(-1, r, c)
            return cat[name].reshape(-1, c, r).transpose(0, 2, 1)

        acc = cat["accepted"].ravel() != 0
        nis = cat["nis"].ravel()
        used = self._used_channels(ys, masks)
        loglik = _log_likelihood(nis, cat["logdet_S"].ravel(), used.sum(axis=1), acc)
        N = len(nis)

        def with_initial(name, r, c, first):
            """States over k = 0..N: the outputs of run() carry the initial row already."""
            m = mats(name, r, c) if name != "x_new" else cat[name].reshape(-1, r)
            if len(m) == N + 1:
                return m
            return np.concatenate([first[None], m])

        if "Q_new" in cat:
            Qd = with_initial("Q_new", nx, nx, init["Q"]).diagonal(axis1=1, axis2=2)
            Rd = with_initial("R_new", ny, ny, init["R"]).diagonal(axis1=1, axis2=2)
        else:
            Qd = np.broadcast_to(np.diag(init["Q"]), (N + 1, nx))
            Rd = np.broadcast_to(np.diag(init["R"]), (N + 1, ny))
        kept = "x_prior" in cat
        return FilterRun(
            x=with_initial("x_new", nx, 1, init["x"]), P=with_initial("P_new", nx, nx, init["P"]),
            x_prior=cat["x_prior"].reshape(-1, nx) if kept else None,
            P_prior=mats("P_prior", nx, nx) if kept else None,
            innovation=cat["innov"].reshape(-1, ny) if kept else None, S=mats("S", ny, ny) if kept else None,
            K=mats("K", nx, ny) if kept else None, nis=nis,
            accepted=acc, mask=used & acc[:, None], us=us, Q=Qd, R=Rd, log_likelihood=loglik)

    @property
    def _initial_for_run(self) -> dict:
        nx, ny = self.system.nx, self.system.ny
        return {"x": self._now("x").copy(), "P": matrix(self._now("P"), nx, nx).copy(),
                "Q": matrix(self._now("Q"), nx, nx).copy(), "R": matrix(self._now("R"), ny, ny).copy()}

    def _run_by_steps(self, us, ys, masks) -> FilterRun:
        """``run`` for a filter whose adaptation is not all in the fused step (a loop of
        :meth:`step`)."""
        init = self._initial_for_run
        rec: dict = {k: [] for k in ("x_new", "P_new", "Q_new", "R_new", *DIAGNOSTICS)}
        for k in range(len(ys)):
            self.step(us[k], ys[k], masks[k] != 0)
            for key, val in (("x_new", self.x), ("P_new", self.P), ("Q_new", self.Q), ("R_new", self.R),
                             *((name, self._diag[name]) for name in DIAGNOSTICS)):
                rec[key].append(np.array(val, float).ravel(order="F"))
        return self._make_run({k: np.array(v) for k, v in rec.items()}, us, ys, masks, init)

    def _after_run(self, cat: dict) -> None:
        """Hook: after a native run, with the per-step outputs ``cat`` (adaptive filters
        record their Q, R history)."""

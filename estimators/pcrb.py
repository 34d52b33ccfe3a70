"""The posterior Cramér-Rao bound (PCRB): the lowest mean-square error any estimator can reach.

The information recursion of Tichavský, Muravchik and Nehorai (1998) for additive Gaussian noise,
``J_{k+1} = D22 - D21 (J_k + D11)^-1 D12``, ``D11 = E[F^T Q^-1 F]``, ``D12 = D21^T = -E[F^T] Q^-1``,
``D22 = Q^-1 + E[H^T R^-1 H]``, ``J_0 = P_0^-1``, in covariance form with expectations by Monte
Carlo over true trajectories (the guide's page on the experiments, docs/guide/experiments.md).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import scipy.linalg

from fmu_models.errors import InputError, NumericalError, TypeMismatchError
from fmu_models.infra import checks
from fmu_models.infra.memory import check_fits

from ._compiled import compile_functions
from .discrete import DiscreteModel, checked_model
from .runtime import BufferedFunction, broadcast_inputs

__all__ = ["PCRB", "posterior_crb", "rmse_ratio"]

#: Steps whose Jacobians are evaluated in one batched call (bounds the memory of a call
#: to ``runs x PCRB_CHUNK x nx^2`` numbers).
PCRB_CHUNK = 500
#: Points per call of the compiled Jacobians (one compiled library per model).
JACOBIAN_BLOCK = 1024


@dataclass
class PCRB:
    """The posterior Cramér-Rao bound along ``N`` steps (what :func:`posterior_crb` returns).

    Attributes
    ----------
    P : ndarray, shape (N + 1, nx, nx)
        The bound ``J_k^-1`` on the error covariance of any estimator of ``x_k`` from
        ``y_1 .. y_k``, k = 0..N (row 0: the prior covariance) [state units squared].
    runs : int
        Number of realisations the expectations were taken over.
    state_names : list of str
    known_initial_state : bool
        True if the bound assumed ``x_0`` known exactly (``P[0] = 0``).
    jacobians : str
        How the model's Jacobians were computed.
    """

    P: np.ndarray
    runs: int
    state_names: list = field(default_factory=list)
    known_initial_state: bool = False
    jacobians: str = ""

    @property
    def mse(self) -> np.ndarray:
        """Lower bound of the mean-square error of each state, ``[J_k^-1]_ii``, shape (N + 1, nx)."""
        return np.diagonal(self.P, axis1=1, axis2=2).copy()

    @property
    def rmse(self) -> np.ndarray:
        """Square root of :attr:`mse`, shape (N + 1, nx) [state units]."""
        return np.sqrt(self.mse)

    def __len__(self) -> int:
        """Number of steps ``N``."""
        return len(self.P) - 1


def _trajectories(X, nx: int) -> np.ndarray:
    X = checks.float_array(X, "true trajectories X")
    if X.ndim != 3 or X.shape[2] != nx:
        raise InputError(f"true trajectories X must have shape (runs, N + 1, {nx}), got {X.shape}")
    if X.shape[0] < 1:
        raise InputError("true trajectories X hold no realisation (runs = 0): the expectations need at least one")
    if X.shape[1] < 2:
        raise InputError(f"true trajectories X must hold at least two steps (x_0 and x_1), got {X.shape[1]}")
    bad = ~np.isfinite(X)
    if bad.any():
        r, k, i = map(int, np.argwhere(bad)[0])
        raise InputError(f"true trajectories X contain NaN or inf ({int(bad.sum())} entries; first: realisation "
                         f"{r}, step {k}, state {i})")
    return np.ascontiguousarray(X)


def _valid_channels(masks, ys, runs: int, N: int, ny: int) -> np.ndarray | None:
    """The used channels (runs, N, ny) of bool, or None if all are used."""
    valid = None                    # all used: no (runs, N, ny) array in the common case
    if masks is not None:
        m = checks.float_array(masks, "masks")
        try:
            m = np.broadcast_to(m, (runs, N, ny))
        except ValueError:
            raise InputError(f"masks must have shape ({runs}, {N}, {ny}), got {m.shape}") from None
        if not np.isin(m, (0.0, 1.0)).all():
            raise InputError("masks must hold 0/1 (or False/True) only")
        valid = m != 0
    if ys is not None:
        y = checks.float_array(ys, "measurements ys")
        if y.shape != (runs, N, ny):
            raise InputError(f"measurements ys must have shape ({runs}, {N}, {ny}), got {y.shape}")
        if np.isinf(y).any():
            raise InputError("measurements ys contain inf (a missing channel is NaN)")
        valid = ~np.isnan(y) if valid is None else valid & ~np.isnan(y)
    return None if valid is None or valid.all() else valid


def _measurement_weights(R: np.ndarray, valid: np.ndarray | None, runs: int, N: int) -> np.ndarray | None:
    """``W[r, k]`` (ny, ny): ``(R_ss)^-1`` embedded at the valid channels ``s`` of realisation
    ``r`` at step ``k + 1`` (zeros elsewhere); None if every channel is valid."""
    if valid is None:
        return None
    ny = R.shape[0]
    codes = valid.astype(np.int64) @ (1 << np.arange(ny, dtype=np.int64))
    W = np.zeros((runs, N, ny, ny))
    for code in np.unique(codes):
        s = np.flatnonzero((int(code) >> np.arange(ny)) & 1)
        if not len(s):
            continue
        w = np.zeros((ny, ny))
        w[np.ix_(s, s)] = scipy.linalg.cho_solve(scipy.linalg.cho_factor(R[np.ix_(s, s)], lower=True), np.eye(len(s)))
        W[codes == code] = w
    return W


class _Jacobians:
    """The exact Jacobians ``F(x, u)`` and ``H(x)`` of ``system``, compiled over :data:`JACOBIAN_BLOCK` points."""

    def __init__(self, system: DiscreteModel, backend: str = "compiled"):
        x, u = system.x, system.u
        xn = ca.SX.sym("x_next", system.nx)
        fn = ca.Function("pcrb_jacobians", [x, u, xn],
                         [ca.densify(ca.jacobian(system.fx, x)),
                          ca.densify(ca.substitute(ca.jacobian(system.hx, x), x, xn))])
        (mapped,), self.backend = compile_functions([fn.map(JACOBIAN_BLOCK, "serial")], backend)
        self.nx, self.nu, self.ny = system.nx, system.nu, system.ny
        self.fn = BufferedFunction(mapped)

    def __call__(self, xs: np.ndarray, us: np.ndarray, xn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``F`` at (``xs``, ``us``) and ``H`` at ``xn``: ``m`` points (..., nx), (..., nu),
        (..., nx) -> (m, nx, nx), (m, ny, nx)."""
        nx, ny, b = self.nx, self.ny, JACOBIAN_BLOCK
        m = int(np.prod(np.shape(xs)[:-1]))
        pts = [np.ascontiguousarray(a).reshape(m, a.shape[-1]) for a in (xs, us, xn)]   # nu may be 0
        F, H = np.empty((m, nx, nx)), np.empty((m, ny, nx))
        args, res = self.fn.args, self.fn.res
        for i0 in range(0, m, b):
            i1 = min(i0 + b, m)
            for a, p in zip(args, pts):
                blk = a.reshape(b, a.size // b)     # point-major = CasADi's column-major (dim, b)
                blk[:i1 - i0] = p[i0:i1]
                blk[i1 - i0:] = p[i1 - 1]           # pad the last block with a valid point
            self.fn.trigger()
            F[i0:i1] = res[0].reshape(b, nx, nx)[:i1 - i0].transpose(0, 2, 1)
            H[i0:i1] = res[1].reshape(b, nx, ny)[:i1 - i0].transpose(0, 2, 1)
        return F, H


def _root(M: np.ndarray) -> np.ndarray:
    """``Z`` with ``Z^T Z = M`` (..., n, n) by eigendecomposition (negative eigenvalues become 0)."""
    lam, U = np.linalg.eigh(0.5 * (M + np.swapaxes(M, -1, -2)))
    return np.sqrt(np.clip(lam, 0.0, None))[..., :, None] * np.swapaxes(U, -1, -2)


def _joseph(P: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """``(P^+ + Z^T Z)^-1``: the update of ``P`` (PSD, zero allowed) with the measurement
    matrix ``Z`` and unit noise, in Joseph form."""
    S = np.eye(len(Z)) + Z @ P @ Z.T
    L = np.linalg.cholesky(0.5 * (S + S.T))
    K = np.linalg.solve(L.T, np.linalg.solve(L, Z @ P)).T       # P Z^T S^-1 by the Cholesky factor
    A = np.eye(len(P)) - K @ Z
    out = A @ P @ A.T + K @ K.T
    return 0.5 * (out + out.T)


def posterior_crb(system: DiscreteModel, X, us, Q, R, P0=None, masks=None, ys=None) -> PCRB:
    """The posterior Cramér-Rao bound along true trajectories (Tichavský, Muravchik and
    Nehorai 1998, the recursion for additive Gaussian noise).

    Parameters
    ----------
    system : DiscreteModel
        The model ``x_{k+1} = f(x_k, u_k) + w_k``, ``y_k = h(x_k) + v_k`` (its exact Jacobians).
    X : array_like, shape (runs, N + 1, nx)
        True trajectories (``X[:, 0]``: the initial states) [state units]; the expectations
        are means over the realisations.
    us : array_like, shape (N, nu) or (runs, N, nu)
        Inputs; ``us[k]`` is held over the step ``k -> k + 1``.
    Q, R : array_like
        Process (nx, nx) and measurement (ny, ny) noise covariances, or their diagonal, or a
        scalar (times I); symmetric positive definite.
    P0 : array_like, optional
        Covariance of the prior of ``x_0`` (``J_0 = P0^-1``); None (default): ``x_0`` known
        exactly (the first prediction's covariance is ``Q``).
    masks, ys : array_like, shape (runs, N, ny), optional
        The missing channels: channel ``j`` of ``y_{k+1}`` of realisation ``r`` is missing where
        ``masks[r, k, j]`` is False or the measurement ``ys[r, k, j]`` is NaN (only that is used).

    Returns
    -------
    PCRB

    Raises
    ------
    TypeMismatchError
        ``system`` is not a DiscreteModel, or an argument is not numbers.
    ConfigurationError
        ``Q``, ``R`` or ``P0`` is not a finite symmetric positive definite matrix of its shape.
    InputError
        ``X``, ``us``, ``masks`` or ``ys`` has the wrong shape, or ``X`` or ``us`` is not finite.
    NumericalError
        A Jacobian along the trajectories, or the recursion, is not finite (an ill-posed model).
    ResourceError
        The work arrays would not fit in memory.
    """
    s = checked_model(system)
    X = _trajectories(X, s.nx)
    runs, N = X.shape[0], X.shape[1] - 1
    us = broadcast_inputs(us, runs, N, s.nu)
    Q, R = checks.covariance(Q, s.nx, "PCRB: Q"), checks.covariance(R, s.ny, "PCRB: R")
    P0 = None if P0 is None else checks.covariance(P0, s.nx, "PCRB: P0 (None for a known initial state)")
    return _Recursion(s, X, us, Q, R, P0, _valid_channels(masks, ys, runs, N, s.ny)).bound()


class _Recursion:
    """The recursion of :func:`posterior_crb` over checked arguments, :data:`PCRB_CHUNK` steps at a time."""

    def __init__(self, system: DiscreteModel, X: np.ndarray, us: np.ndarray, Q: np.ndarray, R: np.ndarray,
                 P0: np.ndarray | None, valid: np.ndarray | None):
        self.system, self.X, self.us, self.Q, self.P0 = system, X, us, Q, P0
        nx, ny = system.nx, system.ny
        runs, N = X.shape[0], X.shape[1] - 1
        self.chunk = min(N, PCRB_CHUNK)
        check_fits(8.0 * (runs * self.chunk * (4 * nx * nx + 3 * ny * nx) + (N + 1) * 4 * nx * nx
                          + (0 if valid is None else runs * N * ny * ny)),
                   f"the PCRB over {runs} realisations x {N} steps", "fewer realisations")
        self.W = _measurement_weights(R, valid, runs, N)
        Rinv = scipy.linalg.cho_solve(scipy.linalg.cho_factor(R, lower=True), np.eye(ny))
        self.Rinv = 0.5 * (Rinv + Rinv.T)
        self.Lq = scipy.linalg.cholesky(Q, lower=True)
        self.B = np.empty((N + 1, nx, nx))
        self.B[0] = np.zeros((nx, nx)) if P0 is None else P0

    def bound(self) -> PCRB:
        """The bound along every step."""
        N = len(self.B) - 1
        for k0 in range(0, N, self.chunk):
            n = min(self.chunk, N - k0)
            self._steps(k0, *self._information(k0, n))
        return PCRB(self.B, self.X.shape[0], list(self.system.state_names), self.P0 is None, self.system.jacobians)

    def _information(self, k0: int, n: int) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """For the ``n`` steps from ``k0``: the mean Jacobian ``F_bar`` (n, nx, nx), the roots
        ``Z`` of the spread ``V`` (None for one realisation) and of ``E[H^T R^-1 H]``."""
        X, runs = self.X, self.X.shape[0]
        nx, ny = self.system.nx, self.system.ny
        jacobians = self.system.compiled("pcrb", (JACOBIAN_BLOCK,), "compiled", lambda: _Jacobians(self.system))
        F, H = jacobians(X[:, k0:k0 + n], self.us[:, k0:k0 + n], X[:, k0 + 1:k0 + n + 1])
        F, H = F.reshape(runs, n, nx, nx), H.reshape(runs, n, ny, nx)
        if not (np.isfinite(F).all() and np.isfinite(H).all()):
            r, k = map(int, np.argwhere(~(np.isfinite(F).all(axis=(2, 3)) & np.isfinite(H).all(axis=(2, 3))))[0])
            failure = self.system.take_failure()
            raise (NumericalError if failure is None else type(failure))(
                f"PCRB: a Jacobian of the model is not finite along realisation {r} at step {k0 + k}"
                + ("" if failure is None else f": {failure}"))
        Fbar = F.mean(axis=0)                                                    # (n, nx, nx)
        # D = Lq^-1 (F - F_bar): V = E[D^T D], the spread of the Jacobians over the realisations
        D = scipy.linalg.solve_triangular(self.Lq, (F - Fbar).transpose(2, 0, 1, 3).reshape(nx, -1), lower=True)
        Dk = D.reshape(nx, runs, n, nx).transpose(2, 0, 1, 3).reshape(n, nx * runs, nx)    # (k, (j, r), i)
        Zv = _root(np.swapaxes(Dk, 1, 2) @ Dk / runs) if runs > 1 else None
        WH = (self.Rinv @ H) if self.W is None else self.W[:, k0:k0 + n] @ H               # (r, k, ny, nx)
        Hk, WHk = (a.transpose(1, 0, 2, 3).reshape(n, runs * ny, nx) for a in (H, WH))
        return Fbar, Zv, _root(np.swapaxes(Hk, 1, 2) @ WHk / runs)

    def _steps(self, k0: int, Fbar: np.ndarray, Zv: np.ndarray | None, Zy: np.ndarray) -> None:
        """The bound at steps ``k0 + 1 .. k0 + n`` from that at ``k0`` (``n = len(Fbar)``)."""
        B, Q, n = self.B, self.Q, len(Fbar)
        with np.errstate(over="ignore", invalid="ignore"):          # a non-finite bound is refused below
            for j in range(n):
                k = k0 + j
                try:
                    Bk = B[k] if Zv is None else _joseph(B[k], Zv[j])
                    P_pred = Fbar[j] @ Bk @ Fbar[j].T + Q
                    B[k + 1] = _joseph(0.5 * (P_pred + P_pred.T), Zy[j])
                except (np.linalg.LinAlgError, ValueError):
                    raise NumericalError(f"PCRB: the bound became non-finite at step {k + 1} (an ill-posed model "
                                         "or noise)") from None
        if not np.isfinite(B[k0 + 1:k0 + n + 1]).all():
            k = k0 + 1 + int(np.argwhere(~np.isfinite(B[k0 + 1:k0 + n + 1]).all(axis=(1, 2)))[0, 0])
            raise NumericalError(f"PCRB: the bound became non-finite at step {k} (an ill-posed model or noise)")


def rmse_ratio(err, bound: PCRB, steps=None) -> np.ndarray:
    """Each state's RMSE over realisations and steps as a multiple of the PCRB,
    ``sqrt(mean_{r,k} e_{r,k,i}^2 / mean_k [J_k^-1]_ii)``, shape (nx,) (1 is the best possible).

    Parameters
    ----------
    err : array_like, shape (runs, N + 1, nx) or (runs, N, nx)
        Estimation errors ``x_hat - x`` along the bound's steps (with or without k = 0) [state units].
    bound : PCRB
        The bound along the same steps.
    steps : slice, optional
        Which steps k to average over (default: 1..N, after the first measurement).
    """
    if not isinstance(bound, PCRB):
        raise TypeMismatchError(f"bound must be a PCRB (from estimators.posterior_crb), got {type(bound).__name__}")
    e = checks.float_array(err, "errors err")
    N, nx = len(bound), bound.P.shape[1]
    if e.ndim != 3 or e.shape[2] != nx or e.shape[1] not in (N, N + 1):
        raise InputError(f"errors err must have shape (runs, {N + 1} or {N}, {nx}), got {e.shape}")
    if e.shape[1] == N:
        e = np.concatenate([np.zeros_like(e[:, :1]), e], axis=1)
    sl = slice(1, None) if steps is None else steps
    mse = np.mean(np.square(e[:, sl]), axis=(0, 1))
    b = bound.mse[sl].mean(axis=0)
    if not (b > 0).all():
        raise InputError("the bound is zero on the steps chosen (a known initial state at k = 0)")
    return np.sqrt(mse / b)

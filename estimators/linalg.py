"""Symbolic linear algebra of the filters (CasADi SX; none inverts a matrix), and the Gaussian log-likelihood of a run.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["CSE", "cholesky_lower", "finite_flag", "gated_gain", "joseph_update", "log_det", "log_likelihood",
           "mask_measurement", "not_nan", "spd_solve", "status_flag", "symmetric", "upper_entries",
           "used_measurement"]

#: Options of the compiled Functions, common subexpressions merged once more after the
#: Jacobians (AD re-creates e.g. cos(theta) beside the model's own; 6 transcendental calls
#: become 2 in the cart-pole EKF step).
CSE = {"cse": True}
#: Status codes of a fused step (all finite, a bad input, a non-finite result).
OK, BAD_INPUT, BAD_RESULT = 0, 1, 2


def symmetric(M: ca.SX) -> ca.SX:
    """The symmetric matrix with ``M``'s upper triangle: exactly symmetric, and the generated
    code computes only that half (16 % fewer operations in the cart-pole EKF step)."""
    return ca.triu(M) + ca.triu(M, False).T


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
    """``X`` with ``A X = B`` for a symmetric positive-definite ``A``, by its Cholesky factor
    (about 40 % fewer operations than CasADi's general symbolic solve for a 4 x 4 system); an
    ``A`` that is not positive definite gives NaN, which the filters' status reports."""
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


def gated_gain(S: ca.SX, B: ca.SX, innov: ca.SX, gate) -> tuple[ca.SX, ca.SX, ca.SX]:
    """Gain ``K = B^T S^{-1}``, ``nis = innov^T S^{-1} innov`` and the verdict ``nis <= gate``
    (``inf``: no gate) from one Cholesky solve ``S Z = [B, innov]``: ``S`` (ny, ny) SPD, ``B``
    (ny, nx) (``H P^-`` or the cross-covariance transposed), ``innov`` (ny, 1)."""
    Z = spd_solve(S, ca.horzcat(B, innov))
    K = Z[:, : B.shape[1]].T
    nis = ca.dot(innov, Z[:, B.shape[1]])
    return K, nis, nis <= gate


def mask_measurement(valid: ca.SX, S_raw: ca.SX, innov_raw: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
    """The update of the ``valid`` channels (SX (ny, 1): 1 used, 0 missing) at fixed size:
    ``(S, innov, M)``, the innovation covariance ``S_raw`` (ny, ny) with the rows and columns of
    missing channels those of the identity, the innovation ``innov_raw`` (ny, 1) zero in them, and
    ``M = diag(valid)``."""
    M = ca.diag(valid)
    S = symmetric(ca.mtimes([M, S_raw, M]) + ca.diag(1 - valid))
    return S, valid * innov_raw, M


def joseph_update(xp: ca.SX, Pp: ca.SX, innov: ca.SX, H: ca.SX, S: ca.SX, R: ca.SX, gate=ca.inf) -> tuple:
    """Kalman gain and Joseph-form update (seed 002 eqs 13-16; stable for any gain):
    ``(x, P, K, nis, accepted)``.

    ``K = Pp H^T S^{-1}`` (by a solve); with ``Ka = K`` if the NIS passes the ``gate``, else 0:
    ``x = xp + Ka innov``, ``P = (I - Ka H) Pp (I - Ka H)^T + Ka R Ka^T``, from the prior ``xp``
    (nx, 1), ``Pp`` (nx, nx), the innovation ``innov`` (ny, 1), the masked Jacobian ``H`` (ny,
    nx), the innovation covariance ``S`` and the masked ``R`` (ny, ny).
    """
    n = xp.numel()
    K, nis, acc = gated_gain(S, ca.mtimes(H, Pp), innov, gate)
    Ka = acc * K
    IKH = ca.SX.eye(n) - ca.mtimes(Ka, H)
    P = symmetric(ca.mtimes([IKH, Pp, IKH.T]) + ca.mtimes([Ka, R, Ka.T]))
    return xp + ca.mtimes(Ka, innov), P, K, nis, acc


def finite_flag(expr_list) -> ca.SX:
    """1 if every entry of the SX sequence ``expr_list`` is finite, else 0: each entry tested on its
    own (``|e| < inf``; CasADi simplifies ``e - e`` to 0) and the results counted, so nothing can
    overflow (a sum of the entries would, for finite values such as 1.5e308)."""
    count = sum(ca.sum1(ca.vec(ca.fabs(e) < ca.inf)) for e in expr_list)
    return count == sum(e.numel() for e in expr_list)


def not_nan(y: ca.SX) -> ca.SX:
    """1 where ``y`` is not NaN (inf included), per entry (CasADi simplifies ``y == y`` to 1)."""
    return ca.fabs(y) <= ca.inf


def used_measurement(y: ca.SX, mask: ca.SX, nan_missing: ca.SX) -> tuple[ca.SX, ca.SX]:
    """``(valid, y_used)``: a channel of ``y`` is used if its ``mask`` is set and (unless
    ``nan_missing`` is 0) it is not NaN; ``y_used`` is 0 in the others (a NaN stays out)."""
    valid = mask * ca.if_else(nan_missing, not_nan(y), 1)
    return valid, ca.if_else(valid, y, 0)


def log_likelihood(nis, logdet_S, n_used, accepted) -> float:
    """``-1/2 sum (nis + logdet_S + n_used log 2 pi)`` over the ``accepted`` steps, from arrays
    of one length (``n_used``: channels used; a missing one contributes 1 to S's diagonal)."""
    terms = np.asarray(nis) + np.asarray(logdet_S) + np.asarray(n_used) * np.log(2 * np.pi)
    return -0.5 * float(np.sum(terms[np.asarray(accepted, bool)]))


def upper_entries(M: ca.SX) -> ca.SX:
    """The upper-triangular entries of the square SX ``M`` (n, n), column by column, as a column."""
    n = M.shape[0]
    return ca.vertcat(*[M[i, j] for j in range(n) for i in range(j + 1)])


def status_flag(inputs, outputs) -> ca.SX:
    """The step's status: :data:`OK` if every entry of ``inputs`` and ``outputs`` is finite,
    :data:`BAD_INPUT` if an input is not, :data:`BAD_RESULT` if only an output is not."""
    return ca.if_else(finite_flag(inputs), ca.if_else(finite_flag(outputs), OK, BAD_RESULT), BAD_INPUT)

"""Symbolic linear algebra of the filters: the CasADi SX building blocks every fused step is
made of (symmetric products, Cholesky solves, the gated Joseph-form update, the masked
measurement, finiteness tests), and the Gaussian log-likelihood of a run.

Each function takes and returns CasADi SX expressions (except :func:`log_likelihood`,
which sums numbers); none of them inverts a matrix.
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


def gated_gain(S: ca.SX, B: ca.SX, innov: ca.SX, gate) -> tuple[ca.SX, ca.SX, ca.SX]:
    """Gain ``K = B^T S^{-1}``, ``nis = innov^T S^{-1} innov`` and the gate's verdict
    ``nis <= gate``, from one Cholesky solve ``S Z = [B, innov]`` (no inverse).

    Parameters: ``S`` (ny, ny) symmetric positive definite, ``B`` (ny, nx) (``H P^-`` or
    the cross-covariance transposed), ``innov`` (ny, 1), ``gate`` a scalar (``inf``: no gate)."""
    Z = spd_solve(S, ca.horzcat(B, innov))
    K = Z[:, : B.shape[1]].T
    nis = ca.dot(innov, Z[:, B.shape[1]])
    return K, nis, nis <= gate


def mask_measurement(valid: ca.SX, S_raw: ca.SX, innov_raw: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
    """The update of the valid channels only, at fixed size.

    Parameters
    ----------
    valid : SX, shape (ny, 1)
        1 for a channel used, 0 for a missing one.
    S_raw : SX, shape (ny, ny)
        The innovation covariance of all channels.
    innov_raw : SX, shape (ny, 1)
        The innovation of all channels.

    Returns
    -------
    tuple
        ``(S, innov, M)``: ``S`` with the rows and columns of missing channels replaced by
        those of the identity, the innovation with those channels zeroed, and
        ``M = diag(valid)``.
    """
    M = ca.diag(valid)
    S = symmetric(ca.mtimes([M, S_raw, M]) + ca.diag(1 - valid))
    return S, valid * innov_raw, M


def joseph_update(xp: ca.SX, Pp: ca.SX, innov: ca.SX, H: ca.SX, S: ca.SX, R: ca.SX, gate=ca.inf) -> tuple:
    """Kalman gain and Joseph-form update (seed 002 eqs 13-16; stable for any gain).

    ``K = Pp H^T S^{-1}`` (by a solve, no inverse); with ``Ka = K`` if the NIS passes the
    ``gate``, else 0: ``x = xp + Ka innov``, ``P = (I - Ka H) Pp (I - Ka H)^T + Ka R Ka^T``.

    Parameters: the prior ``xp`` (nx, 1) and ``Pp`` (nx, nx), the innovation ``innov``
    (ny, 1), the (masked) measurement Jacobian ``H`` (ny, nx), the innovation covariance
    ``S`` and the (masked) ``R`` (ny, ny), and the ``gate``. Returns
    ``(x, P, K, nis, accepted)``.
    """
    n = xp.numel()
    K, nis, acc = gated_gain(S, ca.mtimes(H, Pp), innov, gate)
    Ka = acc * K
    IKH = ca.SX.eye(n) - ca.mtimes(Ka, H)
    P = symmetric(ca.mtimes([IKH, Pp, IKH.T]) + ca.mtimes([Ka, R, Ka.T]))
    return xp + ca.mtimes(Ka, innov), P, K, nis, acc


def finite_flag(expr_list) -> ca.SX:
    """1 if every entry is finite, else 0. Each entry is tested on its own (``|e| < inf``
    is 0 for NaN and inf) and the 0/1 results are counted, so nothing can overflow (a sum
    of the entries would, for finite values such as 1.5e308). (``e - e == 0`` would not
    do: CasADi simplifies ``e - e`` to 0.)

    Parameters
    ----------
    expr_list
        SX expressions whose entries are tested.
    """
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


def log_likelihood(nis, logdet_S, n_used, accepted) -> float:
    """``-1/2 sum (nis + log det S + n_used log 2 pi)`` over the accepted steps (a missing
    channel contributes 1 to S's diagonal: log 1 = 0).

    Parameters: per step the ``nis``, ``logdet_S``, the number of channels used
    ``n_used`` and whether the measurement was ``accepted`` (arrays of one length)."""
    terms = np.asarray(nis) + np.asarray(logdet_S) + np.asarray(n_used) * np.log(2 * np.pi)
    return -0.5 * float(np.sum(terms[np.asarray(accepted, bool)]))


def upper_entries(M: ca.SX) -> ca.SX:
    """The upper-triangular entries of a square matrix, as a column.

    Parameters
    ----------
    M
        A square SX matrix.
    """
    n = M.shape[0]
    return ca.vertcat(*[M[i, j] for j in range(n) for i in range(j + 1)])


def status_flag(inputs, outputs) -> ca.SX:
    """The step's status: :data:`OK` (0) if every entry of ``inputs`` and ``outputs`` is finite,
    :data:`BAD_INPUT` (1) if an input is not, :data:`BAD_RESULT` (2) if only an output is not."""
    return ca.if_else(finite_flag(inputs), ca.if_else(finite_flag(outputs), OK, BAD_RESULT), BAD_INPUT)

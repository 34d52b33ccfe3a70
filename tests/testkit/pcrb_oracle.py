"""An independent numpy implementation of the posterior Cramér-Rao bound (test oracle only).

The recursion exactly as Tichavský, Muravchik and Nehorai (1998) print it, with explicit
inverses, ``J_{k+1} = D22 - D21 (J_k + D11)^-1 D12``; Jacobians from a caller's function
(e.g. complex steps of the sympy-derived cart-pole), expectations as plain means.
"""
from __future__ import annotations

import numpy as np


def pcrb_literal(jac_f, jac_h, X, us, Q, R, P0, valid=None):
    """Bound matrices (N + 1, nx, nx) along ``X`` (runs, N + 1, nx).

    ``jac_f(x, u) -> F`` and ``jac_h(x) -> H`` give the Jacobians at one point; ``us`` is
    (N, nu); ``valid`` (runs, N, ny) of bool marks the channels measured at step k + 1.
    """
    runs, n1, nx = X.shape
    Qi = np.linalg.inv(Q)
    J = np.linalg.inv(P0)
    out = [np.linalg.inv(J)]
    for k in range(n1 - 1):
        Fs = [jac_f(X[r, k], us[k]) for r in range(runs)]
        Hs = [jac_h(X[r, k + 1]) for r in range(runs)]
        D11 = sum(F.T @ Qi @ F for F in Fs) / runs
        D12 = -(sum(Fs) / runs).T @ Qi
        info = np.zeros((nx, nx))
        for r, H in enumerate(Hs):
            s = np.arange(H.shape[0]) if valid is None else np.flatnonzero(valid[r, k])
            if len(s):
                info += H[s].T @ np.linalg.inv(R[np.ix_(s, s)]) @ H[s]
        D22 = Qi + info / runs
        J = D22 - D12.T @ np.linalg.inv(J + D11) @ D12
        out.append(np.linalg.inv(J))
    return np.array(out)

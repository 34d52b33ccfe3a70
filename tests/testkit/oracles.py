"""Independent derivations used only as test oracles (never imported by the package)."""
from __future__ import annotations

import numpy as np
import sympy as sp


def cartpole_lagrange():
    """Cart-pole from Lagrange's equations, derived here from scratch with sympy.

    Generalised coordinates q = (x, theta), theta from upright, positive towards +x;
    pole: mass mp, centre of mass at distance l from the pivot, inertia mp l^2/3 about
    it. Viscous friction Bc on the cart, Bp at the pivot, force F on the cart.

    Returns ``(f, energy)``: numpy-callable ``f(x, u, p) -> xdot`` (accepts complex
    arrays, for complex-step differentiation) and ``energy(x, p) -> E`` [J]; ``p`` is the
    tuple ``(mc, mp, l, Bc, Bp, g)``.
    """
    t = sp.symbols("t")
    mc, mp, l, Bc, Bp, g, F = sp.symbols("mc mp l Bc Bp g F", real=True)
    xq, th = sp.Function("xq")(t), sp.Function("th")(t)
    xd, thd = xq.diff(t), th.diff(t)
    # centre of mass of the pole
    px, py = xq + l * sp.sin(th), l * sp.cos(th)
    T = (mc * xd**2 / 2 + mp * (px.diff(t) ** 2 + py.diff(t) ** 2) / 2
         + (mp * l**2 / 3) * thd**2 / 2)
    V = mp * g * py
    L = T - V
    gen_forces = {xq: F - Bc * xd, th: -Bp * thd}
    eqs = [sp.diff(L.diff(q.diff(t)), t) - L.diff(q) - Q for q, Q in gen_forces.items()]
    a1, a2 = sp.symbols("a1 a2")
    X = sp.symbols("X1:5")
    subs = {xq.diff(t, 2): a1, th.diff(t, 2): a2}
    eqs = [e.subs(subs) for e in eqs]
    sol = sp.solve(eqs, [a1, a2], dict=True)[0]
    back = {xd: X[1], thd: X[3], xq: X[0], th: X[2]}
    acc = [sp.simplify(sol[a].subs(back)) for a in (a1, a2)]
    xdot = [X[1], acc[0], X[3], acc[1]]
    E = (T + V).subs(back)
    params = (mc, mp, l, Bc, Bp, g)
    fnum = sp.lambdify((X, (F,), params), xdot, "numpy")
    enum = sp.lambdify((X, params), E, "numpy")

    def f(x, u, p):
        return np.array([np.asarray(v, dtype=complex if np.iscomplexobj(x) else float) * 1
                         for v in np.broadcast_arrays(*fnum(x, u, p))])

    return f, enum


def iwp_numpy(x, u, p):
    """Seed 002 eqs 1-2 typed anew from SPEC section 3 (accepts complex x for complex-step)."""
    Iw, Ib, mb, lb, mw, lw, Cb, Cw, Km, g, s = p
    Ik, Ir, mc_ = Iw, Ib + mw * lw**2, mb + mw
    lp = (mb * lb + mw * lw) / mc_
    phidd = (Km * u[0] - Cw * x[2]) / Ik
    add = (s * Ik * phidd + mc_ * g * lp * np.sin(x[0]) - Cb * x[1]) / (Ir + Ik)
    return np.array([x[1] + 0 * x[0], add, phidd + 0 * x[0]])


def complex_step_jacobian(fun, z, h=1e-30):
    """Jacobian of ``fun`` at real vector ``z`` by complex steps (exact to rounding)."""
    z = np.asarray(z, dtype=float)
    cols = []
    for j in range(z.size):
        zc = z.astype(complex)
        zc[j] += 1j * h
        cols.append(np.imag(fun(zc)) / h)
    return np.array(cols).T


def central_difference_jacobian(fun, z, h=1e-4):
    """Fourth-order (Richardson-extrapolated) central-difference Jacobian of ``fun`` at ``z``."""
    z = np.asarray(z, dtype=float)
    cols = []
    for j in range(z.size):
        e = np.zeros_like(z)
        e[j] = h * max(1.0, abs(z[j]))
        d1 = (fun(z + e) - fun(z - e)) / (2 * e[j])
        d2 = (fun(z + 2 * e) - fun(z - 2 * e)) / (4 * e[j])
        cols.append((4 * d1 - d2) / 3)
    return np.array(cols).T

"""Discrete-time models that the filters run on, :class:`~estimators.discrete.DiscreteModel` (CasADi expressions).

Its process-model protocol is in the guide's page on writing a filter.
"""
from __future__ import annotations

import hashlib
from collections.abc import Sequence
from functools import cached_property

import casadi as ca
import numpy as np

from fmu_models.errors import ConfigurationError, TypeMismatchError, UnknownNameError
from fmu_models.infra import checks
from fmu_models.plant import PlantModel, check_method


class DiscreteModel:
    """``x_{k+1} = f(x_k, u_k)``, ``y_k = h(x_k)`` built from CasADi SX expressions.

    Parameters
    ----------
    x, u : casadi.SX
        Column symbols of the state (nx) and input (nu).
    f, h : casadi.SX
        Expressions of the next state (nx) and of the measurement (ny) in ``x`` and ``u``.
    dt : float
        Sample period [s].
    state_names, input_names, output_names : sequence of str
    description : str

    Attributes
    ----------
    nx, nu, ny : int
    """

    #: How the Jacobians are computed (in the results' metadata).
    jacobians = "exact: CasADi's automatic differentiation of the model's expressions"
    #: A filter on this model can be exported as an FMU (its step is self-contained C code).
    exportable = True

    def __init__(self, x: ca.SX, u: ca.SX, f: ca.SX, h: ca.SX, dt: float,
                 state_names: Sequence[str], input_names: Sequence[str],
                 output_names: Sequence[str], description: str = ""):
        self.x, self.u, self.fx, self.hx = x, u, ca.densify(f), ca.densify(h)
        self.dt = float(dt)
        self.state_names, self.input_names = list(state_names), list(input_names)
        self.output_names, self.description = list(output_names), description
        self.nx, self.nu, self.ny = x.numel(), u.numel(), h.numel()
        if f.numel() != self.nx:
            raise ConfigurationError(f"f has {f.numel()} entries, expected nx = {self.nx}")
        if ca.depends_on(self.hx, u):
            raise ConfigurationError("h must not depend on the input u (no feed-through)")
        self._f = ca.Function("f", [x, u], [self.fx])
        self._h = ca.Function("h", [x], [self.hx])
        self._jac = ca.Function("jac_fu", [x, u], [ca.densify(ca.jacobian(self.fx, v)) for v in (x, u)])
        self._H = ca.Function("jac_h", [x], [ca.densify(ca.jacobian(self.hx, x))])
        self._compiled: dict = {}

    @cached_property
    def identity(self) -> str:
        """A digest of the model's equations, period and names; two models with the same
        identity step identically."""
        text = "\n".join([str(self.fx), str(self.hx), repr(self.dt), *self.state_names, *self.input_names,
                          *self.output_names])
        return hashlib.sha1(text.encode()).hexdigest()[:16]

    def compiled(self, kind: str, key: tuple, backend: str, build):
        """The compiled object ``kind`` (``"step"``, ``"rts"``, ...) of the filter configuration
        ``key`` with ``backend`` on this model, built by ``build()`` the first time."""
        k = (kind, key, backend)
        if k not in self._compiled:
            self._compiled[k] = build()
        return self._compiled[k]

    def transition(self, x: ca.SX, u: ca.SX) -> tuple[ca.SX, ca.SX]:
        """``(f(x, u), F)`` with ``F = df/dx`` exact, at the symbols ``x`` (nx, 1) and ``u`` (nu, 1)."""
        xu, sym = ca.vertcat(x, u), ca.vertcat(self.x, self.u)
        return ca.substitute(self.fx, sym, xu), ca.substitute(ca.jacobian(self.fx, self.x), sym, xu)

    def measurement(self, x: ca.SX) -> tuple[ca.SX, ca.SX]:
        """``(h(x), H)`` with ``H = dh/dx`` exact, at the symbol ``x`` (nx, 1)."""
        return ca.substitute(self.hx, self.x, x), ca.substitute(ca.jacobian(self.hx, self.x), self.x, x)

    def take_failure(self) -> Exception | None:
        """The first failure of compiled code the expressions call (taking it clears it), or
        None: always None for CasADi expressions."""
        return None

    def describe(self) -> str:
        """What the model is and how its Jacobians are computed, in a few lines."""
        return "\n".join([self.description or "DiscreteModel", f"state ({self.nx}): {', '.join(self.state_names)}",
                          f"inputs ({self.nu}): {', '.join(self.input_names) or 'none'}",
                          f"measurements ({self.ny}): {', '.join(self.output_names)}", f"period {self.dt:g} s",
                          f"Jacobians: {self.jacobians}"])

    def __repr__(self):
        return (f"DiscreteModel({self.description!r}, dt={self.dt}, states={self.state_names}, "
                f"outputs={self.output_names})")

    def f(self, x, u) -> np.ndarray:
        """Next state, shape ``(nx,)``."""
        return np.asarray(self._f(checks.vector(x, self.nx, "x"), checks.vector(u, self.nu, "u"))).ravel()

    def h(self, x) -> np.ndarray:
        """Measurement, shape ``(ny,)``."""
        return np.asarray(self._h(checks.vector(x, self.nx, "x"))).ravel()

    def F(self, x, u) -> np.ndarray:
        """Exact state Jacobian of f, shape ``(nx, nx)``."""
        return np.asarray(self._jac(checks.vector(x, self.nx, "x"), checks.vector(u, self.nu, "u"))[0])

    def G(self, x, u) -> np.ndarray:
        """Exact input Jacobian of f, shape ``(nx, nu)``."""
        return np.asarray(self._jac(checks.vector(x, self.nx, "x"), checks.vector(u, self.nu, "u"))[1])

    def H(self, x) -> np.ndarray:
        """Exact measurement Jacobian, shape ``(ny, nx)``."""
        return np.asarray(self._H(checks.vector(x, self.nx, "x")))

    def linearized(self, x_op, u_op) -> DiscreteModel:
        """The affine model tangent at (x_op, u_op): the Kalman filter's model (seed 001),
        ``x_{k+1} = f(x_op, u_op) + F0 (x_k - x_op) + G0 (u_k - u_op)``,
        ``y_k = h(x_op) + H0 (x_k - x_op)``, with the exact Jacobians of the discrete map
        (for the Euler map, ``F0 = I + T A``: seed 000 eq 20).
        """
        x_op, u_op = checks.vector(x_op, self.nx, "x_op"), checks.vector(u_op, self.nu, "u_op")
        F0, G0 = (ca.DM(M) for M in (self.F(x_op, u_op), self.G(x_op, u_op)))
        c, y0, H0 = ca.DM(self.f(x_op, u_op)), ca.DM(self.h(x_op)), ca.DM(self.H(x_op))
        x, u = ca.SX.sym("x", self.nx), ca.SX.sym("u", self.nu)
        f = c + ca.mtimes(F0, x - x_op) + ca.mtimes(G0, u - u_op)
        h = y0 + ca.mtimes(H0, x - x_op)
        return DiscreteModel(x, u, f, h, self.dt, self.state_names, self.input_names,
                             self.output_names, f"{self.description}, linearised")


def checked_model(system) -> DiscreteModel:
    """``system`` (what was given as the model) if it is a :class:`DiscreteModel`, else TypeMismatchError saying how
    to make one."""
    if not isinstance(system, DiscreteModel):
        raise TypeMismatchError("system must be a DiscreteModel (build one with estimators.discretize, or "
                                f"estimators.FMUProcessModel from an FMU), got {type(system).__name__}")
    return system


def discretize(model: PlantModel, dt: float, method: str = "euler", substeps: int = 1) -> DiscreteModel:
    """The discrete map of a :class:`~fmu_models.PlantModel` with its current parameters.

    ``method="euler"``, ``substeps=1`` is the papers' model (seed 000 eqs 14-17 and 23).

    Parameters
    ----------
    model : PlantModel
    dt : float
        Sample period [s].
    method : {"euler", "rk4"}
    substeps : int
        Integration substeps per period.
    """
    check_method(method, substeps)
    dt = checks.positive(dt, "sample period dt [s]")
    x, u = ca.SX.sym("x", model.nx), ca.SX.sym("u", model.nu)
    p = ca.DM(model.p)
    f = model.sym.step(method, int(substeps))(x, u, p, dt)
    h = model.sym.h(x, p)
    return DiscreteModel(x, u, f, h, dt, model.state_names, model.input_names,
                         model.output_names, f"{model.name} ({method}, {substeps} substep(s))")


def augment_rate_bias(system: DiscreteModel, output: str) -> DiscreteModel:
    """Augment ``system`` with a constant sensor offset ``b`` on measured output ``output``.

    State ``[x, b]`` with ``b_{k+1} = b_k``; the measurement ``output`` becomes
    ``h_j(x) + b``. This is seed 002's EKF that estimates and removes the gyroscope offset
    (``output="y_alpha_dot"`` on the wheel pendulum).
    """
    if output not in system.output_names:
        raise UnknownNameError(f"no output {output!r}; valid outputs: {', '.join(system.output_names)}")
    j = system.output_names.index(output)
    xa = ca.SX.sym("xa", system.nx + 1)
    x, b = xa[: system.nx], xa[system.nx]
    f = ca.vertcat(ca.substitute(system.fx, system.x, x), b)
    e = ca.DM.zeros(system.ny)
    e[j] = 1
    h = ca.substitute(system.hx, system.x, x) + e * b
    return DiscreteModel(xa, system.u, f, h, system.dt,
                         system.state_names + [f"bias_{output}"], system.input_names,
                         system.output_names, f"{system.description}, bias on {output}")


def linear_model(A, B, C, dt: float = 1.0, state_names=None, input_names=None,
                 output_names=None) -> DiscreteModel:
    """The linear model ``x_{k+1} = A x_k + B u_k``, ``y_k = C x_k`` as a DiscreteModel.

    Shapes: A (nx, nx), B (nx, nu), C (ny, nx); ``dt`` [s] is recorded only;
    ``state_names``, ``input_names``, ``output_names`` default to x1.., u1.., y1...
    """
    A, B, C = (np.atleast_2d(np.asarray(M, float)) for M in (A, B, C))
    nx, nu, ny = A.shape[0], B.shape[1], C.shape[0]
    if A.shape != (nx, nx) or B.shape[0] != nx or C.shape[1] != nx:
        raise ConfigurationError(f"inconsistent shapes A {A.shape}, B {B.shape}, C {C.shape}")
    x, u = ca.SX.sym("x", nx), ca.SX.sym("u", nu)
    return DiscreteModel(x, u, ca.mtimes(ca.DM(A), x) + ca.mtimes(ca.DM(B), u),
                         ca.mtimes(ca.DM(C), x), dt,
                         state_names or [f"x{i + 1}" for i in range(nx)],
                         input_names or [f"u{i + 1}" for i in range(nu)],
                         output_names or [f"y{i + 1}" for i in range(ny)], "linear model")

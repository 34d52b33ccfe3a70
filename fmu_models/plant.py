"""`PlantModel`: one CasADi definition of a plant, the single source of its Python functions,
exact Jacobians (algorithmic differentiation), discrete maps, C code and FMUs."""
from __future__ import annotations

import copy
from collections.abc import Callable, Mapping, Sequence
from functools import cache

import casadi as ca
import numpy as np

from .errors import ConfigurationError, InputError, UnknownNameError
from .infra import checks
from .infra.memory import check_fits
from .variables import Variable

#: Integration methods of the discrete maps.
METHODS = ("euler", "rk4")

Dynamics = Callable[[ca.SX, ca.SX, Mapping[str, ca.SX]], ca.SX]
Measurement = Callable[[ca.SX, Mapping[str, ca.SX]], ca.SX]


def check_method(method: str, substeps: int) -> int:
    """Validate an integration method name and a substep count; returns the count as int.

    Raises
    ------
    UnknownNameError, ConfigurationError
        ``method`` is not one of :data:`METHODS`; ``substeps`` is not a positive integer.
    """
    if method not in METHODS:
        raise UnknownNameError(f"unknown method {method!r}; valid methods: {', '.join(METHODS)}")
    return checks.positive_int(substeps, "substeps")


class _Symbolic:
    """The symbolic part of a plant, shared by all parameter variants of a model."""

    def __init__(self, states, inputs, outputs, params, dynamics, measurement):
        self.x = ca.SX.sym("x", len(states))
        self.u = ca.SX.sym("u", len(inputs))
        self.p = ca.SX.sym("p", len(params))
        self.dt = ca.SX.sym("dt")
        pd = {v.name: self.p[i] for i, v in enumerate(params)}
        self.xdot = ca.vertcat(dynamics(self.x, self.u, pd))
        self.y = ca.vertcat(measurement(self.x, pd))
        for what, expr, n in (("dynamics", self.xdot, len(states)), ("measurement", self.y, len(outputs))):
            if expr.shape != (n, 1):
                raise ConfigurationError(f"{what} returned shape {expr.shape}, expected ({n}, 1)")
        x, u, p = self.x, self.u, self.p
        self.f = ca.Function("f", [x, u, p], [self.xdot], ["x", "u", "p"], ["xdot"])
        self.h = ca.Function("h", [x, p], [self.y], ["x", "p"], ["y"])
        self.jac_f = ca.Function("jac_f", [x, u, p],
                                 [ca.jacobian(self.xdot, x), ca.jacobian(self.xdot, u)],
                                 ["x", "u", "p"], ["A", "B"])
        self.jac_h = ca.Function("jac_h", [x, p], [ca.jacobian(self.y, x)], ["x", "p"], ["H"])

    @cache  # noqa: B019 - one symbolic model per PlantModel, kept as long as it
    def step(self, method: str, substeps: int) -> ca.Function:
        """x_{k+1} of (x, u, p, dt): ``substeps`` equal steps of ``method``."""
        h = self.dt / substeps
        xk = self.x
        for _ in range(substeps):
            k1 = self.f(xk, self.u, self.p)
            if method == "euler":
                xk = xk + h * k1
            else:
                k2 = self.f(xk + h / 2 * k1, self.u, self.p)
                k3 = self.f(xk + h / 2 * k2, self.u, self.p)
                k4 = self.f(xk + h * k3, self.u, self.p)
                xk = xk + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return ca.Function(f"step_{method}_{substeps}", [self.x, self.u, self.p, self.dt], [xk],
                           ["x", "u", "p", "dt"], ["x_next"])

    @cache  # noqa: B019 - as step
    def step_jac(self, method: str, substeps: int) -> ca.Function:
        xn = self.step(method, substeps)(self.x, self.u, self.p, self.dt)
        return ca.Function(f"step_jac_{method}_{substeps}", [self.x, self.u, self.p, self.dt],
                           [ca.jacobian(xn, self.x), ca.jacobian(xn, self.u)],
                           ["x", "u", "p", "dt"], ["F", "G"])


class PlantModel:
    """A continuous-time plant ``x' = f(x, u; p)``, ``y = h(x; p)`` defined once in CasADi.

    Build instances with :func:`fmu_models.get_model`; derive parameter variants with
    :meth:`with_params`.

    Parameters
    ----------
    name, fmu_name, description : str
        Registry name, FMU model name and one-line description.
    states, inputs, outputs, parameters : sequence of Variable
        The model's variables (parameters carry their default values and domains).
    dynamics, measurement : callable
        ``dynamics(x, u, p) -> xdot`` (nx) of CasADi SX columns ``x`` (nx), ``u`` (nu) and a dict of
        parameter symbols by name; ``measurement(x, p) -> y`` (ny).
    example_x0, example_input : array_like, callable, optional
        An initial state and an input ``u(t)`` that show the model's behaviour (default: the states'
        starts, zero): what ``pendulum-cosim models`` simulates.

    Attributes
    ----------
    state_names, input_names, output_names, nx, nu, ny
        The names, and the numbers, of the states, inputs and outputs.
    """

    def __init__(self, name: str, fmu_name: str, description: str,
                 states: Sequence[Variable], inputs: Sequence[Variable],
                 outputs: Sequence[Variable], parameters: Sequence[Variable],
                 dynamics: Dynamics | None = None, measurement: Measurement | None = None,
                 example_x0=None, example_input: Callable[[float], Sequence[float]] | None = None):
        self.name, self.fmu_name, self.description = name, fmu_name, description
        self.example_x0, self.example_input = example_x0, example_input
        self.states, self.inputs = tuple(states), tuple(inputs)
        self.outputs, self.parameters = tuple(outputs), tuple(parameters)
        checks.check_unique([v.name for v in self.states + self.inputs + self.outputs + self.parameters],
                            f"model {name!r}: duplicate variable names")
        self.sym = _Symbolic(self.states, self.inputs, self.outputs, self.parameters, dynamics, measurement)
        self._p = np.array([v.check(v.start) for v in self.parameters])

    state_names = property(lambda self: [v.name for v in self.states])
    input_names = property(lambda self: [v.name for v in self.inputs])
    output_names = property(lambda self: [v.name for v in self.outputs])
    #: The parameters' names, in the order of :attr:`p`.
    param_names = property(lambda self: [v.name for v in self.parameters])
    nx = property(lambda self: len(self.states))
    nu = property(lambda self: len(self.inputs))
    ny = property(lambda self: len(self.outputs))

    @property
    def params(self) -> dict[str, float]:
        """Current parameter values by name (a copy)."""
        return dict(zip(self.param_names, self._p.tolist()))

    @property
    def p(self) -> np.ndarray:
        """Current parameter vector, shape ``(n_params,)``, in :attr:`param_names` order."""
        return self._p.copy()

    @property
    def x0(self) -> np.ndarray:
        """Default initial state (the states' start values), shape ``(nx,)``."""
        return np.array([v.start for v in self.states])

    def with_params(self, **params: float) -> PlantModel:
        """Return a copy of this model with parameters overridden by name.

        Raises
        ------
        UnknownNameError, ConfigurationError
            An unknown name (the message lists the valid ones); a value outside the parameter's domain.
        """
        variant = copy.copy(self)           # the symbolic part is shared
        variant._p = self._p.copy()
        index = {n: i for i, n in enumerate(self.param_names)}
        for key, val in params.items():
            if key not in index:
                raise UnknownNameError(f"model {self.name!r} has no parameter {key!r}; "
                                       f"valid parameters: {', '.join(self.param_names)}")
            variant._p[index[key]] = self.parameters[index[key]].check(val)
        return variant

    def __repr__(self) -> str:
        return (f"PlantModel({self.name!r}, states={self.state_names}, "
                f"inputs={self.input_names}, outputs={self.output_names})")

    def _xu(self, x, u):
        return checks.vector(x, self.nx, "state x"), checks.vector(u, self.nu, "input u")

    def _discrete(self, build: Callable[[str, int], ca.Function], x, u, dt, method: str, substeps: int):
        """``build(method, substeps)``, the discrete map or its Jacobians, called on checked arguments."""
        substeps = check_method(method, substeps)
        x, u = self._xu(x, u)
        return build(method, substeps)(x, u, self._p, _check_dt(dt))

    def f(self, x, u) -> np.ndarray:
        """Continuous dynamics x' = f(x, u), shape ``(nx,)``; x in state units, u in input units."""
        x, u = self._xu(x, u)
        return np.asarray(self.sym.f(x, u, self._p)).reshape(self.nx)

    def h(self, x) -> np.ndarray:
        """Noise-free measurement y = h(x), shape ``(ny,)``."""
        return np.asarray(self.sym.h(checks.vector(x, self.nx, "state x"), self._p)).reshape(self.ny)

    def H(self, x) -> np.ndarray:
        """Exact measurement Jacobian dh/dx, shape ``(ny, nx)``."""
        return np.asarray(self.sym.jac_h(checks.vector(x, self.nx, "state x"), self._p))

    def linearize(self, x0, u0) -> tuple[np.ndarray, np.ndarray]:
        """Exact continuous linearisation about (x0, u0): ``A = df/dx`` (nx, nx), ``B = df/du`` (nx, nu)."""
        x, u = self._xu(x0, u0)
        A, B = self.sym.jac_f(x, u, self._p)
        return np.asarray(A), np.asarray(B)

    def step(self, x, u, dt: float, method: str = "euler", substeps: int = 1) -> np.ndarray:
        """One discrete step of length ``dt`` [s] with u held constant, shape ``(nx,)``.

        ``method="euler"`` with ``substeps=1`` is the papers' truth model (seed 000
        eqs 14-17, without the noise w); ``"rk4"`` is the classical Runge-Kutta scheme
        with ``substeps`` equal substeps.
        """
        return np.asarray(self._discrete(self.sym.step, x, u, dt, method, substeps)).reshape(self.nx)

    def jacobians(self, x, u, dt: float, method: str = "euler",
                  substeps: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """Exact Jacobians of :meth:`step`: ``F = dx_next/dx`` (nx, nx), ``G = dx_next/du`` (nx, nu)."""
        F, G = self._discrete(self.sym.step_jac, x, u, dt, method, substeps)
        return np.asarray(F), np.asarray(G)

    def discretize(self, x0, u0, dt: float, method: str = "zoh") -> tuple[np.ndarray, np.ndarray]:
        """Discrete linear model about (x0, u0) for period ``dt`` [s].

        ``method="zoh"``: exact zero-order hold, ``[[Ad, Bd], [0, I]] = expm([[A, B], [0, 0]] dt)``;
        ``method="euler"``: ``Ad = I + A dt``, ``Bd = B dt`` (seed 000 eq 20 form).
        """
        A, B = self.linearize(x0, u0)
        dt = _check_dt(dt)
        if method == "euler":
            return np.eye(self.nx) + A * dt, B * dt
        if method != "zoh":
            raise UnknownNameError(f"unknown discretisation {method!r}; valid: 'zoh', 'euler'")
        n, m = self.nx, self.nu
        M = np.zeros((n + m, n + m))
        M[:n, :n], M[:n, n:] = A, B
        import scipy.linalg  # here: 0.2 s of import time most runs never need

        E = scipy.linalg.expm(M * dt)
        return E[:n, :n], E[:n, n:]

    def simulate(self, x0, u, dt: float, n_steps: int, method: str = "euler",
                 substeps: int = 1) -> np.ndarray:
        """Simulate ``n_steps`` discrete steps; returns states of shape ``(n_steps + 1, nx)``.

        ``u`` is either one input vector held throughout, an array of shape
        ``(n_steps, nu)``, or a callable ``u(t) -> (nu,)`` evaluated at each step start.
        """
        substeps = check_method(method, substeps)
        n_steps = checks.positive_int(n_steps, "n_steps", minimum=0)
        check_fits(8.0 * n_steps * (2 * self.nx + self.nu), f"simulating {n_steps} steps of {self.name}",
                   "simulate fewer steps at a time")
        fn = self.sym.step(method, substeps)
        x = checks.vector(x0, self.nx, "initial state x0")
        dt = _check_dt(dt)
        if callable(u):
            us = np.array([checks.vector(u(k * dt), self.nu, f"u({k * dt})") for k in range(n_steps)])
        else:
            ua = checks.float_array(u, "input u")
            us = (np.broadcast_to(checks.vector(ua, self.nu, "input u"), (n_steps, self.nu))
                  if ua.ndim <= 1 else ua)
            if us.shape != (n_steps, self.nu) or not np.all(np.isfinite(us)):
                raise InputError(f"input sequence must be finite with shape ({n_steps}, {self.nu}), "
                                 f"got {ua.shape}")
        out = np.empty((n_steps + 1, self.nx))
        out[0] = x
        # CasADi's mapaccum folds the step natively, in chunks of at most CHUNK steps
        for k0 in range(0, n_steps, SIMULATE_CHUNK):
            k1 = min(k0 + SIMULATE_CHUNK, n_steps)
            xs = _folded(fn, k1 - k0)(out[k0], us[k0:k1].T, self._p, dt)
            out[k0 + 1: k1 + 1] = np.asarray(xs).T
        return out


#: Steps folded in one native call by :meth:`PlantModel.simulate`.
SIMULATE_CHUNK = 10_000


@cache
def _folded(fn: ca.Function, n: int) -> ca.Function:
    return fn.mapaccum(n)


def _check_dt(dt) -> float:
    return checks.positive(dt, "time step dt [s]")

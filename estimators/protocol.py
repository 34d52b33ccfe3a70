"""The filter protocol: what a filter declares and how :func:`~estimators.protocol.build_step` makes its hooks one step.

The hooks and declarations are documented in the manual's page "Writing a filter".
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import casadi as ca
import numpy as np

from fmu_models.errors import ConfigurationError
from fmu_models.variables import check_declaration

from .discrete import DiscreteModel
from .linalg import CSE, log_det, status_flag, symmetric, upper_entries, used_measurement

__all__ = ["DIAGNOSTICS", "STEP_INPUTS", "Parameter", "StepContext", "StepResult", "Update", "build_step",
           "per_name", "renamed"]

#: Outputs of every fused step after the new state, in order.
DIAGNOSTICS = ("x_prior", "P_prior", "innov", "S", "K", "nis", "accepted", "logdet_S")
#: The step's inputs after the state arrays (then Q, R of a non-adaptive filter, the step parameters).
STEP_INPUTS = ("u", "y", "mask", "gate", "nan_missing")


@dataclass(frozen=True)
class Parameter:
    """A fixed input of a filter's step, or an FMU parameter.

    Attributes
    ----------
    name : str
        Identifier (the step input's name).
    value : ndarray
        Its value, flat (``np.atleast_1d`` of what was given).
    domain : str
        Admissible values of every entry (:data:`fmu_models.variables.DOMAINS`).
    description : str or tuple of str
        One line for users (and the FMU's ``modelDescription.xml``), or one per entry.
    labels : tuple of str
        The FMU parameter name of each entry (default ``name``, or ``name_0``, ``name_1``, ...).
    increasing : bool
        The entries must increase (``(low, high)`` bounds; the FMU checks it too).
    of : tuple of str
        What each entry is of (a state or measurement name): ``"<description> of <of[i]>"``.
    """

    name: str
    value: np.ndarray
    domain: str = "real"
    description: str | tuple[str, ...] = ""
    labels: tuple[str, ...] = ()
    increasing: bool = False
    of: tuple[str, ...] = ()

    def __post_init__(self):
        check_declaration("parameter", self.name, self.domain)
        value = np.atleast_1d(np.asarray(self.value, dtype=float)).ravel()
        object.__setattr__(self, "value", value)
        labels = tuple(self.labels) or ((self.name,) if value.size == 1 else
                                        tuple(f"{self.name}_{i}" for i in range(value.size)))
        if len(labels) != value.size:
            raise ConfigurationError(f"parameter {self.name}: {len(labels)} labels for {value.size} values")
        object.__setattr__(self, "labels", labels)
        if self.of and len(self.of) != value.size:
            raise ConfigurationError(f"parameter {self.name}: {len(self.of)} names in 'of' for {value.size} values")

    def describe(self, i: int) -> str:
        """The description of entry ``i``."""
        if isinstance(self.description, tuple):
            return self.description[i]
        return f"{self.description} of {self.of[i]}" if self.of else self.description

    @property
    def size(self) -> int:
        """Number of entries."""
        return int(self.value.size)


def per_name(name: str, value, domain: str, description: str, names) -> Parameter:
    """The :class:`Parameter` ``name`` of ``value`` in ``domain`` with one entry ``<name>_<n>``,
    described ``"<description> of <n>"``, for each ``n`` of ``names`` (states or measurements)."""
    return Parameter(name, value, domain, description, tuple(f"{name}_{n}" for n in names), of=tuple(names))


class Update(NamedTuple):
    """What ``update_expr`` returns (SX): the posterior ``x`` (nx, 1) and ``P`` (nx, nx), the
    ``innovation`` (ny, 1), its covariance ``S`` (ny, ny), the gain ``K`` (nx, ny), the ``nis``
    and ``accepted`` (1: the gate passed the measurement)."""

    x: ca.SX
    P: ca.SX
    innovation: ca.SX
    S: ca.SX
    K: ca.SX
    nis: ca.SX
    accepted: ca.SX


StepResult = NamedTuple("StepResult", [(f, ca.SX) for f in ("x_prior", "P_prior", *Update._fields, "logdet_S")])
StepResult.__doc__ = """The step so far, as ``adapt_expr`` sees it: the prior ``x_prior`` (nx, 1) and
``P_prior`` (nx, nx), the fields of the :class:`Update` and ``logdet_S``."""


@dataclass
class StepContext:
    """The symbols (SX) a filter's hooks build its step from.

    Attributes
    ----------
    system : DiscreteModel
    x, P, Q, R : SX
        The state estimate (nx, 1), its covariance (nx, nx) and the noise covariances
        (nx, nx), (ny, ny); the matrices symmetric (lower triangle = upper).
    u, y : SX
        The input (nu, 1) held over the prediction; the measurement (ny, 1), 0 in unused channels.
    valid : SX
        1 for a used channel (masked in, and not NaN unless NaN is an error), else 0.
    gate : SX
        The chi-square gate on the NIS (``inf``: none).
    state, params, outputs : dict of str to SX
        The extra state arrays (``extra_state``), the step parameters (column vectors) and the
        extra outputs declared with :meth:`output`, by name.
    """

    system: DiscreteModel
    x: ca.SX
    P: ca.SX
    Q: ca.SX
    R: ca.SX
    u: ca.SX
    y: ca.SX
    valid: ca.SX
    gate: ca.SX
    state: dict = field(default_factory=dict)
    params: dict = field(default_factory=dict)
    outputs: dict = field(default_factory=dict)

    def output(self, name: str, expr) -> None:
        """Declare an extra output ``name`` of the step (not a state, diagnostic or reserved name)."""
        if not name.isidentifier() or name in DIAGNOSTICS or name == "status" or name.endswith("_new"):
            raise ConfigurationError(f"extra step output name {name!r} is reserved or not an identifier")
        self.outputs[name] = ca.SX(expr)


def build_step(filt, extra_state: dict[str, np.ndarray], params: Sequence[Parameter]) -> ca.Function:
    """The fused step Function of the filter ``filt`` from its hooks.

    Inputs, in order: the state arrays (``x``, ``P``, ``Q`` and ``R`` if the filter adapts
    them, then the extra state in ``extra_state`` order), :data:`STEP_INPUTS`, ``Q`` and ``R``
    of a non-adaptive filter, the step parameters ``params``. Outputs: ``<state>_new`` for each
    state array, :data:`DIAGNOSTICS`, the extra outputs and ``status``.
    """
    s, sym = filt.system, ca.SX.sym
    n, m, p = s.nx, s.nu, s.ny
    x, P, Q, R = sym("x", n, 1), sym("P", n, n), sym("Q", n, n), sym("R", p, p)
    u, y, mask = sym("u", m, 1), sym("y", p, 1), sym("mask", p, 1)
    gate, nan_missing = sym("gate", 1, 1), sym("nan_missing", 1, 1)
    extra = {k: sym(k, np.size(v), 1) for k, v in extra_state.items()}
    psym = {q.name: sym(q.name, q.size, 1) for q in params}
    valid, y_used = used_measurement(y, mask, nan_missing)
    ctx = StepContext(s, x, symmetric(P), symmetric(Q), symmetric(R), u, y_used, valid, gate, dict(extra), psym)
    xp, Pp = filt.predict_expr(ctx)
    upd = Update(*filt.update_expr(ctx, xp, Pp))
    result = StepResult(xp, Pp, *upd, log_det(upd.S))
    state = {"x": x, "P": P, **({"Q": Q, "R": R} if filt.adapts_noise else {}), **extra}
    new = {**state, "x": upd.x, "P": upd.P}
    changes = filt.adapt_expr(ctx, result) or {}
    unknown = sorted(set(changes) - (set(state) - {"x", "P"}))
    if unknown:
        raise ConfigurationError(f"{filt.name}: adapt_expr returned {unknown}, which are not its adaptable state "
                                 f"({', '.join(k for k in state if k not in ('x', 'P')) or 'none'})")
    new.update(changes)
    inputs = {**state, "u": u, "y": y, "mask": mask, "gate": gate, "nan_missing": nan_missing,
              **({} if filt.adapts_noise else {"Q": Q, "R": R}), **psym}
    checked = [new["x"]] + [upper_entries(symmetric(new[k])) for k in ("P", "Q", "R") if k in new]
    diagnostics = [result.x_prior, result.P_prior, result.innovation, result.S, result.K, result.nis,
                   result.accepted, result.logdet_S]                                   # named by DIAGNOSTICS
    outs = ([ca.densify(ca.reshape(new[k], state[k].shape)) for k in state]
            + [ca.densify(v) for v in (*diagnostics, *ctx.outputs.values())] + [status_flag([u, y_used], checked)])
    return ca.Function("step", list(inputs.values()), outs, list(inputs),
                       [f"{k}_new" for k in state] + list(DIAGNOSTICS) + list(ctx.outputs) + ["status"], CSE)


def renamed(fn: ca.Function, name: str) -> ca.Function:
    """``fn`` (SX or MX) under another ``name`` (generated C code calls it by that name)."""
    sym = ca.SX if fn.is_a("SXFunction") else ca.MX
    args = [sym.sym(n, fn.sparsity_in(i)) for i, n in enumerate(fn.name_in())]
    return ca.Function(name, args, fn.call(args), fn.name_in(), fn.name_out())

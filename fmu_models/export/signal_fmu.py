"""Signal FMUs: the sources, the process noise and the noisy sensor as native Co-Simulation FMUs
(FMI 2.0 or 3.0) with ``c/signal_core.c``. One per :class:`SignalSpec`, of the kinds :data:`SIGNAL_KINDS`
(their variables: the user guide's page "Taking the estimator to another tool")."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

from ..errors import ConfigurationError
from ..infra.registry import Registry
from .clocked import check_clocked, clock_defines, clock_variables
from .config import config_header
from .description import Description, Unknown, fmi2, fmi3
from .pack import pack_fmu
from .variable_list import VariableList

__all__ = ["KINDS", "SIGNAL_KINDS", "SignalKind", "SignalSpec", "build_signal_fmu", "channel_params",
           "register_signal_kind"]

_INT32_MAX = 2**31 - 1
#: ``SIGNAL_KIND`` of a kind defined by its C expression (``signal_custom.h``).
KIND_CUSTOM = 99
#: The per-channel parameter blocks of a kind, each ``n`` parameters after ``period``.
_BLOCKS = {"noise": ("SIG_STD",), "sensor": ("SIG_STD", "SIG_BIAS", "SIG_QUANT")}


@dataclass(frozen=True)
class SignalKind:
    """A kind of signal FMU.

    Attributes
    ----------
    name, code : str, int
        The name and ``SIGNAL_KIND`` in ``signal_core.c`` (:data:`KIND_CUSTOM` for a C expression).
    c_output : str
        For a custom kind: the C expression of output channel ``j`` at time ``t`` from ``p[P_<NAME>]``
        (Real parameters), ``d->ip[IP_<NAME>]`` (Integer ones), ``d->in[j]`` (inputs) and ``<math.h>``.
    inputs : bool
        The kind has one input per output channel (a sensor).
    """

    name: str
    code: int
    c_output: str = ""
    inputs: bool = False


#: The signal FMU kinds by name.
SIGNAL_KINDS: Registry[SignalKind] = Registry("signal kind")
for _code, _name in enumerate(("constant", "step", "sine", "prbs", "noise", "sensor")):
    SIGNAL_KINDS.register(_name, SignalKind(_name, _code, inputs=_name == "sensor"))
#: The built-in kinds (``signal_core.c``).
KINDS = tuple(SIGNAL_KINDS.names())


def register_signal_kind(name: str, c_output: str, inputs: bool = False) -> SignalKind:
    """Register a signal FMU kind ``name`` whose output channel ``j`` is the C expression
    ``c_output`` (see :class:`.SignalKind`); ``inputs``: one input per channel. Returns it.

    >>> register_signal_kind("ramp", "p[P_SLOPE] * t")        # doctest: +SKIP
    """
    if not isinstance(c_output, str) or not c_output.strip() or ";" in c_output or "}" in c_output:
        raise ConfigurationError(f"signal kind {name!r}: c_output must be one C expression, got {c_output!r}")
    return SIGNAL_KINDS.register(name, SignalKind(name, KIND_CUSTOM, c_output, bool(inputs)))


@dataclass
class SignalSpec:
    """One signal FMU.

    Attributes
    ----------
    kind, description, period : str, str, float
        A registered kind (:data:`SIGNAL_KINDS`); the FMU's description; the sample period [s] (the FMU's
        default communication step and the noise's sample).
    outputs, inputs : list of str
        One name per channel; inputs only for a kind with inputs (the sensor's measured signals).
    reals, ints : list of (name, value, domain, description), list of (name, value, min, max, description)
        Real parameters after ``period``, in the order ``signal_core.c`` reads them; Integer parameters.
    """

    kind: str
    period: float
    outputs: list[str]
    reals: list[tuple] = field(default_factory=list)
    ints: list[tuple] = field(default_factory=list)
    inputs: list[str] = field(default_factory=list)
    description: str = ""

    def parameters(self) -> dict:
        """Every parameter's value by name (``period`` included)."""
        return {"period": self.period, **{r[0]: r[1] for r in self.reals}, **{i[0]: i[1] for i in self.ints}}


def _check(spec: SignalSpec) -> SignalKind:
    kind = SIGNAL_KINDS.get(spec.kind)
    if not spec.outputs or len(spec.inputs) != (len(spec.outputs) if kind.inputs else 0):
        raise ConfigurationError(f"{spec.kind} FMU: needs outputs (and, for a kind with inputs, one input per output)")
    for name, value, lo, hi, _ in spec.ints:
        if not lo <= value <= hi or hi > _INT32_MAX:
            raise ConfigurationError(f"{spec.kind} FMU: {name} = {value} must be in [{lo}, {min(hi, _INT32_MAX)}] "
                                     "(an FMI Int32)")
    return kind


def _variables(spec: SignalSpec, clocked: bool) -> VariableList:
    v = VariableList()
    reals = [("period", spec.period, "positive", "sample period of the noise [s]")] + list(spec.reals)
    for name, value, domain, descr in reals:
        v.parameter(name, float(value), descr, domain=domain)
    for name in spec.inputs:
        v.input(name, 0.0, f"measured signal {name}", "IN")
    for name in spec.outputs:
        v.output(name, f"{spec.kind} output {name}", "OUT")
    v.time(unit=None)
    for name, value, lo, hi, descr in spec.ints:
        v.parameter(name, int(value), descr, "IP", type="Integer", min=int(lo), max=int(hi))
    if clocked:
        v = clock_variables(v, ("IN", "OUT"), spec.period,
                            f"the signal's sample instants (every {spec.period:g} s from the start time)")
    return v


def _write_sources(spec: SignalSpec, kind: SignalKind, variables: VariableList, identifier: str, folder: Path,
                   guid: str) -> list[str]:
    """``model_config.h`` (with the noise's and sensor's per-channel parameter blocks) and ``signal_custom.h``."""
    n = len(spec.outputs)
    defines = [("SIGNAL_KIND", kind.code)] + [(b, 1 + k * n) for k, b in enumerate(_BLOCKS.get(spec.kind, ()))]
    (folder / "model_config.h").write_text(config_header(variables, identifier, guid, "fmu_models.export.signal_fmu",
                                                         groups=("IN", "OUT", "TIME"),
                                                         defines=defines + clock_defines(variables, spec.period)))
    (folder / "signal_custom.h").write_text(
        "/* Generated by pendulum-cosim (fmu_models.export.signal_fmu): the output of a custom signal kind. */\n"
        "static double custom_output(const CoreData *d, int j, const double *p, double t) {\n"
        "    (void)d; (void)j; (void)p; (void)t;\n"
        f"    return ({kind.c_output or '0.0'});\n}}\n")
    return []


def _description(spec: SignalSpec, kind: SignalKind, variables: VariableList, identifier: str, guid: str,
                 c_files: list[str], clocked: bool) -> Description:
    in_idx, p_idx, outs, clk = (variables.indices(g) for g in (["IN"], ["P", "IP"], ["OUT"], ["CLOCK"]))
    # channel j depends on input j only (if the kind has inputs), and on the clock
    deps = [[i] + clk for i in in_idx] if kind.inputs else [clk] * len(outs)
    o_unknowns = [Unknown(o, dep, ["dependent"] * len(dep) if dep else None) for o, dep in zip(outs, deps, strict=True)]
    return Description(model_name=identifier, identifier=identifier, guid=guid,
                       description=spec.description or f"{spec.kind} signal (pendulum-cosim)",
                       variables=variables.variables, outputs=o_unknowns,
                       initial_unknowns=[] if clocked else [Unknown(o, p_idx + in_idx) for o in outs],
                       variable_step=True, default_step=spec.period, source_files=c_files, clocked=clocked)


def build_signal_fmu(spec: SignalSpec, out_dir, fmi_version: int = 2, identifier: str = "Signal",
                     file_name: str | None = None, clocked: bool = False) -> Path:
    """Compile and pack the signal FMU ``spec``; returns the ``.fmu`` path.

    Parameters
    ----------
    spec, out_dir, fmi_version : SignalSpec, path, {2, 3}
        The FMU, the folder to write it into, the FMI version.
    identifier, file_name : str
        Model identifier (a C identifier); FMU file name (default ``<identifier>.fmu``).
    clocked : bool
        The clocked form (FMI 3.0 only, :mod:`fmu_models.export.clocked`), the clock's interval
        ``spec.period``: an activation samples the signal (``period`` must keep its value).

    Raises
    ------
    ConfigurationError
        An inconsistent spec, a bad identifier, or ``clocked`` with FMI 2.0.
    """
    check_clocked(clocked, fmi_version, f"the {spec.kind} FMU")
    kind = _check(spec)
    if not identifier.isidentifier() or not identifier.isascii():
        raise ConfigurationError(f"FMU identifier {identifier!r} must be an ASCII C identifier")
    variables = _variables(spec, clocked)

    def xml(guid: str, c_files: list[str]) -> str:
        d = _description(spec, kind, variables, identifier, guid, c_files, clocked)
        return fmi2(d) if fmi_version == 2 else fmi3(d)

    return pack_fmu(identifier, "signal", fmi_version, partial(_write_sources, spec, kind, variables, identifier),
                    xml, out_dir, fingerprint=f"{spec}|{clocked}", file_name=file_name)


def channel_params(prefix: str, names: Sequence[str], values, domain: str, what: str) -> list[tuple]:
    """Real parameter rows ``<prefix>_<name>`` for per-channel ``values``.

    Parameters
    ----------
    prefix, names, values
        Name prefix (``std``, ``bias``, ...), channel names and one value per channel.
    domain, what
        Domain of every value (:data:`fmu_models.variables.DOMAINS`); what the values are, for the descriptions.
    """
    return [(f"{prefix}_{n}", float(v), domain, f"{what} of {n}") for n, v in zip(names, values, strict=True)]

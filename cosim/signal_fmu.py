"""Signal FMUs: the sources, the process noise and the noisy sensor as native Co-Simulation
FMUs (FMI 2.0 or 3.0), built by the same machinery as the plant and estimator FMUs
(:func:`fmu_models.fmu_pack.pack_fmu` with ``fmu_models/c/signal_core.c``).

A :class:`SignalSpec` describes one FMU: its kind, its channels and its parameters (with
the component's values as defaults). The components of :mod:`cosim.components.sources` and
:mod:`cosim.components.sensors` build theirs in ``export_fmu`` (see :class:`cosim.core.component.Component`);
:func:`build_signal_fmu` compiles and packs it.

Kinds and variables (``period`` [s] is a parameter of every kind; noise is drawn at sample
``round(t / period)``, see :mod:`cosim.components.noise`):

=========  ==========================================  ============================================
kind       parameters                                   outputs (inputs)
=========  ==========================================  ============================================
constant   ``value``                                    ``out``
step       ``t_step``, ``before``, ``after``            ``out``
sine       ``amplitude``, ``frequency``, ``phase``,     ``out``
           ``offset``
prbs       ``amplitude``, ``bit_time``, ``offset``;     ``out``
           Integer ``order`` (2..16), ``seed``
noise      ``std_<port>`` per channel; Integer          ``w_<state>`` per channel
           ``seed``
sensor     ``std_<signal>``, ``bias_<signal>``,         ``y_<signal>`` (inputs ``<signal>``)
           ``quantization_<signal>``; Integer ``seed``
=========  ==========================================  ============================================
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from fmu_models.codegen import c_array, c_strings
from fmu_models.errors import ConfigurationError, UnknownNameError
from fmu_models.fmu_layout import FmuVariable
from fmu_models.fmu_pack import pack_fmu
from fmu_models.variables import DOMAINS
from fmu_models.xml_writer import Description, Unknown, fmi2, fmi3

__all__ = ["KINDS", "SignalSpec", "build_signal_fmu"]

KINDS = ("constant", "step", "sine", "prbs", "noise", "sensor")
_INT32_MAX = 2**31 - 1


@dataclass
class SignalSpec:
    """One signal FMU.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    period : float
        Sample period [s] (the FMU's default communication step and the noise's sample).
    outputs : list of str
        Output names, one per channel.
    inputs : list of str
        Input names (the sensor's measured signals), one per channel; else empty.
    reals : list of (name, value, domain, description)
        Real parameters after ``period``, in the order ``signal_core.c`` reads them
        (domain ``"real"``, ``"positive"`` or ``"nonnegative"``).
    ints : list of (name, value, min, max, description)
        Integer parameters.
    description : str
        The FMU's description.
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


def _check(spec: SignalSpec) -> None:
    if spec.kind not in KINDS:
        raise UnknownNameError(f"signal FMU kind must be one of {KINDS}, got {spec.kind!r}")
    if not spec.outputs or (spec.kind == "sensor" and len(spec.inputs) != len(spec.outputs)):
        raise ConfigurationError(f"{spec.kind} FMU: needs outputs (and for a sensor one input per output)")
    for name, value, lo, hi, _ in spec.ints:
        if not lo <= value <= hi or hi > _INT32_MAX:
            raise ConfigurationError(f"{spec.kind} FMU: {name} = {value} must be in [{lo}, {min(hi, _INT32_MAX)}] "
                                     "(an FMI Int32)")


def _offsets(spec: SignalSpec) -> list[str]:
    """``#define RP_<NAME> index`` for the named Real parameters ``signal_core.c`` reads."""
    names = ["period"] + [r[0] for r in spec.reals]
    n = len(spec.outputs)
    out = ["#define RP_PERIOD 0"]
    if spec.kind in ("noise", "sensor"):
        out.append(f"#define RP_STD {1}")
        if spec.kind == "sensor":
            out += [f"#define RP_BIAS {1 + n}", f"#define RP_QUANT {1 + 2 * n}"]
    else:
        out += [f"#define RP_{nm.upper()} {i}" for i, nm in enumerate(names) if i > 0]
    out += [f"#define IP_{i[0].upper()} {k}" for k, i in enumerate(spec.ints)]
    return out


def build_signal_fmu(spec: SignalSpec, out_dir, fmi_version: int = 2, identifier: str = "Signal",
                     file_name: str | None = None) -> Path:
    """Compile and pack the signal FMU ``spec``; returns the ``.fmu`` path.

    Parameters
    ----------
    spec : SignalSpec
    out_dir : path
    fmi_version : {2, 3}
    identifier : str
        Model identifier (a C identifier).
    file_name : str, optional
        Default ``<identifier>.fmu``.

    Raises
    ------
    ConfigurationError
        An inconsistent spec or a bad identifier.
    """
    _check(spec)
    if not identifier.isidentifier():
        raise ConfigurationError(f"FMU identifier {identifier!r} must be a C identifier")
    variables: list[FmuVariable] = []

    def add(**kw):
        variables.append(FmuVariable(vr=len(variables), unit=None, **kw))

    reals = [("period", spec.period, "positive", "sample period of the noise [s]")] + list(spec.reals)
    for name, value, _, descr in reals:
        add(name=name, type="Real", causality="parameter", variability="fixed", initial="exact",
            start=float(value), description=descr, kind="param")
    for name in spec.inputs:
        add(name=name, type="Real", causality="input", variability="continuous", initial=None, start=0.0,
            description=f"measured signal {name}", kind="input")
    for name in spec.outputs:
        add(name=name, type="Real", causality="output", variability="continuous", initial="calculated",
            start=None, description=f"{spec.kind} output {name}", kind="output")
    n_real = len(variables)
    add(name="time", type="Real", causality="independent", variability="continuous", initial=None, start=None,
        description="simulation time", kind="time")
    n_int_first = len(variables)
    for name, value, lo, hi, descr in spec.ints:
        variables.append(FmuVariable(name=name, vr=len(variables), type="Integer", causality="parameter",
                                     variability="fixed", initial="exact", start=int(value), unit=None,
                                     description=descr, kind="int", min=int(lo), max=int(hi)))
    first = lambda kind: next((v.vr for v in variables if v.kind == kind), n_real)  # noqa: E731
    n = len(spec.outputs)

    def config(guid: str) -> str:
        return "\n".join([
            "/* Generated by pendulum-cosim (cosim.signal_fmu). Do not edit. */",
            "#ifndef MODEL_CONFIG_H", "#define MODEL_CONFIG_H",
            f'#define MODEL_IDENTIFIER_STR "{identifier}"', f'#define MODEL_GUID "{guid}"',
            f"#define SIGNAL_KIND {KINDS.index(spec.kind)}", f"#define NCH {n}",
            f"#define NRP {len(reals)}", f"#define NIP {len(spec.ints)}", f"#define NIN {len(spec.inputs)}",
            f"#define VR_RP {first('param')}", f"#define VR_IN {first('input')}", f"#define VR_OUT {first('output')}",
            f"#define VR_TIME {first('time')}", f"#define VR_IP {n_int_first}", f"#define N_REAL {n_real}",
            *_offsets(spec),
            c_array("double", "RP_DEFAULT", [repr(float(r[1])) for r in reals]),
            c_array("int", "RP_DOMAIN", [str(DOMAINS.index(r[2])) for r in reals]),
            c_array("long long", "IP_DEFAULT", [f"{int(i[1])}LL" for i in spec.ints]),
            c_array("long long", "IP_MIN", [f"{int(i[2])}LL" for i in spec.ints]),
            c_array("long long", "IP_MAX", [f"{int(i[3])}LL" for i in spec.ints]),
            c_strings("REAL_NAMES", [v.name for v in variables[:n_real]]),
            c_strings("INT_NAMES", [i[0] for i in spec.ints]),
            "#endif", ""])

    def generate(folder: Path, guid: str) -> list[str]:
        (folder / "model_config.h").write_text(config(guid))
        return []

    in_idx = [v.vr + 1 for v in variables if v.kind == "input"]
    p_idx = [v.vr + 1 for v in variables if v.kind in ("param", "int")]
    outs = [v.vr + 1 for v in variables if v.kind == "output"]
    if spec.kind == "sensor":       # channel j depends on input j only
        o_unknowns = [Unknown(o, [i], ["dependent"]) for o, i in zip(outs, in_idx, strict=True)]
    else:
        o_unknowns = [Unknown(o, []) for o in outs]

    def xml(guid: str, c_files: list[str]) -> str:
        d = Description(model_name=identifier, identifier=identifier, guid=guid,
                        description=spec.description or f"{spec.kind} signal (pendulum-cosim)",
                        variables=variables, outputs=o_unknowns,
                        initial_unknowns=[Unknown(o, p_idx + in_idx) for o in outs],
                        variable_step=True, default_step=spec.period, source_files=c_files)
        return fmi2(d) if fmi_version == 2 else fmi3(d)

    fingerprint = f"{spec}"
    return pack_fmu(identifier, "signal", fmi_version, generate, xml, out_dir, fingerprint=fingerprint,
                    file_name=file_name)


def channel_params(prefix: str, names: Sequence[str], values, domain: str, what: str) -> list[tuple]:
    """Real parameter rows ``<prefix>_<name>`` for per-channel ``values``."""
    return [(f"{prefix}_{n}", float(v), domain, f"{what} of {n}") for n, v in zip(names, values, strict=True)]

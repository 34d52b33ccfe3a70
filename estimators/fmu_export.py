"""A configured filter as a native Co-Simulation FMU (FMI 2.0 or 3.0), no Python inside.

:func:`export_filter_fmu` generates C code for the filter's compiled fused step (the very
CasADi Function :meth:`~estimators.base.KalmanBase.step` runs) and for a function mapping
the FMU's parameters to the filter's initial state, and packs them with the estimator
core (``fmu_models/c/filter_core.c``) and the project's FMI wrappers
(:mod:`fmu_models.fmu_pack`): the same machinery as the plant FMUs.

Variables (names from the model):

* inputs: the model's inputs ``u`` (e.g. ``F``) and measurements ``y`` (e.g. ``y_x``), and
  one Boolean ``valid_<measurement>`` per channel (false: that channel's update is skipped;
  a NaN measurement is missing too unless the filter has ``nan_is_missing=False``);
* outputs: the estimate (one variable per state, the state names), the diagonal of P
  (``P_<state>``), the innovation (``innov_<measurement>``), ``nis``, and for adaptive
  filters their current Q and R diagonals (``Q_<state>``, ``R_<measurement>``);
* parameters (with the exported filter's values as defaults, checked as in Python):
  ``x0_<state>``, ``P0_<state>`` (diagonal), ``gate`` (chi-square gate on the NIS, 0: none),
  and per filter: ``Q0_<state>``, ``R0_<measurement>`` (KF, EKF, UKF, IAE: diagonals);
  IAE and MF-IAE ``q_min, q_max, r_min, r_max`` (bounds of the adapted variances);
  MF-IAE ``q0``, ``r0`` (or ``r0_<measurement>`` per channel), ``gain_q``, ``gain_r``.

Timing: as :class:`~cosim.components.estimation.EstimatorComponent`; see ``filter_core.h``. One
``doStep`` is one filter step and must last the filter's period.
"""
from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np

from fmu_models.codegen import c_array, c_strings
from fmu_models.errors import ConfigurationError, TypeMismatchError
from fmu_models.fmu_layout import FmuVariable
from fmu_models.fmu_pack import pack_fmu
from fmu_models.variables import DOMAINS
from fmu_models.xml_writer import Description, Unknown, fmi2, fmi3

from .base import DIAGNOSTICS, STEP_INPUTS, KalmanBase, _finite
from .iae import IAE
from .mfiae import MFIAE

__all__ = ["export_filter_fmu", "filter_parameters"]



def _diag(M: np.ndarray, what: str, name: str) -> np.ndarray:
    if np.abs(M - np.diag(np.diag(M))).max() > 0:
        raise ConfigurationError(f"{name}: the FMU takes diagonal {what}; this filter's {what} has "
                                 "off-diagonal entries")
    return np.diag(M).copy()


class _Params:
    """The FMU's parameters: name, default, domain, unit, description."""

    def __init__(self):
        self.rows: list[tuple] = []
        self.less: list[tuple[int, int]] = []

    def add(self, name, value, domain, unit, description) -> int:
        self.rows.append((name, float(value), domain, unit, description))
        return len(self.rows) - 1


def _spec(filt: KalmanBase, p: ca.SX, idx: dict):
    """The initial state arrays and fixed step inputs as expressions of the parameters."""
    s = filt.system
    x = ca.vertcat(*[p[idx[f"x0_{n}"]] for n in s.state_names])
    P = ca.diag(ca.vertcat(*[p[idx[f"P0_{n}"]] for n in s.state_names]))
    if isinstance(filt, MFIAE):
        Q = p[idx["q0"]] * ca.SX.eye(s.nx)
        r = (ca.vertcat(*[p[idx[f"r0_{n}"]] for n in s.output_names]) if filt.per_channel
             else ca.repmat(p[idx["r0"]], s.ny, 1))
        R = ca.diag(r)
    else:
        Q = ca.diag(ca.vertcat(*[p[idx[f"Q0_{n}"]] for n in s.state_names]))
        R = ca.diag(ca.vertcat(*[p[idx[f"R0_{n}"]] for n in s.output_names]))
    state = {"x": x, "P": P, "Q": Q, "R": R}
    extra = {"ring": ca.SX.zeros(s.ny * getattr(filt, "window", 0)), "count": ca.SX(0)}
    fixed = {"gate": ca.if_else(p[idx["gate"]] > 0, p[idx["gate"]], ca.inf),
             "nan_missing": ca.SX(float(filt.nan_is_missing)), "Q": Q, "R": R}
    if isinstance(filt, (IAE, MFIAE)):
        fixed["q_bounds"] = ca.vertcat(p[idx["q_min"]], p[idx["q_max"]])
        fixed["r_bounds"] = ca.vertcat(p[idx["r_min"]], p[idx["r_max"]])
    if isinstance(filt, MFIAE):
        fixed["gains"] = ca.vertcat(p[idx["gain_q"]], p[idx["gain_r"]])
    return {**state, **extra}, fixed


def _parameters(filt: KalmanBase, name: str) -> _Params:
    s = filt.system
    prm = _Params()
    for n, v in zip(s.state_names, filt.x):
        prm.add(f"x0_{n}", v, "real", "", f"initial estimate of {n}")
    for n, v in zip(s.state_names, _diag(filt.P, "P0", name)):
        prm.add(f"P0_{n}", v, "positive", "", f"initial variance of {n}")
    prm.add("gate", filt.gate if np.isfinite(filt.gate) else 0.0, "nonnegative", "",
            "chi-square gate on the NIS: a measurement with a larger NIS is refused (0: no gate)")
    if isinstance(filt, MFIAE):
        prm.add("q0", filt.Q[0, 0], "positive", "", "initial process noise variance sigma_q^2 (Q = q0 I)")
        r = np.diag(filt.R)
        if filt.per_channel:
            for n, v in zip(s.output_names, r):
                prm.add(f"r0_{n}", v, "positive", "", f"initial measurement noise variance of {n}")
        else:
            prm.add("r0", r[0], "positive", "", "initial measurement noise variance sigma_r^2 (R = r0 I)")
        prm.add("gain_q", filt.gain_q, "unit", "", "step size of sigma_q^2 (eq 41), in (0, 1]")
        prm.add("gain_r", filt.gain_r, "unit", "", "step size of sigma_r^2 (eq 42), in (0, 1]")
    else:
        for n, v in zip(s.state_names, _diag(filt.Q, "Q", name)):
            prm.add(f"Q0_{n}", v, "positive", "", f"process noise variance of {n}"
                    + (" (initial)" if filt.adapts_noise else ""))
        for n, v in zip(s.output_names, _diag(filt.R, "R", name)):
            prm.add(f"R0_{n}", v, "positive", "", f"measurement noise variance of {n}"
                    + (" (initial)" if filt.adapts_noise else ""))
    if isinstance(filt, (IAE, MFIAE)):
        lo_q = prm.add("q_min", filt.q_bounds[0], "positive", "", "smallest adapted process variance")
        hi_q = prm.add("q_max", filt.q_bounds[1], "positive", "", "largest adapted process variance")
        lo_r = prm.add("r_min", filt.r_bounds[0], "positive", "", "smallest adapted measurement variance")
        hi_r = prm.add("r_max", filt.r_bounds[1], "positive", "", "largest adapted measurement variance")
        prm.less += [(lo_q, hi_q), (lo_r, hi_r)]
    return prm


def filter_parameters(filt: KalmanBase) -> dict[str, float]:
    """The parameters of ``filt``'s FMU with the filter's current values, by name (see
    the module documentation)."""
    return {r[0]: r[1] for r in _parameters(filt, filt.name).rows}


def export_filter_fmu(filt: KalmanBase, out_dir=".", fmi_version: int = 2, name: str | None = None,
                      file_name: str | None = None) -> Path:
    """Export ``filt`` (KF, EKF, UKF, IAE, MF-IAE, bias-augmented EKF, on any model) as a
    Co-Simulation FMU; returns the ``.fmu`` path.

    Parameters
    ----------
    filt : KalmanBase
        The configured filter; its current estimate, covariances and settings become the
        FMU's parameter defaults (P0, Q, R must be diagonal).
    out_dir : path
        Folder to write ``<name>.fmu`` into.
    fmi_version : {2, 3}
    name : str, optional
        Model identifier (default ``<Filter><Model>``, e.g. ``EKFCartpole``).
    file_name : str, optional
        The FMU file name (default ``<name>.fmu``).

    Raises
    ------
    TypeMismatchError
        Not a filter, or an IAE with ``form="full"`` (its projection is not compiled).
    ConfigurationError
        A non-diagonal P, Q or R, or a bad name.
    """
    if not isinstance(filt, KalmanBase):
        raise TypeMismatchError(f"export_filter_fmu needs a filter, got {type(filt).__name__}")
    if not filt.supports_batch:
        raise TypeMismatchError(f"{filt.name} with form='full' adapts in numpy and cannot be exported; "
                                "use form='diagonal' or 'scalar'")
    s = filt.system
    model = s.description.split(" ")[0].capitalize() or "Model"
    name = name or "".join(ch for ch in f"{filt.name.replace('-', '')}{model}" if ch.isalnum())
    if not name.isidentifier():
        raise ConfigurationError(f"FMU name {name!r} must be an identifier")
    prm = _parameters(filt, name)
    np_ = len(prm.rows)
    idx = {r[0]: i for i, r in enumerate(prm.rows)}
    psym = ca.SX.sym("p", np_)
    state0, fixed0 = _spec(filt, psym, idx)
    step = filt.step_function()
    names_in = [step.name_in(i) for i in range(step.n_in())]
    names_out = [step.name_out(i) for i in range(step.n_out())]
    state_names = list(filt.state_arrays())
    fixed_names = [n for n in names_in if n not in state_names and n not in ("u", "y", "mask")]
    # buffers: state (the filter's state arrays), fixed (the step's fixed inputs), diag
    off, st_off, fx_off, dg_off = 0, {}, {}, {}
    for n in state_names:
        st_off[n], off = off, off + step.nnz_in(n)
    nstate, off = off, 0
    for n in fixed_names:
        fx_off[n], off = off, off + step.nnz_in(n)
    nfixed, off = off, 0
    for n in names_out:
        if not n.endswith("_new") and n != "status":
            dg_off[n], off = off, off + step.nnz_out(n)
    ndiag = off
    init_out = [ca.densify(ca.reshape(state0[n], step.size_in(n))) for n in state_names]
    init_out += [ca.densify(ca.reshape(fixed0[n], step.size_in(n))) for n in fixed_names]
    # the gate may be inf (no gate); everything else must be finite
    bad = 1 - _finite([e for e, n in zip(init_out, state_names + fixed_names) if n != "gate"])
    init = ca.Function("flt_init", [psym], init_out + [bad])
    args = [ca.SX.sym(n, step.sparsity_in(i)) for i, n in enumerate(names_in)]
    run_step = ca.Function("flt_step", args, step.call(args), names_in, names_out)
    src = {"u": (1, 0), "y": (2, 0), "mask": (3, 0)}
    step_src = [(0, st_off[n]) if n in st_off else src.get(n, (4, fx_off.get(n, 0))) for n in names_in]
    step_dst = [(0, st_off[n[:-4]]) if n.endswith("_new") else (2, 0) if n == "status" else (1, dg_off[n])
                for n in names_out]
    # FMU variables: parameters, u, y, outputs (Real), valid (Boolean), time
    variables: list[FmuVariable] = []

    def add(**kw):
        variables.append(FmuVariable(vr=len(variables), **kw))

    for pname, value, _domain, _unit, descr in prm.rows:
        add(name=pname, type="Real", causality="parameter", variability="fixed", initial="exact", start=value,
            unit=None, description=descr, kind="param")
    for n in s.input_names:
        add(name=n, type="Real", causality="input", variability="discrete", initial=None, start=0.0, unit=None,
            description=f"input {n}, held over the prediction that starts now", kind="input")
    for n in s.output_names:
        add(name=n, type="Real", causality="input", variability="discrete", initial=None, start=0.0, unit=None,
            description=f"measurement {n} (NaN: missing)", kind="meas")
    outs: list[tuple[str, int, int, str]] = []           # name, source, offset, description
    nx, ny = s.nx, s.ny
    outs += [(n, 0, st_off["x"] + i, f"estimate of {n}") for i, n in enumerate(s.state_names)]
    outs += [(f"P_{n}", 0, st_off["P"] + i * (nx + 1), f"variance of the estimate of {n}")
             for i, n in enumerate(s.state_names)]
    outs += [(f"innov_{n}", 1, dg_off["innov"] + j, f"innovation of {n}") for j, n in enumerate(s.output_names)]
    outs += [("nis", 1, dg_off["nis"], "normalised innovation squared")]
    if filt.adapts_noise:
        outs += [(f"Q_{n}", 0, st_off["Q"] + i * (nx + 1), f"adapted process variance of {n}")
                 for i, n in enumerate(s.state_names)]
        outs += [(f"R_{n}", 0, st_off["R"] + j * (ny + 1), f"adapted measurement variance of {n}")
                 for j, n in enumerate(s.output_names)]
    for oname, _, _, descr in outs:
        add(name=oname, type="Real", causality="output", variability="discrete", initial="calculated", start=None,
            unit=None, description=descr, kind="output")
    n_real = len(variables)
    for n in s.output_names:
        add(name=f"valid_{n}", type="Boolean", causality="input", variability="discrete", initial=None, start=True,
            unit=None, description=f"measurement {n} is valid (false: its update is skipped)", kind="valid")
    add(name="time", type="Real", causality="independent", variability="continuous", initial=None, start=None,
        unit="s", description="simulation time", kind="time")
    first = {k: next(v.vr for v in variables if v.kind == k) for k in ("param", "output", "valid", "time")}
    first["input"] = next((v.vr for v in variables if v.kind == "input"), first["output"])
    first["meas"] = next(v.vr for v in variables if v.kind == "meas")
    work = {k: max(getattr(f, f"sz_{k}")() for f in (init, run_step)) for k in ("arg", "res", "iw", "w")}
    work["arg"] = max(work["arg"], run_step.n_in(), 1)
    work["res"] = max(work["res"], run_step.n_out(), init.n_out())
    reals = [v.name for v in variables[:n_real]]

    def config(guid: str) -> str:
        return "\n".join([
            "/* Generated by pendulum-cosim (estimators.fmu_export). Do not edit. */",
            "#ifndef MODEL_CONFIG_H", "#define MODEL_CONFIG_H",
            f'#define MODEL_IDENTIFIER_STR "{name}"', f'#define MODEL_GUID "{guid}"',
            f"#define NP {np_}", f"#define NU {s.nu}", f"#define NY {ny}", f"#define NOUT {len(outs)}",
            f"#define NSTATE {max(nstate, 1)}", f"#define NFIXED {max(nfixed, 1)}", f"#define NDIAG {max(ndiag, 1)}",
            f"#define PERIOD {s.dt!r}",
            f"#define VR_P {first['param']}", f"#define VR_U {first['input']}", f"#define VR_Y {first['meas']}",
            f"#define VR_OUT {first['output']}", f"#define VR_VALID {first['valid']}",
            f"#define VR_TIME {first['time']}", f"#define N_REAL {n_real}",
            *(f"#define WORK_{k.upper()} {v}" for k, v in work.items()),
            c_array("double", "PARAM_DEFAULT", [repr(r[1]) for r in prm.rows]),
            c_array("int", "PARAM_DOMAIN", [str(DOMAINS.index(r[2])) for r in prm.rows]),
            f"#define N_LESS {len(prm.less)}",
            c_array("int", "LESS_LO", [str(a) for a, _ in prm.less]),
            c_array("int", "LESS_HI", [str(b) for _, b in prm.less]),
            f"#define INIT_NOUT {len(state_names) + len(fixed_names)}",
            c_array("int", "INIT_DST", ["0"] * len(state_names) + ["1"] * len(fixed_names)),
            c_array("int", "INIT_OFF", [str(st_off[n]) for n in state_names] + [str(fx_off[n]) for n in fixed_names]),
            f"#define STEP_NIN {len(names_in)}",
            c_array("int", "STEP_SRC", [str(a) for a, _ in step_src]),
            c_array("int", "STEP_OFF", [str(b) for _, b in step_src]),
            f"#define STEP_NOUT {len(names_out)}",
            c_array("int", "STEP_DST", [str(a) for a, _ in step_dst]),
            c_array("int", "STEP_ROFF", [str(b) for _, b in step_dst]),
            c_array("int", "OUT_SRC", [str(o[1]) for o in outs]),
            c_array("int", "OUT_OFF", [str(o[2]) for o in outs]),
            c_strings("REAL_NAMES", reals),
            "#endif", ""])

    def generate(folder: Path, guid: str) -> list[str]:
        cg = ca.CodeGenerator("model_funcs.c", {"with_header": True})
        cg.add(init)
        cg.add(run_step)
        cg.generate(str(folder) + "/")
        (folder / "model_config.h").write_text(config(guid))
        return ["model_funcs.c"]

    y_idx = [v.vr + 1 for v in variables if v.kind in ("meas", "valid")]
    p_idx = [v.vr + 1 for v in variables if v.kind == "param"]
    out_idx = [v.vr + 1 for v in variables if v.kind == "output"]

    def xml(guid: str, c_files: list[str]) -> str:
        d = Description(model_name=name, identifier=name, guid=guid,
                        description=f"{filt.name} on {s.description}: a filter step per communication step "
                                    f"of {s.dt:g} s (pendulum-cosim)",
                        variables=variables,
                        outputs=[Unknown(k, y_idx, ["dependent"] * len(y_idx)) for k in out_idx],
                        initial_unknowns=[Unknown(k, p_idx) for k in out_idx],
                        variable_step=False, default_step=s.dt, source_files=c_files)
        return fmi2(d) if fmi_version == 2 else fmi3(d)

    return pack_fmu(name, "filter", fmi_version, generate, xml, out_dir,
                    fingerprint=f"{filt.cache_key}|{prm.rows}|{s.dt}|{STEP_INPUTS}|{DIAGNOSTICS}",
                    file_name=file_name)

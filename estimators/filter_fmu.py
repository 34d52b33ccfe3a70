"""A configured filter as a native Co-Simulation FMU (FMI 2.0 or 3.0), no Python inside.

C code generated for the filter's compiled fused step and for ``fmu_initial`` (the protocol of
:mod:`estimators.protocol`), packed with the estimator core (``c/filter_core.c``) by
:mod:`fmu_models.export.pack`; the manual's page "Taking the estimator to another tool" gives
the FMU's variables, timing and clocked form."""
from __future__ import annotations

from functools import partial
from itertools import accumulate, groupby
from pathlib import Path

import casadi as ca

from fmu_models.errors import ConfigurationError, TypeMismatchError
from fmu_models.export.clocked import check_clocked, clock_defines, clock_variables
from fmu_models.export.config import c_array, config_header, work_sizes
from fmu_models.export.description import Description, Unknown, fmi2, fmi3
from fmu_models.export.pack import pack_fmu
from fmu_models.export.variable_list import VariableList
from fmu_models.infra.checks import check_unique
from fmu_models.infra.codegen import inline_min_max_file

from .linalg import finite_flag

__all__ = ["export_filter_fmu", "filter_parameters"]

#: The step's measurement inputs, set by the FMU from its variables.
_FED = ("u", "y", "mask")
#: The diagnostics the FMU shows (as outputs ``innov_*`` and ``nis``); with the new state and
#: the status they are all its generated step computes (no log-determinant of S, no gain, ...).
_SHOWN = ("innov", "nis")


def _flat_parameters(filt) -> list[tuple]:
    """``(label, value, domain, description, parameter name, entry)`` of every FMU parameter."""
    rows, seen = [], set()
    for prm in filt.fmu_parameters():
        for i, label in enumerate(prm.labels):
            if label in seen:
                raise ConfigurationError(f"{filt.name}: two FMU parameters are named {label!r}")
            seen.add(label)
            rows.append((label, float(prm.value[i]), prm.domain, prm.describe(i), prm.name, i))
    return rows


def filter_parameters(filt) -> dict[str, float]:
    """The parameters of ``filt``'s FMU with the filter's current values, by FMU name (the
    manual's page "Taking the estimator to another tool" lists them)."""
    return {r[0]: r[1] for r in _flat_parameters(filt)}


def _check_exportable(filt) -> None:
    """Refuse what cannot become a filter FMU (the errors :func:`export_filter_fmu` names)."""
    if not all(hasattr(filt, a) for a in ("fmu_parameters", "fmu_initial", "step_function", "state_arrays",
                                          "system", "supports_batch")):
        raise TypeMismatchError(f"export_filter_fmu needs a filter of estimators, got {type(filt).__name__}")
    if not filt.supports_batch:
        raise TypeMismatchError(f"{filt.name} adapts part of its state in numpy and cannot be exported"
                                + ("; use form='diagonal' or 'scalar'" if hasattr(filt, "form") else ""))
    if not filt.system.exportable:
        raise ConfigurationError(f"{filt.name} runs on {filt.system!r}, whose map calls compiled code outside the "
                                 "filter (an FMU's): its step cannot be packed into an FMU of its own")


def export_filter_fmu(filt, out_dir=".", fmi_version: int = 2, name: str | None = None,
                      file_name: str | None = None, clocked: bool = False) -> Path:
    """Export ``filt`` (any filter of :mod:`estimators`, on any model) as a Co-Simulation FMU;
    returns the ``.fmu`` path.

    Parameters
    ----------
    filt : KalmanBase
        The configured filter; its current estimate, covariances and settings become the
        FMU's parameter defaults (P0, Q, R must be diagonal).
    out_dir : path
        Folder to write ``<name>.fmu`` into.
    fmi_version : {2, 3}
    name, file_name : str, optional
        Model identifier (default ``<Filter><Model>``, e.g. ``EKFCartpole``) and file name
        (default ``<name>.fmu``).
    clocked : bool
        Write the clocked form (FMI 3.0 only; see the manual's page "Taking the estimator to
        another tool").

    Raises
    ------
    TypeMismatchError
        Not a filter, or a filter whose adaptation is not all in its step (an IAE with
        ``form="full"``).
    ConfigurationError
        A non-diagonal P, Q or R, a bad name, parameters the FMU cannot hold, or a model
        whose map calls compiled code outside the filter (an FMU's process model);
        ``clocked=True`` with ``fmi_version=2`` (FMI 2.0 has no clocks).
    """
    check_clocked(clocked, fmi_version, "the filter FMU")
    _check_exportable(filt)
    s = filt.system
    model = s.description.split(" ")[0].capitalize() or "Model"
    name = name or "".join(ch for ch in f"{filt.name.replace('-', '')}{model}" if ch.isalnum())
    if not name.isidentifier() or not name.isascii():
        raise ConfigurationError(f"FMU name {name!r} must be an ASCII identifier")
    core = _FilterCore(filt)
    v = core.variables(clocked)
    y_idx = v.indices(["Y", "VALID"]) + v.indices(["CLOCK"])
    p_idx, out_idx = v.indices(["P"]), v.indices(["OUT"])

    def xml(guid: str, c_files: list[str]) -> str:
        d = Description(model_name=name, identifier=name, guid=guid,
                        description=f"{filt.name} on {s.description}: a filter step per communication step "
                                    f"of {s.dt:g} s (pendulum-cosim)",
                        variables=v.variables,
                        outputs=[Unknown(k, y_idx, ["dependent"] * len(y_idx)) for k in out_idx],
                        initial_unknowns=[] if clocked else [Unknown(k, p_idx) for k in out_idx],
                        variable_step=True, default_step=s.dt, source_files=c_files, clocked=clocked)
        return fmi2(d) if fmi_version == 2 else fmi3(d)

    return pack_fmu(name, "filter", fmi_version, partial(core.write_sources, v, name), xml, out_dir,
                    fingerprint=f"{filt.cache_key}|{core.rows}|{s.dt}|{core.names_in}|{core.names_out}|{clocked}",
                    file_name=file_name)


def _offsets(names: list[str], size) -> tuple[dict[str, int], int]:
    """Where each array ``names[i]`` of ``size(name)`` entries starts in one flat buffer, and
    the buffer's size."""
    starts = list(accumulate(map(size, names), initial=0))
    return dict(zip(names, starts)), starts[-1]


class _FilterCore:
    """What the filter core (``c/filter_core.h``) is told about ``filt``: its parameters (``rows``),
    three flat buffers (state arrays, fixed step inputs, diagnostics) with each array's offset,
    ``flt_init`` (parameters to initial buffers) and ``flt_step`` with where each of its arguments
    comes from and each result goes, and the FMU's outputs."""

    def __init__(self, filt):
        self.filt, self.rows = filt, _flat_parameters(filt)
        step = filt.step_function()
        self.names_in = [step.name_in(i) for i in range(step.n_in())]
        full = [step.name_out(i) for i in range(step.n_out())]
        keep = [i for i, n in enumerate(full) if n.endswith("_new") or n in _SHOWN or n == "status"]
        self.names_out = [full[i] for i in keep]
        self.state_names = list(filt.state_arrays())
        self.fixed_names = [n for n in self.names_in if n not in self.state_names and n not in _FED]
        self.init = self._init_function(step)
        self.step = step.slice("flt_step", list(range(step.n_in())), keep)
        st_off, self.nstate = _offsets(self.state_names, step.nnz_in)
        fx_off, self.nfixed = _offsets(self.fixed_names, step.nnz_in)
        dg_off, self.ndiag = _offsets([n for n in self.names_out if n in _SHOWN], step.nnz_out)
        self.init_off = [st_off[n] for n in self.state_names] + [fx_off[n] for n in self.fixed_names]
        src = {"u": (1, 0), "y": (2, 0), "mask": (3, 0)}
        self.step_src = [(0, st_off[n]) if n in st_off else src.get(n, (4, fx_off.get(n, 0))) for n in self.names_in]
        self.step_dst = [(0, st_off[n[:-4]]) if n.endswith("_new") else (2, 0) if n == "status" else (1, dg_off[n])
                         for n in self.names_out]
        self.outs = _outputs(filt.system, st_off, dg_off)
        self.less = self._ordered_pairs()

    def _init_function(self, step):
        """``flt_init``: the FMU parameters to the initial state arrays and fixed inputs, and a
        flag (1: one is not finite; the gate may be inf, no gate)."""
        filt, rows = self.filt, self.rows
        psym = ca.SX.sym("p", len(rows))
        initial = filt.fmu_initial({name: ca.vertcat(*(psym[k] for k, _ in group))
                                    for name, group in groupby(enumerate(rows), key=lambda kr: kr[1][4])})
        names = self.state_names + self.fixed_names
        missing = [n for n in names if n not in initial]
        if missing:
            raise ConfigurationError(f"{filt.name}: fmu_initial gives no value for {missing}")
        init_out = []
        for n in names:
            expr = ca.SX(initial[n])
            if expr.numel() != step.nnz_in(n):
                raise ConfigurationError(f"{filt.name}: fmu_initial gives {expr.numel()} values for {n!r}, the step "
                                         f"takes {step.nnz_in(n)}")
            init_out.append(ca.densify(ca.reshape(expr, step.size_in(n))))
        bad = 1 - finite_flag([e for e, n in zip(init_out, names) if n != "gate"])
        return ca.Function("flt_init", [psym], init_out + [bad])

    def variables(self, clocked: bool) -> VariableList:
        """The FMU's variables (listed on the manual's page "Taking the estimator to another tool")."""
        s = self.filt.system
        v = VariableList()
        for label, value, domain, descr, _, _ in self.rows:
            v.parameter(label, value, descr, domain=domain)
        for n in s.input_names:
            v.input(n, 0.0, f"input {n}, held over the prediction that starts now", "U", variability="discrete")
        for n in s.output_names:
            v.input(n, 0.0, f"measurement {n} (NaN: missing)", "Y", variability="discrete")
        for oname, _, _, descr in self.outs:
            v.output(oname, descr, "OUT", variability="discrete")
        for n in s.output_names:
            v.input(f"valid_{n}", True, f"measurement {n} is valid (false: its update is skipped)", "VALID",
                    type="Boolean", variability="discrete")
        v.time()
        if clocked:
            v = clock_variables(v, ("U", "Y", "OUT", "VALID"), s.dt,
                                f"the filter's sample instants (every {s.dt:g} s from the start time)")
        check_unique((x.name for x in v.variables), f"{self.filt.name}: FMU variable names collide:",
                     hint="rename the model's variables or the filter's parameters")
        return v

    def _ordered_pairs(self) -> list[tuple[int, int]]:
        """The parameter pairs ``(lo, hi)`` (indices) that must increase."""
        less, names = [], [r[4] for r in self.rows]
        for prm in self.filt.fmu_parameters():
            if prm.increasing:
                k0 = names.index(prm.name)
                less += [(k0 + i, k0 + i + 1) for i in range(prm.size - 1)]
        return less

    def write_sources(self, v: VariableList, name: str, folder: Path, guid: str) -> list[str]:
        """The generated code of ``flt_init`` and ``flt_step`` and ``model_config.h`` for the
        FMU ``name`` with variables ``v``."""
        cg = ca.CodeGenerator("model_funcs.c", {"with_header": True})
        cg.add(self.init)
        cg.add(self.step)
        cg.generate(str(folder) + "/")
        inline_min_max_file(folder / "model_funcs.c")
        less, n_init, dt = self.less, len(self.init_off), self.filt.system.dt
        header = config_header(
            v, name, guid, "estimators.filter_fmu", groups=("U", "Y", "OUT", "VALID", "TIME"),
            work=work_sizes([self.init, self.step], minimum_res=self.init.n_out()),
            defines=[("NSTATE", max(self.nstate, 1)), ("NFIXED", max(self.nfixed, 1)), ("NDIAG", max(self.ndiag, 1)),
                     ("PERIOD", repr(dt)), ("N_LESS", len(less)), ("INIT_NOUT", n_init),
                     ("STEP_NIN", len(self.names_in)), ("STEP_NOUT", len(self.names_out))] + clock_defines(v, dt),
            tables=[c_array("int", "LESS_LO", [a for a, _ in less]), c_array("int", "LESS_HI", [b for _, b in less]),
                    c_array("int", "INIT_DST", [0] * len(self.state_names) + [1] * len(self.fixed_names)),
                    c_array("int", "INIT_OFF", self.init_off),
                    c_array("int", "STEP_SRC", [a for a, _ in self.step_src]),
                    c_array("int", "STEP_OFF", [b for _, b in self.step_src]),
                    c_array("int", "STEP_DST", [a for a, _ in self.step_dst]),
                    c_array("int", "STEP_ROFF", [b for _, b in self.step_dst]),
                    c_array("int", "OUT_SRC", [o[1] for o in self.outs]),
                    c_array("int", "OUT_OFF", [o[2] for o in self.outs])])
        (folder / "model_config.h").write_text(header)
        return ["model_funcs.c"]


def _outputs(s, st_off: dict[str, int], dg_off: dict[str, int]) -> list[tuple[str, int, int, str]]:
    """The FMU's outputs ``(name, buffer (0: state, 1: diagnostics), offset, description)``: the
    estimate, the diagonal of P, the innovation, the NIS and, if adapted, the diagonals of Q, R."""
    def diagonal(key: str, names: list[str], what: str) -> list[tuple]:
        return [(f"{key}_{n}", 0, st_off[key] + i * (len(names) + 1), f"{what} of {n}") for i, n in enumerate(names)]

    outs = [(n, 0, st_off["x"] + i, f"estimate of {n}") for i, n in enumerate(s.state_names)]
    outs += diagonal("P", s.state_names, "variance of the estimate")
    outs += [(f"innov_{n}", 1, dg_off["innov"] + j, f"innovation of {n}") for j, n in enumerate(s.output_names)]
    outs += [("nis", 1, dg_off["nis"], "normalised innovation squared")]
    if "Q" in st_off:
        outs += diagonal("Q", s.state_names, "adapted process variance")
        outs += diagonal("R", s.output_names, "adapted measurement variance")
    return outs

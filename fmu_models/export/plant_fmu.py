"""The plant FMUs (Model Exchange and Co-Simulation, FMI 2.0 or 3.0) of a :class:`~fmu_models.PlantModel`,
packed by :func:`fmu_models.export.pack.pack_fmu` with ``c/plant_core.c``; the C code of f, h and
their Jacobians is CasADi's, the ModelStructure the structural sparsity of its expressions.

Variables in value-reference order, by group (:mod:`fmu_models.export.config`): the parameters
[P], ``step_size`` [STEP], the states [X], ``der(state)`` [DX], the inputs [U], the process
noises ``w_<state>`` [W], the measured outputs [Y], ``integrator`` and ``substeps`` [IP], ``time``.
"""
from __future__ import annotations

from functools import partial
from pathlib import Path

import casadi as ca

from ..catalog import get_model, model_names
from ..infra.codegen import inline_min_max_file
from ..plant import PlantModel
from .config import c_array, config_header, work_sizes
from .description import Description, Unknown, fmi2, fmi3
from .pack import pack_fmu
from .variable_list import VariableList

__all__ = ["DEFAULT_STEP_SIZE", "build_fmu", "build_fmus", "derivative_unit", "plant_variables"]

#: Default internal step [s], seed 000's sampling period T.
DEFAULT_STEP_SIZE = 0.01
_ITEMS = (("euler", 1, "forward Euler (seed 000 eqs 14-17)"), ("rk4", 2, "classical Runge-Kutta 4"))


def derivative_unit(unit: str) -> str:
    """Unit of the time derivative of a quantity in ``unit`` (``"m/s"`` -> ``"m/s2"``)."""
    if unit.endswith("/s"):
        return unit + "2"
    return "1/s" if unit == "1" else unit + "/s"


def plant_variables(model: PlantModel) -> VariableList:
    """The FMU variables of ``model`` (see the module documentation)."""
    v = VariableList()
    for p, val in zip(model.parameters, model.p):
        v.parameter(p.name, float(val), p.description, unit=p.unit, domain=p.domain)
    v.parameter("step_size", DEFAULT_STEP_SIZE, "internal integration step is step_size/substeps; a communication "
                "step that is not a multiple of it ends with a partial step", "STEP", unit="s", domain="positive")
    first_state = len(v.variables) + 1
    for s in model.states:
        v.add(name=s.name, type="Real", causality="output", variability="continuous", initial="exact",
              start=float(s.start), unit=s.unit, description=s.description + " (continuous state)", group="X")
    for i, s in enumerate(model.states):
        v.add(name=f"der({s.name})", type="Real", causality="local", variability="continuous",
              initial="calculated", unit=derivative_unit(s.unit), description=f"time derivative of {s.name}",
              derivative_of=first_state + i, group="DX")
    for u in model.inputs:
        v.input(u.name, float(u.start), u.description, "U", unit=u.unit)
    for s in model.states:
        v.input(f"w_{s.name}", 0.0, f"process noise added to {s.name} at the end of each Co-Simulation step (seed "
                "000 eq 12); not used in Model Exchange", "W", unit=s.unit)
    for y in model.outputs:
        v.output(y.name, y.description, "Y", unit=y.unit)
    v.parameter("integrator", 1, "Co-Simulation integrator: 1 = euler (seed 000 truth map), 2 = rk4", "IP",
                type="Enumeration", declared_type="Integrator", min=1, max=2)
    v.parameter("substeps", 1, "internal steps per step_size (both integrators)", "IP", type="Integer", min=1,
                max=1_000_000)
    v.time()
    return v


def _write_sources(model: PlantModel, variables: VariableList, folder: Path, guid: str) -> list[str]:
    """``model_funcs.c``: the four functions the plant core calls, with dense outputs (column-major
    arrays in C); and ``model_config.h``."""
    s = model.sym
    x, u, p, d = s.x, s.u, s.p, ca.densify
    funcs = [ca.Function("mdl_f", [x, u, p], [d(s.xdot)]),
             ca.Function("mdl_h", [x, p], [d(s.y)]),
             ca.Function("mdl_jac_f", [x, u, p], [d(ca.jacobian(s.xdot, x)), d(ca.jacobian(s.xdot, u))]),
             ca.Function("mdl_jac_h", [x, p], [d(ca.jacobian(s.y, x))])]
    cg = ca.CodeGenerator("model_funcs.c", {"with_header": True})
    for f in funcs:
        cg.add(f)
    cg.generate(str(folder) + "/")
    inline_min_max_file(folder / "model_funcs.c")
    header = config_header(variables, model.fmu_name, guid, "fmu_models.export.plant_fmu", work=work_sizes(funcs, 3, 2),
                           defines=[("DEFAULT_STEP_SIZE", repr(DEFAULT_STEP_SIZE))],
                           tables=[c_array("double", "X_START", [repr(float(s.start)) for s in model.states])])
    (folder / "model_config.h").write_text(header)
    return ["model_funcs.c"]


def _dependencies(model: PlantModel, J: ca.SX, row: int, known: list[int]) -> tuple[list[int], list[str]]:
    """The indices ``known`` that row ``row`` of ``J`` depends on, and the FMI 2.0 dependenciesKind of each."""
    s, deps, kinds = model.sym, [], []
    xu = ca.vertcat(s.x, s.u)
    for col, k in enumerate(known):
        if not J.sparsity().has_nz(row, col):
            continue
        e = J[row, col]
        if e.is_zero():
            continue
        deps.append(k)
        if ca.depends_on(e, xu):
            kinds.append("dependent")
        else:
            kinds.append("fixed" if ca.depends_on(e, s.p) else "constant")
    return deps, kinds


def _description(model: PlantModel, variables: VariableList, guid: str, source_files=()) -> Description:
    s = model.sym
    index = {v.name: v.vr + 1 for v in variables.variables}
    states = [index[n] for n in model.state_names]
    inputs = [index[n] for n in model.input_names]
    params = [index[p.name] for p in model.parameters]
    Jf, Jh = ca.jacobian(s.xdot, ca.vertcat(s.x, s.u)), ca.jacobian(s.y, s.x)
    Jfp, Jhp = ca.jacobian(s.xdot, s.p), ca.jacobian(s.y, s.p)
    measured = [Unknown(index[n], *_dependencies(model, Jh, j, states)) for j, n in enumerate(model.output_names)]
    derivatives = [Unknown(index[f"der({n})"], *_dependencies(model, Jf, i, states + inputs))
                   for i, n in enumerate(model.state_names)]
    initial = [Unknown(u.index, u.deps + _dependencies(model, J, i, params)[0])
               for J, unknowns in ((Jfp, derivatives), (Jhp, measured)) for i, u in enumerate(unknowns)]
    outputs = [Unknown(k, [k], ["constant"]) for k in states] + measured
    return Description(model_name=model.fmu_name, identifier=model.fmu_name, guid=guid,
                       description=model.description, variables=variables.variables, outputs=outputs,
                       derivatives=derivatives, initial_unknowns=initial, model_exchange=True,
                       directional=True, enumerations={"Integrator": _ITEMS}, source_files=source_files)


def build_fmu(model: PlantModel | str, out_dir: str | Path = ".", fmi_version: int = 2) -> Path:
    """Build the FMU of one plant model into ``out_dir``; returns the ``.fmu`` path.

    Parameters
    ----------
    model : PlantModel or str
        The model (its current parameter values become the FMU's start values) or its name.
    out_dir, fmi_version : path, int
        Directory to write ``<fmu_name>.fmu`` into (created if missing); 2 or 3, either way Model
        Exchange and Co-Simulation in one FMU.

    Raises
    ------
    CompilerNotFoundError, BuildError
        No C compiler is available; the compiler failed (its output is in the message).
    """
    if isinstance(model, str):
        model = get_model(model)
    variables = plant_variables(model)

    def xml(guid: str, c_files: list[str]) -> str:
        d = _description(model, variables, guid, c_files if fmi_version == 2 else ())
        return fmi2(d) if fmi_version == 2 else fmi3(d)

    return pack_fmu(model.fmu_name, "plant", fmi_version, partial(_write_sources, model, variables), xml, out_dir,
                    fingerprint=f"{model.p.tolist()}")


def build_fmus(out_dir: str | Path = ".", fmi_version: int = 2, models: tuple[str, ...] | None = None) -> list[Path]:
    """Build the FMUs of the registered plant models into ``out_dir``, as :func:`build_fmu`.

    Parameters
    ----------
    out_dir, fmi_version : path, int
        Output directory (created if missing); 2 or 3.
    models : tuple of str, optional
        Registry names of the models to build (default: all).
    """
    return [build_fmu(get_model(name), out_dir, fmi_version) for name in (models or model_names())]

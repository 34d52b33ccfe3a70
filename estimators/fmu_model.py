"""A Model Exchange FMU (FMI 2.0 or 3.0) as the process model of the filters.

:class:`FMUProcessModel`'s map (a fixed-step integrator over the FMU's right-hand side, exact
Jacobians through its stages) and measurement are compiled C (``estimators/c/fmu_process.c``)
calling the FMU's Model Exchange functions; the FMU tutorial (docs/tutorial-fmu.md) says how and
what is refused."""
from __future__ import annotations

import atexit
import ctypes
import hashlib
import shutil
import tempfile
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from fmu_models.errors import (
    BuildError,
    ConfigurationError,
    FMUError,
    NumericalError,
    TypeMismatchError,
    UnknownNameError,
)
from fmu_models.export.pack import FMI_HEADERS
from fmu_models.infra import checks
from fmu_models.infra.native_library import compiled_library
from fmu_models.infra.resources import shipped
from fmu_models.plant import check_method

from .discrete import DiscreteModel

__all__ = ["JACOBIANS", "FMUProcessModel"]

#: The sources of the Jacobians, ``"auto"`` (the FMU's directional derivatives if it provides
#: them, else central differences), ``"directional"`` (refused without them) or ``"fd"``.
JACOBIANS = ("auto", "directional", "fd")
_FLOAT = ("Real", "Float64")
_P = ctypes.POINTER


class _Config(ctypes.Structure):
    """``fp_config`` of ``fmu_process.c``, field for field."""

    _fields_ = ([(n, ctypes.c_int64) for n in ("version", "nx", "nu", "ny", "nz", "npar", "method", "substeps",
                                                "directional", "restore", "completed_step")]
                + [("dt", ctypes.c_double), ("t0", ctypes.c_double)]
                + [(n, ctypes.c_char_p) for n in ("library", "instance_name", "token", "resources")]
                + [(n, _P(ctypes.c_uint32)) for n in ("vr_x", "vr_dx", "vr_u", "vr_y", "vr_par")]
                + [("y_state", _P(ctypes.c_int64))]
                + [(n, _P(ctypes.c_double)) for n in ("nominal_x", "nominal_u", "u_start", "par")]
                + [(n, _P(ctypes.c_char_p)) for n in ("x_names", "y_names")])


@dataclass
class _Description:
    """What the model needs of an FMU's ``modelDescription.xml``."""

    md: object
    version: int
    identifier: str
    platform: str                   # the folder of this platform's binary
    directional: bool
    can_restore: bool
    needs_completed_step: bool
    variables: dict
    states: list
    derivatives: list
    outputs: dict


def _flag(xml: bytes, *names: str) -> bool:
    """Whether one of the boolean attributes ``names`` of the ``ModelExchange`` element is true."""
    from lxml import etree

    root = etree.fromstring(xml, etree.XMLParser(resolve_entities=False, no_network=True))
    me = root.find("ModelExchange")
    return me is not None and any(me.get(name, "false") == "true" for name in names)


def _read(path: Path) -> tuple[_Description, bytes]:
    """The FMU at ``path`` described, and its bytes (for the model's identity)."""
    from fmpy import platform, platform_tuple, read_model_description

    try:
        data = path.read_bytes()
        with zipfile.ZipFile(path) as z:
            xml = z.read("modelDescription.xml")
        md = read_model_description(str(path), validate=False)
    except (OSError, KeyError, zipfile.BadZipFile) as e:
        raise FMUError(f"cannot read the FMU {path}: {e}") from None
    except Exception as e:  # noqa: BLE001 - lxml, attrs and fmpy raise a variety of types for bad XML
        raise FMUError(f"{path.name}: modelDescription.xml is not a valid FMI model description: "
                       f"{str(e).splitlines()[0] if str(e) else type(e).__name__}") from None
    version = int(str(md.fmiVersion)[0])
    if version not in (2, 3):
        raise FMUError(f"{path.name} is an FMI {md.fmiVersion} FMU: a process model needs FMI 2.0 or 3.0 Model "
                       "Exchange")
    me = md.modelExchange
    if me is None:
        raise FMUError(f"{path.name} has no Model Exchange interface (only "
                       f"{'Co-Simulation' if md.coSimulation else 'other interfaces'}): a process model integrates "
                       "the FMU's right-hand side, which only Model Exchange gives")
    # fmpy reads FMI 3.0's providesDirectionalDerivatives under its FMI 2.0 name only; that
    # spelling is read too, since some FMI 3.0 FMUs carry it (their derivatives are checked anyway)
    directional = _flag(xml, "providesDirectionalDerivative", *(("providesDirectionalDerivatives",) * (version == 3)))
    return _Description(md, version, me.modelIdentifier, platform if version == 2 else platform_tuple, directional,
                        _flag(xml, "canGetAndSetFMUstate" if version == 2 else "canGetAndSetFMUState"),
                        bool(me.needsCompletedIntegratorStep), {v.name: v for v in md.modelVariables},
                        [d.variable.derivative for d in md.derivatives], [d.variable for d in md.derivatives],
                        {o.variable.name: o.dependencies for o in md.outputs}), data


def _nominal(v) -> float:
    """The nominal value of the variable ``v`` (its type's, else 1), positive."""
    value = getattr(v, "nominal", None) or getattr(getattr(v, "declaredType", None), "nominal", None)
    return abs(float(value)) if value not in (None, "") and float(value) != 0 else 1.0


def _start(v) -> float:
    """The start value of the variable ``v`` (0 if none)."""
    return float(v.start) if v.start not in (None, "") else 0.0


def _names(value, what: str) -> list[str]:
    """``value`` (a name or names) as a list of names, or TypeMismatchError."""
    value = [value] if isinstance(value, str) else list(value)
    if not all(isinstance(v, str) for v in value):
        raise TypeMismatchError(f"{what} must be variable names (strings), got {value!r}")
    return value


def _check_float(d: _Description, name: str, what: str, path: Path):
    """The variable ``name`` of the FMU, a scalar Float64, or the named error."""
    v = d.variables.get(name)
    if v is None:
        raise UnknownNameError(f"{path.name} has no variable {name!r} ({what}); its variables: "
                               f"{', '.join(d.variables)}")
    if v.type not in _FLOAT:
        raise TypeMismatchError(f"{path.name}: {what} {name!r} is {v.type}, not Float64: the process model "
                                "takes Float64 variables only")
    if getattr(v, "dimensions", None):
        raise TypeMismatchError(f"{path.name}: {what} {name!r} is an array variable; the process model takes "
                                "scalar variables only")
    return v


class _Runtime:
    """The compiled model of one configuration in this process (one FMU instance)."""

    def __init__(self, prefix: str, lib: ctypes.CDLL, folder: str, config: _Config, keep: tuple):
        self.prefix, self.lib, self.folder, self.config, self.keep = prefix, lib, folder, config, keep
        self.path = lib._name
        for name, res in (("open", ctypes.c_int), ("message", ctypes.c_char_p), ("failures", ctypes.c_int),
                          ("numerical", ctypes.c_int), ("advance", ctypes.c_int)):
            getattr(lib, prefix + name).restype = res
        self.closed = False

    def call(self, name: str, *args):
        return getattr(self.lib, self.prefix + name)(*args)

    def message(self) -> str:
        return self.call("message").decode(errors="replace")

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self.call("close")
            shutil.rmtree(self.folder, ignore_errors=True)


#: The runtimes of this process by prefix: one FMU instance per configuration, shared by every
#: model object of that configuration (each evaluation starts from the same FMU state).
_RUNTIMES: dict[str, _Runtime] = {}


@atexit.register
def _close_all() -> None:
    for rt in _RUNTIMES.values():
        rt.close()


class FMUProcessModel(DiscreteModel):
    """``x_{k+1} = f(x_k, u_k)``, ``y_k = h(x_k)`` of a Model Exchange FMU.

    Parameters
    ----------
    path : str or Path
        The ``.fmu`` file (FMI 2.0 or 3.0, with Model Exchange).
    dt : float
        Sample period [s].
    measurements : sequence of str
        FMU outputs (read with the inputs at their start values) or continuous states.
    inputs : sequence of str
        The FMU's continuous Float64 inputs the filters set, held over each period (default none).
    parameters : mapping of str to float, optional
        FMU parameters (Float64, fixed or tunable) set by name before initialisation.
    method, substeps : {"rk4", "euler"}, int
        The integrator over one period (default ``"rk4"``) and its steps per period (default 1).
    jacobian : {"auto", "directional", "fd"}
        The Jacobians' source (:data:`JACOBIANS`; default ``"auto"``).
    tolerance : float, optional
        Largest relative error (to ``max(|x|, nominal)``) of one period's integration by step
        doubling at the start values; default the FMU's ``DefaultExperiment`` tolerance, else
        none (only a diverging integration is refused).
    jacobian_check : float
        With directional derivatives: largest relative difference to the FMU's own central
        differences at its start values (default 1e-5).

    Attributes
    ----------
    path : Path
    fmi_version : int
    jacobians : str
        How the Jacobians are computed (also in every run's metadata).
    start : ndarray, shape (nx,)
        The states' start values.
    """

    #: The filters' steps call this model's compiled code, so they cannot be packed into FMUs.
    exportable = False

    def __init__(self, path, dt: float, measurements: Sequence[str], inputs: Sequence[str] = (),
                 parameters: Mapping[str, float] | None = None, method: str = "rk4", substeps: int = 1,
                 jacobian: str = "auto", tolerance: float | None = None, jacobian_check: float = 1e-5):
        substeps = check_method(method, substeps)
        dt = checks.positive(dt, "sample period dt [s]")
        if jacobian not in JACOBIANS:
            raise UnknownNameError(f"jacobian must be one of {JACOBIANS}, got {jacobian!r}")
        self.path = Path(path)
        d, data = _read(self.path)
        self.fmi_version = d.version
        self._description = d
        states = [_check_float(d, s.name, "continuous state", self.path) for s in d.states]
        if not states:
            raise ConfigurationError(f"{self.path.name} has no continuous states: nothing for a filter to estimate")
        ins = [self._input(d, n) for n in _names(inputs, "inputs")]
        meas = [self._measurement(d, n) for n in _names(measurements, "measurements")]
        if not meas:
            raise ConfigurationError(f"{self.path.name}: name at least one measurement (an output or a state)")
        pars = self._parameters(d, parameters)
        if jacobian == "directional" and not d.directional:
            raise FMUError(f"{self.path.name} provides no directional derivatives; use jacobian='fd' or 'auto'")
        directional = jacobian != "fd" and d.directional
        self.method, self.substeps = method, substeps
        self.start = np.array([_start(v) for v in states])
        self._u_start = np.array([_start(v) for v in ins])
        settings = dict(dt=repr(dt), method=method, substeps=substeps, directional=directional,
                        inputs=[v.name for v in ins], measurements=meas, parameters=sorted(pars.items()))
        digest = hashlib.sha256(data + repr(settings).encode()).hexdigest()[:20]
        self._rt = _RUNTIMES.get(f"fmumodel_{digest}_") or self._runtime(d, digest, dt, states, ins, meas, pars,
                                                                         directional)
        self.jacobians = ("the FMU's directional derivatives" if directional else
                          "central differences of the FMU's derivatives (steps from the states' nominal values)") \
            + f", through the stages of {method} (the exact derivative of the discrete map)"
        x, u = ca.SX.sym("x", len(states)), ca.SX.sym("u", len(ins))
        self._ext = {k: ca.external(self._rt.prefix + k, self._rt.path) for k in ("f", "fF", "h", "hH")}
        super().__init__(x, u, self._ext["f"](x, u), self._ext["h"](x), dt, [v.name for v in states],
                         [v.name for v in ins], meas,
                         f"{self.path.name} (FMI {d.version}.0 Model Exchange, {method}, {substeps} substep(s))")
        tol = tolerance if tolerance is not None else getattr(d.md.defaultExperiment, "tolerance", None)
        self._check_accuracy(None if tol in (None, "") else checks.positive(tol, "tolerance"))
        if directional:
            self._check_directional(checks.positive(jacobian_check, "jacobian_check"))

    def _input(self, d: _Description, name: str):
        v = _check_float(d, name, "input", self.path)
        if v.causality != "input":
            raise ConfigurationError(f"{self.path.name}: {name!r} is not an input (its causality is "
                                     f"{v.causality})")
        if v.variability != "continuous":
            raise ConfigurationError(f"{self.path.name}: input {name!r} is {v.variability}: it may change only in "
                                     "Event Mode, which the process model does not enter; a continuous input only")
        return v

    def _measurement(self, d: _Description, name: str) -> str:
        v = _check_float(d, name, "measurement", self.path)
        if any(s.name == name for s in d.states):
            return name
        if v.causality != "output":
            raise ConfigurationError(f"{self.path.name}: measurement {name!r} is neither an output nor a "
                                     f"continuous state (its causality is {v.causality})")
        bad = [u.name for u in d.outputs.get(name) or () if u.causality == "input"]
        if bad:
            raise ConfigurationError(f"{self.path.name}: output {name!r} depends directly on the input(s) "
                                     f"{', '.join(bad)} (feed-through); a filter's measurement h(x) depends on the "
                                     "state only")
        return name

    def _parameters(self, d: _Description, parameters) -> dict[str, float]:
        if parameters is None:
            return {}
        if not isinstance(parameters, Mapping):
            raise TypeMismatchError(f"parameters must be a table of name = value, got {parameters!r}")
        out = {}
        for name, value in parameters.items():
            v = _check_float(d, name, "parameter", self.path)
            if v.causality != "parameter" or v.variability not in ("fixed", "tunable"):
                raise ConfigurationError(f"{self.path.name}: {name!r} is not a parameter that can be set (causality "
                                         f"{v.causality}, variability {v.variability})")
            out[name] = checks.finite(value, f"parameter {name}")
        return out

    def _runtime(self, d: _Description, digest: str, dt: float, states, ins, meas, pars, directional) -> _Runtime:
        """The compiled model of this configuration, its FMU unpacked and instantiated."""
        prefix = f"fmumodel_{digest}_"
        lib, why = compiled_library(shipped("estimators", "c", "fmu_process.c").read_text(), "fmu_process",
                                    ["-O2", "-std=gnu99", "-shared", "-fPIC", "-fvisibility=hidden", f"-I{FMI_HEADERS}",
                                     f"-DFP_PREFIX={prefix}"],
                                    f"{prefix}open", "the compiled process model of an FMU",
                                    "the FMU cannot be a process model", link=["-ldl", "-lm"])
        if lib is None:
            raise BuildError(f"{self.path.name}: the process model of an FMU is compiled C, and it could not be "
                             f"built: {why}")
        lib = ctypes.CDLL(lib._name, mode=ctypes.RTLD_GLOBAL)   # the filters' compiled steps call it by name
        folder = tempfile.mkdtemp(prefix="pendulum_cosim_fmumodel_")
        try:
            with zipfile.ZipFile(self.path) as z:  # its binary for this platform and its resources only
                z.extractall(folder, [n for n in z.namelist() if n.startswith((f"binaries/{d.platform}/",
                                                                                "resources/"))])
        except (OSError, zipfile.BadZipFile) as e:
            shutil.rmtree(folder, ignore_errors=True)
            raise FMUError(f"cannot unpack {self.path.name}: {e}") from None
        config, keep = self._config(d, folder, dt, states, ins, meas, pars, directional)
        rt = _Runtime(prefix, lib, folder, config, keep)
        if not Path(config.library.decode()).exists():
            rt.close()
            raise FMUError(f"{self.path.name} has no binary for this platform ({config.library.decode()} is "
                           "missing)")
        if rt.call("open", ctypes.byref(config)):
            message = rt.message()
            rt.close()
            raise FMUError(f"{self.path.name}: {message}")
        _RUNTIMES[prefix] = rt
        return rt

    def _config(self, d: _Description, folder: str, dt: float, states, ins, meas, pars, directional):
        """The ``_Config`` of the C code, and the arrays it points to."""
        import fmpy

        version, md = d.version, d.md
        library = Path(folder, "binaries", d.platform, d.identifier + fmpy.sharedLibraryExtension)
        resources = Path(folder, "resources")
        names = [s.name for s in states]
        y_state = np.array([names.index(m) if m in names else -1 for m in meas], np.int64)
        arrays = dict(vr_x=[s.valueReference for s in states], vr_dx=[v.valueReference for v in d.derivatives],
                      vr_u=[v.valueReference for v in ins],
                      vr_y=[d.variables[m].valueReference for m, s in zip(meas, y_state) if s < 0],
                      vr_par=[d.variables[n].valueReference for n in pars])
        keep = {k: np.ascontiguousarray(v, np.uint32) for k, v in arrays.items()}
        keep.update(y_state=y_state, nominal_x=np.array([_nominal(s) for s in states]),
                    nominal_u=np.array([_nominal(v) for v in ins]), u_start=self._u_start.copy(),
                    par=np.array(list(pars.values()), float))
        strings = {k: (ctypes.c_char_p * max(len(v), 1))(*[s.encode() for s in v])
                   for k, v in (("x_names", names), ("y_names", list(meas)))}
        c = _Config(version=version, nx=len(states), nu=len(ins), ny=len(meas), nz=int(md.numberOfEventIndicators or 0),
                    npar=len(pars), method=("euler", "rk4").index(self.method), substeps=self.substeps,
                    directional=int(directional), restore=int(d.can_restore),
                    completed_step=int(d.needs_completed_step and d.can_restore), dt=dt,
                    t0=float(getattr(md.defaultExperiment, "startTime", None) or 0.0),
                    library=str(library).encode(), instance_name=d.identifier.encode(), token=md.guid.encode(),
                    resources=(resources.as_uri() if version == 2 else str(resources) + "/").encode()
                    if resources.is_dir() else None,
                    **{k: v.ctypes.data_as(_P(np.ctypeslib.as_ctypes_type(v.dtype))) for k, v in keep.items()},
                    **strings)
        return c, (keep, strings)

    def _advance(self, x: np.ndarray, u: np.ndarray, substeps: int) -> np.ndarray:
        """One period of ``substeps`` steps from ``x`` with ``u``, or the FMU's error."""
        D = _P(ctypes.c_double)
        x, u, out = np.array(x, float), np.array(u, float), np.empty(self.nx)
        if self._rt.call("advance", x.ctypes.data_as(D), u.ctypes.data_as(D), ctypes.c_int64(substeps),
                         out.ctypes.data_as(D)):
            raise self.take_failure() or FMUError(f"{self.path.name}: one period from the start values failed")
        return out

    def _check_accuracy(self, tol: float | None) -> None:
        """Refuse an integration whose error by step doubling at the start values is above ``tol``."""
        n, x, u = self.substeps, self.start, self._u_start
        coarse, fine = self._advance(x, u, n), self._advance(x, u, 2 * n)
        scale = np.maximum(np.maximum(np.abs(fine), np.abs(x)), self._rt.keep[0]["nominal_x"])
        order = 4 if self.method == "rk4" else 1
        err = np.abs(coarse - fine) / scale * (2**order / (2**order - 1))
        i = int(np.argmax(err))
        if not (np.isfinite(err[i]) and (tol is None or err[i] <= tol)):
            need = int(np.ceil(n * (err[i] / tol) ** (1 / order))) if np.isfinite(err[i]) else None
            raise ConfigurationError(
                f"{self.path.name}: {self.method} with {n} substep(s) of {self.dt / n:g} s "
                + (f"errs by {err[i]:.3g} (relative) on {self.state_names[i]} over one period from the start values, "
                   f"above the tolerance {tol:g}: use about {need} substeps" if need else
                   f"diverges on {self.state_names[i]} over one period from the start values: use many more "
                   "substeps, a shorter period or another integrator"))

    def _check_directional(self, tol: float) -> None:
        """Refuse directional derivatives that disagree with the FMU's central differences."""
        x, u = self.start, self._u_start
        steps = np.cbrt(np.finfo(float).eps) * np.maximum(np.abs(x), self._rt.keep[0]["nominal_x"])
        for what, exact, fn in (("f", self.F(x, u), lambda z: self.f(z, u)), ("h", self.H(x), self.h)):
            fd = np.column_stack([(fn(x + s * e) - fn(x - s * e)) / (2 * s) for s, e in zip(steps, np.eye(self.nx))])
            bad = np.abs(exact - fd) > tol * max(1.0, np.abs(fd).max())
            if bad.any():
                i, j = map(int, np.argwhere(bad)[0])
                rows = self.state_names if what == "f" else self.output_names
                raise FMUError(f"{self.path.name}: its directional derivatives disagree with its own finite "
                               f"differences: d{what}/dx of {rows[i]} by {self.state_names[j]} is {exact[i, j]:.10g} "
                               f"from the directional derivatives, {fd[i, j]:.10g} from central differences (relative "
                               f"tolerance {tol:g}); pass jacobian='fd' to use differences")

    def transition(self, x: ca.SX, u: ca.SX) -> tuple[ca.SX, ca.SX]:
        """One call of the compiled map and its tangent."""
        return self._ext["fF"](x, u)

    def measurement(self, x: ca.SX) -> tuple[ca.SX, ca.SX]:
        """One call of the compiled measurement and its Jacobian."""
        return self._ext["hH"](x)

    def take_failure(self) -> Exception | None:
        """NumericalError (a non-finite derivative or measurement) or FMUError (a failed call, an
        event inside a period)."""
        if not self._rt.call("failures"):
            return None
        error = NumericalError if self._rt.call("numerical") else FMUError
        message = self._rt.message()
        self._rt.call("clear")
        return error(f"{self.path.name}: {message}")

    def describe(self) -> str:
        d = self._description
        restore = ("restored with SetFMUState before every evaluation" if d.can_restore else
                   "not restorable (no SetFMUState): every evaluation is a trial step from the start time, "
                   "without CompletedIntegratorStep")
        outputs = [m for m in self.output_names if m not in self.state_names]
        return "\n".join([f"{self.path.name}: FMI {d.version}.0 Model Exchange, model identifier {d.identifier}",
                 f"state ({self.nx}): {', '.join(self.state_names)}",
                 f"inputs ({self.nu}): {', '.join(self.input_names) or 'none'} (held over each period)",
                 f"measurements ({self.ny}): {', '.join(self.output_names)}"
                 + ("; outputs read with the inputs at their start values" if outputs and self.nu else ""),
                 f"period {self.dt:g} s: {self.method}, {self.substeps} substep(s), from t = "
                 f"{self._rt.config.t0:g} s each period (time-invariant)",
                 f"Jacobians: {self.jacobians}",
                 f"FMU state: {restore}",
                 f"events: {int(d.md.numberOfEventIndicators or 0)} event indicator(s), checked at every substep; "
                 "an event inside a period is refused"])

    def __repr__(self):
        return (f"FMUProcessModel({str(self.path)!r}, dt={self.dt}, states={self.state_names}, "
                f"measurements={self.output_names})")

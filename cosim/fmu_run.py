"""One FMU file run on its own, as fmpy's ``simulate_fmu`` runs it, with fmpy's defaults
(``pendulum-cosim run Model.fmu``; the third-party FMUs page of the documentation says how)."""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from fmu_models.errors import ConfigurationError, UnknownNameError
from fmu_models.infra.checks import finite, positive

from .components.sources import Table
from .core.component import PORT_TYPES
from .core.master import Cosimulation
from .fmi.archive import read_description
from .fmi.fmu_component import FMUComponent

__all__ = ["FMUExperiment", "open_fmu", "run_fmu"]

#: The component name of the FMU (its signals are ``fmu.<variable>`` in the master).
NAME = "fmu"


@dataclass
class FMUExperiment:
    """An FMU ready to run (:func:`open_fmu`).

    Attributes
    ----------
    cosim : Cosimulation
        The FMU (component ``fmu``) and its input table (component ``input``), if any.
    start_time, stop_time, step_size : float
        [s] The span and the communication step (Model Exchange: the output grid).
    """

    cosim: Cosimulation
    start_time: float
    stop_time: float
    step_size: float

    def run(self, **kw) -> pd.DataFrame:
        """Run and return the FMU's recorded outputs, one column per variable (its own name);
        keywords go to :meth:`cosim.core.master.Cosimulation.run`."""
        kw.setdefault("signals", [f"{NAME}.*"])
        df = self.cosim.run(self.stop_time, self.start_time, **kw)
        df.columns = [c.removeprefix(f"{NAME}.") for c in df.columns]
        return df


def _times(md, start_time, stop_time, step_size) -> tuple[float, float, float]:
    exp = md.defaultExperiment                     # None, or its attributes None where not given
    t0 = finite(start_time if start_time is not None else getattr(exp, "startTime", None) or 0.0, "start_time [s]")
    t1 = finite(stop_time if stop_time is not None else getattr(exp, "stopTime", None) or t0 + 1.0, "stop_time [s]")
    if t1 <= t0:
        raise ConfigurationError(f"stop_time {t1:g} s must be after start_time {t0:g} s")
    h = step_size if step_size is not None else getattr(exp, "stepSize", None) or (t1 - t0) / 500
    return t0, t1, positive(h, "step_size [s]")


def _input_table(md, inputs, step: float) -> Table:
    """The input table as a source whose columns are typed and interpolated as fmpy does."""
    df = Table.read(inputs, "input")
    variables = {v.name: v for v in md.modelVariables if v.causality == "input"}
    columns = [str(c) for c in df.columns if c != "time"]
    unknown = [c for c in columns if c not in variables]
    if unknown:
        raise UnknownNameError(f"input column {unknown[0]!r} is not an input of the FMU; its inputs: "
                               f"{', '.join(variables) or '(none)'}")
    types = {c: variables[c].type for c in columns if PORT_TYPES.get(variables[c].type) != "real"}
    linear = {c: "linear" for c in columns
              if c not in types and variables[c].variability not in ("discrete", "tunable")}
    return Table("input", step, df, interpolation=linear, types=types)


def open_fmu(path, stop_time: float | None = None, *, start_time: float | None = None,
             step_size: float | None = None, start: Mapping | None = None, inputs=None,
             outputs: Sequence[str] | None = None, interface: str = "auto", rtol: float | None = None,
             isolate: bool = False) -> FMUExperiment:
    """The FMU at ``path`` ready to run, with fmpy's defaults.

    Parameters
    ----------
    path : str or Path
        An FMU file (FMI 1.0, 2.0 or 3.0).
    stop_time, start_time : float, optional
        [s] Default: the FMU's ``DefaultExperiment``, else 0 and start + 1 s.
    step_size : float, optional
        [s] The communication step (Model Exchange: the output grid). Default: the
        ``DefaultExperiment`` stepSize, else a 500th of the span.
    start : mapping, optional
        Parameter and start values by variable name (lists for arrays).
    inputs : str, Path or DataFrame, optional
        The input table (a ``time`` column [s], one column per input).
    outputs : sequence of str, optional
        The variables recorded (outputs, or locals); default every output.
    interface : {"auto", "cs", "me", "se"}
        As :class:`~cosim.fmi.fmu_component.FMUComponent` takes it.
    rtol : float, optional
        Model Exchange: CVODE's relative tolerance (default the ``DefaultExperiment``
        tolerance, else 1e-5).
    isolate : bool
        Run the FMU in a process of its own (a crash of its code is a named error).
    """
    md = read_description(path)
    t0, t1, h = _times(md, start_time, stop_time, step_size)
    tol = rtol if rtol is not None else float(getattr(md.defaultExperiment, "tolerance", None) or 1e-5)
    tables = [_input_table(md, inputs, h)] if inputs is not None else []
    names = tables[0].output_names if tables else None
    fmu = FMUComponent(NAME, Path(path), h, inputs=names, outputs=None if outputs is None else list(outputs),
                       start=dict(start or {}), interface=interface, rtol=tol, isolate=isolate)
    wiring = {f"{NAME}.{c}": f"input.{c}" for c in names or []}
    return FMUExperiment(Cosimulation([fmu, *tables], wiring), t0, t1, h)


def run_fmu(path, stop_time: float | None = None, **options) -> pd.DataFrame:
    """Run the FMU at ``path`` and return its outputs (a DataFrame indexed by ``time`` [s],
    one column per recorded variable).

    Parameters
    ----------
    path, stop_time
        As :func:`open_fmu` takes them.
    **options
        Keywords of :func:`open_fmu`, and ``output_interval`` [s] (a multiple of the step)
        and ``progress`` of :meth:`FMUExperiment.run`.
    """
    run_kw = {k: options.pop(k) for k in ("output_interval", "progress") if k in options}
    return open_fmu(path, stop_time, **options).run(**{"progress": False, **run_kw})

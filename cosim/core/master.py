"""The co-simulation master (:class:`~cosim.core.master.Cosimulation`): steps FMUs and Python
components, each at its own period; each run is a :class:`~cosim.core.run.Run` (orders, periods,
latencies, loops, the native kernel and parallel stepping: the co-simulation page of the documentation).
"""
from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from functools import partial
from pathlib import Path

import numpy as np
import pandas as pd

from fmu_models.errors import ConfigurationError, CosimError, ResourceError, TypeMismatchError, UnknownNameError
from fmu_models.infra.checks import check_unique, finite, positive, positive_int

from .clocking import ClockPlan
from .component import CLOCK, Component, port_kind, ports_compatible, split_port
from .native import ENGINES
from .recording import MemorySink, ParquetSink, select_signals
from .run import Run
from .schedule import Group, Unit, base_step, evaluation_order

__all__ = ["LOOPS", "LOOP_SOLVERS", "ORDERS", "ConfigurationError", "CosimError", "Cosimulation"]

ORDERS = ("auto", "given", "jacobi")
LOOPS = ("refuse", "iterate")
LOOP_SOLVERS = ("newton", "fixed-point")
#: Largest number of base steps of one run.
MAX_STEPS = 10**10
#: Most threads that step FMUs at once (the native kernel's pool).
MAX_THREADS = 64


class Cosimulation:
    """Couples components and runs them (the co-simulation page of the documentation says how).

    Parameters
    ----------
    components : sequence of Component
        FMUs (:class:`~cosim.fmi.fmu_component.FMUComponent`), plant models
        (:class:`~cosim.components.plant_model.ModelComponent`) and Python components.
    connections : mapping or iterable of pairs
        ``{"dst.port": "src.port"}`` or ``[("src.port", "dst.port"), ...]``: each input gets at most
        one source, of a compatible type (:func:`cosim.core.component.ports_compatible`). Every
        input of a Python component must be connected; unconnected FMU inputs keep their start values.
    step_size : float, optional
        Base step [s]; every period must be a multiple of it. Default: the periods' greatest common divisor.
    order : {"auto", "given", "jacobi"}
        Evaluation order within an instant: from the connections and the declared direct
        feedthrough (default), the list order, or every component reading the values before it.
    loops : {"refuse", "iterate"}
        Algebraic loops: refused before the run (default) or solved at each instant.
    loop_tolerance : float
        Iteration stops when every loop signal changes by less than ``loop_tolerance * (1 + |value|)``.
    loop_max_iter : int
        Iteration limit per instant; reaching it stops the run with a CosimError.
    loop_solver : {"newton", "fixed-point"}
        How loops are iterated.
    engine : {"auto", "native", "python"}
        What runs the base-step loop: the native kernel (:mod:`cosim.core.native`), the Python
        loop, or (default) the kernel where it can run; :meth:`describe` says each component's path.
    threads : "auto" or int
        Threads that step the FMUs of an update phase at once in the native kernel
        (:mod:`cosim.core.native_loop`): ``"auto"`` (default) where they pay, N on up to N, 1 serially.

    Attributes
    ----------
    step_size : float
        The base step [s].
    signal_names : list of str
        ``component.port`` of every output, the columns of the results.
    schedule : list of Group
        The evaluation order (see :mod:`cosim.core.schedule`).
    timings : dict
        Wall times [s] of the last run: ``setup``, ``loop``, ``teardown``.
    clock_plan : ClockPlan or None
        The clocks and clock connections, checked (None without clocks).
    clock_ticks : DataFrame or None
        The last run's clock activations (columns ``time`` [s], ``clock``), None without clocks.
    stepping : str
        How the last run stepped its FMUs: serially and why, or on which threads.

    Raises
    ------
    ConfigurationError
        Duplicate names, an unknown component or port (the message lists the valid ones),
        an input connected twice, an unconnected required input, incompatible port types,
        periods that are not multiples of the base step or not commensurate, an algebraic
        loop, a clock the run cannot honour (see :mod:`cosim.core.clocking`).
    """

    def __init__(self, components: Sequence[Component], connections, step_size: float | None = None,
                 order: str = "auto", loops: str = "refuse", loop_tolerance: float = 1e-10,
                 loop_max_iter: int = 50, loop_solver: str = "newton", engine: str = "auto",
                 threads: int | str = "auto"):
        for what, value, valid in (("order", order, ORDERS), ("loops", loops, LOOPS),
                                   ("loop_solver", loop_solver, LOOP_SOLVERS)):
            if value not in valid:
                raise ConfigurationError(f"{what} must be one of {valid}, got {value!r}")
        self.order, self.loops, self.loop_solver = order, loops, loop_solver
        self.loop_tolerance = positive(loop_tolerance, "loop_tolerance")
        self.loop_max_iter = positive_int(loop_max_iter, "loop_max_iter")
        self.components = list(components)
        for c in self.components:
            if not isinstance(c, Component):
                raise TypeMismatchError(f"{c!r} is not a cosim.core.component.Component")
        check_unique((c.name for c in self.components), "duplicate component names:")
        self.by_name = {c.name: c for c in self.components}
        self.connections = self._parse_connections(connections)
        base, self._ratio, self._hyper = base_step({c.name: c.period for c in self.components}, step_size)
        self.step_size = float(base)
        self._layout()
        if order == "auto":
            self.schedule = evaluation_order(self.components, self.connections, loops)
        else:
            self.schedule = [Group((Unit(c, "all", frozenset(c.output_names), frozenset()),))
                             for c in self.components]
        self.clock_plan = ClockPlan.build(self.components, self.connections, self._ratio, base, order)
        self._update_order = self.components if self.clock_plan is None else self.clock_plan.update_order
        self.engine = engine                    # checked by the property, like a later change
        self.threads = threads
        self.stepping = "no run yet"
        self.clock_ticks: pd.DataFrame | None = None
        self.timings: dict[str, float] = {}

    # ---------------------------------------------------------------- validation
    def _port(self, ref: str, direction: str) -> tuple[tuple[str, str], str]:
        """``((component, port), FMI type)`` of the connection end ``ref``."""
        comp, port = split_port(ref, f"{direction} port")
        if comp not in self.by_name:
            raise UnknownNameError(f"unknown component {comp!r} in {ref!r}; components: "
                                   f"{', '.join(self.by_name)}")
        c = self.by_name[comp]
        ports = c.output_ports if direction == "output" else c.input_ports
        found = next((p for p in ports if p.name == port), None)
        if found is None:
            raise UnknownNameError(f"component {comp!r} has no {direction} {port!r}; its "
                                   f"{direction}s: {', '.join(p.name for p in ports) or '(none)'}")
        return (comp, port), found.type

    def _parse_connections(self, connections) -> dict:
        if isinstance(connections, Mapping):
            pairs = [(src, dst) for dst, src in connections.items()]
        else:
            try:
                pairs = [tuple(p) for p in connections]
            except TypeError:
                raise ConfigurationError("connections must be a mapping {dst: src} or pairs (src, dst)") from None
            if any(len(p) != 2 for p in pairs):
                raise ConfigurationError("each connection must be a pair (src, dst)")
        out = {}
        for src, dst in pairs:
            if not isinstance(src, str) or not isinstance(dst, str):
                raise ConfigurationError(f"connection {dst!r} = {src!r}: both ends must be written "
                                         "'component.port' (text)")
            (s, st), (d, dt) = self._port(src, "output"), self._port(dst, "input")
            if d in out:
                raise ConfigurationError(f"input {dst!r} is connected twice "
                                         f"(from {'.'.join(out[d])} and {src})")
            if not ports_compatible(st, dt):
                why = (": a clock connects only to a clock (an output clock to a triggered input clock)"
                       if CLOCK in (st, dt) else " (values would be rounded); convert it in a component")
                raise TypeMismatchError(f"connection {src} -> {dst}: a {st} output cannot drive a {dt} input{why}")
            out[d] = s
        for c in self.components:
            for p in c.required_inputs():
                if (c.name, p) not in out:
                    signals = [f"{o.name}.{q}" for o in self.components for q in o.output_names]
                    raise ConfigurationError(
                        f"input {c.name}.{p} is not connected; available signals: {', '.join(signals)}")
        return out

    # ---------------------------------------------------------------- layout
    def _layout(self):
        pairs = [(c.name, p) for c in self.components for p in c.output_names]
        self._slots = slots = {pair: i for i, pair in enumerate(pairs)}
        sizes = [len(c.output_names) for c in self.components]
        self._out_slices = {c.name: slice(end - size, end)
                            for c, size, end in zip(self.components, sizes, itertools.accumulate(sizes))}
        self.signal_names = [f"{c}.{p}" for (c, p) in pairs]
        self.signal_types = [p.type for c in self.components for p in c.output_ports]
        self._inputs = {}           # per component, where its connected inputs are: a slice, else indices
        for c in self.components:
            ports = [p for p in c.input_names if (c.name, p) in self.connections]
            srcs = [self.connections[(c.name, p)] for p in ports]
            c.use_inputs(ports, [(".".join(s), self.signal_types[slots[s]]) for s in srcs])
            idx = np.array([slots[s] for s in srcs], dtype=np.intp)
            contiguous = len(idx) and np.all(np.diff(idx) == 1)
            self._inputs[c.name] = slice(int(idx[0]), int(idx[-1]) + 1) if contiguous else idx

    # ---------------------------------------------------------------- engine
    @property
    def engine(self) -> str:
        """The loop that runs the co-simulation (see the constructor; ``"native"`` is refused where
        the kernel cannot run it); may be changed between runs."""
        return self._engine

    @engine.setter
    def engine(self, value: str) -> None:
        if value not in ENGINES:
            raise ConfigurationError(f"engine must be one of {ENGINES}, got {value!r}")
        why = self._whole_run_python(value)
        if value == "native" and why is not None:
            raise ConfigurationError(f"engine='native' cannot run this co-simulation: {why}; use engine='auto'")
        self._engine = value

    @property
    def threads(self) -> int | str:
        """Threads that step the FMUs at once, ``"auto"`` or a whole number from 1 to
        :data:`MAX_THREADS` (see the constructor); may be changed between runs."""
        return self._threads

    @threads.setter
    def threads(self, value: int | str) -> None:
        if value != "auto" and (isinstance(value, bool) or not isinstance(value, (int, np.integer))
                                or not 1 <= value <= MAX_THREADS):
            raise ConfigurationError(f"threads must be 'auto' or a whole number from 1 to {MAX_THREADS}, got {value!r}")
        self._threads = value if value == "auto" else int(value)

    def _whole_run_python(self, engine: str | None = None) -> str | None:
        """Why every call of a run with ``engine`` (default the current one) takes the Python path, or None."""
        if (engine or self.engine) == "python":
            return "engine='python'"
        if self.order == "jacobi":
            return "order='jacobi' (every component reads the values before the instant)"
        if self.clock_plan is not None:
            return "the run has clocks"
        return None

    def component_paths(self) -> dict[str, str | None]:
        """Per component, why its calls run in Python (None: in the native kernel)."""
        whole = self._whole_run_python()
        return {c.name: whole or (c.native_reason() if callable(getattr(c, "native_reason", None))
                                  else "a Python component") for c in self.components}

    # ---------------------------------------------------------------- description
    def describe(self) -> str:
        """The schedule in words: base step, evaluation order, and for every connection
        when the value is read and how old it can be."""
        h = self.step_size
        lines = [f"base step {h:g} s; the pattern of due components repeats every {self._hyper} "
                 f"base step(s) ({self._hyper * h:g} s); order: {self.order}; loops: {self.loops}", "",
                 "components (period; what an output at t means):"]
        lines += [f"  {c.name:16s} every {c.period:g} s; {c.timing()}" for c in self.components]
        lines += ["", "evaluation order of the outputs at an instant (components not due hold theirs):"]
        loop = "   [algebraic loop, solved by iteration]"
        lines += [f"  {i}. {' + '.join(map(str, g.units))}{loop if g.loop else ''}"
                  for i, g in enumerate(self.schedule, 1)]
        if self.clock_plan is not None:
            lines += ["", *self.clock_plan.describe_lines()]
        whole = self._whole_run_python()
        lines += ["", f"engine: {self.engine}; " + (f"every call runs in Python ({whole})" if whole else
                  "the base-step loop runs in the native kernel (when a C compiler is available), calls "
                  "marked Python return to the interpreter:")]
        if whole is None:
            lines += [f"  {name:16s} " + ("native" if why is None else f"Python ({why})")
                      for name, why in self.component_paths().items()]
            if any(g.loop for g in self.schedule):
                lines.append("  algebraic loops: Python (solved by iteration)")
            lines += self._threads_lines()
        position = {}                                   # each component's first group
        for i, g in enumerate(self.schedule):
            for u in g.units:
                position.setdefault(u.comp.name, i)
        lines += ["", "connections (latency = age of the value when it is used):"]
        lines += [f"  {sn}.{sp} -> {dn}.{dp}: {self._latency((sn, sp), (dn, dp), position)}"
                  for (dn, dp), (sn, sp) in self.connections.items()]
        return "\n".join(lines)

    def _latency(self, source: tuple[str, str], target: tuple[str, str], position: dict) -> str:
        """When the input ``target`` reads the output ``source`` and how old the value is
        (``position``: each component's first group in the evaluation order)."""
        (sn, sp), (dn, dp) = source, target
        src, dst, plan = self.by_name[sn], self.by_name[dn], self.clock_plan
        ft = any(dp in deps for deps in dst.feedthrough.values())
        if plan is not None and self.signal_types[self._slots[source]] == CLOCK:       # only a clock drives a clock
            return plan.connection_text(f"{sn}.{sp}", f"{dn}.{dp}")
        clocks = plan is not None and getattr(dst, "port_clocks", None) and dst.port_clocks(dp)
        if clocks:
            return plan.clocked_text(dn, clocks, ft)
        if self.order == "jacobi":
            when = "read at t from the values before t: one base step old when both are due"
        elif ft:
            before = position.get(sn, -1) <= position.get(dn, -1) or sn == dn
            when = ("direct feedthrough, read at t after the source's output at t: latency 0" if before
                    else "read at t before the source's output at t (list order): one source period old")
        else:
            when = ("consumed at t by update (no direct feedthrough): "
                    + ("held over the component's step [t, t + period]" if dst.holds_inputs
                       else "used for the component's next instant"))
        if src.period > dst.period or self._ratio[dn] % self._ratio[sn]:
            when += f"; {sn} updates every {src.period:g} s, held in between (zero-order hold)"
        return when

    def _threads_lines(self) -> list[str]:
        """The lines of :meth:`describe` on parallel stepping."""
        paths = self.component_paths()
        fmus = [c for c in self.components if paths[c.name] is None and getattr(c, "md", None) is not None]
        once = [c.name for c in fmus if getattr(c.md.coSimulation, "canBeInstantiatedOnlyOncePerProcess", False)]
        how = {"auto": "where the FMU steps, timed on threads at the start (and now and then), pay for them",
               1: "never (serial)"}
        lines = ["", f"parallel stepping (threads={self.threads}): "
                 + how.get(self.threads, f"on up to {self.threads} threads") + "; FMUs that may step at once: "
                 + (", ".join(c.name for c in fmus) if len(fmus) >= 2 and self.threads != 1 else "none")]
        if len(once) >= 2:
            lines.append(f"  never at once (canBeInstantiatedOnlyOncePerProcess): {', '.join(once)}")
        lines.append(f"  last run: {self.stepping}")
        return lines

    def sample_counts(self, stop_time: float, start_time: float = 0.0) -> dict[str, int]:
        """How many times each component computes its outputs in a run (a planning aid)."""
        n = round((stop_time - start_time) / self.step_size)
        return {c.name: n // self._ratio[c.name] + 1 for c in self.components}

    # ---------------------------------------------------------------- running
    def _steps(self, stop_time: float, start_time: float, output_interval) -> tuple[int, int]:
        """The run's base steps and the base steps between rows, checked."""
        stop, start = finite(stop_time, "stop_time [s]"), finite(start_time, "start_time [s]")
        n = self._multiple(stop - start, "stop_time - start_time",
                           f"stop_time {stop!r} s - start_time {start!r} s = {stop - start!r} s")
        if n > MAX_STEPS:
            raise ResourceError(f"{n} base steps of {self.step_size:g} s (more than {MAX_STEPS})")
        for c in self.components:
            c.check_run(start, stop)
        if output_interval is None:
            return n, 1
        interval = finite(output_interval, "output_interval [s]")
        return n, self._multiple(interval, "output_interval", f"output_interval {interval!r} s")

    def _multiple(self, span: float, what: str, shown: str) -> int:
        """``span`` [s] as a whole number of base steps, up to the rounding of the floats
        that gave it (a relative 1e-9 of the base step): Roberts' 1e-5 .. 1e8 s in steps
        of 9999999.999999 s is 10 steps, though no float sum says so exactly."""
        h = self.step_size
        ratio = span / h
        n = round(ratio) if np.isfinite(ratio) else 0
        if n < 1 or abs(span - n * h) > 1e-9 * h + 4 * np.finfo(float).eps * abs(span):
            near = f"; the nearest is {max(n, 1)} steps = {max(n, 1) * h!r} s" if np.isfinite(ratio) else ""
            raise ConfigurationError(f"{what} must be a positive whole number of base steps of {h!r} s: "
                                     f"{shown} is {ratio!r} steps{near}")
        return int(n)

    def run(self, stop_time: float, start_time: float = 0.0, *, signals=None,
            output_interval: float | None = None, progress: bool | None = None) -> pd.DataFrame:
        """Run from ``start_time`` to ``stop_time`` [s] and return the recorded signals.

        Parameters
        ----------
        stop_time, start_time : float
            [s]; the span must be a multiple of the base step.
        signals : str or sequence of str, optional
            Glob patterns of the signals to record (e.g. ``["plant.*", "ekf.x"]``); default all.
        output_interval : float, optional
            Record every this many seconds (a multiple of the base step); default every base step.
        progress : bool, optional
            Show a progress bar; default: shown when the run takes more than 2 s.

        Returns
        -------
        DataFrame indexed by ``time`` with one column per recorded signal.

        Raises
        ------
        CosimError
            A component raised, an FMU returned discard/error/fatal, or a signal became NaN or
            inf; the message names the component and the time, ``error.results`` holds the rows
            so far. FMU instances are always freed.
        Interrupted
            Ctrl-C: ``error.partial`` holds the rows recorded so far.
        ResourceError
            The recording would not fit in memory (the message gives the numbers).
        """
        return self._run(MemorySink, stop_time, start_time, signals, output_interval, progress)

    def run_to_parquet(self, path, stop_time: float, start_time: float = 0.0, *, signals=None,
                       output_interval: float | None = None, progress: bool | None = None,
                       chunk_rows: int = 8192) -> Path:
        """Run like :meth:`run`, streaming the rows to the Parquet file ``path`` in chunks
        of ``chunk_rows`` (constant memory; a failed run leaves ``<name>.partial.parquet``); returns the path."""
        return self._run(partial(ParquetSink, path, chunk_rows=chunk_rows), stop_time, start_time, signals,
                         output_interval, progress)

    def _run(self, sink_type, stop_time, start_time, signals, output_interval, progress):
        """A run (see :mod:`cosim.core.run`) recording into ``sink_type(columns, n_rows, t0, step,
        every, int_columns=...)``; the arguments as :meth:`run` takes them."""
        n, m = self._steps(stop_time, start_time, output_interval)
        sel = select_signals(self.signal_names, signals)
        exact = {pos: ("Int64" if self.signal_types[i] == CLOCK else self.signal_types[i]) for pos, i in enumerate(sel)
                 if port_kind(self.signal_types[i]) in ("integer", "clock")}      # integer columns, kept exact
        sink = sink_type([self.signal_names[i] for i in sel], n // m + 2, float(start_time), self.step_size, m,
                         int_columns=exact)
        return Run(self, sink, sel, n, m, float(start_time), progress).execute()
